"""Stage: dead point moments (director models), solved on the exact equilibrium equations.

Contract: ``solve_with_moments(ctx, problem, warm)`` gives the outcome of the pairs-fixed solve
(``ladder.solve_once``) for ``problem``; under point moments a warm update first tries Newton on
the exact equations from ``ctx.start``, and a ladder answer (which applied the moments through a
pseudo-potential centred on its start) is polished on them (``solve_moments``), its saddles left
with each re-solve polished too.  Without point moments it is ``ladder.solve_once`` itself.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...model.problem import Problem
from ..build.moments import ExactMomentKKT
from ..build.nlp import has_point_moments
from ..results.outputs import no_shape
from ..results.result import ShapeResult
from ..state import SolverState
from . import attempts as AT
from . import ladder as LD
from . import moment_paths as MP
from .context import Outcome, UpdateContext
from .ipopt import Attempt, escape_saddle
from .newton import newton
from .slot_rounds import carry_slots

#: Newton steps per solve of the exact equilibrium equations
MOMENT_NEWTON_STEPS = 25
#: a path that stops with a fold row this close to its bound (``fold_margin``) stopped because the
#: mesh cannot follow the rotation, not at a limit point of the equilibria: seeds 31 and 66 of
#: test/random_scenes.py stop at margins 3e-4 and below, seed 57's true limit point (at 0.773 of
#: its moment, where the shooting reference folds too) at 0.43
FOLD_MARGIN = 0.01
#: how a failure for a mesh too coarse for the moments' rotation begins (after "point moments: "):
#: ``solver.model: auto`` then tries the next orders
UNRESOLVED = "unresolved:"
#: the start of that failure's whole message
UNRESOLVED_MESSAGE = f"point moments: {UNRESOLVED}"
#: that failure's advice to a fixed model (auto says which orders it tried instead)
RAISE_ORDER_ADVICE = "(raise solver.order)"

#: Newton solves along one path of raising the moments from zero (``moment_paths``)
MOMENT_CONTINUATION_SOLVES = MP.PATH_SOLVES


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
    too far for that, the moments are raised from zero along the exact equations
    (``moment_paths.raise_along``), from the scene without its moments (a true potential, solved
    by the usual warm update); where that path meets a limit point, from the scene without any
    load or weight: its moments first, then its weight and forces (``moment_paths``).
    """
    ok, new, it, viol = exact_newton(ctx, state, problem)
    if ok:
        return escape_saddle_moments(
            ctx,
            problem,
            exact_result(ctx, problem, new, result.iterations + it, viol, result.warm_started, 0),
            new,
        )
    iterations = result.iterations + it
    notes = []
    for name, legs in paths(problem):
        raised, it, note = follow(ctx, legs, state)
        iterations += it
        notes.append(f"{name}: {note}")
        if raised is not None:
            exact = exact_result(
                ctx,
                problem,
                raised.state,
                iterations,
                raised.violation,
                result.warm_started,
                raised.solves,
            )
            return escape_saddle_moments(ctx, problem, exact, raised.state)
    if any(note.endswith("(at a fold guard)") for note in notes):
        why = (
            f"{UNRESOLVED} the string turns by 120° between neighbouring nodes of its rotation "
            f"field on the way to them {RAISE_ORDER_ADVICE}: " + "; ".join(notes)
        )
    else:
        why = (
            "no path from zero along the exact equilibrium equations reached them ("
            + "; ".join(notes)
            + "; a limit point: the moment may snap the string through)"
        )
    return moment_failure(ctx, iterations, why)


#: a path: the problems along its legs, each a function of the leg's load fraction in [0, 1]
Legs = tuple[Callable[[float], Problem], ...]


def paths(problem: Problem) -> tuple[tuple[str, Legs], ...]:
    """Return the two ways of raising the loads from zero (``moment_paths``), by name."""
    return (
        ("the moments raised with the other loads on", (lambda f: MP.scaled(problem, 1.0, f),)),
        (
            "the moments first, then weight and forces",
            (lambda f: MP.scaled(problem, 0.0, f), lambda f: MP.scaled(problem, f, 1.0)),
        ),
    )


def follow(
    ctx: UpdateContext, legs: Legs, state: SolverState
) -> tuple[MP.Raised | None, int, str]:
    """Follow one path from the solution of its start (``legs[0](0)``) near ``state``.

    Return (the equilibrium at its end, or None; Newton iterations; what happened).
    """
    base, iterations = free_of_loads(ctx, legs[0](0.0), state)
    if base is None:
        return None, iterations, "its start did not solve from the pseudo-potential's answer"
    done = []
    raised = MP.Raised(0.0, base, 0, 0, 0.0)
    for k, at in enumerate(legs):

        def solve_at(start: SolverState, f: float, at: Callable = at) -> AT.NewtonAttempt:
            return exact_newton(ctx, start, at(f))

        raised = MP.raise_along(solve_at, base, deadline=ctx.deadline)
        iterations += raised.iterations
        done.append(f"leg {k + 1} reached {raised.fraction:.3g} in {raised.solves} Newton solves")
        if not raised.done:
            if fold_margin(ctx.parts.nlp, raised.state) < FOLD_MARGIN:
                done[-1] += " (at a fold guard)"
            return None, iterations, ", ".join(done)
        base = raised.state
    return raised, iterations, ", ".join(done)


def fold_margin(nlp, state: SolverState) -> float:
    """Return how far ``state`` is from its nearest fold guard (inf without fold rows).

    The director model's fold rows c − v_i·v_{i+1} ≤ 0 (``model/director.py``) keep neighbouring
    nodes of the rotation field within 120° (frame) or 90° (tangent); a margin near 0 means the
    mesh's nodes are too far apart for the shape's rotation.
    """
    rows = [k for k, kind in enumerate(nlp.row_kind) if kind[0] == "fold"]
    if not rows:
        return float("inf")
    g = np.asarray(nlp.g_fn(state.z, state.p)).ravel()
    return float(-np.max(g[rows]))


def free_of_loads(
    ctx: UpdateContext, problem: Problem, state: SolverState
) -> tuple[SolverState | None, int]:
    """Solve ``problem`` (no moments: a true potential) from ``state``: Newton, then IPOPT."""
    p0 = AT.pack(ctx, problem, state.z, keep=state.p)
    ok, base, it, _ = AT.newton_to(ctx, state, p0)
    if ok:
        return base, it
    ok, base, _, it2, _ = AT.ipopt_call(ctx, True, state.z, p0, state)
    return (base if ok else None), it + it2


def escape_saddle_moments(
    ctx: UpdateContext, problem: Problem, result: ShapeResult, state: SolverState
) -> Outcome:
    """Leave a saddle as ``ladder.escape_unstable`` does, each re-solve polished exactly."""
    ctx.met_unstable(result)

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
