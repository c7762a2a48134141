"""Paths from a load-free equilibrium to a scene's dead point moments, on the exact equations.

Contract: ``scaled(problem, forces, moments)`` is ``problem`` with its weight and point forces
multiplied by ``forces`` and its point moments by ``moments``; ``raise_along(solve_at, base,
budget, deadline)`` marches a load fraction from 0 to 1 with Newton solves (``solve_at(start,
fraction)``), and returns how far it got (``Raised``).

Why two paths (``update/moments.py`` uses both): raising the moments with the scene's forces and
weight already on can meet a limit point (a fold of the equilibrium branch in the moment's size:
seeds 31 and 57 of test/random_scenes.py at 0.854 and 0.773 of their moments, the second
confirmed by the independent shooting reference, test/reference/kirchhoff.py).  The equilibrium at
the full loads then lies on another branch.  Raising the moments first, on the scene without its
weight and forces (a moment alone bends a clamped string into a helix about its axis, a branch
without folds), and then the weight and forces, reaches it in those scenes.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

from ...model.problem import Problem
from ...model.profile import Profile
from ..state import SolverState

#: Newton solves along one path before it gives up (a failed one stops at its first step)
PATH_SOLVES = 200
#: the first fraction step, the largest, and the smallest worth taking (a limit point below it)
FIRST_STEP, LARGEST_STEP, SMALLEST_STEP = 0.25, 0.5, 1e-4

#: (converged, state, Newton steps, constraint violation), as ``attempts.NewtonAttempt``
NewtonAttempt = tuple[bool, SolverState, int, float]


@dataclass
class Raised:
    """How far ``raise_along`` got: the fraction reached, its equilibrium and the work done."""

    fraction: float
    state: SolverState
    solves: int
    iterations: int
    violation: float

    @property
    def done(self) -> bool:
        return self.fraction >= 1.0


def scaled(problem: Problem, forces: float, moments: float) -> Problem:
    """Return ``problem`` with weight and point forces × ``forces``, moments × ``moments``."""
    string = problem.string
    weight = string.weight_per_length
    string = dataclasses.replace(
        string,
        weight_per_length=Profile(weight.s, tuple(forces * v for v in weight.values)),
    )
    loads = tuple(
        dataclasses.replace(ld, force=forces * ld.force, moment=moments * ld.moment)
        for ld in problem.loads
    )
    return dataclasses.replace(problem, string=string, loads=loads)


def raise_along(
    solve_at: Callable[[SolverState, float], NewtonAttempt],
    base: SolverState,
    budget: int = PATH_SOLVES,
    deadline: float | None = None,
) -> Raised:
    """March a load fraction from 0 (``base``, solved) towards 1 by Newton solves.

    Each step from the last equilibrium; a failed step is halved, and the step grows (×1.5, at
    most LARGEST_STEP) only after two successes in a row: Newton's step limit fails a step that
    is too long at once (no work), and growing after every success made a path alternate between
    a success and a failure, which spent its budget at a quarter of the pace.  Stops at 1, after
    ``budget`` solves, with a step under SMALLEST_STEP, or past ``deadline``
    (``time.perf_counter()``; a streamed update's limit).
    """
    out = Raised(0.0, base, 0, 0, 0.0)
    step, streak = FIRST_STEP, 0
    while out.fraction < 1.0 and out.solves < budget and step >= SMALLEST_STEP:
        if deadline is not None and time.perf_counter() >= deadline:
            break
        target = min(1.0, out.fraction + step)
        ok, new, iterations, violation = solve_at(out.state, target)
        out.iterations += iterations
        out.solves += 1
        if ok:
            out.fraction, out.state, out.violation = target, new, violation
            streak += 1
            if streak >= 2:
                step = min(LARGEST_STEP, 1.5 * step)
        else:
            step, streak = 0.5 * step, 0
    return out
