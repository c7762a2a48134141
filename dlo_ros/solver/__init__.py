"""CasADi + IPOPT solver of the Ritz NLP (no ROS).

Importing it sets the OpenBLAS libraries numpy and SciPy loaded to one thread, unless the user set
``OPENBLAS_NUM_THREADS`` (``dlo_ros/blas_threads.py`` says why), and refuses a CasADi without
thread-safe symbolics (``dlo_ros/casadi_threads.py``).
"""

from ..blas_threads import one_blas_thread_now
from ..casadi_threads import require_threadsafe_casadi
from .options import SolverOptions
from .results.result import STATUSES, GripWrench, ShapeResult
from .results.summary import ModelSummary
from .protocol import Solver
from .shape_solver import ShapeSolver
from .auto import AutoShapeSolver, make_solver

require_threadsafe_casadi()  # before any model is built (none is at import): the fix named
one_blas_thread_now()  # every module above is imported: numpy's and SciPy's OpenBLAS are loaded

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
