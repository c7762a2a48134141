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
import queue
import signal
import sys
import threading
import time
from concurrent.futures import CancelledError, Executor, Future, InvalidStateError, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
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
_default: "WorkerPool | None" = None
_default_lock = threading.Lock()
_worker_lock = threading.Lock()  # a thread executor's workers share this process's solvers: one at a time


def process_pool(workers: int | None = None, background: bool = False) -> ProcessPoolExecutor:
    """A process pool for :func:`solve_chunk`: ``workers`` (default ``os.cpu_count()``) processes started
    with 'spawn' (a fork of a process with CasADi and DDS threads is unsafe) that ignore SIGINT (a
    Ctrl-C reaches the whole process group; the parent decides how to stop) and die with this process
    (:func:`die_with_parent`), even when it is SIGKILLed.  ``background``: the workers run
    BACKGROUND_NICE above the caller, so that a node's stream comes first on a shared core.

    It does not recover from a dead worker (``BrokenProcessPool``) and has no timeout: :class:`WorkerPool`
    adds both."""
    return _Pool(max_workers=workers or os.cpu_count() or 1, mp_context=multiprocessing.get_context("spawn"),
                 initializer=_worker_init, initargs=(bool(background), os.getpid()))


class _Pool(ProcessPoolExecutor):
    """A ProcessPoolExecutor whose workers are started from one long-lived thread (:data:`_SPAWNER`).

    Why: ``PR_SET_PDEATHSIG`` fires when the *thread* that created a child ends, not its process.  The
    executor starts workers from whichever thread calls ``submit`` (or its manager thread, replacing
    one): a batch submitted from a short-lived thread would have its workers SIGKILLed when that thread
    returned.  The spawner thread lives as long as the process, so the signal means "the parent died"."""

    def _spawn_process(self) -> None:  # CPython >= 3.9 (concurrent.futures.process); else the default
        _SPAWNER.call(super()._spawn_process)
        # every worker ever started, for naming a dead one's exit code (the executor forgets them)
        self.started = {**getattr(self, "started", {}), **(self._processes or {})}


class _Spawner:
    """One daemon thread, started on first use, that runs the calls handed to it (see :class:`_Pool`)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._calls: "queue.SimpleQueue[tuple[object, Future]]" = queue.SimpleQueue()

    def call(self, fn):
        if threading.current_thread() is self._thread:
            return fn()
        with self._lock:
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="dlo-worker-spawner", daemon=True)
                self._thread.start()
        done: Future = Future()
        self._calls.put((fn, done))
        return done.result()

    def _run(self) -> None:
        while True:
            fn, done = self._calls.get()
            try:
                done.set_result(fn())
            except BaseException as exc:  # noqa: BLE001 - handed back to the caller
                done.set_exception(exc)


_SPAWNER = _Spawner()

#: [s] How often a worker checks that its parent is alive, where ``PR_SET_PDEATHSIG`` does not apply (not
#: Linux) or cannot act (the worker was started by a thread that was not the spawner's).
PARENT_CHECK_S = 0.5


def die_with_parent(parent_pid: int) -> str:
    """(worker) End this process when ``parent_pid`` (its parent) dies, however it dies; returns how.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (the kernel kills the worker even while it is inside
    IPOPT holding the GIL); it fires on the death of the creating thread, which :class:`_Pool` keeps
    alive for the whole process.  Everywhere, also a daemon thread that polls ``os.getppid()`` every
    PARENT_CHECK_S s and leaves with ``os._exit`` once the worker was re-parented.  A worker that
    outlived its parent also held multiprocessing's resource tracker alive (spawned children inherit
    the write end of its pipe, and it exits only at end-of-file)."""
    how = "watchdog"
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
                how = "pdeathsig+watchdog"
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)

    threading.Thread(target=watch, name="dlo-parent-watchdog", daemon=True).start()
    return how


_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _worker_init(background: bool = False, parent_pid: int | None = None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent_pid is not None:
        die_with_parent(parent_pid)
    if background:
        os.nice(BACKGROUND_NICE)


def stop_pool(pool, timeout: float = 5.0) -> bool:
    """Stop ``pool`` now: pending work is cancelled, work in flight is abandoned (its workers are
    terminated), and the pool's manager thread is joined, at most ``timeout`` s; True if it ended.
    ``pool``: a ProcessPoolExecutor (e.g. :func:`process_pool`) or a :class:`WorkerPool`.

    Joining matters: CPython 3.11's exit hook wakes every live manager thread through a pipe that
    the thread closes as it ends, so a ``shutdown(wait=False)`` followed by interpreter exit can
    race the two and print an ``OSError: Bad file descriptor`` traceback."""
    if isinstance(pool, WorkerPool):
        return pool.stop(timeout)
    # private attributes, read before shutdown() drops them; absent on other executors
    manager = getattr(pool, "_executor_manager_thread", None)
    workers = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        if process.is_alive():
            process.terminate()
    deadline = time.monotonic() + timeout
    for process in workers:  # a worker stuck in C code ignores SIGTERM until it returns: SIGKILL it
        process.join(max(0.0, min(1.0, deadline - time.monotonic())))
        if process.is_alive():
            process.kill()
    if manager is None:
        return True
    manager.join(max(0.0, deadline - time.monotonic()))
    return not manager.is_alive()


def worker_pids(pool) -> list[int]:
    """The process ids of ``pool``'s live workers (a ProcessPoolExecutor or :class:`WorkerPool`)."""
    if isinstance(pool, WorkerPool):
        return pool.worker_pids()
    return [pid for pid, p in list((getattr(pool, "_processes", None) or {}).items()) if p.is_alive()]


class WorkerDied(RuntimeError):
    """A worker process died with the work in flight on it (crashed, killed, or killed by
    :class:`WorkerPool` because another task on the pool timed out); the message names the cause."""


class TaskTimeout(TimeoutError):
    """A task of a :class:`WorkerPool` was not answered within its timeout; its workers were killed."""


class WorkerPool(Executor):
    """A :func:`process_pool` that repairs itself: ``submit(fn, *args, timeout=...)``.

    * A dead worker breaks a ProcessPoolExecutor for good; here the tasks in flight on it fail with
      :class:`WorkerDied` (naming the worker's pid and exit code, or the reason it was killed) and the
      next ``submit`` runs on a new pool.
    * ``timeout`` [s]: a task not done by then fails with :class:`TaskTimeout`, and the pool's workers
      are killed (a worker stuck in IPOPT cannot be interrupted otherwise) and replaced; the other tasks
      then in flight fail with WorkerDied naming the timeout.

    Thread-safe.  ``max_workers``: the worker count."""

    def __init__(self, workers: int | None = None, background: bool = False) -> None:
        self.max_workers = workers or os.cpu_count() or 1
        self.background = bool(background)
        self._lock = threading.RLock()  # submit may replace a broken pool while holding it
        self._pool: ProcessPoolExecutor | None = None
        self._generation = 0
        self._causes: dict[int, str] = {}  # generation -> why its workers were killed
        self._stopped = False
        self.restarts = 0  # pools replaced (dead worker or timeout)

    def submit(self, fn, /, *args, timeout: float | None = None, **kwargs) -> Future:
        answer: Future = Future()
        with self._lock:
            if self._stopped:
                raise RuntimeError("cannot schedule new futures after the pool was stopped")
            if self._pool is not None and self._dead_workers(self._pool):  # died while idle: not noticed yet
                self._replace(self._generation, f"a worker process had died ({self._dead_workers(self._pool)})")
            for attempt in range(2):
                pool, generation = self._live_pool(), self._generation
                try:
                    inner = pool.submit(fn, *args, **kwargs)
                    break
                except BrokenProcessPool as exc:  # a worker died while idle: a new pool, once
                    self._replace(generation, f"a worker process had died ({self._dead_workers(pool) or exc})")
                    if attempt:
                        raise
        timer = None
        if timeout is not None:
            timer = threading.Timer(float(timeout), self._expire, (answer, inner, generation, float(timeout)))
            timer.daemon = True
            timer.start()
        inner.add_done_callback(lambda f: self._relay(f, answer, pool, generation, timer))
        return answer

    def _relay(self, inner: Future, answer: Future, pool, generation: int, timer) -> None:
        if timer is not None:
            timer.cancel()
        if inner.cancelled():
            _settle(answer, exc=WorkerDied(self._causes.get(generation, "the pool was stopped")))
            return
        exc = inner.exception()
        if isinstance(exc, BrokenProcessPool):
            cause = self._causes.get(generation) or f"a worker process died: {self._dead_workers(pool) or exc}"
            _settle(answer, exc=WorkerDied(cause))
            self._replace(generation, cause)
        elif exc is not None:
            _settle(answer, exc=exc)
        else:
            _settle(answer, result=inner.result())

    def _expire(self, answer: Future, inner: Future, generation: int, timeout: float) -> None:
        if inner.done():
            return
        cause = f"timeout: no answer within {timeout:g} s; the worker was killed and replaced"
        _settle(answer, exc=TaskTimeout(cause))
        self._replace(generation, f"killed: a task on the same pool timed out after {timeout:g} s")

    def _live_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = process_pool(self.max_workers, self.background)
        return self._pool

    def _replace(self, generation: int, cause: str) -> None:
        """Kill generation ``generation``'s workers (if it is still the current pool); the next submit
        starts a new pool."""
        with self._lock:
            if generation != self._generation or self._pool is None:
                return
            self._causes.setdefault(generation, cause)
            old, self._pool = self._pool, None
            self._generation += 1
            self.restarts += 1
        # in a thread: this may run in the old pool's manager thread (a done callback), which stop_pool joins
        threading.Thread(target=stop_pool, args=(old, 2.0), name="dlo-pool-stop", daemon=True).start()

    @staticmethod
    def _dead_workers(pool) -> str:
        """'pid N exit code -9 (SIGKILL)' for each of ``pool``'s workers that has ended."""
        from multiprocessing.connection import wait

        procs = list(getattr(pool, "started", {}).values())
        try:  # a worker's sentinel is ready once it has ended (its exit code may still be unreaped)
            ended = set(wait([p.sentinel for p in procs], timeout=0))
        except (OSError, ValueError):
            ended = set()
        text = []
        for p in procs:
            if p.sentinel in ended:
                p.join(0.2)
                code = p.exitcode
                name = f" ({signal.Signals(-code).name})" if code is not None and -code in _SIGNALS else ""
                text.append(f"pid {p.pid} ended" + ("" if code is None else f" with exit code {code}{name}"))
        return ", ".join(text)

    def worker_pids(self) -> list[int]:
        """The process ids of the current workers (started on demand: empty before the first task)."""
        with self._lock:
            pool = self._pool
        return [] if pool is None else worker_pids(pool)

    def stop(self, timeout: float = 5.0) -> bool:
        """Stop for good (see :func:`stop_pool`); tasks in flight fail with WorkerDied."""
        with self._lock:
            self._stopped = True
            self._causes.setdefault(self._generation, "the pool was stopped")
            old, self._pool = self._pool, None
        return True if old is None else stop_pool(old, timeout)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self.stop(5.0)


_SIGNALS = {s.value for s in signal.Signals}


def _settle(future: Future, result=None, exc: BaseException | None = None) -> None:
    """Complete ``future`` unless a timer or the relay already did."""
    try:
        if exc is not None:
            future.set_exception(exc)
        else:
            future.set_result(result)
    except InvalidStateError:
        pass


def default_executor() -> WorkerPool:
    """The pool ``query_many`` uses when given none: a :class:`WorkerPool` of ``os.cpu_count()``
    workers, replaced when a worker dies or a call times out, stopped at exit."""
    global _default
    with _default_lock:
        if _default is None:
            _default = WorkerPool()
            atexit.register(_default.stop, 5.0)
        return _default


def scene_payload(problem: Problem, options: SolverOptions) -> bytes:
    """The pickled (problem, options) :func:`solve_chunk` takes."""
    return pickle.dumps((problem, options), protocol=pickle.HIGHEST_PROTOCOL)


def query_many(problem: Problem, options: SolverOptions | None, targets: Sequence[Mapping],
               executor: Executor | None = None, *, chunks: int | None = None,
               compile: str = "cached", timeout: float | None = None) -> list[ShapeResult]:
    """One ShapeResult per entry of ``targets`` (each a ``{grip name: pose}`` mapping, as for
    ``solve``), in order.  ``chunks``: how many pieces the targets are cut into (default: the
    executor's worker count, or ``os.cpu_count()``).  A query that fails answers with its status and
    message, as ``solve`` does; the others are unaffected.

    ``timeout`` [s] (default None: no limit): the longest the call waits.  Queries not answered by then
    answer ``failed`` with a message starting "timeout:"; on a :class:`WorkerPool` (the default
    executor) their workers are killed and replaced.  Queries whose worker died answer ``failed``
    naming the cause; the default pool is rebuilt for the next call.  The call never hangs on a dead
    worker."""
    options = options or SolverOptions()
    problem.validate()
    options.validate()
    targets = [dict(t) for t in targets]
    if not targets:
        return []
    executor = executor or default_executor()
    n = (chunks or getattr(executor, "max_workers", None) or getattr(executor, "_max_workers", None)
         or os.cpu_count() or 1)
    n = max(1, min(int(n), len(targets)))
    bounds = [round(i * len(targets) / n) for i in range(n + 1)]
    spans = [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    payload = scene_payload(problem, options)
    deadline = None if timeout is None else time.monotonic() + float(timeout)
    futures: list[Future | BaseException] = []
    for a, b in spans:
        try:
            if isinstance(executor, WorkerPool):
                futures.append(executor.submit(solve_chunk, payload, targets[a:b], compile, timeout=timeout))
            else:
                futures.append(executor.submit(solve_chunk, payload, targets[a:b], compile))
        except (BrokenProcessPool, RuntimeError) as exc:  # a given executor that is broken or shut down
            futures.append(exc)
    results: list[ShapeResult] = []
    for (a, b), future in zip(spans, futures):
        if isinstance(future, BaseException):
            message = f"{type(future).__name__}: {future}"
            results.extend(ShapeResult(status="failed", message=message) for _ in range(b - a))
            continue
        try:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            # a WorkerPool's futures time out by themselves (and replace the workers)
            results.extend(future.result(None if left is None or isinstance(executor, WorkerPool) else left))
        except TimeoutError as exc:  # TaskTimeout, or concurrent.futures' on another executor
            future.cancel()
            message = str(exc) if isinstance(exc, TaskTimeout) else f"timeout: no answer within {timeout:g} s"
            results.extend(ShapeResult(status="failed", message=message) for _ in range(b - a))
        except (WorkerDied, BrokenProcessPool, CancelledError) as exc:
            message = f"{type(exc).__name__}: {exc}"
            results.extend(ShapeResult(status="failed", message=message) for _ in range(b - a))
    return results


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
