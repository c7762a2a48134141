"""AutoShapeSolver: the Solver protocol with the model chosen, checked and escalated by auto.

The policy is :mod:`.policy` (the a-posteriori rule) and one page of
``msg_docs/model_and_solver.md`` ("auto's policy").  This module holds the coordinator: the
streaming model and its switches and the update (:meth:`AutoShapeSolver.solve`).  The pieces it
coordinates are modules of their own: the choice (:mod:`.choice`, :mod:`.reach`), the reduced
models and their pool (:mod:`.reduced`, :mod:`.pool`), the background worker (:mod:`.background`),
the checks (:mod:`.checks`, :mod:`.shadows`, :mod:`.mesh_check`) and where their verdicts are
applied (:mod:`.stream_checks`), the escalations inside one update (:mod:`.escalate`) and the
refinement of a query (:mod:`.query_refine`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import replace

from ...model.problem import GripPose, Problem
from ..options import SolverOptions
from ..parallel.batch import query_many
from ..results.result import ShapeResult
from ..results.summary import ModelSummary
from ..shape_solver import ShapeSolver, with_checked_poses
from . import escalate, follow, report, stream_checks
from .background import CheckWorker
from .checks import ModelChecks
from .choice import ModelChoice, full_choice, initial_choice
from .pool import ModelPool
from .query_refine import refine_query
from .reduced import ReducedModels
from .stream_checks import CheckBook


class AutoShapeSolver:
    """The Solver protocol (solver/protocol.py) with model selection.

    A solve that is not a streamed update (a cold solve, ``check_now``) is checked before it is
    returned, in both modes.  A streamed update k's check takes effect just before update
    k + CHECK_LAG (:mod:`.check_schedule`), in both modes, so that both give the same models and
    shapes: checks 'sync' runs it inline at k (the CLI), 'background' on a worker thread from a
    snapshot of the solve (the node), and update k + CHECK_LAG waits for it if it has not finished.
    An escalation switches to the model the check has already built and warmed, so the switch costs
    no build.  'background' lowers the process's ``sys.setswitchinterval`` to SWITCH_INTERVAL_S, so
    that the worker's Python holds the stream thread up for at most that long.  Until the first
    check of a model has taken effect, ``model.checked`` is false and ``estimated_error_m`` is
    None.  ``compile`` is each streaming model's compile mode (``ShapeSolver``), but 'blocking'
    holds for the models of the first committed solve only: a model a later update switches to
    compiles in the background, so that no update waits for gcc.
    """

    POOL_SIZE = ModelPool.SIZE

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions | None = None,
        compile: str = "background",
        checks: str = "background",
    ):
        """Choose the first model of ``problem`` and build it (see the class docstring)."""
        options = options or SolverOptions()
        if options.model != "auto":
            raise ValueError("AutoShapeSolver needs solver.model 'auto'")
        if checks not in ("sync", "background"):
            raise ValueError(f"checks: must be 'sync' or 'background', got {checks!r}")
        problem.validate()
        options.validate()
        self.options = options
        self.compile = compile
        self.checks = checks
        self.problem = problem
        #: (time.time(), reason, the update index it took effect at), the newest 50
        self.changes: list[tuple[float, str, int]] = []
        self._lock = threading.RLock()
        self.worker = CheckWorker(checks == "background")
        self.reduced = ReducedModels(options)
        self.pool = ModelPool(self.reduced, compile, self.worker)
        self.model_checks = ModelChecks(
            self.pool, options.error_tolerance or 1e-3 * problem.string.length
        )
        self.book = CheckBook()  # what the stream knows of its checks (stream_checks.py)
        self.choice = initial_choice(problem, options, self.tolerance)
        self.inner = self.pool.solver_for(self.choice, problem, stream=True)
        if self.worker.background:
            follow.build_first(self, problem)

    # ---- the state the pieces share -------------------------------------------------------------
    @property
    def inner(self) -> ShapeSolver:
        """The ShapeSolver of the model the stream solves on (``choice``)."""
        assert self.pool.streaming is not None
        return self.pool.streaming

    @inner.setter
    def inner(self, solver: ShapeSolver) -> None:
        self.pool.streaming = solver

    @property
    def tolerance(self) -> float:
        """δ [m]: ``solver.error_tolerance``, by default 1e-3·L of the current scene."""
        return self.model_checks.tolerance

    @property
    def lower_tried(self) -> set[tuple]:
        """Model keys already tried as a lower order (each is tried once per model)."""
        return self.model_checks.lower_tried

    def switch(
        self,
        choice: ModelChoice,
        reason: str,
        start: tuple | None = None,
        at: int | None = None,
        led: ShapeSolver | None = None,
    ) -> None:
        """Stream on ``choice`` from now on, mapping the warm start (unchecked until checked).

        Waits for a running background job only if that job may be using the model switched to.
        ``start``: (solver, its state or None, problem) to map instead of the streaming model's
        committed shape at ``self.problem`` (None: a cold start).  ``led``: the model of ``choice``
        holding its own equilibrium of the last update (a mesh's lead-in, ``lead_in.py``), streamed
        on from there instead of a mapped shape.  The change is appended to
        ``changes`` (the newest 50 are kept) with the update index it takes effect at: ``at``,
        by default the update being solved.
        """
        t0 = time.perf_counter()
        self.worker.wait_for_model(("",) + choice.key())
        t1 = time.perf_counter()
        pooled = self.pool.pooled(choice) is not None
        at = self.book.index if at is None else at
        self.changes.append((time.time(), reason, at))
        del self.changes[:-50]  # the newest 50 (all are in the log and the recording)
        if choice.order > self.choice.order and choice.planar == self.choice.planar:
            # just found too coarse
            self.lower_tried.add(replace(choice, order=self.choice.order).key())
        source, state, problem = (self.inner, None, self.problem) if start is None else start
        if led is not None:  # its own equilibrium of the last update: nothing to map
            source = None
        self.inner = self.pool.solver_for(
            choice, problem, stream=True, source=source, state=state, built=led
        )
        if start is not None and state is None:
            self.inner.reset()
        waited, built = t1 - t0, time.perf_counter() - t1
        if waited > 0.05 or built > 0.2:  # visible in the change's reason: the stream stalled
            self.changes[-1] = (
                self.changes[-1][0],
                f"{reason} [waited {waited:.2f} s for the worker's build, "
                f"{built:.2f} s to set up the "
                f"{'pooled' if pooled else 'missing, so built here,'} model]",
                at,
            )
        # the reasons say why this model: drop the planar one when leaving the plane, add this
        # change
        choice.reasons = [
            r for r in choice.reasons if choice.planar or not r.startswith("planar:")
        ] + [reason]
        self.choice = choice
        self.book.unchecked = True
        self.book.generation += 1
        # a held verdict is about the model left: dropped now, so that this one's check starts
        self.book.pending = None

    # ---- public API -----------------------------------------------------------------------------
    @property
    def has_warm_start(self) -> bool:
        """Whether the next solve starts warm (the streaming model has a committed shape)."""
        return self.inner.has_warm_start

    @property
    def kkt_compiled(self) -> bool:
        """Whether the streaming model's derivatives run compiled C."""
        return self.inner.kkt_compiled

    @property
    def checks_pending(self) -> bool:
        """Whether a check's verdict is held (a later update applies it) or a job runs."""
        return self.book.pending is not None or not self.worker.idle

    def reset(self) -> None:
        """Forget every warm start (the streaming model's and the pooled ones'): the next is cold.

        A background verdict still pending is dropped (it describes a shape that is gone).
        """
        with self._lock:
            self.worker.wait()
            self.book.pending = None
            for solver in self.pool.solvers() + [self.inner]:
                solver.reset()
            self.book.unchecked = True
            self.book.generation += 1

    def close(self) -> None:
        """Stop the check worker (waits for a running check); later solves check inline."""
        with self._lock:
            if self.worker.background:
                self.worker.shutdown()  # a held verdict is kept: it is done, applied when due
                self.checks = "sync"

    def query_many(
        self,
        targets: Sequence[Mapping[str, GripPose | tuple]],
        executor: Executor | None = None,
    ) -> list[ShapeResult]:
        """Answer many independent queries in worker processes (see ShapeSolver.query_many).

        Each worker runs its own auto solver of this scene, with inline checks.
        """
        return query_many(AutoShapeSolver, self.problem, self.options, targets, executor)

    def set_problem(self, problem: Problem) -> None:
        """Take new scene values; the model is chosen again (its order and stretch kept)."""
        problem.validate()
        with self._lock:
            self.worker.wait()
            self.book.pending = None  # its verdict is about the old scene
            self.book.generation += 1
            self.problem = problem
            self.model_checks.tolerance = (
                self.options.error_tolerance or 1e-3 * problem.string.length
            )
            self.lower_tried.clear()
            choice = initial_choice(problem, self.options, self.tolerance)
            choice.order, choice.stretch = self.choice.order, self.choice.stretch or choice.stretch
            if choice.key() != self.choice.key():
                self.switch(choice, "scene changed", at=self.book.updates)  # from the next update
            else:
                self.inner.set_problem(self.reduced.reduce(self.choice, problem)[0])
                self.book.unchecked = True

    # ---- one update -----------------------------------------------------------------------------
    def solve(
        self,
        poses: Mapping[str, GripPose | tuple] | None = None,
        *,
        warm: bool = True,
        commit: bool = True,
        check_now: bool = False,
    ) -> ShapeResult:
        """Return the equilibrium with the given grip poses (missing grips keep their target).

        check_now: run the a-posteriori checks on this (committed) result before returning it, even
        in background mode, escalating and re-solving while one fails — for a re-solve after a
        change of the scene's values, whose answer must not be published before it is checked.  A
        running background check is waited for first (its verdict is about an earlier solve and is
        dropped).

        ``solver.update_time_limit`` bounds a streamed update only (``update/time_limit.py``): its
        re-solves and checks here stop at it; a cold solve's (no committed shape), a ``check_now``
        re-solve's and a query's never do, so the limit cannot change their answers.
        """
        with self._lock:
            t0 = time.perf_counter()
            limited = commit and warm and not check_now and self.inner.has_warm_start
            before_problem = self.problem
            try:
                problem = with_checked_poses(self.problem, poses)
            except (ValueError, KeyError) as exc:
                return self.finish(
                    ShapeResult(status="invalid", message=str(exc).strip("'\"")), t0, []
                )
            off_plane = follow.off_kept_plane(self, problem)
            if off_plane:
                return self.finish(ShapeResult(status="invalid", message=off_plane), t0, [])
            notes: list[str] = []
            if commit:
                self.book.index, self.book.updates = self.book.updates, self.book.updates + 1
                stream_checks.apply_due(self, notes)
            answer = follow.follow_scene(self, problem, commit, notes, t0)
            if answer is not None:  # a query answered by a richer model
                return answer
            run = (warm, commit, check_now, limited)
            result = self._update(problem, before_problem, run, notes, t0)
            if commit:
                follow.build_ahead(self, problem)
                if self.pool.compile == "blocking":
                    # 'blocking' compiles the models of the first solve before it returns; a model
                    # a later update switches to compiles in the background: a switch that ran gcc
                    # on the stream's thread held a node's centrelines back for over 10 s
                    self.pool.compile = "background"
            return result

    def _update(
        self,
        problem: Problem,
        before_problem: Problem,
        run: tuple[bool, bool, bool, bool],
        notes: list[str],
        t0: float,
    ) -> ShapeResult:
        """Solve on the streaming model, escalate inside the update, commit and check.

        ``run``: (warm, commit, check_now, limited) of ``solve``; ``limited``: every re-solve and
        check of this update stops at ``solver.update_time_limit``.
        """
        warm, commit, check_now, limited = run
        inner_poses = self.reduced.poses(self.choice, problem)
        # the shape this update starts from (a switch to self-contact may start there)
        before = (self.inner, self.inner.committed_state if warm else None, before_problem)
        # the poses are checked and the plane too (above): the inner solver need not again
        result = self.inner.solve(
            inner_poses, warm=warm, commit=commit, checked=True, limited=limited
        )
        if commit and escalate.refusal(result) is not None:
            result = escalate.richer_for_topology(self, problem, result, notes, limited)
        if result.status == "ok" and result.stable is False:
            result, answered_by = escalate.richer_for_stability(
                self, problem, result, notes, commit, limited
            )
            if answered_by is not None:  # a query answered by the next order's model
                return refine_query(self, problem, result, t0, *answered_by)
        # an unverified result (residual over the tolerance) is committed as the warm start and
        # checked: the check escalates the order
        if not commit:
            return refine_query(self, problem, result, t0)
        if result.status not in ("ok", "unverified"):
            return self.finish(result, t0, notes)
        approach = escalate.self_approach(self, problem, result)
        if approach:  # the shape came within reach of itself: solve again with self-contact
            start, why = escalate.contact_start(self, problem, before)
            self.problem = problem if start is None else before_problem
            contact = replace(full_choice(self.choice, problem), self_contact=True)
            self.switch(contact, approach + why, start)
            notes.append(self.changes[-1][1])
            inner_poses = self.reduced.poses(self.choice, problem)
            result = self.inner.solve(
                inner_poses, warm=warm, commit=commit, checked=True, limited=limited
            )
            if result.status not in ("ok", "unverified"):
                return self.finish(result, t0, notes)
        checking = (check_now, limited)
        return stream_checks.committed(self, problem, inner_poses, result, checking, notes, t0)

    def _wait_for_check(self) -> None:
        """Let the worker's jobs finish (a held verdict is still applied when it is due)."""
        self.worker.wait()

    # ---- results (report.py) ------------------------------------------------------------------
    def model_summary(
        self,
        choice: ModelChoice | None = None,
        solver: ShapeSolver | None = None,
        changed: tuple[str, ...] = (),
        estimate: float | None = None,
    ) -> ModelSummary:
        """Return the ``model`` object of a result: the streaming model, or a query's.

        A query's is ``choice``/``solver``; ``changed``: the changes of model this very solve made;
        ``estimate``: a refined query's own checked estimate.  See :func:`.report.model_summary`.
        """
        streaming = choice is None
        c, s = (self.choice, self.inner) if streaming else (choice, solver)
        assert c is not None and s is not None
        return report.model_summary(
            c,
            s,
            tolerance=self.tolerance,
            checks=self.checks,
            changes=tuple(r for _, r, _ in self.changes),
            changes_at=tuple(at for _, _, at in self.changes),
            checked=streaming and not self.book.unchecked,
            updates_ago=self.book.index - self.book.checked_update,
            changed=changed,
            estimate=estimate,
        )

    def finish(
        self,
        result: ShapeResult,
        t0: float,
        notes: list[str],
        choice: ModelChoice | None = None,
        solver: ShapeSolver | None = None,
        estimate: float | None = None,
    ) -> ShapeResult:
        """Return ``result`` with its model and time; contact forces keyed by scene obstacle index.

        The model is the streaming one, or the query's ``choice``/``solver``, its estimate at
        least twice the answer's own residual (``report.with_own_residual``); ``t0`` is when the
        solve started (``time.perf_counter``), ``notes`` the changes it made.
        """
        c = choice or self.choice
        model = self.model_summary(choice, solver, tuple(notes), estimate)
        result.model = report.with_own_residual(model, result.equilibrium_residual_m)
        return report.finished(result, t0, c.obstacles, len(self.problem.obstacles))
