"""The node's solving engine: one worker thread owns the ShapeSolver (no ROS here).

* Streaming targets go into a "latest pending targets" slot: per grip the newest accepted pose,
  plus
  the stamp of the newest message.  The worker drains the slot, so a burst of targets never builds
  a queue: whatever arrives while a solve runs is merged, and the next solve uses the newest of
  everything.
* Every solve warm-starts from the last committed shape (``ShapeSolver.solve(..., warm=True)``).
* Control jobs (query, reset, parameter changes, a rebuild for a new output resolution) are queued
  and run before the next streaming solve; callers get a ``concurrent.futures.Future``.
* A query solves with ``commit=False``: it never touches the streaming state or its warm start.
* The re-solve after a parameter change or a rebuild is checked before it is published
  (``solve(..., check_now=True)``); streamed targets are checked in the background.
* A failed solve (or an exception) is reported through ``on_failure``; the last good shape stays.

Callbacks run in the worker thread.  All CasADi/IPOPT calls happen in that one thread.
"""

from __future__ import annotations

import collections
import threading
import time
import traceback
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from typing import Any, Callable

from ..model.problem import GripPose, Problem
from ..solver import make_solver
from ..solver.options import SolverOptions
from ..solver.results.result import ShapeResult
from .validation import grip_miss


CHECKED_TRIGGERS = (
    "parameters",
    "rebuild",
)  # re-solves whose answer is checked before it is published


@dataclass
class Update:
    """One solve of the streaming state, as handed to ``on_update`` / ``on_failure``."""

    result: ShapeResult
    problem: Problem  # the problem solved (grip poses = the targets)
    trigger: str  # 'initial', 'targets', 'parameters', 'reset', 'rebuild'
    stamp_ns: int | None  # header stamp of the newest target included (None: not target-driven)
    received_ns: int | None  # monotonic time that target arrived
    targets_merged: int = 0  # target messages folded into this solve
    finished_ns: int = 0  # monotonic time the solve finished


@dataclass
class _Job:
    kind: str
    payload: Any  # the job's argument: targets, an edit function or None
    future: Future = field(default_factory=Future)


class ShapeEngine:
    """Owns a ShapeSolver in a single worker thread (see the module docstring).

    make_solver(problem, options) builds the solver (may take long: it runs in the worker).
    on_update(update) gets every converged streaming solve; on_failure(kind, message, update) every
    failed one (kind = the ShapeResult status or 'internal').  on_state(text) tells what the worker
    is doing ('building', 'ready', 'failed: ...') for the diagnostics.
    """

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions,
        *,
        make_solver: Callable[[Problem, SolverOptions], Any],
        on_update: Callable[[Update], None],
        on_failure: Callable[[str, str, Update | None], None],
        on_state: Callable[[str], None] = lambda s: None,
        name: str = "dlo-solver",
    ):
        self._problem0 = problem
        self._options = options
        self._make_solver = make_solver
        self._on_update = on_update
        self._on_failure = on_failure
        self._on_state = on_state
        self._cond = threading.Condition()
        self._jobs: collections.deque[_Job] = collections.deque()
        self._idle: collections.deque[_Job] = collections.deque()  # when_idle's, in order
        self._targets: dict[str, GripPose] = {g.name: g.pose for g in problem.grips}
        self._dirty = False
        self._stamp_ns: int | None = None
        self._received_ns: int | None = None
        self._merged = 0
        self._stop = False
        self._solver: Any = None  # a ShapeSolver (or auto's) once built
        self.state = "not started"
        self.targets_received = 0
        self.targets_coalesced = 0  # received but superseded before a solve used them
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    # ---- called from any thread -----------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 10.0) -> bool:
        """Ask the worker to finish (after the solve in progress) and wait; True if it ended."""
        with self._cond:
            self._stop = True
            jobs, self._jobs = list(self._jobs) + list(self._idle), collections.deque()
            self._idle = collections.deque()
            self._cond.notify_all()
        for job in jobs:
            job.future.cancel()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    @property
    def ready(self) -> bool:
        return self._solver is not None

    def targets(self) -> dict[str, GripPose]:
        with self._cond:
            return dict(self._targets)

    def submit_targets(
        self,
        poses: dict[str, GripPose],
        stamp_ns: int | None = None,
        received_ns: int | None = None,
    ) -> None:
        """Merge checked poses into the pending slot (newest wins per grip) and wake the worker."""
        with self._cond:
            self._targets.update(poses)
            self._dirty = True
            self._merged += 1
            self.targets_received += 1
            if stamp_ns is not None:
                self._stamp_ns = stamp_ns
            self._received_ns = received_ns if received_ns is not None else time.monotonic_ns()
            self._cond.notify_all()

    def query_scene(self) -> tuple[Problem, SolverOptions] | None:
        """Return the scene a query is answered in by a solver outside this engine.

        The solver's problem (its current values) at the current targets, and its options; None
        until the solver is built.
        """
        solver = self._solver
        if solver is None:
            return None
        with self._cond:
            targets = dict(self._targets)
        return solver.problem.with_grip_poses(targets), solver.options

    def query(self, poses: dict[str, GripPose]) -> Future:
        """Solve the current targets updated by ``poses``, uncommitted; a ShapeResult Future."""
        return self._submit("query", dict(poses))

    def reset(self) -> Future:
        """Future of the cold re-solve of the current targets after forgetting the warm start."""
        return self._submit("reset", None)

    def change_problem(self, edit: Callable[[Problem], Problem]) -> Future:
        """Apply ``edit`` to the solver's problem (ShapeSolver.set_problem); re-solve."""
        return self._submit("problem", edit)

    def change_options(self, edit: Callable[[SolverOptions], SolverOptions]) -> Future:
        """Rebuild the solver with edited options (the next solve is cold); re-solve."""
        return self._submit("options", edit)

    def when_idle(self, work: Callable[[Any], Any]) -> Future:
        """Run ``work(solver)`` in the worker when nothing else waits; its result as a Future.

        For work that must never delay the stream (the node's envelope): it runs only when no
        control job and no new target is pending, so a target arriving meanwhile waits for at
        most one such piece of work.  Cancelled by ``stop``.
        """
        job = _Job("idle", work)
        with self._cond:
            if self._stop:
                job.future.cancel()
                return job.future
            self._idle.append(job)
            self._cond.notify_all()
        return job.future

    def _submit(self, kind: str, payload: Any) -> Future:
        job = _Job(kind, payload)
        with self._cond:
            if self._stop:
                job.future.cancel()
                return job.future
            if self.state.startswith("failed"):  # the worker has ended: nobody would run the job
                job.future.set_exception(RuntimeError(f"no solver: {self.state}"))
                return job.future
            self._jobs.append(job)
            self._cond.notify_all()
        return job.future

    # ---- worker thread --------------------------------------------------------------------------
    def _set_state(self, state: str) -> None:
        self.state = state
        self._on_state(state)

    def _run(self) -> None:
        self._set_state("building")
        try:
            self._solver = self._make_solver(self._problem0, self._options)
        except Exception as exc:  # noqa: BLE001 - reported, the node stays up without a solver
            self._set_state(f"failed: {exc}")
            self._on_failure("internal", f"building the solver failed: {exc}", None)
            self._fail_jobs(exc)
            return
        self._set_state("ready")
        try:
            self._serve()
        finally:
            close_solver(self._solver)

    def _serve(self) -> None:
        """Solve the first shape, then serve targets and jobs until stopped."""
        with self._cond:
            if self._stop:
                return
            slot = self._take_slot()
        self._stream("initial", *slot)
        while True:
            with self._cond:
                while not (self._stop or self._jobs or self._dirty or self._idle):
                    self._cond.wait()
                if self._stop:
                    return
                job = self._jobs.popleft() if self._jobs else None
                if job is None and not self._dirty:
                    job = self._idle.popleft()  # nothing else waits
                elif job is None:
                    slot = self._take_slot()
            if job is None:
                self._stream("targets", *slot)
            else:
                self._run_job(job)

    def _take_slot(self) -> tuple[dict[str, GripPose], int | None, int | None, int]:
        """Empty the pending slot (caller holds the lock).

        Returns (the targets, newest stamp, its arrival, messages merged).  The targets are taken
        with their stamp, under the same lock: a target arriving between the two would otherwise
        be solved under the previous one's stamp.
        """
        stamp, received, merged = self._stamp_ns, self._received_ns, self._merged
        self.targets_coalesced += max(0, merged - 1)
        self._dirty, self._stamp_ns, self._received_ns, self._merged = False, None, None, 0
        return dict(self._targets), stamp, received, merged

    def _fail_jobs(self, exc: Exception) -> None:
        with self._cond:
            jobs, self._jobs = list(self._jobs), collections.deque()
        for job in jobs:
            job.future.set_exception(exc)

    def _stream(
        self,
        trigger: str,
        targets: dict[str, GripPose],
        stamp_ns: int | None,
        received_ns: int | None,
        merged: int,
    ) -> ShapeResult | None:
        solver = self._solver
        update = None
        try:
            # after a live change of values or options the answer is checked before it is
            # published: the shape latched until the next target must not be one the changed scene
            # makes unstable
            result = solver.solve(
                targets, warm=True, commit=True, check_now=trigger in CHECKED_TRIGGERS
            )
            shaped = (
                result.ok or result.status == "unverified"
            )  # unverified: a shape, published with a warning
            problem = solver.problem if shaped else solver.problem.with_grip_poses(targets)
            update = Update(
                result, problem, trigger, stamp_ns, received_ns, merged, time.monotonic_ns()
            )
            miss = target_miss(result, problem, targets)
            if miss:
                self._on_failure("internal", miss, update)
            elif shaped:
                self._on_update(update)
            else:
                self._on_failure(result.status, result.message, update)
            return result
        except Exception as exc:  # noqa: BLE001 - a bug must not kill the worker
            self._on_failure(
                "internal", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}", update
            )
            return None

    def _stream_now(self, trigger: str) -> ShapeResult | None:
        """Re-solve the targets after a control job, folding in whatever is pending."""
        with self._cond:
            slot = self._take_slot()
        return self._stream(trigger, *slot)

    def _run_job(self, job: _Job) -> None:
        if not job.future.set_running_or_notify_cancel():
            return
        solver = self._solver
        try:
            if job.kind == "idle":
                job.future.set_result(job.payload(solver))
            elif job.kind == "query":
                with self._cond:
                    targets = dict(self._targets)
                targets.update(job.payload)
                result = solver.solve(targets, warm=True, commit=False)
                miss = target_miss(result, solver.problem, targets)
                if miss:
                    result.status, result.message = "failed", miss
                job.future.set_result(result)
            elif job.kind == "reset":
                solver.reset()
                job.future.set_result(self._stream_now("reset"))
            elif job.kind == "problem":
                solver.set_problem(job.payload(solver.problem))
                job.future.set_result(self._stream_now("parameters"))
            elif job.kind == "options":
                options = job.payload(solver.options)
                if options != solver.options:
                    self._set_state("building")
                    new = self._make_solver(solver.problem, options)
                    close_solver(solver)
                    self._solver = solver = new
                    self._set_state("ready")
                job.future.set_result(self._stream_now("rebuild"))
            else:  # pragma: no cover
                raise ValueError(f"unknown job {job.kind!r}")
        except Exception as exc:  # noqa: BLE001 - handed to the caller
            if self._solver is not None:
                self._set_state("ready")
            job.future.set_exception(exc)


def target_miss(result: ShapeResult, problem: Problem, targets: dict[str, GripPose]) -> str:
    """validation.grip_miss for a converged result (tolerance 1e-5 L); '' otherwise."""
    if result.status not in ("ok", "unverified") or len(result.points) == 0:
        return ""
    return grip_miss(
        result.points,
        result.s,
        [(g.name, g.s, targets[g.name].position) for g in problem.grips if g.name in targets],
        1e-5 * problem.string.length,
    )


def build_solver(problem: Problem, options: SolverOptions, compile: str | None = None):
    """Build the node's solver for a scene: ``dlo_ros.solver.make_solver``.

    It picks the model for solver.model 'auto', with its a-posteriori checks on a worker thread
    so that the stream never waits for them.  compile: 'background', 'blocking', 'cached' or
    'off'; None: 'background'.
    """
    return make_solver(problem, options, compile=compile or "background", checks="background")


def close_solver(solver) -> None:
    """Stop a solver's helper threads (auto's check worker), if it has any."""
    close = getattr(solver, "close", None)
    if close is not None:
        close()


def options_with_output_points(options: SolverOptions, n: int) -> SolverOptions:
    return replace(options, output_points=int(n))
