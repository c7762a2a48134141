"""When a streamed update's check takes effect: a fixed number of updates later, in both modes.

The rule (#37).  Streamed updates are numbered 0, 1, 2, ... (every ``solve(commit=True)``: the
stream's update index).  When update k's committed shape is due for a check (its model is
unchecked, or ``recheck_every`` updates have passed), the check of that shape is started at k and
no other check starts until its verdict has taken effect:

* a verdict that keeps the model takes effect just before update k + CHECK_LAG is solved;
* a verdict that switches to another model (a mesh refined or coarsened, the physics changed)
  takes effect just before update k + CHECK_LAG + BUILD_LAG: the check decides first and then
  builds and warm-starts that model, which costs more than the decision (a new mesh: a tenth to
  a quarter of a second interpreted, and its lead-in), so the stream gets BUILD_LAG more updates
  to build it beside.

* ``checks='background'``: the check runs on the worker thread beside the updates; the update a
  verdict is due at waits for the decision (and a switch's for the build) if they have not
  finished.  The wait is bounded as the check is: each of its re-solves stops at
  ``solver.update_time_limit`` (``update/time_limit.py``).  An answer never depends on whether the
  check had finished.
* ``checks='sync'``: the check and the build run inline at k, and the verdict is held until the
  update it is due at.

So both modes, on a fast or a loaded machine, switch models at the same updates and solve the
same shapes.  A verdict about a model the stream has left meanwhile (an escalation inside an
update, a reset, a scene change) is dropped in both, at the switch; a switch of physics first
takes the finer mesh such a verdict decided (:func:`held_refinement`).  Solves that are not
streamed updates (a cold solve, ``check_now``) are checked before they return, in both modes
(``AutoShapeSolver``).
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from ..build.mesh import MeshSpec
from .checks import CheckSnapshot, CheckVerdict
from .choice import ORDERS, ModelChoice, full_choice
from .lead_in import LeadIn

if TYPE_CHECKING:  # the solver calls these functions (auto_solver.py imports this module)
    from .auto_solver import AutoShapeSolver

#: A check started at update k takes effect just before update k + CHECK_LAG.  Large enough that a
#: background check (one or two shadow solves and a 3D eigenvalue: about the cost of 1–3 updates)
#: usually finishes beside the stream without holding it up; small enough that an escalation
#: follows within a few updates, and below the default ``recheck_every`` (10), so that the checks
#: still run every ``recheck_every`` updates.
CHECK_LAG = 4
#: A switch a check decides on takes effect BUILD_LAG updates after its decision would (module
#: docstring): the model it names is built and warm-started on the worker meanwhile, and a new
#: mesh leads in (:mod:`.lead_in`), so that the switch neither builds nor waits for the build
#: (bench/perf/auto_vs_full.py: the updates over 20 ms were the switches waiting for it; at 8 the
#: table stream's switches still waited for the lead-in, a check and build of its 150-unknown
#: meshes taking 0.2–0.25 s of the worker interpreted).
BUILD_LAG = 16


@dataclass
class PendingCheck:
    """A started check whose verdict is held until update ``apply_at``.

    ``job``: the background check (its decision, then the build of the model it names);
    ``decided``: the background decision alone, known before the build; ``verdict`` / ``error``:
    an inline check's outcome.  ``switching``: the verdict names another model, and ``apply_at``
    was moved on by BUILD_LAG.  ``lead``: the lead-in of a mesh switch (:mod:`.lead_in`), and
    ``steps`` its queued solves on the worker.
    """

    apply_at: int
    job: Future | None = None
    decided: Future | None = None
    verdict: CheckVerdict | None = None
    error: Exception | None = None
    switching: bool = False
    lead: LeadIn | None = None
    steps: list[Future] = field(default_factory=list)

    def decision(self) -> CheckVerdict | None:
        """Return the verdict, waiting for a background decision; raise what the check raised."""
        if self.decided is not None:
            return self.decided.result()
        if self.error is not None:
            raise self.error
        return self.verdict

    def outcome(self) -> CheckVerdict | None:
        """Return the verdict once its model is built, waiting for a background build."""
        if self.job is not None:
            return self.job.result()
        return self.decision()

    def drop_lead_in(self) -> None:
        """Cancel the lead-in's queued solves: its switch will not be made.

        A solve the worker has started runs to its end; the others never run, so that the check
        started next does not queue behind them (the main job: a switch dropped at update 446,
        its lead-in's solves of 0.1-0.3 s each still ran, and the next check's update waited).
        The new mesh's pooled solver is never streamed on from where they stopped: a later
        verdict naming it maps its check's snapshot onto it first (``ModelChecks.evaluate``).
        """
        for step in self.steps:
            step.cancel()


def _checked(
    auto: AutoShapeSolver, snap: CheckSnapshot, decided: Future, lead: LeadIn
) -> CheckVerdict:
    """Run the check of ``snap`` on the worker; ``decided`` gets the decision before the build.

    A mesh it switches to starts its ``lead`` in, after the build.
    """
    try:
        verdict = auto.model_checks.evaluate(snap, True, decided=decided)
    except BaseException as exc:
        if not decided.done():  # the stream waits on it: it must never be left unresolved
            decided.set_exception(exc)
        raise
    lead.begin(auto.pool, verdict)
    return verdict


def start_check(auto: AutoShapeSolver, snap: CheckSnapshot) -> PendingCheck:
    """Start the check of ``snap`` (update ``snap.update``): on the worker, or run it now.

    Its verdict is held until update ``snap.update + CHECK_LAG``, a switch's BUILD_LAG updates
    longer (module docstring, :func:`due`).
    """
    apply_at = snap.update + CHECK_LAG
    lead = LeadIn(snap.update, apply_at + BUILD_LAG - 1, snap.generation)
    if auto.worker.background:
        i = ORDERS.index(snap.choice.order)
        keys = {("",) + replace(snap.choice, order=o).key() for o in ORDERS[max(i - 1, 0) : i + 2]}
        if snap.choice.may_leave_plane:  # the 3D model that checks a planar shape (shadows.py)
            keys.add(("",) + full_choice(snap.choice, snap.problem).key())
        decided: Future = Future()
        job = auto.worker.submit(_checked, keys, auto, snap, decided, lead)
        return PendingCheck(apply_at, job=job, decided=decided, lead=lead)
    try:
        verdict = auto.model_checks.evaluate(snap, False)
    except Exception as exc:  # noqa: BLE001 - reported when applied, as a background one is
        return PendingCheck(apply_at, error=exc)
    lead.begin(auto.pool, verdict)
    return PendingCheck(apply_at, verdict=verdict, lead=lead)


def lead_step(auto: AutoShapeSolver, pending: PendingCheck, update: int, poses: dict) -> None:
    """Queue (or, checks 'sync', run) the lead-in's solve at streamed update ``update``.

    ``poses``: the update's inner poses.  Only the updates it follows are queued, each after the
    check (the worker runs its jobs in order), so that it finds the lead-in begun if the verdict
    names a mesh (:mod:`.lead_in`).
    """
    lead = pending.lead
    if lead is None or not lead.follows(update):
        return
    generation = auto.book.generation
    if auto.worker.background:
        pending.steps.append(auto.worker.submit(lead.step, set(), update, dict(poses), generation))
    else:
        lead.step(update, poses, generation)


def due(pending: PendingCheck, update: int, generation: int) -> bool:
    """Tell whether ``pending``'s verdict takes effect before ``update`` (else it stays held).

    At ``apply_at`` the decision is read (waiting for it); one that switches models is held
    BUILD_LAG updates more, once, unless it is stale (``generation``: the stream's switch count
    now), which is dropped at once.  Raises what the check raised.
    """
    if update < pending.apply_at:
        return False
    if pending.switching:
        return True
    verdict = pending.decision()
    if verdict is None or verdict.choice is None or verdict.snapshot.generation != generation:
        return True
    pending.switching = True
    pending.apply_at += BUILD_LAG
    return update >= pending.apply_at


def held_refinement(
    pending: PendingCheck | None,
    choice: ModelChoice,
    generation: int,
    tolerance: float,
    wait: bool,
) -> MeshSpec | None:
    """Return the finer mesh a held check decided for the streaming model ``choice``, else None.

    The check must be of this model (``generation``: the stream's switch count now) and its verdict
    the same physics on another mesh because the current one is too coarse (its estimate over
    δ/2, ``tolerance`` = δ [m]: the mesh check's refinement).  A switch of physics before that
    verdict takes effect carries the finer mesh with it (``follow.follow_scene``: the main job's
    3D model started on the planar mesh the check had just found too coarse, and its answers were
    unverified until the 3D model's own check refined it 30 updates later).  ``wait``: wait for a
    background decision (a switch reads it, so that both check modes switch alike); else None
    while it is undecided (what is built ahead).  A check that raised gives None.
    """
    if pending is None:
        return None
    if not wait and pending.decided is not None and not pending.decided.done():
        return None
    try:
        verdict = pending.decision()
    except Exception:  # noqa: BLE001 - reported when it is due, as any check's failure
        return None
    if verdict is None or verdict.choice is None or verdict.snapshot.generation != generation:
        return None
    new = verdict.choice
    if new.mesh is None or replace(new, mesh=choice.mesh).key() != choice.key():
        return None
    return new.mesh if verdict.estimate > tolerance / 2 else None
