"""CasADi + IPOPT solver of the Ritz NLP (no ROS)."""
from .options import SolverOptions
from .result import STATUSES, GripWrench, ShapeResult
from .shape_solver import ShapeSolver

__all__ = ["SolverOptions", "STATUSES", "GripWrench", "ShapeResult", "ShapeSolver"]
