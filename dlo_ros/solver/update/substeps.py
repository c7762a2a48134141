"""Stage: a move split into substeps, of the Newton path and of the whole update.

Contract:

* ``newton_in_substeps(ctx, start, p1, problem)``: Newton along the straight path from
  ``start.p`` to ``p1`` in SUBSTEPS equal parts, as a Newton attempt (ok, state, steps,
  violation); the ladder's rung between plain Newton and IPOPT;
* ``in_substeps(ctx, problem, refused, solve, tracker)``: a warm update refused as a jump
  (``JUMP_REFUSALS``) or left with an unsettled contact solved again as warm updates of the grip
  poses, each by ``solve`` (``pipeline.solve_update``) from the last: two halves of the move, else
  four quarters, a quarter that fails split in two again down to FINEST; it gives the last
  substep's outcome, uncommitted, or ``refused`` with the substeps' outcome added (``refused``
  as it was when the grips did not move: ``moves``).
  ``ctx.start``, ``ctx.scene``, ``ctx.clamp_turns`` and ``ctx.turns`` are restored when it
  returns.

``newton_in_substeps`` is called through this module's attribute, so a test may wrap it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...model.problem import GripPose, Problem
from ...model.rotations import slerp
from ..results.result import ShapeResult
from ..state import SolverState
from . import attempts as AT
from .context import Outcome, UpdateContext
from .linking import ClampTurnTracker

#: the messages of a warm update refused as a jump of the solver (retried in substeps)
JUMP_REFUSALS = (
    "self-contact: the string passed through itself",
    "self-contact: this shape is not reached",
    "topology:",
)
#: substeps Newton's path is split into when it cannot take a move at once (each count in turn)
SUBSTEPS = (2, 4)
#: the smallest substep of a whole update retried (``in_substeps``), as a share of its move: the
#: main job's cable by every 3rd target (a planner at 17 Hz, or the node coalescing) rolls its
#: contact on the post 2 cm in the third quarter of update 429's move and 0.7 cm in the first
#: half; uniform quarters left that quarter unsettled (the slot rounds crawl when the cable nearly
#: conforms to the post), its eighths settle.  (Halves split on failure instead of quarters from
#: the start flipped the landing's stream, interpreted, to the mirror side of the post at 411.)
FINEST = 1 / 8

#: a warm or cold solve from the context's start (``pipeline.solve_update``)
Solve = Callable[[UpdateContext, Problem, bool], Outcome]


def newton_in_substeps(
    ctx: UpdateContext, start: SolverState, p1: np.ndarray, problem: Problem | None = None
) -> AT.NewtonAttempt:
    """Run Newton along the straight path from ``start.p`` to ``p1`` in SUBSTEPS equal parts.

    Each part is warm-started from the last (the continuation IPOPT would do next, at the cost of
    Newton steps); ``problem``: what ``p1`` packs.  No move (``p1`` is ``start.p``: a re-solve on a
    new mesh from the shape mapped onto it) has nothing to split: each first part would be the
    Newton that just failed (Fig. 3's floor cold: 0.13 s of its 1.1 s).
    """
    if np.array_equal(p1, start.p):
        return False, start, 0, np.inf
    iterations = 0
    for parts in SUBSTEPS:
        state, ok = start, True
        for i in range(1, parts + 1):
            ok, state, it, viol = (
                AT.newton_to(ctx, state, p1, problem)
                if i == parts
                else AT.newton_to(ctx, state, start.p + (p1 - start.p) * (i / parts))
            )
            iterations += it
            if not ok:
                break
        if ok:
            return True, state, iterations, viol
    return False, start, iterations, np.inf


def substep_scene(problem: Problem, start: dict[str, GripPose], t: float) -> Problem:
    """Return ``problem`` with its grips at the fraction ``t`` of the way from ``start``.

    Positions move linearly, orientations by slerp.
    """
    return problem.with_grip_poses(
        {
            g.name: GripPose(
                (1.0 - t) * start[g.name].position + t * g.pose.position,
                slerp(start[g.name].orientation, g.pose.orientation, t),
            )
            for g in problem.grips
        }
    )


def moves(scene: Problem, problem: Problem) -> bool:
    """Tell whether ``problem``'s grip poses differ from ``scene``'s (a move to split)."""
    held = {g.name: g.pose for g in scene.grips}
    return any(
        g.name not in held
        or not np.array_equal(held[g.name].position, g.pose.position)
        or not np.array_equal(held[g.name].orientation, g.pose.orientation)
        for g in problem.grips
    )


def in_substeps(
    ctx: UpdateContext,
    problem: Problem,
    refused: ShapeResult,
    solve: Solve,
    tracker: ClampTurnTracker,
) -> Outcome:
    """Solve a refused or unsettled warm update again in substeps of its move.

    The refusal: the string passed through itself, or turns of twist were released
    (``JUMP_REFUSALS``); unsettled: a contact moved faster than the slot rounds follow
    (``slot_rounds.unsettled``).  The substeps go from the committed poses (``ctx.scene``'s) to
    ``problem``'s, each checked as any update is: IPOPT's iterates need not keep the contact rows,
    and a smaller move keeps it on the branch (Fig. 2 at radius 0).  First two halves of the move;
    if one fails, four quarters from the start again, a quarter that is not ``ok`` split in two
    from its own start, down to FINEST of the move.  Returns the last substep's (result, state),
    uncommitted; or ``refused`` (with the outcome of the substep that failed added) when that
    fails too.  The context's start is restored either way: ``ShapeSolver.solve`` commits.
    """
    if not moves(ctx.scene, problem):
        # no move to split: each substep would be the refused solve again, from its start (the
        # main job's post cold at 1e-4 m: a refinement pass at the same poses, unsettled, then
        # twice three substeps that each came back as unsettled, 4 s each time)
        return refused, None
    committed = (ctx.start, ctx.scene, ctx.clamp_turns)
    why = ""
    with ctx.scoped(
        start=ctx.start, scene=ctx.scene, clamp_turns=ctx.clamp_turns, turns=ctx.turns
    ):
        for first, finest in ((0.5, 0.5), (0.25, FINEST)):
            ctx.start, ctx.scene, ctx.clamp_turns = committed
            result, state, why = _split_move(ctx, problem, solve, tracker, first, finest)
            if state is not None:
                result.message += (
                    f"; solved in {result.continuation_steps} substeps "
                    f"(one update was refused: {refused.message})"
                )
                return result, state
    refused.message += why
    return refused, None


def _split_move(
    ctx: UpdateContext,
    problem: Problem,
    solve: Solve,
    tracker: ClampTurnTracker,
    length: float,
    finest: float,
) -> tuple[ShapeResult, SolverState | None, str]:
    """Take the move from ``ctx.scene``'s poses to ``problem``'s in substeps of ``length``.

    A substep that is not ``ok`` is tried again as two of half its length from its own start,
    down to ``finest``, and the substeps after it keep the shorter length (binary fractions of the
    move: their sums are exact).  Returns the last substep's result and state
    (``continuation_steps``: how many were solved), or (the failed substep's result, None, what
    failed).  Moves ``ctx.start``, ``ctx.scene`` and the turns on.
    """
    start = {g.name: g.pose for g in ctx.scene.grips}
    done, solved = 0.0, 0
    while True:
        to = done + length
        step = substep_scene(problem, start, to) if to < 1.0 else problem
        ctx.turns = tracker.advance(ctx.start, ctx.clamp_turns, step)
        result, state = solve(ctx, step, True)
        if result.status != "ok" or state is None:  # a rescue must be a verified equilibrium
            if length / 2 >= finest:
                length /= 2
                continue
            return (
                result,
                None,
                (
                    f"; in substeps, the one from {done:g} to {to:g} of the move "
                    f"{result.status}: {result.message}"
                ),
            )
        solved += 1
        if to >= 1.0:
            result.continuation_steps = solved
            return result, state, ""
        ctx.start, ctx.scene, done = state, step, to  # the next substep starts here
        ctx.clamp_turns = None if ctx.turns is None else ctx.turns.committed()
