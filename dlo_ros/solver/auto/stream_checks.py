"""The stream's checks: when a committed solve is checked, and where a verdict is applied.

A committed solve that is not a streamed update (a cold solve, ``check_now``) is checked before it
returns (:func:`check_now`: escalate and re-solve while the policy says so, :mod:`.policy`); a
streamed update's check starts when one is due and its verdict is applied CHECK_LAG updates later,
a switch BUILD_LAG more (:mod:`.check_schedule`, :func:`apply_due`).  :class:`CheckBook` holds
what the stream knows of its checks.  Each function takes the
:class:`.auto_solver.AutoShapeSolver` it serves and uses only its public members (``book``,
``choice``, ``inner``, ``worker``, ``model_checks``, ``switch``, ``changes``, ``options``,
``finish``).
"""

from __future__ import annotations

from concurrent.futures import wait
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from ...model.problem import Problem
from ..contact.obstacle_slots import CARRIED
from ..update.slot_rounds import ACTIVE
from ..results.result import ShapeResult
from ..shape_solver import ShapeSolver
from . import escalate
from .check_schedule import PendingCheck, due, lead_step, start_check
from .checks import CheckSnapshot, CheckVerdict
from .choice import ModelChoice
from .reach import pressed_obstacles, same_contacts

if TYPE_CHECKING:  # the solver calls these functions (auto_solver.py imports this module)
    from .auto_solver import AutoShapeSolver


#: escalations a checked solve (cold, ``check_now``, a refined query) may make before it answers,
#: and how many in a row may find no new lowest estimate: a point contact's refinement converges
#: by about 0.8 per pass (the main job's post at 1e-5 m: 28 passes, 2.3e-5 → 5.0e-6 m over the
#: last 16)
CHECK_NOW_PASSES, CHECK_NOW_STALL = 40, 4
#: a new lowest estimate counts as progress when below this part of the lowest before: at the
#: unknowns cap the rule moves breakpoints, and Fig. 3's floor at ρ = 3000, δ = 1e-6 L, made ten
#: passes of 3 s at 320 nodes for estimates of 6.22e-7 ... 6.16e-7 m
CHECK_NOW_GAIN = 0.95


@dataclass
class Escalations:
    """How far a checked solve's escalations got: its lowest estimate [m], passes since, passes."""

    best: float = float("inf")
    stalled: int = 0
    passes: int = 0

    def spent(self, estimate: float, moves_only: bool = False) -> bool:
        """Count a verdict with ``estimate`` [m] (nan: a change of physics or order, none).

        True when no escalation may follow it: CHECK_NOW_PASSES made, or CHECK_NOW_STALL in a
        row without a new lowest estimate by CHECK_NOW_GAIN, or one without it that proposes
        only to move breakpoints (``moves_only``: :func:`moves_breakpoints`).  At the unknowns
        cap the rule can only move them, and a move that followed no gain gained none either
        (Fig. 3's floor at ρ = 1000, δ = 1e-6 L: four more passes of ~1.5 s at 320 nodes for
        estimates of 6.12e-7 … 6.13e-7 m).
        """
        self.passes += 1
        progress = False
        if np.isfinite(estimate):
            progress = estimate < CHECK_NOW_GAIN * self.best
            self.stalled = 0 if progress else self.stalled + 1
            self.best = min(self.best, estimate)
        stalled = self.stalled >= CHECK_NOW_STALL or (moves_only and not progress)
        return self.passes > CHECK_NOW_PASSES or stalled


def moves_breakpoints(current: ModelChoice, proposed: ModelChoice) -> bool:
    """Tell whether ``proposed`` is ``current`` with as many elements and nodes, moved."""
    a, b = current.mesh, proposed.mesh
    if a is None or b is None or a.counts is None or b.counts is None:
        return False
    same_physics = replace(proposed, mesh=a).key() == current.key()
    return same_physics and len(a.counts) == len(b.counts) and sum(a.counts) == sum(b.counts)


@dataclass
class CheckBook:
    """What a stream knows of its checks.

    ``updates``: committing solves so far (the next one's update index); ``index``: the update
    index of the committing solve running (or the last one); ``since_check``: committed solves
    since the last kept check; ``unchecked``: the model has no kept check yet;
    ``checked_update``: the update whose shape the last kept check described; ``pending``: a check
    whose verdict is held (:mod:`.check_schedule`); ``generation``: bumped by every switch, reset
    and scene change (an older verdict is stale); ``checked_contacts``: the obstacles the checked
    shape pressed on and their forces (a streamed shape whose contacts differ is unchecked again:
    ``committed``).
    """

    updates: int = 0
    index: int = 0
    since_check: int = 0
    unchecked: bool = True
    checked_update: int = 0
    pending: PendingCheck | None = None
    generation: int = 0
    checked_contacts: dict[int, float] = field(default_factory=dict)


def committed(
    auto: AutoShapeSolver,
    problem: Problem,
    inner_poses: dict,
    result: ShapeResult,
    run: tuple[bool, bool],
    notes: list[str],
    t0: float,
) -> ShapeResult:
    """Count a committed update and check it now, or start its check when one is due.

    ``run``: (check_now, limited); ``limited``: a streamed update (a warm, committing solve
    from a committed shape), whose check takes effect CHECK_LAG updates later
    (:mod:`.check_schedule`); any other committed solve is checked before it returns.
    """
    now, limited = run
    book = auto.book
    auto.problem = problem
    book.since_check += 1
    if limited and not (
        book.unchecked or same_contacts(pressed_obstacles(result), book.checked_contacts)
    ):
        # the last check's estimate is about a shape with other contacts (the main job's cable
        # landing on its post: 0.04-0.11 m off while it still said 1.4e-4 m, tolerance met):
        # unknown until the check this starts takes effect
        book.unchecked = True
    if now or not limited:  # one-shot: cold, or checked before it is published
        auto.worker.wait()
        book.pending = None  # about an earlier shape
        snap = snapshot(auto, problem, inner_poses, result, limited=limited)
        return auto.finish(check_now(auto, snap, result, notes), t0, notes)
    if book.pending is not None:  # a mesh switch it may hold leads in (lead_in.py)
        lead_step(auto, book.pending, book.index, inner_poses)
    due = book.unchecked or book.since_check >= auto.options.recheck_every
    if due and book.pending is None:
        snap = snapshot(auto, problem, inner_poses, result, limited=limited)
        book.pending = start_check(auto, snap)
    return auto.finish(result, t0, notes)


def check_now(
    auto: AutoShapeSolver, snap: CheckSnapshot, result: ShapeResult, notes: list[str]
) -> ShapeResult:
    """Run the checks synchronously: escalate and re-solve while one fails.

    An answer that passes through itself is solved again with self-contact first.  It escalates
    while the estimate keeps falling: once CHECK_NOW_STALL escalations in a row found no new
    lowest estimate, or after CHECK_NOW_PASSES, the last answer keeps its model with its estimate
    (the tolerance then reported as not met), never unchecked.
    """
    auto.pool.hold_compiles = True
    try:
        return _escalated(auto, snap, result, notes)
    finally:
        auto.pool.hold_compiles = False
        auto.inner.start_compile(auto.pool.compile)  # the model it answers with


def _escalated(
    auto: AutoShapeSolver, snap: CheckSnapshot, result: ShapeResult, notes: list[str]
) -> ShapeResult:
    """Run ``check_now``'s escalations (the pool holds its compiles meanwhile)."""
    escalations = Escalations()
    while True:
        if result.passes_through_itself and not auto.choice.self_contact:
            result, poses = escalate.contact_for_pass(auto, snap.problem, result, notes)
            snap = snapshot(auto, snap.problem, poses, result)
        verdict = auto.model_checks.evaluate(snap, False)
        if verdict.choice is None or escalations.spent(
            verdict.estimate, moves_breakpoints(auto.choice, verdict.choice)
        ):
            keep(auto, verdict)
            return result
        auto.switch(verdict.choice, verdict.reason)
        notes.append(auto.changes[-1][1])
        previous, result = result, answer_on_switch(auto, verdict, snap)
        if result.status not in ("ok", "unverified"):  # keep the answer we had, and say so
            previous.message += (
                f"; the richer model failed to solve ({result.message}): "
                "answer of the previous model"
            )
            return previous
        snap = snapshot(auto, snap.problem, snap.poses, result, limited=snap.limited)


def answer_on_switch(auto: AutoShapeSolver, verdict: CheckVerdict, snap: CheckSnapshot):
    """Return the answer at ``snap``'s poses of the model ``verdict`` switched to.

    The check's own answer there (:func:`checks_answer`), else a solve.
    """
    answer = checks_answer(auto.inner, verdict)
    if answer is None:
        answer = auto.inner.solve(snap.poses, limited=snap.limited)
    return answer


def checks_answer(solver: ShapeSolver, verdict: CheckVerdict) -> ShapeResult | None:
    """Return the check's answer on the model it names, its state installed on ``solver``.

    ``verdict.answer``: that model solved by the check at the snapshot's poses from the
    snapshot's shape, as the model switched to (``solver``) would solve it from the same shape
    mapped: a solve again would repeat it (the main job's post cold at 1e-4 m: a moved mesh's
    answer, unsettled, solved twice for 1.5 s each).  None when the check did not solve it.
    """
    if verdict.answer is None:
        return None
    result, state = verdict.answer
    solver.install_warm_start(state.copy())
    return result


def snapshot(
    auto: AutoShapeSolver,
    problem: Problem,
    poses: dict,
    result: ShapeResult,
    solver: ShapeSolver | None = None,
    choice: ModelChoice | None = None,
    limited: bool = True,
) -> CheckSnapshot:
    """Return what a check needs of the streaming model's committed ``result``, or a query's.

    A copy, for another thread.  A query's: ``result`` committed on ``solver``, a model of
    ``choice``.  ``limited``: the check's re-solves stop at ``solver.update_time_limit`` (a
    streamed update's check; never a cold solve's or a query's).
    """
    solver, choice = solver or auto.inner, choice or auto.choice
    return CheckSnapshot(
        solver,
        solver.snapshot(),
        replace(choice, reasons=list(choice.reasons)),
        problem,
        poses,
        result.points.copy(),
        max((float(np.linalg.norm(w.force)) for w in result.grips.values()), default=0.0),
        auto.book.generation,
        float(np.nan_to_num(result.equilibrium_residual_m, nan=np.inf)),
        bool(contacts := pressed_obstacles(result)),
        auto.book.index,
        limited,
        contacts,
    )


def keep(auto: AutoShapeSolver, verdict: CheckVerdict) -> None:
    """Keep the model: record the verdict's estimates; the next check is due later."""
    auto.choice.estimated_error_m = verdict.estimate
    auto.choice.order_error_m = verdict.order_error
    if np.isfinite(verdict.sampling_error):
        auto.choice.sampling_error_m = verdict.sampling_error
    auto.book.unchecked = False
    auto.book.since_check = 0
    auto.book.checked_update = verdict.snapshot.update
    auto.book.checked_contacts = verdict.snapshot.contacts


def apply_due(auto: AutoShapeSolver, notes: list[str]) -> None:
    """Apply the held check's verdict when this update is the one it is due at.

    Waits for a background check that has not finished (:mod:`.check_schedule`): its decision
    at the update it is due at, and a switch's build BUILD_LAG updates later.  Meanwhile the
    results report the decision's estimate of the current model (and ``tolerance_met`` by it):
    the shapes streamed while a finer model is built are not called better than that.
    """
    book = auto.book
    pending = book.pending
    try:
        if pending is None:
            return
        if not due(pending, book.index, book.generation):
            if pending.switching:  # decided on a switch, built meanwhile: report its estimate
                verdict = pending.decision()
                assert verdict is not None  # ``switching``: a decision named a richer model
                if book.unchecked or book.checked_update != verdict.snapshot.update:
                    keep(auto, verdict)  # the current model's (a richer one comes)
            return
        book.pending = None
        verdict = pending.decision()
        if verdict is not None and verdict.choice is not None:
            verdict = pending.outcome()  # a switch: wait for its model's build
    except Exception as exc:  # a check that raised is reported, never fatal to the stream
        book.pending = None
        notes.append(f"model check failed: {type(exc).__name__}: {exc}")
        # retry after recheck_every updates, not at once
        book.unchecked, book.since_check = False, 0
        return
    if verdict is None or verdict.snapshot.generation != book.generation:
        return  # a prebuild, or stale
    if verdict.choice is None:
        keep(auto, verdict)
    elif contact_left(auto, verdict.choice):
        pending.drop_lead_in()
        book.unchecked = True  # about a contact that has moved on: checked again from here
    else:
        # the new mesh's own equilibrium of the last update when it led in (lead_in.py), else
        # the latest committed shape mapped (not the snapshot's)
        wait(pending.steps)
        led = pending.lead.ready(book.index) if pending.lead is not None else None
        auto.switch(verdict.choice, verdict.reason, led=led)
        notes.append(auto.changes[-1][1])


def contact_left(auto: AutoShapeSolver, choice: ModelChoice) -> bool:
    """Tell whether a verdict moving breakpoints onto contacts comes due after they moved away.

    ``choice``: the verdict's model, the streaming one with the same element counts and some
    breakpoints moved (``mesh_check.moved_verdict``: onto contacts inside elements, checked
    CHECK_LAG + BUILD_LAG updates earlier).  True when a moved breakpoint is near no contact of
    the streaming model's committed shape (:func:`contact_places`): the main job's cable rolled
    its contact from s = 0.417 to 0.503 on its post meanwhile, and the breakpoint moved to 0.417
    left the new contact inside an element (the true error 3e-5 → 6.1e-4 m).  Read from the
    committed state when such a verdict comes due, never on other updates.
    """
    new, now = choice.mesh, auto.choice.mesh
    if new is None or now is None or new.counts != now.counts:
        return False
    if replace(choice, mesh=now).key() != auto.choice.key():
        return False
    moved = [
        b for b in new.breakpoints if min((abs(b - c) for c in now.breakpoints), default=1.0) > 0
    ]
    state = auto.inner.committed_state
    if not moved or state is None:
        return False
    places = contact_places(auto.inner, state, CARRIED * auto.problem.string.length)
    return any(all(abs(b - s) > near for s, near in places) for b in moved)


def contact_places(solver: ShapeSolver, state, near: float) -> list[tuple[float, float]]:
    """Return where ``state``'s contacts act, each with how near [m] a breakpoint counts as on it.

    A filled contact slot carrying force: its σ, within ``near``; an obstacle row carrying force
    (a line contact's rows, a lift-off among them): its sample's s, within the rows' spacing (a
    lift-off lies between two rows).
    """
    nlp, parameters = solver.nlp, solver.parameters
    places: list[tuple[float, float]] = []
    for i in range(len(nlp.slot_rows)):
        sigma, on = parameters.slot_lists(state.p, i)[:2]
        force = state.lam_g[np.asarray(nlp.slot_rows[i], dtype=int)]
        places += [(x, near) for x, o, f in zip(sigma, on, force) if o > 0 and f > ACTIVE]
    spacing = max(near, float(nlp.obstacle_spacing))
    for rows in nlp.obstacle_rows:
        force = state.lam_g[np.asarray(rows, dtype=int)]
        places += [(float(x), spacing) for x in np.asarray(nlp.obstacle_s)[force > ACTIVE]]
    return places
