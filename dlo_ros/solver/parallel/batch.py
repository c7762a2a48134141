"""Many independent shape queries at once, on every core (or a cluster).

``query_many(factory, problem, options, targets)`` answers each entry of ``targets`` (grip poses,
as for ``solve``) as a solver that ``factory`` builds of ``problem``/``options``, holding the shape
at ``problem``'s grip poses, answers ``solve(poses, commit=False)``, but in worker processes: the
targets are cut into one contiguous chunk per worker; each worker solves the held shape once (cold,
from the scene's poses) and starts every query of the chunk from it, so an answer does not depend
on which worker gave it or on the other queries.  The caller's solver and its warm start are never
touched.  (The caller's own held shape came from its stream; where a scene has several equilibria
at the held poses, the worker's cold one can be another branch.)

Workers keep their solvers between calls (``_WORKER_SOLVERS``, keyed by the scene's structure, at
most ``WORKER_SOLVERS`` per process), so only the first call pays for the build.  By default
(``compile='on_query'``) a worker whose queries find a model's compiled derivatives missing from
the cache compiles them in a background thread while its queries go on interpreted, one compiler
per worker, each library built once (one build at a time per cache directory; the other workers
wait for it and load it): a first batch on an empty cache reaches compiled speed within seconds,
where workers that never compiled stayed interpreted for the pool's life
(bench/results/queries_first_batch.md).
``compile='cached'`` (the node's query workers: its stream comes first) uses only what the cache
holds, looking again every second.

``executor``: any ``concurrent.futures.Executor`` whose workers can import dlo_ros — by default a
process pool of ``os.cpu_count()`` spawned workers kept for the life of the process
(:func:`default_executor`); a Dask ``distributed`` client's ``client.get_executor()`` runs the same
call on a cluster.  Threads would not help: an interpreted CasADi call holds the GIL.

``factory`` (a :data:`~dlo_ros.solver.protocol.SolverFactory`: ``make_solver``, or a solver class)
is the caller's: this module sits beside the solvers and imports none of them.  The pool helpers of
:mod:`.worker_pool` that callers pass as ``executor`` are re-exported here.
"""

from __future__ import annotations

import atexit
import collections
import dataclasses
import inspect
import os
import pickle
import threading
import time
import warnings
from concurrent.futures import CancelledError, Executor, Future
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Mapping, Sequence

from ...model.problem import Problem
from ..options import SolverOptions
from ..protocol import Solver, SolverFactory
from ..results.result import ShapeResult
from ..update.inputs import structure_key
from .worker_pool import (
    BACKGROUND_NICE,
    MODULE_LEVEL_CALL,
    TaskTimeout,
    WorkerDied,
    WorkerPool,
    process_pool,
    starting_as_worker,
    stop_pool,
)

__all__ = [
    "BACKGROUND_NICE",
    "WORKER_SOLVERS",
    "answer",
    "build_solver",
    "default_executor",
    "held_solver",
    "process_pool",
    "query_many",
    "scene_payload",
    "solve_chunk",
    "stop_pool",
    "worker_lock",
]


#: Solvers a worker process keeps (least recently used dropped first).
WORKER_SOLVERS = 2

_WORKER_SOLVERS: collections.OrderedDict[bytes, tuple[bytes, Solver]] = collections.OrderedDict()
_default: WorkerPool | None = None
_default_lock = threading.Lock()
#: a thread executor's workers share this process's solvers: one at a time
worker_lock = threading.Lock()


def default_executor() -> WorkerPool:
    """Return the pool ``query_many`` uses when given none.

    A :class:`WorkerPool` of ``os.cpu_count()`` workers, replaced when a worker dies or a call
    times out, stopped at exit.
    """
    global _default
    with _default_lock:
        if _default is None:
            _default = WorkerPool()
            atexit.register(_default.stop, 5.0)
        return _default


def scene_payload(factory: SolverFactory, problem: Problem, options: SolverOptions) -> bytes:
    """Return the pickled (factory, problem, options) :func:`solve_chunk` takes."""
    return pickle.dumps((factory, problem, options), protocol=pickle.HIGHEST_PROTOCOL)


def query_many(
    factory: SolverFactory,
    problem: Problem,
    options: SolverOptions | None,
    targets: Sequence[Mapping],
    executor: Executor | None = None,
    *,
    chunks: int | None = None,
    compile: str = "on_query",
    timeout: float | None = None,
) -> list[ShapeResult]:
    """Return one ShapeResult per entry of ``targets``, in order (see the module docstring).

    Each target is a ``{grip name: pose}`` mapping, as for ``solve``; ``factory`` builds the
    workers' solvers of ``problem``/``options`` (``make_solver``, or a solver class).  ``chunks``:
    how many pieces the targets are cut into (default: the executor's worker count, or
    ``os.cpu_count()``).  A query that fails answers with its status and message, as ``solve``
    does; the others are unaffected.

    ``timeout`` [s] (default None: no limit): the longest the call waits.  Queries not answered by
    then answer ``failed`` with a message starting "timeout:"; on a :class:`WorkerPool` (the
    default executor) their workers are killed and replaced.  Queries whose worker died answer
    ``failed`` naming the cause; the default pool is rebuilt for the next call.  The call never
    hangs on a dead worker.  Called from a script's top level (no ``if __name__ == "__main__":``),
    the spawned workers run that call again while they start: there it answers ``failed`` at once
    with a warning that says so, and the workers go on to serve the script's own call.
    """
    options = options or SolverOptions()
    problem.validate()
    options.validate()
    queries = [dict(t) for t in targets]
    if not queries:
        return []
    if executor is None and starting_as_worker():
        warnings.warn(f"query_many: {MODULE_LEVEL_CALL}", RuntimeWarning, stacklevel=2)
        message = f"not solved: query_many {MODULE_LEVEL_CALL}"
        return [ShapeResult(status="failed", message=message) for _ in queries]
    executor = executor or default_executor()
    spans = _spans(executor, chunks, len(queries))
    payload = scene_payload(factory, problem, options)
    deadline = None if timeout is None else time.monotonic() + float(timeout)
    futures: list[Future | BaseException] = []
    for a, b in spans:
        try:
            if isinstance(executor, WorkerPool):
                futures.append(
                    executor.submit(solve_chunk, payload, queries[a:b], compile, timeout=timeout)
                )
            else:
                futures.append(executor.submit(solve_chunk, payload, queries[a:b], compile))
        except (
            BrokenProcessPool,
            RuntimeError,
        ) as exc:  # a given executor that is broken or shut down
            futures.append(exc)
    results: list[ShapeResult] = []
    for (a, b), future in zip(spans, futures):
        results.extend(_answers(future, b - a, executor, deadline, timeout))
    return results


def _spans(executor: Executor, chunks: int | None, count: int) -> list[tuple[int, int]]:
    """Return the [a, b) index ranges the ``count`` targets are cut into, one per chunk."""
    n = (
        chunks
        or getattr(executor, "max_workers", None)
        or getattr(executor, "_max_workers", None)
        or os.cpu_count()
        or 1
    )
    n = max(1, min(int(n), count))
    bounds = [round(i * count / n) for i in range(n + 1)]
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def _answers(
    future: Future | BaseException,
    count: int,
    executor: Executor,
    deadline: float | None,
    timeout: float | None,
) -> list[ShapeResult]:
    """Return the ``count`` answers of one chunk: its worker's, or ``failed`` ones saying why."""
    if isinstance(future, BaseException):
        message = f"{type(future).__name__}: {future}"
        return [ShapeResult(status="failed", message=message) for _ in range(count)]
    try:
        left = None if deadline is None else max(0.0, deadline - time.monotonic())
        # a WorkerPool's futures time out by themselves (and replace the workers)
        return list(
            future.result(None if left is None or isinstance(executor, WorkerPool) else left)
        )
    except TimeoutError as exc:  # TaskTimeout, or concurrent.futures' on another executor
        future.cancel()
        message = (
            str(exc)
            if isinstance(exc, TaskTimeout)
            else f"timeout: no answer within {timeout:g} s"
        )
    except (WorkerDied, BrokenProcessPool, CancelledError) as exc:
        message = f"{type(exc).__name__}: {exc}"
    return [ShapeResult(status="failed", message=message) for _ in range(count)]


def solve_chunk(
    scene: bytes, targets: list[dict], compile: str = "on_query", checks: str = "sync"
) -> list[ShapeResult]:
    """Solve ``targets`` in a worker with this process's solver of the ``scene`` payload.

    ``scene`` is a :func:`scene_payload`: the pickled (factory, problem, options).  Each target is
    solved from the held shape at the scene's poses (``commit=False``); the solver is kept for the
    next call.  ``checks``: the a-posteriori checks of an auto solver (a factory that takes
    ``checks``): 'sync' for a batch (a scene solved once, checked before its queries), 'background'
    for a node's workers, whose held shape follows the stream: a check due on one of its updates
    then runs beside the queries, not in front of them.
    """
    factory, problem, options = pickle.loads(scene)
    with worker_lock:  # one CasADi/IPOPT solver must never be called from two threads at once
        solver = _worker_solver(scene, factory, problem, options, compile, checks)
        results = [answer(solver, poses) for poses in targets]
    return results


def answer(solver: Solver, poses: Mapping, **solve: Any) -> ShapeResult:
    """Return ``solver.solve(poses, **solve)`` (a query by default), or 'failed' naming why.

    One bad target must not lose a chunk's other answers.
    """
    try:
        return solver.solve(poses, **{"warm": True, "commit": False, **solve})
    except Exception as exc:  # noqa: BLE001 - any exception: reported in the answer
        return ShapeResult(status="failed", message=f"{type(exc).__name__}: {exc}")


def held_solver(scene: bytes, compile: str = "on_query", checks: str = "sync") -> Solver:
    """Return this process's solver of the ``scene`` payload, holding the shape at its poses.

    The solver :func:`solve_chunk` answers with (kept between calls, ``WORKER_SOLVERS`` per
    process).  The caller holds :data:`worker_lock` while it uses it.
    """
    factory, problem, options = pickle.loads(scene)
    return _worker_solver(scene, factory, problem, options, compile, checks)


def build_solver(
    factory: SolverFactory, problem: Problem, options: SolverOptions, compile: str, checks: str
) -> Solver:
    """Return ``factory(problem, options, compile=compile)``, with ``checks`` if it takes them.

    ``make_solver`` and ``AutoShapeSolver`` take ``checks``; a fixed model (``ShapeSolver``) has
    none.
    """
    if "checks" in inspect.signature(factory).parameters:
        return factory(problem, options, compile=compile, checks=checks)
    return factory(problem, options, compile=compile)


def _worker_solver(
    scene: bytes,
    factory: SolverFactory,
    problem: Problem,
    options: SolverOptions,
    compile: str,
    checks: str,
) -> Solver:
    """Return this process's solver for the scene's structure, holding the shape at its poses.

    Built once per structure (``structure_key``), factory and checks; when the scene's values or
    poses change, it is re-solved from its previous shape.  At most ``WORKER_SOLVERS`` are kept.
    """
    key = pickle.dumps(
        (factory, structure_key(problem, options), options, checks),
        protocol=pickle.HIGHEST_PROTOCOL,
    )
    entry = _WORKER_SOLVERS.pop(key, None)
    if entry is None:
        solver = build_solver(factory, problem, options, compile, checks)
        solver.solve()  # the held shape: every query starts from it
    else:
        values, solver = entry
        if values != scene:
            _, held, _ = pickle.loads(values)
            if _grips_moved_only(held, problem):
                # only the grips moved (a node's stream did): a warm update, as the stream's, which
                # runs auto's checks every recheck_every updates; set_problem would check the model
                # now
                solver.solve({g.name: g.pose for g in problem.grips})
            else:
                solver.set_problem(problem)
                solver.solve()
    _WORKER_SOLVERS[key] = (scene, solver)
    while len(_WORKER_SOLVERS) > WORKER_SOLVERS:
        _, (_, old) = _WORKER_SOLVERS.popitem(last=False)
        old.close()
    return solver


def _grips_moved_only(old: Problem, new: Problem) -> bool:
    """Whether ``new`` differs from ``old`` in grip poses at most.

    Compared field by field: pickles of the whole problems can differ where only the sharing of
    equal objects does.
    """

    def rest(grip) -> bytes:
        return pickle.dumps(
            [getattr(grip, f.name) for f in dataclasses.fields(grip) if f.name != "pose"]
        )

    if len(old.grips) != len(new.grips) or any(
        rest(a) != rest(b) for a, b in zip(old.grips, new.grips)
    ):
        return False
    return all(
        pickle.dumps(getattr(old, f.name)) == pickle.dumps(getattr(new, f.name))
        for f in dataclasses.fields(new)
        if f.name != "grips"
    )
