"""The worker thread that runs auto's checks and builds ahead, and what it may be using.

With ``checks='background'`` one worker thread runs its jobs in the order they were submitted: a
model check on a snapshot of a committed solve, or a build of models a coming switch or check
needs.  While a job is queued or running it owns the pooled models named by its keys
(:attr:`CheckWorker.keys`); the streaming thread waits for it only when it needs one of those
(:meth:`CheckWorker.wait_for_model`).  With ``checks='sync'`` there is no worker
(:attr:`CheckWorker.executor` is None) and nothing runs in the background.

When a check's verdict takes effect does not depend on this worker's timing
(:mod:`.check_schedule`): the worker only decides how long the stream waits for it.
"""

from __future__ import annotations

import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Any, Callable

#: With background checks the stream thread waits for the GIL whenever the worker runs Python, up
#: to the interpreter's switch interval (5 ms by default).  A CheckWorker lowers it to this for the
#: process (never raises it), which bounds that wait (bench/perf/auto_vs_full.py measures the
#: stream with checks).
SWITCH_INTERVAL_S = 1e-4


class CheckWorker:
    """The worker's jobs, oldest first, and the pool keys each may use meanwhile."""

    def __init__(self, background: bool) -> None:
        """Start the worker thread when ``background``; else checks run inline (no executor)."""
        self.executor: ThreadPoolExecutor | None = (
            ThreadPoolExecutor(1, thread_name_prefix="dlo-auto-check") if background else None
        )
        if self.executor is not None and sys.getswitchinterval() > SWITCH_INTERVAL_S:
            sys.setswitchinterval(SWITCH_INTERVAL_S)  # the stream gets the GIL back within 0.1 ms
        # (job, the pool keys it may use) of every job not known to be done, oldest first
        self._jobs: list[tuple[Future, set]] = []
        self._lock = threading.Lock()  # guards _jobs and their key sets (both threads use them)

    @property
    def background(self) -> bool:
        """Whether a worker thread runs the checks (False after :meth:`shutdown`)."""
        return self.executor is not None

    def _running(self) -> list[tuple[Future, set]]:
        """Return the jobs not done yet, oldest first (and forget the done ones)."""
        with self._lock:
            self._jobs = [(job, keys) for job, keys in self._jobs if not job.done()]
            return list(self._jobs)

    @property
    def keys(self) -> frozenset:
        """The pool keys the queued and running jobs may use."""
        return frozenset().union(*(keys for _, keys in self._running()))

    @property
    def idle(self) -> bool:
        """Whether no job is queued or running."""
        return not self._running()

    def submit(self, fn: Callable[..., Any], keys: set, *args: Any) -> Future:
        """Run ``fn(*args)`` on the worker after the jobs before it; return its future.

        ``keys``: the pooled models it may use meanwhile.
        """
        assert self.executor is not None, "submit needs a background worker"
        job = self.executor.submit(fn, *args)
        with self._lock:
            self._jobs.append((job, set(keys)))
        return job

    def claim(self, key: tuple) -> None:
        """Add ``key`` to the running job's models (worker thread), before it builds that model."""
        with self._lock:
            for job, keys in self._jobs:
                if not job.done():
                    keys.add(key)
                    return

    def built(self, key: tuple) -> None:
        """Release ``key`` (worker thread): it is built, a switch to it need not wait.

        The running job is the oldest one not done (one worker thread runs them in order).
        """
        with self._lock:
            for job, keys in self._jobs:
                if not job.done():
                    keys.discard(key)
                    return

    def busy_with(self, key: tuple) -> bool:
        """Whether a queued or running job may be using (or building) the pooled model ``key``."""
        return any(key in keys for _, keys in self._running())

    def wait_for_model(self, key: tuple) -> None:
        """Wait until no job that may be using the pooled model ``key`` is left.

        One solver is never called from two threads at once.
        """
        while True:
            jobs = [job for job, keys in self._running() if key in keys]
            if not jobs:
                return
            wait(jobs, timeout=0.005)  # a prebuild releases its keys one by one (built)

    def wait(self) -> None:
        """Let every queued and running job finish: they own pooled helper solvers meanwhile."""
        wait([job for job, _ in self._running()])

    def shutdown(self) -> None:
        """Stop the worker once its jobs are done; later checks run inline."""
        if self.executor is not None:
            self.wait()
            self.executor.shutdown(wait=True)
            self.executor = None
