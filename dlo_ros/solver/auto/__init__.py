"""``solver.model: auto``: the policy that picks the model a scene needs."""

from .auto_solver import AutoShapeSolver, make_solver

__all__ = ["AutoShapeSolver", "make_solver"]
