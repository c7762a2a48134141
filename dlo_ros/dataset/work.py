"""What a worker does for a data set: solve one chunk of samples into rows (any executor).

:func:`solve_samples` runs in a worker process (a local pool, or a Dask worker): it takes the
process's solver of the scene (``parallel/batch.held_solver``: built once per structure, holding
the equilibrium at the scene's poses) and answers each sample as a query (``commit=False``), so a
sample's answer depends only on the scene, its own targets and the plan's ``start``, never on the
worker, the chunk or the samples before it.
"""

from __future__ import annotations

import pickle
from typing import Any

from ..solver.parallel import batch
from ..solver.results.result import ShapeResult
from .rows import sample_row


def solve_samples(
    scene: bytes, first: int, targets: list[dict], start: str, compile: str = "on_query"
) -> list[dict[str, Any]]:
    """Return the rows of samples ``first`` … ``first + len(targets) - 1``.

    ``scene``: a ``batch.scene_payload``; ``start``: 'held' (from the held equilibrium) or 'cold'
    (from the initial guess).  A solve that raises answers ``failed`` with the exception's text.
    """
    _, problem, _ = pickle.loads(scene)
    rows = []
    with batch.worker_lock:  # one CasADi solver is never called from two threads at once
        solver = batch.held_solver(scene, compile)
        for k, poses in enumerate(targets):
            try:
                result = solver.solve(poses, warm=start == "held", commit=False)
            # any exception: one sample must not lose the chunk's other answers
            except Exception as exc:  # noqa: BLE001
                result = ShapeResult(status="failed", message=f"{type(exc).__name__}: {exc}")
            rows.append(sample_row(first + k, poses, result, problem, start))
    return rows
