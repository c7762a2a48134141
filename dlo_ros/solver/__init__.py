"""CasADi + IPOPT solver of the Ritz NLP (no ROS)."""

from .options import SolverOptions
from .results.result import STATUSES, GripWrench, ShapeResult
from .results.summary import ModelSummary
from .protocol import Solver
from .shape_solver import ShapeSolver
from .auto import AutoShapeSolver, make_solver

__all__ = [
    "AutoShapeSolver",
    "make_solver",
    "ModelSummary",
    "Solver",
    "SolverOptions",
    "STATUSES",
    "GripWrench",
    "ShapeResult",
    "ShapeSolver",
]
