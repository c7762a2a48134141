"""What a worker does for a data set: solve one chunk of samples into rows (any executor).

:func:`solve_samples` runs in a worker process (a local pool, or a Dask worker): it takes the
process's solver of the scene (``parallel/batch.held_solver``: built once per structure, holding
the equilibrium at the scene's poses) and answers each sample as a query (``commit=False``), so a
sample's answer depends only on the scene, its own targets and the plan's ``start``, never on the
worker, the chunk or the samples before it.  With ``start: previous`` a chunk is a stream instead:
each sample starts from the answer of the one before it in the plan (:func:`_along`).
"""

from __future__ import annotations

import pickle
from dataclasses import replace
from typing import Any

from ..solver.parallel import batch
from ..solver.parallel.batch import scene_payload
from ..solver.results.result import ShapeResult
from .materials import with_values
from .rows import sample_row


def solve_samples(
    scene: bytes,
    first: int,
    targets: list[dict],
    start: str,
    compile: str = "on_query",
    values: list[dict[str, float]] | None = None,
) -> list[dict[str, Any]]:
    """Return the rows of samples ``first`` … ``first + len(targets) - 1``.

    ``scene``: a ``batch.scene_payload``; ``start``: 'held' (from the held equilibrium), 'cold'
    (from the initial guess) or 'previous' (:func:`_along`); ``values``: each sample's string
    values (``materials.py``; the held equilibrium is then the scene's with those values).  A
    solve that raises answers ``failed`` with the exception's text.
    """
    values = values or [{} for _ in targets]
    if start == "previous":
        return _along(scene, first, targets, values, compile)
    factory, problem, options = pickle.loads(scene)
    rows = []
    held: tuple[bytes, Any] | None = None  # (payload, its solver): looked up when it changes
    with batch.worker_lock:  # one CasADi solver is never called from two threads at once
        for k, poses in enumerate(targets):
            own = with_values(problem, values[k])
            payload = scene if not values[k] else scene_payload(factory, own, options)
            try:
                if held is None or held[0] != payload:
                    held = (payload, batch.held_solver(payload, compile))
                result = batch.answer(held[1], poses, warm=start == "held")
            except Exception as exc:  # noqa: BLE001 - its held equilibrium could not be made
                held = None
                result = _failed(exc)
            rows.append(sample_row(first + k, poses, result, own, start))
    return rows


def _along(
    scene: bytes, first: int, targets: list[dict], values: list[dict], compile: str
) -> list[dict[str, Any]]:
    """Return the rows of a chunk solved as a stream: each sample from the one before it.

    A new solver of the scene per chunk (its first sample streamed from the scene's equilibrium,
    row ``start`` 'held'; the others 'previous'; a sample's string values set before its solve),
    with checks inline and no time limit, so that the chunk's answers depend only on the plan: the
    branch a sample lands on is the one its neighbour along the plan's order leads to.  The first
    sample, and any the stream answers 'unverified' (its model not yet refined for the shape),
    are solved again with the checks run at once (``check_now``: auto refines until they pass).
    """
    factory, problem, options = pickle.loads(scene)
    options = replace(options, update_time_limit=0.0)
    rows = []
    # a stream commits every sample: 'on_query' would never see a query, so compile as a stream
    mode = "background" if compile == "on_query" else compile
    solver = batch.build_solver(factory, problem, options, mode, "sync")
    try:
        solver.solve()
        for k, poses in enumerate(targets):
            own, label = with_values(problem, values[k]), "previous" if k else "held"
            try:
                if values[k]:
                    solver.set_problem(own)
            except Exception as exc:  # noqa: BLE001 - as in solve_samples
                rows.append(sample_row(first + k, poses, _failed(exc), own, label))
                continue
            # the chunk's first sample, and any the stream answers unverified, checked now
            result = batch.answer(solver, poses, commit=True, check_now=k == 0)
            if result.status == "unverified":
                result = batch.answer(solver, poses, commit=True, check_now=True)
            rows.append(sample_row(first + k, poses, result, own, label))
    finally:
        solver.close()
    return rows


def _failed(exc: Exception) -> ShapeResult:
    """Return the 'failed' answer naming what a sample's set-up raised."""
    return ShapeResult(status="failed", message=f"{type(exc).__name__}: {exc}")
