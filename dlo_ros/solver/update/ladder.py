"""Stage: the escalation ladder of one solve with fixed contact pairs.

Contract: ``solve_once(ctx, problem, warm)`` gives an outcome (result, state or None) for
``problem``.  A warm solve starts from ``ctx.start`` and climbs:

1. Newton on the KKT conditions (``attempts.newton_to``), then Newton in substeps
   (``substeps.newton_in_substeps``); an unstable Newton answer is left downhill by shifted Newton
   steps (``leave_newton_saddle``), unless the start is another element mesh's shape
   (``SolverState.remeshed``): that saddle is the mapping's, and IPOPT from the start (rung 2)
   finds the stable answer for a fraction of what the steps spend failing (the main job's post:
   each of the lead-ins of its refined meshes that met one, 0.17 and 1.4 s of steps that
   failed, then IPOPT in 33 and 10 iterations).  Either of the latter sets ``ctx.newton_far``;
2. warm IPOPT, then the continuation: the jump split into 2, 4, … ``max_continuation_steps`` equal
   steps (skipped when the cold solve also finds the targets infeasible, or when there is no jump:
   the parameters are the start's);
3. an unstable IPOPT answer is left along its negative-curvature mode (``escape_unstable``), or
   replaced by a stable, lower cold answer (``stable_cold``);
4. the cold fallback: IPOPT from the buckled initial guess; a warm answer over the residual
   tolerance ('unverified') competes with it.

A failed solve gives a result without a shape and no state.  Every IPOPT call honours
``ctx.deadline`` (``attempts.ipopt_call``).  ``escape_unstable`` is called through this module's
attribute, so a test may wrap it.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from ..results.outputs import no_shape
from ..results.result import ShapeResult
from ..state import SolverState
from . import attempts as AT
from . import substeps as SS
from .context import Outcome, UpdateContext
from .ipopt import INFEASIBLE, LEFT_SADDLE, Attempt, escape_saddle, lower_than, witness
from ..native.settings import SADDLE_RETRY_STEP, SADDLE_STEP
from .saddle import leave_saddle
from .slot_rounds import carry_slots

#: what the warm rungs leave to the cold fallback: (iterations, IPOPT's unverified warm answer,
#: the cold attempt if made, whether warm and cold both found the targets infeasible)
Trail = tuple[int, Outcome | None, Attempt | None, bool]


def solve_once(ctx: UpdateContext, problem: Problem, warm: bool) -> Outcome:
    """Solve ``problem`` warm from ``ctx.start`` (if ``warm``) up the ladder, else cold."""
    trail: Trail = (0, None, None, False)
    if warm and ctx.start is not None:
        p1 = AT.pack(ctx, problem, ctx.start.z, keep=ctx.start.p)
        start = carry_slots(ctx.parts, ctx.start, p1)
        done, iterations = newton_rungs(ctx, problem, start, p1)
        if done is not None:
            return done
        done, trail = ipopt_rungs(ctx, problem, start, p1, iterations)
        if done is not None:
            return done
    return cold_rung(ctx, problem, warm, trail)


def newton_rungs(
    ctx: UpdateContext, problem: Problem, start: SolverState, p1: np.ndarray
) -> tuple[Outcome | None, int]:
    """Return (Newton's verified, stable answer or None, the iterations counted)."""
    ok, state, iterations, viol = AT.newton_to(ctx, start, p1, problem)
    if not ok:
        ok, state, it, viol = SS.newton_in_substeps(ctx, start, p1, problem)
        iterations += it
        ctx.newton_far = ok
    if ok:
        result = AT.result(ctx, problem, state, "Newton", iterations, viol, True, 0)
        if result.stable is not False and result.status != "failed":  # (failed: a flipped branch)
            return (result, state), iterations
        if result.stable is False and not (ctx.start is not None and ctx.start.remeshed):
            left, iterations = leave_newton_saddle(ctx, problem, result, state, iterations)
            if left is not None:
                ctx.newton_far = True
                return left, iterations
    return None, iterations


def ipopt_rungs(
    ctx: UpdateContext, problem: Problem, start: SolverState, p1: np.ndarray, iterations: int
) -> tuple[Outcome | None, Trail]:
    """Return (warm IPOPT's or the continuation's answer, or None; what the cold rung needs)."""
    unverified: Outcome | None = None  # IPOPT's warm answer, over the residual tolerance
    cold: Attempt | None = None  # the cold solve's attempt, once made
    agreed, steps = False, 0
    max_steps = ctx.parts.options.max_continuation_steps
    ok, state, last_status, it, viol = AT.ipopt_call(ctx, True, start.z, p1, start)
    iterations += it
    k = 2
    if not ok and last_status == INFEASIBLE:
        # the targets themselves may admit no shape: the cold solve says so at once, where the
        # continuation's steps would each be solved before its last one failed the same way (the
        # default cable's grip put under its table: 6.5 s, 15 IPOPT calls)
        cold = AT.cold_ipopt(ctx, problem)
        iterations += cold[3]
        if not cold[0] and cold[2] == INFEASIBLE:
            k, agreed = max_steps + 1, True
    if np.array_equal(p1, start.p):
        # no jump to split: each step of the continuation would be the warm solve just made, from
        # the same start (a refinement pass's start mapped from the mesh before: the paper's Fig. 3
        # floor at ρ = 2000, cold, spent 4 × 180 ms failing IPOPT's same 200 iterations)
        k = max_steps + 1
    while not ok and k <= max_steps:
        state, ok = start, True
        for i in range(1, k + 1):
            p_i = start.p + (p1 - start.p) * (i / k)
            ok, state, last_status, it, viol = AT.ipopt_call(ctx, True, state.z, p_i, state)
            iterations += it
            if not ok:
                break
        steps = k if ok else 0
        k *= 2
    if ok:
        result = AT.result(ctx, problem, state, last_status, iterations, viol, True, steps)
        if result.status == "ok":
            escaped = escape_unstable(ctx, problem, result, state)
            done = (
                escaped if escaped[0].stable is not False else stable_cold(ctx, problem, *escaped)
            )
            return done, (iterations, unverified, cold, agreed)
        if result.status == "unverified":
            # IPOPT from the warm start can end on a spurious stationary point of the discrete
            # problem (a folded field, residual of metres); the cold guess decides, the smaller
            # residual wins
            unverified = (result, state)
    return None, (iterations, unverified, cold, agreed)


def cold_rung(ctx: UpdateContext, problem: Problem, warm: bool, trail: Trail) -> Outcome:
    """Return the cold solve's answer, the warm unverified one if better, or a failure."""
    iterations, unverified, cold, agreed = trail
    if cold is None:
        cold = AT.cold_ipopt(ctx, problem)
        iterations += cold[3]
    ok, state, last_status, _, viol = cold
    if ok:
        result = AT.result(ctx, problem, state, last_status, iterations, viol, False, 0)
        if unverified is not None and not (
            result.status == "ok"
            or result.status == "unverified"
            and result.equilibrium_residual_m < unverified[0].equilibrium_residual_m
        ):
            result, state = unverified  # type: ignore[assignment]  # a warm answer has a state
            result.iterations = iterations
        if result.status != "failed":
            return escape_unstable(ctx, problem, result, state)
        last_status = result.message
    elif unverified is not None:
        unverified[0].iterations = iterations
        return escape_unstable(ctx, problem, *unverified)  # type: ignore[arg-type]  # (see above)
    status = "infeasible" if last_status == INFEASIBLE else "failed"
    message = (
        f"IPOPT: {last_status} (constraint violation {viol:.3g}"
        f"{witness(ctx.parts.nlp, state.g)})"
        + (
            "; so did the warm start"
            if agreed
            else "; warm start and continuation also failed"
            if warm
            else ""
        )
    )
    # a failed result carries no shape, energy, wrench or eigenvalue that could be mistaken for one
    return no_shape(
        ctx.parts.options,
        ctx.parts.summary(),
        status,
        message,
        iterations=iterations,
        constraint_violation=viol,
        warm_started=warm,
        ipopt_status=last_status,
    ), None


def leave_newton_saddle(
    ctx: UpdateContext,
    problem: Problem,
    saddle: ShapeResult,
    state: SolverState,
    iterations: int,
) -> tuple[Outcome | None, int]:
    """Continue a warm Newton update that landed on a saddle downhill, by shifted Newton steps.

    ``saddle.leave_saddle``, either way along the unstable mode, with a first step of SADDLE_STEP
    and, where neither way found a point below the saddle, of SADDLE_RETRY_STEP: (the first stable,
    verified result of lower energy, or None: then IPOPT and ``escape_unstable`` take over; the
    iterations counted so far).  Where the steps reach only a lower but still unstable
    equilibrium, that one is left by ``escape_unstable`` (a cable lying on a table that buckles
    out of its plane: the steps hold the table's contacts and stop on a lower saddle; IPOPT's warm
    start from the update's start falls back onto the first saddle, whose escapes can run to
    their iteration limit).
    """
    parts = ctx.parts
    assert saddle.min_eigenvalue is not None  # an unstable result has its eigenvalue
    lower: tuple[ShapeResult, SolverState] | None = None
    for first_step in (SADDLE_STEP, SADDLE_RETRY_STEP):
        for sign in (1.0, -1.0):
            ok, new, it, viol = leave_saddle(
                parts.nlp,
                parts.functions,
                state,
                state.p,
                saddle.min_eigenvalue,
                sign,
                fused=parts.fused_newton,
                first_step=first_step,
            )
            iterations += it
            if not ok:
                continue
            result = AT.result(ctx, problem, new, "Newton", iterations, viol, True, 0)
            if result.status != "ok" or not lower_than(result, saddle):
                continue
            if result.stable:
                result.message += LEFT_SADDLE
                return (result, new), iterations
            if result.stable is False and lower is None:
                lower = (result, new)
        if lower is not None:  # a lower saddle: left by escape_unstable below
            break
    if lower is not None:
        lower[0].iterations = iterations
        result, new = escape_unstable(ctx, problem, *lower)  # type: ignore[assignment]
        iterations = result.iterations
        if result.status == "ok" and result.stable:
            return (result, new), iterations
    return None, iterations


def stable_cold(
    ctx: UpdateContext, problem: Problem, unstable: ShapeResult, state: SolverState | None
) -> Outcome:
    """Replace a warm update's unstable answer by the cold solve's, if that is stable and lower.

    A warm update that found only unstable equilibria near its start (Newton, IPOPT and the
    escapes): the cold solve from the initial guess instead, if it is verified, stable and lower.
    (The planar cable pressed onto the table: every escape from the planar saddle failed, the cold
    solve found the stable out-of-plane shape.)  Otherwise the unstable answer, as it was.
    """
    ok, cold, status, it, viol = AT.cold_ipopt(ctx, problem)
    unstable.iterations += it
    if ok:
        result = AT.result(ctx, problem, cold, status, unstable.iterations, viol, False, 0)
        if result.status == "ok":
            result, cold = escape_unstable(ctx, problem, result, cold)  # type: ignore[assignment]
        if result.status == "ok" and result.stable and lower_than(result, unstable):
            result.message += "; no stable equilibrium near the warm start: solved cold"
            return result, cold
    return unstable, state


def escape_unstable(
    ctx: UpdateContext, problem: Problem, result: ShapeResult, state: SolverState
) -> Outcome:
    """Leave an unstable stationary point along its negative-curvature mode.

    ``ipopt.escape_saddle``, each re-solve a cold IPOPT call (``attempts.ipopt_call``).  The
    first unstable point a solve leaves is kept (``UpdateContext.unstable_met``).
    """
    ctx.met_unstable(result)
    return escape_saddle(
        result,
        state,
        lambda z0, p: AT.ipopt_call(ctx, False, z0, p, escape=True),
        lambda *attempt: AT.result(ctx, problem, *attempt),
    )
