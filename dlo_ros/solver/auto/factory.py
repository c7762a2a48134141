"""``make_solver``: the solver a scene's options ask for (auto's, or one fixed model)."""

from __future__ import annotations

from ...model.problem import Problem
from ..options import SolverOptions
from ..protocol import Solver
from ..shape_solver import ShapeSolver
from .auto_solver import AutoShapeSolver


def make_solver(
    problem: Problem,
    options: SolverOptions | None = None,
    compile: str = "background",
    checks: str = "background",
) -> Solver:
    """Return an AutoShapeSolver for solver.model 'auto' (the default), else a ShapeSolver.

    ``checks`` as AutoShapeSolver's: 'background' by default, so that a stream never builds or
    switches a model on the caller's thread; 'sync' for one-shot answers that must be checked
    before they return, as the CLI's.
    """
    options = options or SolverOptions()
    if options.model == "auto":
        return AutoShapeSolver(problem, options, compile=compile, checks=checks)
    return ShapeSolver(problem, options, compile=compile)
