"""The update as a pipeline of stages: what ``ShapeSolver.solve`` runs under its lock.

Contract: ``run_update(ctx, problem, warm, tracker)`` gives the outcome (result, state to commit or
None) of moving from ``ctx.start`` (warm) or from nothing (cold) to ``problem``; it commits
nothing.  The stages, each its own module:

========================  ============================================================
``contact_rounds``        self-contact rounds and the refusal of a jump through itself
``moments``               dead point moments on the exact equilibrium equations
``ladder``                Newton, saddle escape, IPOPT, continuation, cold fallback
``slot_rounds``           obstacle contact slots placed again on the answer
``linking``               the linking-number check of the clamped span
``substeps``              a refused jump or an unsettled contact retried in substeps
``results.self_pass``     an answer without self-contact rows that passes through itself
========================  ============================================================

A new feature is a new stage: a module with a function of ``(ctx, problem, warm)`` (or wrapping
one, as ``slot_rounds`` and ``substeps`` do), called from here.
"""

from __future__ import annotations

from ...model.problem import Problem
from ..contact.apart_memo import ApartMemo
from . import linking as LK
from ..results import self_pass as SP
from .contact_rounds import solve_self_contact
from .context import Outcome, UpdateContext
from .linking import ClampTurnTracker
from .moments import solve_with_moments
from .slot_rounds import (
    COLD_SLOT_ROUNDS,
    SLOT_ROUNDS,
    place_slots_again,
    predicted_slots,
    unsettled,
)
from .substeps import JUMP_REFUSALS, in_substeps


def solve_update(ctx: UpdateContext, problem: Problem, warm: bool) -> Outcome:
    """Solve ``problem`` from ``ctx.start``: contact rounds, or the pairs-fixed solve and checks.

    Without self-contact the obstacle slots are placed again on the answer, and the linking number
    is checked where ``linking.needs_check`` asks for it.
    """
    nlp = ctx.parts.nlp
    if nlp.self_contact_slots:
        return solve_self_contact(ctx, problem, warm)
    start = ctx.start if warm else None
    ctx.newton_far = False
    predicted = predicted_slots(ctx.parts, start) if nlp.obstacle_slots and start else None
    with ctx.scoped(slot_override=predicted if predicted else ctx.slot_override):
        result, state = solve_with_moments(ctx, problem, warm)
    newton_only = result.ipopt_status.startswith("Newton")
    if nlp.obstacle_slots:
        rounds = SLOT_ROUNDS if ctx.streamed else COLD_SLOT_ROUNDS
        result, state = place_slots_again(
            ctx, problem, result, state, solve_with_moments, rounds, start
        )
    if start is not None and state is not None and LK.needs_check(ctx, result, newton_only):
        jump = LK.linking_jump(ctx, problem, start, state)
        if jump is not None:
            return LK.linking_failure(ctx, jump, result.iterations, True), None
    return result, state


def run_update(
    ctx: UpdateContext,
    problem: Problem,
    warm: bool,
    tracker: ClampTurnTracker,
    apart: ApartMemo | None = None,
) -> Outcome:
    """Solve ``problem`` (``solve_update``); a refused or unsettled warm update in substeps.

    A warm update refused as a jump, or whose obstacle contact did not settle
    (``slot_rounds.unsettled``), is solved again in substeps of the grip poses; an unsettled one
    whose substeps fail stands as it was.

    Every answer of a model without self-contact rows, of a string with a radius, is tested for
    passing through itself (``results.self_pass``): cold, warm and queries alike (``apart``: the
    solver's shape proved apart last, ``contact/apart_memo.py``).  An answer
    reached by leaving an unstable stationary point carries that point (``unstable_met``).
    """
    result, state = solve_update(ctx, problem, warm)
    if warm and result.status == "failed" and result.message.startswith(JUMP_REFUSALS):
        result, state = in_substeps(ctx, problem, result, solve_update, tracker)
    elif warm and unsettled(result):
        # a contact moved faster than the slot rounds follow: the smaller moves of substeps
        # keep each slot within reach; if they fail too, the unverified answer stands
        retried, retried_state = in_substeps(ctx, problem, result, solve_update, tracker)
        if retried_state is not None:
            result, state = retried, retried_state
    nlp, radius = ctx.parts.nlp, problem.string.radius
    if state is not None and radius > 0 and not nlp.self_contact_slots:
        geometry = SP.geometry_of(problem, ctx.parts.options.self_contact_samples)
        SP.flag(result, SP.check(nlp, state, geometry, radius, apart))
    met = ctx.unstable_met
    if met is not None and met is not result and result.stable is not False:
        result.unstable_met = met  # the escape led elsewhere: the saddle it left
    return result, state
