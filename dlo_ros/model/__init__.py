"""The string model (no ROS): properties, bases, quadrature, kinematics, energy, obstacles.

The string model (no ROS): properties, bases, quadrature, kinematics, energy terms,
obstacles.
"""

from .basis import ChebyshevBasis, FourierBasis, make_basis
from .obstacles import OBSTACLE_TYPES, Obstacle
from .problem import GRIP_MODES, Grip, GripPose, Load, Problem, RelativePosition, StringProperties
from .profile import Profile
from .quadrature import ChebyshevQuadrature

__all__ = [
    "ChebyshevBasis",
    "FourierBasis",
    "make_basis",
    "OBSTACLE_TYPES",
    "Obstacle",
    "GRIP_MODES",
    "Grip",
    "GripPose",
    "Load",
    "Problem",
    "RelativePosition",
    "StringProperties",
    "Profile",
    "ChebyshevQuadrature",
]
