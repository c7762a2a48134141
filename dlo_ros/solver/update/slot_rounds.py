"""Stage: the obstacle contact slots (``contact/obstacle_slots.py``) placed again on the answer.

Contract:

* ``place_slots_again(ctx, problem, result, state, solve)`` takes a solve's outcome and gives the
  outcome of at most SLOT_ROUNDS repeats of ``solve`` (the pairs-fixed solve, ``pipeline.py``),
  each warm from the last answer (``ctx.start``) with the slots moved (``ctx.slot_override``);
  both fields are restored when it returns;
* ``carry_slots(parts, start, p)`` gives ``start`` with the slots of ``p``, its multipliers carried
  row by row (what a Newton start needs when the slots moved).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...model.problem import Problem
from ..contact import obstacle_slots as OSL
from ..results.result import ShapeResult
from ..state import SolverState
from .context import Outcome, SolverParts, UpdateContext

#: how many times a solve is repeated with the obstacle contact slots placed on its own answer
SLOT_ROUNDS = 2

#: a solve with the context's start and slots (``pipeline.solve_pairs_fixed``)
Solve = Callable[[UpdateContext, Problem, bool], Outcome]


def place_slots_again(
    ctx: UpdateContext,
    problem: Problem,
    result: ShapeResult,
    state: SolverState | None,
    solve: Solve,
) -> Outcome:
    """Repeat a solve while the answer's contacts moved away from their slots.

    The slots are placed on the shape a solve starts from; while the answer touches an obstacle at
    a minimum that moved further than TOLERANCE·L from its slot, the solve is repeated warm from
    the answer (at most SLOT_ROUNDS times), each slot at the secant estimate of its fixed point
    σ = s*(σ) from the rounds so far (the first round: s* itself).  A repeat that fails keeps the
    previous answer (a converged solution of its own rows).
    """
    iterations, first = result.iterations, result
    history: dict[tuple[int, int], list[tuple[float, float]]] = {}
    for _ in range(SLOT_ROUNDS):
        if state is None or result.status not in ("ok", "unverified"):
            break
        if not slots_moved(ctx.parts, problem, state):
            break
        override = secant_slots(ctx.parts, state, history)
        with ctx.scoped(start=state, slot_override=override):
            again, new_state = solve(ctx, problem, True)
        iterations += again.iterations
        if new_state is None or again.status not in ("ok", "unverified"):
            break
        result, state = again, new_state
    # the rounds refine the answer the first solve found: its method and warm start describe the
    # result
    result.iterations, result.ipopt_status, result.warm_started = (
        iterations,
        first.ipopt_status,
        first.warm_started,
    )
    return result, state


def slots_moved(parts: SolverParts, problem: Problem, state: SolverState) -> bool:
    """Whether a slot placed on ``state`` moved from the one it was solved with, where it touches.

    Leaves the placement on ``state`` in ``parts.parameters.placements``.
    """
    nlp, parameters = parts.nlp, parts.parameters
    parameters.pack(problem, state.z, keep=state.p)
    moved = False
    for i, new in enumerate(parameters.placements):
        if new.kept:
            continue
        used = parameters.slots(state.p, i)
        touching = (new.on > 0) & (new.clearance < OSL.TOUCH * nlp.length)
        moved |= bool(
            np.any(
                touching & ((used.on == 0) | (np.abs(new.s - used.s) > OSL.TOLERANCE * nlp.length))
            )
        )
    return moved


def secant_slots(
    parts: SolverParts,
    state: SolverState,
    history: dict[tuple[int, int], list[tuple[float, float]]],
) -> list:
    """Return each obstacle's slots at the secant estimate of σ = s*(σ) from the rounds so far.

    ``parts.parameters.placements`` holds the placement on ``state`` (``slots_moved``);
    ``history`` gathers (σ used, s* found) per slot over the rounds.
    """
    nlp, parameters = parts.nlp, parts.parameters
    override = []
    for i, new in enumerate(parameters.placements):
        used, s = parameters.slots(state.p, i), new.s.copy()
        for k in np.flatnonzero((new.on > 0) & (used.on > 0)):
            trail = history.setdefault((i, k), [])
            trail.append((float(used.s[k]), float(new.s[k])))
            if len(trail) >= 2:  # secant on g(σ) = s*(σ) − σ
                (a, fa), (b, fb) = trail[-2], trail[-1]
                ga, gb = fa - a, fb - b
                if gb != ga:
                    s[k] = float(
                        np.clip(
                            b - gb * (b - a) / (gb - ga),
                            min(a, b, fa, fb),
                            max(a, b, fa, fb),
                        )
                    )
        override.append(
            OSL.assign(
                (s[new.on > 0], new.clearance[new.on > 0]),
                nlp.obstacle_s,
                nlp.obstacle_slots,
                new,
                nlp.length,
            )
        )
    return override


def carry_slots(parts: SolverParts, start: SolverState, p: np.ndarray) -> SolverState:
    """Return ``start`` with the obstacle contact slots (and sample switches) of ``p``.

    When they differ: each row of the new placement takes the multiplier of the start's row
    nearest to it along s, within a quarter of the sample spacing (the contact force stays where
    it acts), the others none; the inequality rows' values are evaluated anew and the stored
    derivatives dropped.
    """
    nlp, parameters = parts.nlp, parts.parameters
    if not nlp.obstacle_slots:
        return start
    lay = nlp.params
    names = [n for i in range(len(nlp.slot_rows)) for n in nlp.slot_parameters(i)]
    if all(np.array_equal(start.p[lay[n]], p[lay[n]]) for n in names):
        return start
    moved = start.p.copy()
    for n in names:
        moved[lay[n]] = p[lay[n]]
    lam = start.lam_g.copy()
    reach = 0.25 * nlp.obstacle_spacing
    for i, slot_rows in enumerate(nlp.slot_rows):
        rows = np.concatenate([nlp.obstacle_rows[i], slot_rows])
        old, new = parameters.slots(start.p, i), parameters.slots(moved, i)
        on_old = np.flatnonzero(np.concatenate([old.samples_on, old.on]) > 0)
        on_new = np.flatnonzero(np.concatenate([new.samples_on, new.on]) > 0)
        s_old = np.concatenate([nlp.obstacle_s, old.s])
        s_new = np.concatenate([nlp.obstacle_s, new.s])
        carried = np.zeros(rows.size)
        for j in on_new:  # the start's row nearest along s, within a quarter sample spacing
            k = on_old[int(np.argmin(np.abs(s_old[on_old] - s_new[j])))] if on_old.size else None
            if k is not None and abs(s_old[k] - s_new[j]) <= reach:
                carried[j] = start.lam_g[rows[k]]
        lam[rows] = carried
    g = np.asarray(nlp.g_fn(start.z, moved)).ravel()
    return SolverState(start.z, lam, start.lam_x, moved, g=g, contact=start.contact)
