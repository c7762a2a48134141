"""Many independent shape queries at once, on every core (or a cluster).

``query_many(problem, options, targets)`` answers each entry of ``targets`` (grip poses, as for
``solve``) as a solver of ``problem``/``options`` holding the shape at ``problem``'s grip poses answers
``solve(poses, commit=False)``, but in worker processes: the targets are cut into one contiguous
chunk per worker; each worker solves the held shape once (cold, from the scene's poses) and starts
every query of the chunk from it, so an answer does not depend on which worker gave it or on the
other queries.  The caller's solver and its warm start are never touched.  (The caller's own held
shape came from its stream; where a scene has several equilibria at the held poses, the worker's
cold one can be another branch.)

Workers keep their solvers between calls (``_WORKER_SOLVERS``, keyed by the scene's structure, at most
``WORKER_SOLVERS`` per process), so only the first call pays for the build.  Workers never start a C
compiler: they use compiled derivatives only when the cache already has them (``compile='cached'``).

``executor``: any ``concurrent.futures.Executor`` whose workers can import dlo_ros — by default a
process pool of ``os.cpu_count()`` spawned workers kept for the life of the process
(:func:`default_executor`); a Dask ``distributed`` client's ``client.get_executor()`` runs the same
call on a cluster.  Threads would not help: an interpreted CasADi call holds the GIL.
"""
from __future__ import annotations

import atexit
import collections
import dataclasses
import multiprocessing
import os
import pickle
import threading
from concurrent.futures import Executor, ProcessPoolExecutor
from typing import Mapping, Sequence

from ..model.problem import Problem
from .options import SolverOptions
from .result import ShapeResult

#: The nice value added to a node's query and fit workers (``process_pool(background=True)``), so that
#: the stream comes first on a shared core (bench/results/soak_3_clients.md against soak_no_queries.md).
#: Not SCHED_IDLE: it favours the stream more, but starves the workers whenever both cores are busy
#: (a planner beside the node, or CI's two test processes), and their queries would time out.
BACKGROUND_NICE = 10

#: Solvers a worker process keeps (least recently used dropped first).
WORKER_SOLVERS = 2

_WORKER_SOLVERS: "collections.OrderedDict[bytes, tuple[bytes, object]]" = collections.OrderedDict()
_default: ProcessPoolExecutor | None = None
_default_lock = threading.Lock()
_worker_lock = threading.Lock()  # a thread executor's workers share this process's solvers: one at a time


def process_pool(workers: int | None = None, background: bool = False) -> ProcessPoolExecutor:
    """A process pool for :func:`solve_chunk`: ``workers`` (default ``os.cpu_count()``) processes started
    with 'spawn' (a fork of a process with CasADi and DDS threads is unsafe) that ignore SIGINT (a
    Ctrl-C reaches the whole process group; the parent decides how to stop).  ``background``: the
    workers run BACKGROUND_NICE above the caller, so that a node's stream comes first on a shared core."""
    return ProcessPoolExecutor(max_workers=workers or os.cpu_count() or 1,
                               mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init,
                               initargs=(bool(background),))


def stop_pool(pool: ProcessPoolExecutor, timeout: float = 5.0) -> bool:
    """Stop ``pool`` now: pending work is cancelled, work in flight is abandoned (its workers are
    terminated), and the pool's manager thread is joined, at most ``timeout`` s; True if it ended.

    Joining matters: CPython 3.11's exit hook wakes every live manager thread through a pipe that
    the thread closes as it ends, so a ``shutdown(wait=False)`` followed by interpreter exit can
    race the two and print an ``OSError: Bad file descriptor`` traceback."""
    # private attributes, read before shutdown() drops them; absent on other executors
    manager = getattr(pool, "_executor_manager_thread", None)
    workers = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        if process.is_alive():
            process.terminate()
    if manager is None:
        return True
    manager.join(timeout)
    return not manager.is_alive()


def _worker_init(background: bool = False) -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if background:
        os.nice(BACKGROUND_NICE)


def default_executor() -> ProcessPoolExecutor:
    """The process pool ``query_many`` uses when given none (:func:`process_pool`), shut down at exit."""
    global _default
    with _default_lock:
        if _default is None:
            _default = process_pool()
            atexit.register(_default.shutdown, wait=False, cancel_futures=True)
        return _default


def scene_payload(problem: Problem, options: SolverOptions) -> bytes:
    """The pickled (problem, options) :func:`solve_chunk` takes."""
    return pickle.dumps((problem, options), protocol=pickle.HIGHEST_PROTOCOL)


def query_many(problem: Problem, options: SolverOptions | None, targets: Sequence[Mapping],
               executor: Executor | None = None, *, chunks: int | None = None,
               compile: str = "cached") -> list[ShapeResult]:
    """One ShapeResult per entry of ``targets`` (each a ``{grip name: pose}`` mapping, as for
    ``solve``), in order.  ``chunks``: how many pieces the targets are cut into (default: the
    executor's worker count, or ``os.cpu_count()``).  A query that fails answers with its status and
    message, as ``solve`` does; the others are unaffected."""
    options = options or SolverOptions()
    problem.validate()
    options.validate()
    targets = [dict(t) for t in targets]
    if not targets:
        return []
    executor = executor or default_executor()
    n = chunks or getattr(executor, "_max_workers", None) or os.cpu_count() or 1
    n = max(1, min(int(n), len(targets)))
    bounds = [round(i * len(targets) / n) for i in range(n + 1)]
    payload = scene_payload(problem, options)
    futures = [executor.submit(solve_chunk, payload, targets[a:b], compile)
               for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    return [result for future in futures for result in future.result()]


def solve_chunk(scene: bytes, targets: list[dict], compile: str = "cached", checks: str = "sync") -> list[ShapeResult]:
    """(worker) Solve ``targets`` with this process's solver of the pickled (problem, options)
    ``scene``, each from the held shape at the scene's poses (``commit=False``); the solver is kept
    for the next call.  ``checks``: the a-posteriori checks of an auto solver (``make_solver``): 'sync'
    for a batch (a scene solved once, checked before its queries), 'background' for a node's workers,
    whose held shape follows the stream: a check due on one of its updates then runs beside the
    queries, not in front of them."""
    problem, options = pickle.loads(scene)
    results = []
    with _worker_lock:  # one CasADi/IPOPT solver must never be called from two threads at once
        solver = _worker_solver(scene, problem, options, compile, checks)
        for poses in targets:
            try:
                result = solver.solve(poses, warm=True, commit=False)
            except Exception as exc:  # noqa: BLE001 - one bad query must not lose the chunk's other answers
                result = ShapeResult(status="failed", message=f"{type(exc).__name__}: {exc}")
            results.append(result)
    return results


def _worker_solver(scene: bytes, problem: Problem, options: SolverOptions, compile: str, checks: str):
    """This process's solver for the scene's structure, built once, holding the shape at the scene's
    values and poses (re-solved from its previous shape when they change)."""
    from .auto import make_solver
    from .shape_solver import structure_key

    key = pickle.dumps((structure_key(problem, options), options, checks), protocol=pickle.HIGHEST_PROTOCOL)
    entry = _WORKER_SOLVERS.pop(key, None)
    if entry is None:
        solver = make_solver(problem, options, compile=compile, checks=checks)
        solver.solve()  # the held shape: every query starts from it
    else:
        values, solver = entry
        if values != scene:
            held, _ = pickle.loads(values)
            if _grips_moved_only(held, problem):
                # only the grips moved (a node's stream did): a warm update, as the stream's, which runs
                # auto's checks every recheck_every updates; set_problem would check the model now
                solver.solve({g.name: g.pose for g in problem.grips})
            else:
                solver.set_problem(problem)
                solver.solve()
    _WORKER_SOLVERS[key] = (scene, solver)
    while len(_WORKER_SOLVERS) > WORKER_SOLVERS:
        _, (_, old) = _WORKER_SOLVERS.popitem(last=False)
        close = getattr(old, "close", None)
        if close is not None:
            close()
    return solver


def _grips_moved_only(old: Problem, new: Problem) -> bool:
    """Whether ``new`` differs from ``old`` in grip poses at most (field by field: pickles of the whole
    problems can differ where only the sharing of equal objects does)."""
    def rest(grip) -> bytes:
        return pickle.dumps([getattr(grip, f.name) for f in dataclasses.fields(grip) if f.name != "pose"])

    if len(old.grips) != len(new.grips) or any(rest(a) != rest(b) for a, b in zip(old.grips, new.grips)):
        return False
    return all(pickle.dumps(getattr(old, f.name)) == pickle.dumps(getattr(new, f.name))
               for f in dataclasses.fields(new) if f.name != "grips")
