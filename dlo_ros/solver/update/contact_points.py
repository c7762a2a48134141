"""Stage: hold each self-contact at the closest points of its two strands (``closest_points.py``).

Contract: ``hold_at_closest_points(ctx, problem, outcome, loaded)`` takes an accepted answer of the
self-contact rounds (``contact_rounds.py``) and returns it with every contact that carries a force
held exactly: the slot moved from its sample pair (kept at D = √((2r)² + h²/2)) to the closest
points (σ_a, σ_b) of the answer's two strands, kept at 2r, the other slots of the same contact
emptied, and the NLP solved again warm from the answer (the contact's multipliers summed onto the
held slot).  Repeated until the strands come less than ``STEP`` · L inside 2r at the held slots'
closest points (a fixed point: there the answer satisfies the exact contact's conditions), at most
``ROUNDS`` times; so a warm update whose held contacts barely slid is not solved again.  Contacts
between near-parallel strands (``closest_points.MIN_SINE``) and line contacts (loaded slots
spread over more than ``LINE`` sample spacings, e.g. a plectoneme's wrapped legs) stay sampled.
A re-solve that fails, or whose sample pairs away from the held contacts come closer than D (a
contact the rounds did not hold), leaves the rounds' answer as it was: never worse than the
sampled rows.
``loaded(nlp, state)``: the slots whose rows carry a force (``contact_rounds.loaded_slots``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...model.problem import Problem
from ..build.nlp import StringNLP
from ..contact import self_contact as SC
from ..contact.closest_points import closest_points
from ..state import SolverState
from . import recovery as RC
from .context import Outcome, UpdateContext
from .moments import solve_with_moments

#: a contact whose loaded slots spread over more than LINE spacings along a strand is a line
#: contact (held on its sample pairs); sample pairs within NEAR spacings of a held contact belong
#: to it (``near_held``)
LINE, NEAR = 2.5, 3.0
#: re-solves at most, and how far [L] the strands may come inside 2r at the closest points of a
#: slot held at stale ones (the excess of a stale pair's distance is second order in its offset, so
#: a warm update whose contact slid by 1e-5 L needs no re-solve)
ROUNDS, STEP = 6, 1e-10


def near_held(pair: tuple[int, int], slots: SC.ContactSlots) -> bool:
    """Tell whether the sample ``pair`` lies within ``NEAR`` spacings of a held contact.

    There a sample pair may come closer than D while the strands keep 2r (crossing at an angle
    of at least asin ``closest_points.MIN_SINE``, a pair offset by w along either strand is at
    least w sin θ further apart than the closest points: past 2.4 h that exceeds D).
    """
    s, near = slots.geometry.s, NEAR * slots.geometry.spacing
    return any(
        abs(s[pair[0]] - a) <= near and abs(s[pair[1]] - b) <= near for a, b in slots.at.values()
    )


def penetrating(
    candidates: list[tuple[tuple[int, int], float]], slots: SC.ContactSlots, slack: float
) -> list[tuple[int, int]]:
    """Return the candidate pairs that penetrate, nearest first.

    Closer than D − ``slack`` [m] away from the held contacts (``near_held``), closer than
    2r − ``slack`` anywhere (a sample pair's distance bounds the strands' from above).
    """
    floor = 2.0 * slots.geometry.radius - slack
    return [
        pair
        for pair in SC.penetrations(candidates, slots.geometry, slack)
        if not near_held(pair, slots) or dict(candidates)[pair] < floor
    ]


def kept_points(
    previous: SC.ContactSlots | None, pairs: list[tuple[int, int] | None]
) -> dict[int, tuple[float, float]]:
    """Return the held points of ``previous`` whose slots still hold the same pair."""
    if previous is None:
        return {}
    return {
        k: v for k, v in previous.at.items() if k < len(pairs) and pairs[k] == previous.pairs[k]
    }


def held_slots(
    nlp: StringNLP, state: SolverState, contact: SC.ContactSlots, loaded: set[int]
) -> tuple[SC.ContactSlots, dict[int, list[int]], float] | None:
    """Return the slots with each loaded contact held at its closest points, and more.

    The second value maps each held slot to the loaded slots whose force it takes over (itself
    included); the third is how far [m] the strands come inside 2r at those closest points when the
    slots were held already (inf when one was not: a new contact, or one on its sample pair).  None
    when no loaded contact has closest points (``closest_points``).
    """
    geometry, length = contact.geometry, nlp.length
    arc = geometry.exclusion
    lam = state.lam_g

    def positions(s: np.ndarray) -> np.ndarray:
        return nlp.model.positions(state.z, np.asarray(s, dtype=float))

    def tangents(s: np.ndarray) -> np.ndarray:
        return nlp.model.tangents_at(state.z, np.asarray(s, dtype=float))

    rows = nlp.self_contact_rows
    clusters: list[list[int]] = []  # the loaded slots of one contact, strongest first
    for k in sorted(loaded, key=lambda j: -lam[rows[j]]):
        a, b = contact.arc_lengths(k)
        home = next(
            (
                c
                for c in clusters
                if abs(contact.arc_lengths(c[0])[0] - a) <= arc
                and abs(contact.arc_lengths(c[0])[1] - b) <= arc
            ),
            None,
        )
        if home is None:
            clusters.append([k])
        else:
            home.append(k)
    at: dict[int, tuple[float, float]] = {}
    merged: dict[int, list[int]] = {}
    inside = 0.0
    for cluster in clusters:
        spans = np.ptp([contact.arc_lengths(k) for k in cluster], axis=0)
        if spans.max() > LINE * geometry.spacing:  # a line contact: stays on its sample pairs
            continue
        k = cluster[0]
        cp = closest_points(positions, tangents, *contact.arc_lengths(k), arc, length)
        if cp is not None and cp.s_b - cp.s_a >= arc:
            at[k], merged[k] = (cp.s_a, cp.s_b), cluster
            held_before = k in contact.at
            inside = max(inside, 2 * geometry.radius - cp.distance if held_before else np.inf)
    if not at:
        return None
    s = geometry.s
    pairs = list(contact.pairs)
    held = SC.ContactSlots(geometry, pairs, at={**contact.at, **at})
    new_points = SC.ContactSlots(geometry, [], at=at)
    for k, pair in enumerate(pairs):
        if k in at:
            pairs[k] = (int(np.argmin(np.abs(s - at[k][0]))), int(np.argmin(np.abs(s - at[k][1]))))
        elif pair is not None and near_held(pair, new_points):
            pairs[k] = None
            held.at.pop(k, None)
    return held, merged, inside


def hold_at_closest_points(
    ctx: UpdateContext,
    problem: Problem,
    outcome: Outcome,
    loaded: Callable[[StringNLP, SolverState], set[int]],
) -> Outcome:
    """Return ``outcome`` with its contacts held at their closest points (module docstring)."""
    result, state = outcome
    if state is None or state.contact is None or problem.string.radius <= 0:
        return outcome
    nlp, outputs = ctx.parts.nlp, ctx.parts.outputs
    iterations = result.iterations
    for _ in range(ROUNDS):
        contact = state.contact
        assert contact is not None
        found = held_slots(nlp, state, contact, loaded(nlp, state))
        if found is None:
            break
        held, merged, inside = found
        if inside < STEP * nlp.length:
            break
        start = state.copy()
        rows = nlp.self_contact_rows
        for k in range(len(held.pairs)):
            start.lam_g[rows[k]] = sum(state.lam_g[rows[j]] for j in merged.get(k, [k]))
            if held.pairs[k] is None:
                start.lam_g[rows[k]] = 0.0
        start.contact = held
        SC.fill(start.p, held, nlp, nlp.length)
        outputs.contact_slots = held  # type: ignore[assignment]
        with ctx.scoped(contact=held, start=start):
            again, solved = solve_with_moments(ctx, problem, True)
        iterations += again.iterations
        if solved is None or again.status != "ok" or stray(nlp, solved, held):
            outputs.contact_slots = contact  # type: ignore[assignment]
            break
        points = nlp.model.positions(solved.z, held.geometry.s)
        candidates = SC.candidate_pairs(points, held.geometry)
        tangents = nlp.model.tangents_at(solved.z, held.geometry.s)
        signs = SC.crossing_signs(points, tangents, candidates) if candidates else {}
        solved.contact = SC.ContactSlots(
            held.geometry, list(held.pairs), signs, candidates, dict(held.at)
        )
        again.warm_started = result.warm_started
        held_distance = 2.0 * problem.string.radius
        again.min_self_distance = min(
            min((d for _, d in candidates), default=float("inf")), held_distance
        )
        result, state = again, solved
    result.iterations = iterations
    return result, state


def stray(nlp: StringNLP, state: SolverState, held: SC.ContactSlots) -> bool:
    """Tell whether a sample pair penetrates the answer held at ``held`` (``penetrating``)."""
    points = nlp.model.positions(state.z, held.geometry.s)
    candidates = SC.candidate_pairs(points, held.geometry)
    return bool(penetrating(candidates, held, RC.SLACK * nlp.length))
