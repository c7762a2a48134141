"""Stage: dead point moments (director models), solved on the exact equilibrium equations.

Contract: ``solve_with_moments(ctx, problem, warm)`` gives the outcome of the pairs-fixed solve
(``ladder.solve_once``) for ``problem``; under point moments a warm update first tries Newton on
the exact equations from ``ctx.start``, and a ladder answer (which applied the moments through a
pseudo-potential centred on its start) is polished on them (``solve_moments``), its saddles left
with each re-solve polished too.  Without point moments it is ``ladder.solve_once`` itself.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from ..build.moments import ExactMomentKKT
from ..build.nlp import has_point_moments
from ..results.outputs import no_shape
from ..results.result import ShapeResult
from ..state import SolverState
from . import attempts as AT
from . import ladder as LD
from .context import Outcome, UpdateContext
from .ipopt import Attempt, escape_saddle
from .newton import newton
from .slot_rounds import carry_slots

#: Newton steps per solve of the exact equilibrium equations, and Newton solves for raising the
#: moments from zero when one solve does not get there
MOMENT_NEWTON_STEPS = 25
MOMENT_CONTINUATION_SOLVES = 40


def solve_with_moments(ctx: UpdateContext, problem: Problem, warm: bool) -> Outcome:
    """Solve with fixed contact pairs: the ladder, and the exact moments where there are some."""
    moments = ctx.parts.nlp.director and has_point_moments(problem)
    if moments and warm and ctx.start is not None:
        # a warm update under dead moments: Newton on the exact equations first
        ok, exact, it, viol = exact_newton(ctx, ctx.start, problem)
        if ok:
            result = exact_result(ctx, problem, exact, it, viol, True, 0)
            if result.status == "ok" and result.stable is not False:
                return result, exact
    result, state = LD.solve_once(ctx, problem, warm)
    if moments and result.status in ("ok", "unverified") and state is not None:
        return solve_moments(ctx, problem, result, state)
    return result, state


def exact_newton(
    ctx: UpdateContext, start: SolverState, problem: Problem, fraction: float = 1.0
) -> AT.NewtonAttempt:
    """Run Newton on the exact equilibrium equations (``moments.ExactMomentKKT``).

    From ``start`` to ``problem`` with its point moments scaled by ``fraction``.
    """
    parts = ctx.parts
    p = AT.pack(ctx, problem, start.z, keep=start.p)
    start = carry_slots(parts, start, p)
    if fraction != 1.0:
        for i, _ in enumerate(problem.loads):
            p[parts.nlp.params[f"load:{i}:moment"]] *= fraction
    return newton(
        parts.nlp,
        parts.functions,
        start,
        p,
        max_steps=MOMENT_NEWTON_STEPS,
        kkt_fn=ExactMomentKKT(parts.nlp, parts.functions, parts.parameters, problem),
    )


def exact_result(
    ctx: UpdateContext,
    problem: Problem,
    state: SolverState,
    iterations: int,
    violation: float,
    warm: bool,
    steps: int,
) -> ShapeResult:
    """Return the result of an exact-moment Newton solution.

    The pseudo-potential is re-centred on it (its gradient is then M·δθ exactly), derivatives
    re-evaluated there for the stability verdict.
    """
    nlp = ctx.parts.nlp
    p = AT.pack(ctx, problem, state.z)
    for i in range(len(problem.obstacles) if nlp.obstacle_slots else 0):
        for name in nlp.slot_parameters(i):  # the slots z was solved with
            p[nlp.params[name]] = state.p[nlp.params[name]]
    state.p = p
    state.hessian = state.jacobian = state.gradient = state.energies = state.kkt = (
        state.residual
    ) = None
    state.reduced_eigen = state.outputs = None
    state.g = None
    return AT.result(
        ctx, problem, state, "Newton (exact moments)", iterations, violation, warm, steps
    )


def solve_moments(
    ctx: UpdateContext, problem: Problem, result: ShapeResult, state: SolverState
) -> Outcome:
    """Polish the ladder's answer under dead point moments on the exact equilibrium equations.

    The answer of ``ladder.solve_once`` applied them through a pseudo-potential centred on its
    start, so it is polished by Newton on the exact equations.  Where the moment turned the string
    too far for that, the moments are raised from zero along the exact equations (steps of a
    fraction of the moment, halved on a failed step, at most MOMENT_CONTINUATION_SOLVES Newton
    solves), starting from the scene without its moments (a true potential, solved by the usual
    warm update).
    """
    iterations = result.iterations
    ok, new, it, viol = exact_newton(ctx, state, problem)
    iterations += it
    if ok:
        return escape_saddle_moments(
            ctx,
            problem,
            exact_result(ctx, problem, new, iterations, viol, result.warm_started, 0),
            new,
        )
    p0 = AT.pack(ctx, problem, state.z, keep=state.p)
    for i, _ in enumerate(problem.loads):
        p0[ctx.parts.nlp.params[f"load:{i}:moment"]] = 0.0
    ok, base, it, viol = AT.newton_to(ctx, state, p0)
    iterations += it
    if not ok:
        ok, base, _, it, viol = AT.ipopt_call(ctx, True, state.z, p0, state)
        iterations += it
    if not ok:
        why = "the scene without its moments did not solve from the pseudo-potential's answer"
        return moment_failure(ctx, iterations, why)
    fraction, step, solves = 0.0, 0.25, 0
    while fraction < 1.0 and solves < MOMENT_CONTINUATION_SOLVES:
        target = min(1.0, fraction + step)
        ok, new, it, viol = exact_newton(ctx, base, problem, target)
        iterations += it
        solves += 1
        if ok:
            base, fraction, step = new, target, min(0.5, 2.0 * step)
        else:
            step *= 0.5
    if fraction < 1.0:
        why = (
            f"raising the moments from zero along the exact equilibrium equations stopped at "
            f"{fraction:.3g} of them after {solves} Newton solves (a limit point: the moment may "
            f"snap the string through)"
        )
        return moment_failure(ctx, iterations, why)
    return escape_saddle_moments(
        ctx,
        problem,
        exact_result(ctx, problem, base, iterations, viol, result.warm_started, solves),
        base,
    )


def escape_saddle_moments(
    ctx: UpdateContext, problem: Problem, result: ShapeResult, state: SolverState
) -> Outcome:
    """Leave a saddle as ``ladder.escape_unstable`` does, each re-solve polished exactly."""

    def attempt(z0: np.ndarray, p: np.ndarray) -> Attempt:
        ok, trial, status, it, viol = AT.ipopt_call(ctx, False, z0, p, escape=True)
        if not ok:
            return ok, trial, status, it, viol
        ok, polished, it2, viol = exact_newton(ctx, trial, problem)
        return ok, polished, status, it + it2, viol

    def build(
        trial: SolverState, status: str, iterations: int, viol: float, warm: bool, steps: int
    ) -> ShapeResult:
        return exact_result(ctx, problem, trial, iterations, viol, warm, steps)

    return escape_saddle(result, state, attempt, build)


def moment_failure(ctx: UpdateContext, iterations: int, why: str) -> Outcome:
    """Return 'failed' with the reason the point moments could not be applied."""
    return no_shape(
        ctx.parts.options,
        ctx.parts.summary(),
        "failed",
        f"point moments: {why}",
        iterations=iterations,
    ), None
