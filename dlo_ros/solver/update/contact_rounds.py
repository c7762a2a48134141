"""Stage: self-contact rounds (``contact/self_contact.py``) and the checks of their answer.

Contract: ``solve_self_contact(ctx, problem, warm)`` gives the outcome of a solve of a model with
self-contact slots.  The slots are filled from the start's shape (``ctx.start``, or the cold
guess); each round runs the pairs-fixed solve (``moments.solve_with_moments``) with its pairs in
``ctx.contact`` and its start in ``ctx.start`` (both restored after the round).  A pair the answer
penetrates is added and the solve repeated, at most ``CONTACT_ROUNDS`` times.  On a warm update
the answer is refused ('failed', no state) when a crossing changed sides, when the straight move
from the start meets itself, or when the linking number jumped (``linking.linking_jump``).  The
state of an accepted answer carries its pairs (``SolverState.contact``).  Side effect, as before:
``ctx.parts.outputs.contact_slots`` is left at the last round's pairs.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from ..build.initial_guess import initial_guess
from ..build.nlp import StringNLP
from ..contact import self_contact as SC
from ..results.outputs import no_shape
from ..results.result import ShapeResult
from ..state import SolverState
from . import contact_points as CP
from . import linking as LK
from . import recovery as RC
from .context import Outcome, UpdateContext
from .moments import solve_with_moments


def solve_self_contact(ctx: UpdateContext, problem: Problem, warm: bool) -> Outcome:
    """Solve with self-contact rounds (see the module docstring).

    On a warm update a crossing sign that flipped since the committed shape, or two samples that
    meet when the shape is moved straight from the committed one to the answer, mean the string
    (may have) passed through itself: 'failed', not committed; so does a change of the clamped
    span's linking number Tw + Wr that the clamps' own turns do not explain (whole turns of twist
    released without the centreline coming near itself).
    """
    parts, st = ctx.parts, problem.string
    nlp = parts.nlp
    geometry = SC.contact_geometry(
        st.length, st.radius, parts.options.self_contact_samples, tuple(g.s for g in problem.grips)
    )
    capacity = nlp.self_contact_slots
    start = ctx.start if warm else None
    previous: SC.ContactSlots | None = (
        start.contact if start is not None and start.contact is not None else None
    )
    if previous is not None and previous.geometry.key != geometry.key:
        # another radius: the slots' indices mean other samples, and the start's multipliers on
        # them belong to the old pairs: start cold
        start, previous, warm = None, None, False
    slots: list[tuple[int, int] | None] = (
        previous.pairs if previous is not None else [None] * capacity
    )
    keep = loaded_slots(nlp, start) if start is not None and previous is not None else set()
    reference = start  # what the sweep and the linking number are checked against
    if previous is not None and previous.candidates is not None:
        candidates = previous.candidates  # the committed shape's, found when committed
    else:
        z0 = start.z if start is not None else initial_guess(nlp, parts.parameters, problem)
        candidates = SC.candidate_pairs(nlp.model.positions(z0, geometry.s), geometry)
        if start is not None and RC.through_itself(candidates, geometry, st.length):
            # mapped from a model without self-contact, through itself (recovery.py)
            reference = None
    slots, _ = SC.assign(slots, [pair for pair, _ in candidates], keep, capacity)
    slack = RC.SLACK * st.length
    iterations = 0
    round_start = start
    for _ in range(SC.CONTACT_ROUNDS):
        contact = SC.ContactSlots(geometry, slots, at=CP.kept_points(previous, slots))
        # (ShapeOutputs declares the attribute by its initial None: it holds ContactSlots too)
        parts.outputs.contact_slots = contact  # type: ignore[assignment]
        # a warm update repeats from its (non-penetrating) start; a cold solve from the previous
        # round's answer, whose strands already pass each other on the side they will touch on
        with ctx.scoped(contact=contact, start=round_start):
            result, state = solve_with_moments(ctx, problem, round_start is not None)
        iterations += result.iterations
        if state is None:
            return result, None
        points = nlp.model.positions(state.z, geometry.s)
        candidates = SC.candidate_pairs(points, geometry)
        missing = [
            pair for pair in CP.penetrating(candidates, contact, slack) if pair not in slots
        ]
        if not missing:
            result.iterations, result.warm_started = iterations, warm
            answer = (result, state, geometry, points, candidates, contact)
            outcome = checked_answer(ctx, problem, answer, previous, reference, start is not None)
            return CP.hold_at_closest_points(ctx, problem, outcome, loaded_slots)
        if start is None:
            round_start = state
        # the next round starts from round_start: its loaded slots keep their pairs (Newton uses
        # λ there)
        keep = loaded_slots(nlp, round_start) if round_start is not None else set()
        slots, left = SC.assign(slots, missing + [pair for pair, _ in candidates], keep, capacity)
        if any(pair in left for pair in missing):
            break
    why = (
        f"self-contact: the shape still penetrates itself after {SC.CONTACT_ROUNDS} rounds of "
        f"adding pairs (capacity solver.self_contact_pairs = {capacity})"
    )
    return refusal(ctx, why, iterations, warm)


def checked_answer(
    ctx: UpdateContext,
    problem: Problem,
    answer: tuple,
    previous: SC.ContactSlots | None,
    reference: SolverState | None,
    warm_start: bool,
) -> Outcome:
    """Return a round's non-penetrating answer, or 'failed' when it is a jump from ``reference``.

    ``answer``: (result, state, contact geometry, sample points, candidate pairs, the slots'
    ``ContactSlots``);
    ``previous``: the start's
    pairs and crossing signs; ``warm_start``: the solve had a start (a start that was not a
    reference is said so in the message).
    """
    result, state, geometry, points, candidates, contact = answer
    nlp = ctx.parts.nlp
    iterations, warm = result.iterations, result.warm_started
    result.min_self_distance = min((d for _, d in candidates), default=float("inf"))
    signs = (
        SC.crossing_signs(points, nlp.model.tangents_at(state.z, geometry.s), candidates)
        if candidates
        else {}
    )
    flips = SC.crossing_flips(previous.signs, signs) if previous is not None else []
    if flips:
        a, b = flips[0]
        why = (
            f"self-contact: the string passed through itself between the last shape and this one "
            f"(the crossing at s = {geometry.s[a]:.4g} m and {geometry.s[b]:.4g} m changed sides)"
        )
        return refusal(ctx, why, iterations, warm)
    swept = (
        None
        if reference is None
        else SC.swept_crossing(nlp.model.positions(reference.z, geometry.s), points, geometry)
    )
    if swept is not None:
        a, b = swept
        why = (
            f"self-contact: this shape is not reached from the last one without the string "
            f"passing through itself (moved straight, s = {geometry.s[a]:.4g} m and "
            f"{geometry.s[b]:.4g} m meet on the way); a jump of the solver, not published"
        )
        return refusal(ctx, why, iterations, warm)
    jump = None if reference is None else LK.linking_jump(ctx, problem, reference, state)
    if jump is not None:
        return LK.linking_failure(ctx, jump, iterations, warm), None
    if reference is None and warm_start:
        result.message += (
            "; its warm start passed through itself (mapped from a "
            "model without self-contact): checked as a cold start"
        )
    state.contact = SC.ContactSlots(
        geometry, list(contact.pairs), signs, candidates, dict(contact.at)
    )
    return result, state


def refusal(ctx: UpdateContext, why: str, iterations: int, warm: bool) -> Outcome:
    """Return 'failed' without a shape, for ``why``."""
    result: ShapeResult = no_shape(
        ctx.parts.options,
        ctx.parts.summary(),
        "failed",
        why,
        iterations=iterations,
        warm_started=warm,
    )
    return result, None


def loaded_slots(nlp: StringNLP, state: SolverState) -> set[int]:
    """Return the slots whose row is active in ``state`` as Newton counts it.

    At its bound with λ > 1e-8: IPOPT leaves ~1e-10 barrier multipliers on rows far from their
    bound.
    """
    g = state.g if state.g is not None else np.asarray(nlp.g_fn(state.z, state.p)).ravel()
    return {
        k
        for k, row in enumerate(nlp.self_contact_rows)
        if state.lam_g[row] > 1e-8 and g[row] > nlp.ubg[row] - 1e-7
    }
