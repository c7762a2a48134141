"""A cold refinement loop: solve, estimate, refine the mesh, carry the state over, solve again.

It stops when the global estimate (the sum of the per-element estimates with the rule's
``share='length'``, their maximum with ``share='each'``) is at most the tolerance δ and the
solve is 'ok', when the rule changes nothing (every element within its band, or the caps), when
a solve fails, or after ``max_rounds`` meshes.  The estimator is an argument: a function of the
solver and its result that returns ``ElementEstimates`` for the solver's mesh.  Every solve after
the first starts from the previous mesh's equilibrium (``transfer.warm_start_from``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from ...model.problem import Problem
from ..build.mesh import MeshSpec, element_mesh, mesh_spec
from ..build.structure import breakpoints
from ..options import SolverOptions
from ..results.result import ShapeResult
from ..shape_solver import ShapeSolver
from .rule import ElementEstimates, RefinementRule, next_mesh, unknowns
from .transfer import warm_start_from

#: the estimator: per-element estimates of a solver's committed shape (its ``result``)
Estimator = Callable[[ShapeSolver, ShapeResult], ElementEstimates]


@dataclass(frozen=True)
class RefinementRound:
    """One mesh of the loop: its spec, unknowns per field, the solve and its estimate [m]."""

    spec: MeshSpec
    unknowns: int
    status: str
    iterations: int
    warm_started: bool
    estimate: float


@dataclass
class RefinementOutcome:
    """The last solver and result, every round, and why the loop stopped.

    ``converged``: the last result is 'ok' with its estimate ≤ δ; ``reason`` says why not.
    """

    solver: ShapeSolver
    result: ShapeResult
    rounds: list[RefinementRound] = field(default_factory=list)
    converged: bool = False
    reason: str = ""


def global_estimate(estimates: ElementEstimates, rule: RefinementRule) -> float:
    """Return the global estimate [m]: the sum (share 'length') or maximum (share 'each')."""
    errors = estimates.errors
    return float(errors.sum() if rule.share == "length" else errors.max())


def refine_until(
    problem: Problem,
    options: SolverOptions,
    estimator: Estimator,
    rule: RefinementRule,
    start: MeshSpec | None = None,
    max_rounds: int = 8,
    compile: str = "off",
) -> RefinementOutcome:
    """Solve ``problem`` on refined meshes until the estimate is ≤ ``rule.tolerance``.

    start: the first mesh (default: the scene's, ``solver.order`` shared out).  Module docstring
    for when it stops.
    """
    rule.validate()
    if not 1 <= max_rounds <= 100:
        raise ValueError(f"refinement.max_rounds: must be in [1, 100], got {max_rounds}")
    spec = start or mesh_spec(element_mesh(problem, options))
    solver = ShapeSolver(problem, options, compile=compile, mesh=spec)
    result = solver.solve()
    outcome = RefinementOutcome(solver, result)
    fixed, length = breakpoints(problem), problem.string.length
    while True:
        if result.status not in ("ok", "unverified"):
            outcome.reason = f"the solve on {spec} failed: {result.message}"
            return outcome
        estimates = estimator(solver, result)
        total = global_estimate(estimates, rule)
        outcome.rounds.append(
            RefinementRound(
                spec,
                unknowns(spec.counts or ()),
                result.status,
                result.iterations,
                result.warm_started,
                total,
            )
        )
        if total <= rule.tolerance and result.ok:
            outcome.converged = True
            return outcome
        if len(outcome.rounds) >= max_rounds:
            outcome.reason = f"{max_rounds} meshes, estimate {total:.3g} m"
            return outcome
        following = next_mesh(spec, length, estimates, rule, fixed)
        if following is None:
            outcome.reason = f"the rule changes nothing (caps reached?), estimate {total:.3g} m"
            return outcome
        spec = following
        refined = ShapeSolver(problem, options, compile=compile, mesh=spec)
        warm_start_from(solver, refined)
        solver, result = refined, refined.solve()
        outcome.solver, outcome.result = solver, result
