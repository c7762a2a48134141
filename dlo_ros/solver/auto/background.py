"""The worker thread that runs auto's checks and builds ahead, and what it may be using.

With ``checks='background'`` one worker thread runs a job at a time: a model check on a snapshot
of a committed solve, or a build of models a coming switch or check needs.  While a job runs it
owns the pooled models named by its keys (:attr:`CheckWorker.keys`); the streaming thread waits for
it only when it needs one of those (:meth:`CheckWorker.wait_for_model`).  With ``checks='sync'``
there is no worker (:attr:`CheckWorker.executor` is None) and nothing runs in the background.
"""

from __future__ import annotations

import sys
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Any, Callable

#: With background checks the stream thread waits for the GIL whenever the worker runs Python, up
#: to the interpreter's switch interval (5 ms by default).  A CheckWorker lowers it to this for the
#: process (never raises it), which bounds that wait (bench/perf/auto_vs_full.py measures the
#: stream with checks).
SWITCH_INTERVAL_S = 1e-4


class CheckWorker:
    """One background job at a time, and the pool keys it may use meanwhile."""

    def __init__(self, background: bool) -> None:
        """Start the worker thread when ``background``; else checks run inline (no executor)."""
        self.executor: ThreadPoolExecutor | None = (
            ThreadPoolExecutor(1, thread_name_prefix="dlo-auto-check") if background else None
        )
        if self.executor is not None and sys.getswitchinterval() > SWITCH_INTERVAL_S:
            sys.setswitchinterval(SWITCH_INTERVAL_S)  # the stream gets the GIL back within 0.1 ms
        #: the running (or finished, not yet applied) job
        self.job: Future | None = None
        #: pool keys the running job may use
        self.keys: frozenset = frozenset()

    @property
    def background(self) -> bool:
        """Whether a worker thread runs the checks (False after :meth:`shutdown`)."""
        return self.executor is not None

    @property
    def idle(self) -> bool:
        """Whether no job is running or waiting to be applied."""
        return self.job is None

    def submit(self, fn: Callable[..., Any], keys: set, *args: Any) -> None:
        """Run ``fn(*args)`` on the worker; ``keys``: the pooled models it may use meanwhile."""
        assert self.executor is not None, "submit needs a background worker"
        self.keys = frozenset(keys)
        self.job = self.executor.submit(fn, *args)

    def built(self, key: tuple) -> None:
        """Release ``key`` (worker thread): it is built, a switch to it need not wait."""
        self.keys = self.keys - {key}

    def busy_with(self, key: tuple) -> bool:
        """Whether the running job may be using (or building) the pooled model ``key``."""
        job = self.job
        return job is not None and not job.done() and key in self.keys

    def wait_for_model(self, key: tuple) -> None:
        """Wait until the running job is done, if it may be using the pooled model ``key``.

        One solver is never called from two threads at once.
        """
        job = self.job
        while job is not None and not job.done() and key in self.keys:
            wait([job], timeout=0.005)

    def wait(self) -> None:
        """Let a running job finish first: it owns the pooled helper solvers meanwhile."""
        if self.job is not None:
            wait([self.job])

    def take_finished(self) -> Future | None:
        """Return the finished job and forget it (None while it runs or when there is none)."""
        job = self.job
        if job is None or not job.done():
            return None
        self.job = None
        return job

    def shutdown(self) -> None:
        """Stop the worker (waits for a running job); later checks run inline."""
        if self.executor is not None:
            self.executor.shutdown(wait=True, cancel_futures=True)
            self.executor, self.job = None, None
