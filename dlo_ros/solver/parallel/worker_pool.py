"""Process pools for solver work that repair themselves and die with their parent.

* :func:`process_pool` — a ``ProcessPoolExecutor`` of spawned workers that ignore SIGINT and die
  with
  this process (:func:`die_with_parent`), even when it is SIGKILLed.
* :class:`WorkerPool` — the same, plus: a dead worker fails only the tasks in flight on it
  (:class:`WorkerDied`, naming its pid and exit code) and the next ``submit`` runs on a new pool; a
  task with a ``timeout`` fails with :class:`TaskTimeout` after it and its workers are killed and
  replaced.
* :func:`stop_pool`, :func:`worker_pids` — stop either kind now; the live workers' process ids.

Used by ``batch.query_many`` and by the node's query and fit workers.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, InvalidStateError, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.connection import wait as wait_for_sentinels
from typing import Any

#: The nice value added to a node's query and fit workers (``process_pool(background=True)``), so
#: that the stream comes first on a shared core (bench/results/soak_3_clients.md against
#: soak_no_queries.md). Not SCHED_IDLE: it favours the stream more, but starves the workers
#: whenever both cores are busy (a planner beside the node, or CI's two test processes), and their
#: queries would time out.
BACKGROUND_NICE = 10


def process_pool(workers: int | None = None, background: bool = False) -> ProcessPoolExecutor:
    """Return a process pool of spawned workers that ignore SIGINT and die with this process.

    A process pool for :func:`solve_chunk`: ``workers`` (default ``os.cpu_count()``) processes
    started with 'spawn' (a fork of a process with CasADi and DDS threads is unsafe) that ignore
    SIGINT (a Ctrl-C reaches the whole process group; the parent decides how to stop) and die with
    this process (:func:`die_with_parent`), even when it is SIGKILLed.  ``background``: the workers
    run BACKGROUND_NICE above the caller, so that a node's stream comes first on a shared core.

    It does not recover from a dead worker (``BrokenProcessPool``) and has no timeout:
    :class:`WorkerPool` adds both.
    """
    return _Pool(
        max_workers=workers or os.cpu_count() or 1,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_worker_init,
        initargs=(bool(background), os.getpid()),
    )


class _Pool(ProcessPoolExecutor):
    """A ProcessPoolExecutor whose workers are started from one long-lived thread.

    A ProcessPoolExecutor whose workers are started from one long-lived thread
    (:data:`_SPAWNER`).

    Why: ``PR_SET_PDEATHSIG`` fires when the *thread* that created a child ends, not its process.
    The executor starts workers from whichever thread calls ``submit`` (or its manager thread,
    replacing one): a batch submitted from a short-lived thread would have its workers SIGKILLed
    when that thread returned.  The spawner thread lives as long as the process, so the signal
    means "the parent died".
    """

    def _spawn_process(self) -> None:
        # CPython >= 3.9 (concurrent.futures.process); else the default
        _SPAWNER.call(super()._spawn_process)  # type: ignore[misc]  # private: not in typeshed
        # every worker ever started, for naming a dead one's exit code (the executor forgets them)
        self.started = {**getattr(self, "started", {}), **(self._processes or {})}


class _Spawner:
    """One daemon thread, started on first use, that runs the calls handed to it.

    One daemon thread, started on first use, that runs the calls handed to it (see
    :class:`_Pool`).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._calls: queue.SimpleQueue[tuple[Callable[[], Any], Future]] = queue.SimpleQueue()

    def call(self, fn: Callable[[], Any]) -> Any:
        if threading.current_thread() is self._thread:
            return fn()
        with self._lock:
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(
                    target=self._run, name="dlo-worker-spawner", daemon=True
                )
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

#: [s] How often a worker checks that its parent is alive, where ``PR_SET_PDEATHSIG`` does not
#: apply (not Linux) or cannot act (the worker was started by a thread that was not the
#: spawner's).
PARENT_CHECK_S = 0.5


#: what a pool call says when made while its own process starts as a spawned worker
MODULE_LEVEL_CALL = (
    "called while this process starts as a spawned worker: a script that calls it at module "
    "level runs again in every worker; put the call under `if __name__ == \"__main__\":`"
)


def starting_as_worker() -> bool:
    """Tell whether this process is a spawned worker still importing its parent's main module.

    With 'spawn' every worker imports the parent's script as ``__mp_main__`` before it takes any
    task; a pool started from the script's top level would then start again in each worker
    (multiprocessing refuses that with a RuntimeError per worker).  Callers answer at once with
    :data:`MODULE_LEVEL_CALL` instead of starting a pool.
    """
    return bool(getattr(multiprocessing.current_process(), "_inheriting", False))


def die_with_parent(parent_pid: int) -> str:
    """End this worker process when its parent dies, however it dies; return how.

    (worker) End this process when ``parent_pid`` (its parent) dies, however it dies; returns
    how.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (the kernel kills the worker even while it is
    inside IPOPT holding the GIL); it fires on the death of the creating thread, which
    :class:`_Pool` keeps alive for the whole process.  Everywhere, also a daemon thread that polls
    ``os.getppid()`` every PARENT_CHECK_S s and leaves with ``os._exit`` once the worker was
    re-parented.  A worker that outlived its parent also held multiprocessing's resource tracker
    alive (spawned children inherit the write end of its pipe, and it exits only at
    end-of-file).
    """
    how = "watchdog"
    if sys.platform.startswith("linux"):
        try:
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
    """Stop ``pool`` now, within ``timeout`` s; return whether it ended.

    Stop ``pool`` now: pending work is cancelled, work in flight is abandoned (its workers are
    terminated), and the pool's manager thread is joined, at most ``timeout`` s; True if it ended.
    ``pool``: a ProcessPoolExecutor (e.g. :func:`process_pool`) or a :class:`WorkerPool`.

    Joining matters: CPython 3.11's exit hook wakes every live manager thread through a pipe that
    the thread closes as it ends, so a ``shutdown(wait=False)`` followed by interpreter exit can
    race the two and print an ``OSError: Bad file descriptor`` traceback.
    """
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
    for (
        process
    ) in workers:  # a worker stuck in C code ignores SIGTERM until it returns: SIGKILL it
        process.join(max(0.0, min(1.0, deadline - time.monotonic())))
        if process.is_alive():
            process.kill()
    if manager is None:
        return True
    manager.join(max(0.0, deadline - time.monotonic()))
    return not manager.is_alive()


def worker_pids(pool) -> list[int]:
    """Return the process ids of ``pool``'s live workers.

    The process ids of ``pool``'s live workers (a ProcessPoolExecutor or
    :class:`WorkerPool`).
    """
    if isinstance(pool, WorkerPool):
        return pool.worker_pids()
    return [
        pid for pid, p in list((getattr(pool, "_processes", None) or {}).items()) if p.is_alive()
    ]


#: Generations of replaced pools whose cause a late answer may still name (older ones are
#: forgotten).
KEPT_CAUSES = 16


class WorkerDied(RuntimeError):
    """A worker process died with the work in flight on it.

    A worker process died with the work in flight on it (crashed, killed, or killed by
    :class:`WorkerPool` because another task on the pool timed out); the message names the
    cause.
    """


class TaskTimeout(TimeoutError):
    """A task of a :class:`WorkerPool` was not answered within its timeout.

    A task of a :class:`WorkerPool` was not answered within its timeout; its workers were
    killed.
    """


class WorkerPool(Executor):
    """A :func:`process_pool` that repairs itself: ``submit(fn, *args, timeout=...)``.

    * A dead worker breaks a ProcessPoolExecutor for good; here the tasks in flight on it fail with
      :class:`WorkerDied` (naming the worker's pid and exit code, or the reason it was killed) and
      the next ``submit`` runs on a new pool.
    * ``timeout`` [s]: a task not done by then fails with :class:`TaskTimeout`, and the pool's
      workers
      are killed (a worker stuck in IPOPT cannot be interrupted otherwise) and replaced; the other
      tasks then in flight fail with WorkerDied naming the timeout.

    Thread-safe.  ``max_workers``: the worker count.
    """

    def __init__(self, workers: int | None = None, background: bool = False) -> None:
        self.max_workers = workers or os.cpu_count() or 1
        self.background = bool(background)
        self._lock = threading.RLock()  # submit may replace a broken pool while holding it
        self._pool: ProcessPoolExecutor | None = None
        self._generation = 0
        self._causes: dict[int, str] = {}  # generation -> why its workers ended
        # generation -> why this pool killed them on purpose (a timeout, stop): never retried;
        # a worker that died by itself ends its pool too, and every task then in flight retries
        self._killed: dict[int, str] = {}
        self._stopped = False
        self.restarts = 0  # pools replaced (dead worker or timeout)

    # Executor.submit passes every keyword to fn; this one keeps timeout and retries for itself
    def submit(  # type: ignore[override]  # keyword-only timeout/retries added to Executor's
        self, fn, /, *args, timeout: float | None = None, retries: int = 0, **kwargs
    ) -> Future:
        """Run ``fn(*args, **kwargs)`` on a worker; return its Future.

        ``fn(*args, **kwargs)`` on a worker; ``timeout`` [s] (None: none) as in the class
        docstring. ``retries``: how many times a task whose worker died under it (not one killed
        for a timeout) runs again on a new pool, for a task that is a pure function of its
        arguments; once they are used up it fails with WorkerDied, so a task that kills its worker
        is not retried for ever.
        """
        answer: Future = Future()
        self._start(answer, fn, args, kwargs, timeout, retries)
        return answer

    def _start(
        self, answer: Future, fn, args: tuple, kwargs: dict, timeout: float | None, retries: int
    ) -> None:
        with self._lock:
            if self._stopped:
                raise RuntimeError("cannot schedule new futures after the pool was stopped")
            if self._pool is not None and self._dead_workers(
                self._pool
            ):  # died while idle: not noticed yet
                self._replace(
                    self._generation,
                    f"a worker process had died ({self._dead_workers(self._pool)})",
                )
            for attempt in range(2):
                pool, generation = self._live_pool(), self._generation
                try:
                    inner = pool.submit(fn, *args, **kwargs)
                    break
                except BrokenProcessPool as exc:  # a worker died while idle: a new pool, once
                    self._replace(
                        generation,
                        f"a worker process had died ({self._dead_workers(pool) or exc})",
                    )
                    if attempt:
                        raise
        timer = None
        if timeout is not None:
            timer = threading.Timer(
                float(timeout), self._expire, (answer, inner, generation, float(timeout))
            )
            timer.daemon = True
            timer.start()

        def again() -> bool:
            """Run the task once more on a new pool (``retries`` left); False when it cannot."""
            if retries <= 0:
                return False
            try:
                self._start(answer, fn, args, kwargs, timeout, retries - 1)
            except (RuntimeError, BrokenProcessPool):  # stopped meanwhile
                return False
            return True

        inner.add_done_callback(lambda f: self._relay(f, answer, pool, generation, timer, again))

    def _relay(self, inner: Future, answer: Future, pool, generation: int, timer, again) -> None:
        if timer is not None:
            timer.cancel()
        if inner.cancelled():
            _settle(answer, exc=WorkerDied(self._causes.get(generation, "the pool was stopped")))
            return
        exc = inner.exception()
        if isinstance(exc, BrokenProcessPool):
            killed = self._killed.get(generation)  # by a timeout or stop(): never retried
            cause = killed or f"a worker process died: {self._dead_workers(pool) or exc}"
            self._replace(generation, cause)
            if answer.done() or (killed is None and again()):
                return
            _settle(answer, exc=WorkerDied(cause))
        elif exc is not None:
            _settle(answer, exc=exc)
        else:
            _settle(answer, result=inner.result())

    def _expire(self, answer: Future, inner: Future, generation: int, timeout: float) -> None:
        if inner.done():
            return
        cause = f"timeout: no answer within {timeout:g} s; the worker was killed and replaced"
        _settle(answer, exc=TaskTimeout(cause))
        self._replace(
            generation, f"killed: a task on the same pool timed out after {timeout:g} s", True
        )

    def _live_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = process_pool(self.max_workers, self.background)
        return self._pool

    def _replace(self, generation: int, cause: str, on_purpose: bool = False) -> None:
        """Kill the workers of pool ``generation``; the next submit starts a new pool.

        Kill generation ``generation``'s workers (if it is still the current pool); the next
        submit starts a new pool.  ``on_purpose``: killed for a timeout (its tasks in flight are
        not retried), not replaced after a worker died.
        """
        with self._lock:
            if generation != self._generation or self._pool is None:
                return
            self._causes.setdefault(generation, cause)
            if on_purpose:
                self._killed.setdefault(generation, cause)
            for book in (self._causes, self._killed):
                for old_generation in [g for g in book if g < generation - KEPT_CAUSES]:
                    del book[old_generation]  # a long-lived node replaces workers without end
            old, self._pool = self._pool, None
            self._generation += 1
            self.restarts += 1
        # in a thread: this may run in the old pool's manager thread (a done callback), which
        # stop_pool joins
        threading.Thread(
            target=stop_pool, args=(old, 2.0), name="dlo-pool-stop", daemon=True
        ).start()

    @staticmethod
    def _dead_workers(pool) -> str:
        """'pid N exit code -9 (SIGKILL)' for each of ``pool``'s workers that has ended."""
        procs = list(getattr(pool, "started", {}).values())
        # a worker's sentinel is ready once it has ended (its exit code may still be unreaped)
        try:
            ended = set(wait_for_sentinels([p.sentinel for p in procs], timeout=0))
        except (OSError, ValueError):
            ended = set()
        text = []
        for p in procs:
            if p.sentinel in ended:
                p.join(0.2)
                code = p.exitcode
                name = (
                    f" ({signal.Signals(-code).name})"
                    if code is not None and -code in _SIGNALS
                    else ""
                )
                text.append(
                    f"pid {p.pid} ended"
                    + ("" if code is None else f" with exit code {code}{name}")
                )
        return ", ".join(text)

    def worker_pids(self) -> list[int]:
        """Return the process ids of the current workers.

        The process ids of the current workers (started on demand: empty before the first
        task).
        """
        with self._lock:
            pool = self._pool
        return [] if pool is None else worker_pids(pool)

    def stop(self, timeout: float = 5.0) -> bool:
        """Stop for good (see :func:`stop_pool`); tasks in flight fail with WorkerDied."""
        with self._lock:
            self._stopped = True
            self._causes.setdefault(self._generation, "the pool was stopped")
            self._killed.setdefault(self._generation, "the pool was stopped")
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
