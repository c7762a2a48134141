"""Stage: the obstacle contact slots (``contact/obstacle_slots.py``) placed again on the answer.

Contract:

* ``place_slots_again(ctx, problem, result, state, solve, rounds, start)`` takes a solve's
  outcome and gives the outcome of at most ``rounds`` repeats of ``solve`` (the pairs-fixed
  solve, ``pipeline.py``), each warm from the last answer (``ctx.start``) with the slots moved
  (``ctx.slot_override``), both fields restored when it returns; the answer's state records how
  its slots moved from ``start`` (the update's warm start; None for a cold solve);
* ``carry_slots(parts, start, p)`` gives ``start`` with the slots of ``p``, its multipliers carried
  row by row (what a Newton start needs when the slots moved);
* ``predicted_slots(parts, start)`` gives the slots a warm update's first solve takes: the
  start's fixed points, each moved on by its steady drift over the update that reached the start
  (``SolverState.slot_motion``), or None when that is not known.

A slot's row bounds the obstacle's reach at the closest approach near it
(``build/slot_envelope.py``), so the answer's closest approach s* barely moves with its slot σ:
the rounds are the plain fixed-point iteration σ ← s* (the row held at σ alone made s* move by
−2.5 σ on the table, and a secant was needed).  A contact sliding along the obstacle at v per
update starts from its slot moved on by v, and the first solve lands within the slot tolerance
of its fixed point while the sliding is steady.  A contact that jumps out of its slot's reach
while the slot still holds the string is held at both places for a round (``_jumped``); an answer
the rounds leave with a slot over UNSETTLED·δ from its minimum is unverified
(``_flag_unsettled``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...model.problem import Problem
from ..build.nlp import StringNLP
from ..build.slot_envelope import shift_bound
from ..contact import obstacle_slots as OSL
from ..results.result import ShapeResult
from ..state import SolverState
from .context import Outcome, SolverParts, UpdateContext

#: how many times a streamed update's solve is repeated with the obstacle contact slots placed on
#: its own answer (``place_slots_again``): a cable lowered onto a post that snaps to another side
#: of it took 4 (its first round lands on the new side, the secant's first step is wasted there)
SLOT_ROUNDS = 4
#: as many for a solve that is not a streamed update (a cold solve, a query, auto's re-solves
#: outside an update's time limit), whose slot starts where no earlier update put it (the default
#: cable on its table, cold: 1.3 mm off, converged in 3 rounds where 2 were allowed)
COLD_SLOT_ROUNDS = 8

#: a steady drift is carried on up to this × L per update (``predicted_slots``): the main job's
#: cable slides 1.8–2.8 mm per update along its post once it has landed, and a cap of 2 mm left
#: each of those updates solved twice; a landing's jump (25 mm on the post) is not carried on
PREDICTED = 1e-2

#: an answer whose slot ends over this × δ from its minimum is unverified (``_flag_unsettled``):
#: the centreline moves about 1.3× a point contact's shift (``adapt/contact_shift.py``)
UNSETTLED = 0.5

#: a slot whose multiplier kept this share of the solve's start's holds the string
#: (``_jumped``: 59 % where the string swung about a post, 0.6 % where it rolled off the slot)
HELD = 0.25

#: a slot row's multiplier above this carries force (IPOPT leaves ~1e-10 on free rows; as
#: ``kkt.active_rows``)
ACTIVE = 1e-8

#: how an answer ``_flag_unsettled`` reported begins (``unsettled``)
UNSETTLED_MESSAGE = "an obstacle contact did not settle"

#: one obstacle's slots: σ [m], on, the samples' switches (``ProblemParameters.slot_lists``)
Slots = tuple[list[float], list[float], list[float]]

#: a solve with the context's start and slots (``pipeline.solve_pairs_fixed``)
Solve = Callable[[UpdateContext, Problem, bool], Outcome]


def place_slots_again(
    ctx: UpdateContext,
    problem: Problem,
    result: ShapeResult,
    state: SolverState | None,
    solve: Solve,
    rounds: int = SLOT_ROUNDS,
    start: SolverState | None = None,
) -> Outcome:
    """Repeat a solve while the answer's contacts moved away from their slots.

    The slots are placed on the shape a solve starts from (a warm update's: ``predicted_slots``);
    while the answer touches an obstacle at a minimum s* more than ``obstacle_slots.
    slot_tolerance`` from its slot σ (or a slot carrying force lost its minimum), the solve is
    repeated warm from the answer (at most ``rounds`` times) with the slots placed on the answer,
    each at its s* (in a stream, where that overshot, the secant estimate: ``placed_slots``).
    A repeat that fails keeps the previous answer (a converged solution of its own rows); of the
    answers, the one whose slots sit closest to their minima is kept.  Its state records the
    slots' motion.
    """
    iterations, first = result.iterations, result
    history: dict[tuple[int, int], list[tuple[float, float]]] = {}
    nlp = ctx.parts.nlp
    tolerance = OSL.slot_tolerance(nlp.length, nlp.options.error_tolerance)
    best: tuple[float, ShapeResult, SolverState | None] | None = None
    before = start  # the state the last solve started from
    tried: list[tuple[SolverState, list]] = []  # each round's start and slots
    for round_ in range(rounds + 1):
        if state is None or result.status not in ("ok", "unverified"):
            break
        offset = slot_offset(ctx.parts, problem, state)
        if best is None or offset < best[0]:
            best = (offset, result, state)
        if offset <= tolerance or round_ == rounds:
            break
        # not a streamed update: a fresh history each round, so no secant
        override = placed_slots(ctx.parts, state, history if ctx.streamed else {}, before)
        if any(_repeats(earlier, state, override, nlp.length) for earlier in tried):
            break  # a round made before: its answers again, in a cycle
        tried.append((state, override))
        with ctx.scoped(start=state, slot_override=override):
            again, new_state = solve(ctx, problem, True)
        iterations += again.iterations
        if new_state is None or again.status not in ("ok", "unverified"):
            break
        if ctx.streamed and _let_go(ctx.parts, problem, state, new_state):
            break  # left the stream's contact: the answers before stand
        before, result, state = state, again, new_state
    # the rounds' answer whose slots sat closest to their minima; the placement on it is the
    # last one made when it is the last answer checked
    placed = best is not None and best[2] is state
    if best is not None:
        offset, result, state = best
        if state is not None and start is not None:
            state.slot_motion = slot_motion(ctx.parts, start, state, placed)
        _flag_unsettled(result, offset, nlp)
    # the rounds refine the answer the first solve found: its method and warm start describe the
    # result
    result.iterations, result.ipopt_status, result.warm_started = (
        iterations,
        first.ipopt_status,
        first.warm_started,
    )
    return result, state


#: two starts of a slot round whose unknowns differ by at most this (relative to the largest), with
#: slots at arc lengths that differ by at most this × L, are the same start (``_repeats``): two
#: Newton answers of the same rows differ by ~1e-10 (1.1e-10 measured), a slot placed on each by
#: rounding
SAME_START = 1e-8


def _repeats(
    earlier: tuple[SolverState, list], state: SolverState, override: list, length: float
) -> bool:
    """Tell whether a round would start where an earlier one did, with the same slots.

    ``earlier``: that round's start and slots; ``length``: L [m].  Its answer is then that
    round's answer again (the solve is a function of its start and slots), and so are the rounds
    after it: the rounds cycle.  The paper's Fig. 3 strip at ρ = 1000, cold, on its fifth mesh:
    a slot placed at the touching minimum gave a saddle, left to an answer on which that slot
    carried force with no minimum left (offset inf); the slot emptied, the answer came back, and
    so on until the rounds ran out (8 rounds, 4 saddle escapes of 41 ms each).
    """
    start, slots = earlier
    if len(slots) != len(override) or start.z.shape != state.z.shape:
        return False
    scale = max(1.0, float(np.max(np.abs(start.z), initial=0.0)))
    if not np.max(np.abs(state.z - start.z), initial=0.0) <= SAME_START * scale:
        return False
    near = SAME_START * length
    return all(
        np.array_equal(a.on, b.on) and np.max(np.abs(a.s - b.s), initial=0.0) <= near
        for a, b in zip(slots, override)
    )


def _flag_unsettled(result: ShapeResult, offset: float, nlp: StringNLP) -> None:
    """Report (in place) an answer whose slot sits over UNSETTLED·δ from its minimum: unverified.

    δ: ``solver.error_tolerance`` (0: 1e-3·L).  The force acts at the slot, the string is
    closest to the obstacle elsewhere: that is no equilibrium of the contact, and the residual on
    the answer's own rows cannot see it.  An offset of inf (a touching minimum without a slot) is
    left to the mesh check, which bounds a contact held by rows.
    """
    delta = nlp.options.error_tolerance or 1e-3 * nlp.length
    if not np.isfinite(offset) or offset <= UNSETTLED * delta:
        return
    if result.status not in ("ok", "unverified"):
        return
    result.status, result.stable = "unverified", None
    result.message = (
        f"{UNSETTLED_MESSAGE}: its slot is {offset:.3g} m from the string's "
        f"closest approach after the slot rounds (over {UNSETTLED:g}·solver.error_tolerance); "
        f"{result.message}"
    )


def unsettled(result: ShapeResult) -> bool:
    """Tell whether ``result`` is an answer ``_flag_unsettled`` reported (a slot off its min)."""
    return result.status == "unverified" and result.message.startswith(UNSETTLED_MESSAGE)


def slot_offset(parts: SolverParts, problem: Problem, state: SolverState) -> float:
    """Return how far [m] the slots of ``state`` are from the minima they touch.

    The largest |s* − σ| over the touching minima s* placed on ``state``; inf for a touching
    minimum without a slot, or a slot that carries force where no minimum is left (a cable lying
    down flat on a table: its row then stands for no closest approach).  Leaves the placement on
    ``state`` in ``parts.parameters.placements``.
    """
    nlp, parameters = parts.nlp, parts.parameters
    worst = 0.0
    for i, new in enumerate(parameters.place_on(problem, state.z, state.p)):
        if new.kept:
            continue
        used = parameters.slots(state.p, i)
        carrying = state.lam_g[np.asarray(nlp.slot_rows[i], dtype=int)] > ACTIVE
        if np.any((used.on > 0) & (new.on == 0) & carrying):
            return float("inf")
        # a slot carrying force counts though its minimum clears the obstacle: a slot away
        # from its minimum can hold the string off it (the row's reach is a model of the
        # closest approach near σ; a strip on a post, the slot 1 cm off: 5e-5 m clear)
        touching = (new.on > 0) & ((new.clearance < OSL.TOUCH * nlp.length) | carrying)
        for k in np.flatnonzero(touching):
            if used.on[k] == 0:
                return float("inf")
            worst = max(worst, abs(new.s[k] - used.s[k]))
    return worst


def placed_slots(
    parts: SolverParts,
    state: SolverState,
    history: dict[tuple[int, int], list],
    before: SolverState | None = None,
) -> list:
    """Return each obstacle's slots for the next round, from the placement on the last answer.

    ``parts.parameters.placements`` holds the placement on ``state`` (``slot_offset``);
    ``history`` gathers (σ used, s* found) per slot over the rounds.  A slot goes to its minimum
    s*; where that overshot (g = s* − σ changed sign without halving), to the secant estimate of
    σ = s*(σ) kept within the last two rounds' σ and s*: a strip pulled tight over a post nearly
    wraps it, its clearance is flat about the contact and s* swings about σ with a growing
    amplitude.  With an empty ``history`` each round (not a streamed update: a cold solve's
    first answers pass through the obstacle at several places and their minima jump between
    them; a secant across two of them sent the post's cold solve at 1e-5 m through six
    refinements instead of three) each goes to its s*.  The rows about the slots are off.  A
    slot still holding the string while its minimum jumped out of its reach keeps its place
    beside the minimum's (``_jumped``; ``before``: the state the solve of ``state`` started
    from, None: no slot is kept).
    """
    nlp, parameters = parts.nlp, parts.parameters
    out = []
    for i, new in enumerate(parameters.placements):
        used, s, on = parameters.slots(state.p, i), new.s.copy(), new.on.copy()
        jumped = dict(_jumped(nlp, state, before, i, used, new))
        for k, j in jumped.items():
            s[j], on[j] = used.s[k], 1.0
            history.pop((i, k), None)
        for k in np.flatnonzero((new.on > 0) & (used.on > 0)).tolist():
            if k in jumped:
                continue
            trail = history.setdefault((i, k), [])
            trail.append((float(used.s[k]), float(new.s[k])))
            if len(trail) >= 2:  # secant on g(σ) = s*(σ) − σ where σ ← s* overshot
                (a, fa), (b, fb) = trail[-2], trail[-1]
                ga, gb = fa - a, fb - b
                if ga * gb < 0 and abs(gb) > 0.5 * abs(ga):
                    secant = b - gb * (b - a) / (gb - ga)
                    s[k] = float(np.clip(secant, min(a, b, fa, fb), max(a, b, fa, fb)))
        out.append(_placement(nlp, s, on, new.clearance))
    return out


def _jumped(
    nlp: StringNLP,
    state: SolverState,
    before: SolverState | None,
    i: int,
    used: OSL.SlotPlacement,
    new: OSL.SlotPlacement,
) -> list[tuple[int, int]]:
    """Return (slot, free slot) pairs of obstacle i whose contact jumped out of the slot's reach.

    A slot that still holds the string on ``state`` (``used``; its multiplier at least HELD of
    the force it carried on ``before``, which must be known: a start interpolated from another
    mesh carries no slot multipliers) while the placement on ``state`` (``new``) finds that slot's
    minimum cutting into the obstacle more than half the envelope's reach away
    (``slot_envelope.shift_bound``: the row models the closest approach within it) keeps its
    place in a free slot, and the minimum takes the slot: the next round holds the string at both
    places, and the slot whose minimum is gone empties on the round after.  Moved alone, such a
    slot swung the string about the post by more each round (the main job's landing, σ ← s*
    jumping 2.4 → 4 → 3.7 cm: four rounds spent and the answer 1.5 cm off; the slot had kept 59 %
    of its force).  A slot that lets go (the same cable rolling off its contact later, 0.6 %
    kept) moves alone: kept beside its minimum it pinched the cable between two slots at 2 N
    each, no equilibrium of the cable (residual 2.7 mm).
    """
    if before is None:
        return []
    free = [j for j in range(len(new.on)) if new.on[j] == 0 and used.on[j] == 0]
    rows = np.asarray(nlp.slot_rows[i], dtype=int)
    lam, had = state.lam_g[rows], before.lam_g[rows]
    far, cut = 0.5 * shift_bound(nlp.length), -OSL.TOUCH * nlp.length
    out = []
    holds = (had > ACTIVE) & (lam >= HELD * had)
    for k in np.flatnonzero((new.on > 0) & (used.on > 0) & holds):
        k = int(k)
        if free and new.clearance[k] < cut and abs(new.s[k] - used.s[k]) > far:
            out.append((k, free.pop(0)))
    return out


def _let_go(
    parts: SolverParts, problem: Problem, state: SolverState, new_state: SolverState
) -> bool:
    """Tell whether a round's answer let go of the string and fell into the obstacle elsewhere.

    A slot that carried force on ``state`` (the answer the round started from, its slots moved
    since) carries none on ``new_state`` while the string cuts into that obstacle (a minimum
    below −TOUCH·L): the solve's active set dropped the contact with the slot moved and the
    string fell through between the sampled rows.  Followed, the rounds moved the slot to the cut
    and the main job's cable landing on its post ended on the mirror equilibrium, the cable on
    the post's other side (contact s = 0.524 instead of 0.476), in one update.  A streamed
    update's rounds stop there (the answer left unsettled is solved again in substeps,
    ``pipeline.run_update``); a cold solve has no contact to keep, and its first answers pass
    through the obstacle at several places.
    """
    nlp, parameters = parts.nlp, parts.parameters
    dropped = [
        bool(np.any((state.lam_g[rows] > ACTIVE) & (new_state.lam_g[rows] <= ACTIVE)))
        for rows in (np.asarray(r, dtype=int) for r in nlp.slot_rows)
    ]
    if not any(dropped):  # the common round: no placement needed (the next round makes it)
        return False
    placements = parameters.place_on(problem, new_state.z, new_state.p)
    return any(
        drop and np.any((new.on > 0) & (new.clearance < -OSL.TOUCH * nlp.length))
        for drop, new in zip(dropped, placements)
    )


def _placement(nlp, s: np.ndarray, on: np.ndarray, clearance: np.ndarray) -> OSL.SlotPlacement:
    """Return slots at ``s`` (filled where ``on``), the rows about them off (``rows_on``)."""
    samples_on = OSL.rows_on(nlp.obstacle_s, s[on > 0], nlp.length)
    return OSL.SlotPlacement(s, on.copy(), samples_on, clearance)


def slot_motion(
    parts: SolverParts, start: SolverState, state: SolverState, placed: bool
) -> OSL.SlotMotion | None:
    """Return how the slots moved from ``start`` to ``state`` (None: none filled).

    With ``placed`` (``parts.parameters.placements`` holds the placement on ``state``): each
    slot's fixed point is its minimum s* there and ``on`` that placement's (a slot whose minimum
    is gone empties, a new one fills at it); else σ and ``state``'s slots.  drift: the move from
    the start's fixed point [m]; steady: within half of itself of the update before's.  Worked
    out in floats, slot by slot.
    """
    nlp, parameters = parts.nlp, parts.parameters
    shape = (len(nlp.slot_rows), nlp.obstacle_slots)
    motion = start.slot_motion
    before = motion.fixed.tolist() if motion is not None else None
    rows: list[tuple[list[float], list[float], list[float]]] = []  # fixed, drift, on
    for i in range(shape[0]):
        s_old, on_old, _ = parameters.slot_lists(start.p, i)
        fixed, on_new, _ = parameters.slot_lists(state.p, i)
        on = on_new
        if placed:
            found = parameters.placements[i]
            on = found.on.tolist()
            fixed = [f if o > 0 else x for f, o, x in zip(found.s.tolist(), on, fixed)]
        origin = s_old if before is None else before[i]
        drift = [
            f - o if (a > 0 and b > 0 and c > 0) else 0.0
            for f, o, a, b, c in zip(fixed, origin, on_old, on_new, on)
        ]
        rows.append((fixed, drift, on))
    if not any(o != 0 for r in rows for o in r[2]):  # (np.any: a NaN counts)
        return None
    on_all = np.array([r[2] for r in rows], dtype=float).reshape(shape)
    fixed_all = np.array([r[0] for r in rows], dtype=float).reshape(shape)
    drift_all = np.array([r[1] for r in rows], dtype=float).reshape(shape)
    last = motion.drift if motion is not None else np.zeros(shape)
    steady = (drift_all != 0) & (np.abs(drift_all - last) <= 0.5 * np.abs(drift_all))
    return OSL.SlotMotion(fixed_all, drift_all, steady, on_all)


def carry_slots(parts: SolverParts, start: SolverState, p: np.ndarray) -> SolverState:
    """Return ``start`` with the obstacle contact slots (and sample switches) of ``p``.

    When they differ: each row of the new placement takes the multiplier of the start's row
    nearest to it along s, within a quarter of the sample spacing (the contact force stays where
    it acts), the others none; the inequality rows' values are evaluated anew (a moved slot that
    carries a force counts as at its bound) and the stored derivatives dropped.
    """
    nlp, parameters = parts.nlp, parts.parameters
    if not nlp.obstacle_slots:
        return start
    entries = parameters.slot_entries()
    new_entries = p[entries]
    if np.array_equal(start.p[entries], new_entries):
        return start
    moved = start.p.copy()
    moved[entries] = new_entries
    lam = start.lam_g.copy()
    held: list[int] = []  # the rows of moved slots that carry a force
    for i, slot_rows in enumerate(nlp.slot_rows):
        rows = [*nlp.obstacle_rows[i], *slot_rows]
        old, new = parameters.slot_lists(start.p, i), parameters.slot_lists(moved, i)
        carried = _carried(nlp, old, new, start.lam_g[rows].tolist())
        lam[rows] = carried
        moved_s, old_s = new[0], old[0]
        k0 = len(rows) - len(slot_rows)
        held.extend(
            int(r)
            for k, r in enumerate(slot_rows)
            if moved_s[k] != old_s[k] and carried[k0 + k] > 0
        )
    g = parts.functions.g(start.z, moved)[0].ravel()
    # a moved slot that carries the contact's force holds it: its row counts as at its bound
    # (``kkt.active_rows``), though the start's shape leaves the obstacle there by the slot's
    # move (the sagging bottom of a cable on a table, slot moved 0.8 mm: 2e-6 m); Newton then
    # keeps the contact instead of starting contact-free and falling back to IPOPT
    g[held] = np.maximum(g[held], nlp.ubg[held])
    return SolverState(start.z, lam, start.lam_x, moved, g=g, contact=start.contact)


def _carried(nlp: StringNLP, old: Slots, new: Slots, lam: list[float]) -> list[float]:
    """Return one obstacle's multipliers carried from ``old`` to ``new`` (``carry_slots``).

    ``old``, ``new``: the slots (σ, on, the samples' switches: ``ProblemParameters.slot_lists``);
    ``lam``: the start's multipliers of the obstacle's rows (its samples, then its slots).  Each
    row ``new`` switches on takes that of the row ``old`` had on nearest to it along s (the first
    of equals, as np.argmin), when within a quarter of the sample spacing; the others 0.  A
    sample row on in both is its own nearest (the samples strictly increasing, no NaN).
    """
    reach = 0.25 * nlp.obstacle_spacing
    samples = nlp.obstacle_s.tolist()
    s_old, s_new = samples + old[0], samples + new[0]
    was_on = old[2] + old[1]
    on_old = [k for k, on in enumerate(was_on) if on > 0]
    carried = [0.0] * len(s_new)
    if not on_old:
        return carried
    # a sample row on in both is nearest to itself (np.argmin would pick a NaN first)
    own = all(a < b for a, b in zip(samples, samples[1:])) and all(
        s_old[k] == s_old[k] for k in on_old
    )
    for j, on in enumerate(new[2] + new[1]):
        if not on > 0:
            continue
        if own and j < len(samples) and was_on[j] > 0:
            carried[j] = lam[j]
            continue
        k = _nearest(on_old, s_old, s_new[j])
        if abs(s_old[k] - s_new[j]) <= reach:
            carried[j] = lam[k]
    return carried


def _nearest(rows: list[int], s: list[float], at: float) -> int:
    """Return the row of ``rows`` whose s is nearest ``at``, as np.argmin picks it.

    The first with a NaN distance, else the first of equals.
    """
    d = [abs(s[k] - at) for k in rows]
    nan = next((i for i, x in enumerate(d) if x != x), None)
    return rows[nan if nan is not None else min(range(len(d)), key=d.__getitem__)]


def predicted_slots(parts: SolverParts, start: SolverState) -> list | None:
    """Return the slots of a warm update's first solve: the start's fixed points moved on.

    Each slot the placement on the start's answer filled (``SolverState.slot_motion``) at its
    fixed point plus its drift where that is steady and under PREDICTED·L (clipped to the string),
    the rows about it switched off; a slot whose minimum was gone is empty;
    None when ``start`` has no motion (the placement on the start shape stands).  A contact that
    landed or jumped is not extrapolated: on the post, a cable lowered onto it had its slot
    predicted 25 mm past the contact.
    """
    motion = start.slot_motion
    if motion is None:
        return None
    nlp = parts.nlp
    length, limit = nlp.length, PREDICTED * nlp.length
    out = []
    for on, fixed, drift, steady in zip(
        motion.on, motion.fixed.tolist(), motion.drift.tolist(), motion.steady.tolist()
    ):
        s = [
            OSL.clip(f + (d if (st and abs(d) <= limit) else 0.0), 0.0, length) if o > 0 else 0.0
            for o, f, d, st in zip(on.tolist(), fixed, drift, steady)
        ]
        out.append(_placement(nlp, np.array(s, dtype=float), on, np.full(on.shape, np.inf)))
    return out
