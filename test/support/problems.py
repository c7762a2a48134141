"""Small problems built from the model classes (no YAML, no ROS)."""
from __future__ import annotations

import numpy as np

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties


def quat_about(axis: str, angle: float) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation by ``angle`` about a coordinate axis."""
    q = [0.0, 0.0, 0.0, np.cos(angle / 2)]
    q["xyz".index(axis)] = np.sin(angle / 2)
    return q


def clamped_pair(
    left: tuple = (0.0, 0.0, 0.0),
    right: tuple = (0.5, 0.0, 0.0),
    q_left: list | None = None,
    q_right: list | None = None,
    length: float = 1.0,
    bend: float = 1.0,
    twist: float = 1.0,
    weight: float = 0.0,
    modes: tuple[str, str] = ("clamp", "clamp"),
    loads: tuple[Load, ...] = (),
    obstacles: tuple = (),
    gravity: tuple = (0.0, 0.0, -1.0),
) -> Problem:
    """A string of ``length`` held at s = 0 and s = L (tangents along +x unless given)."""
    ident = [0.0, 0.0, 0.0, 1.0]
    string = StringProperties(length, Profile.constant(bend), Profile.constant(twist), Profile.constant(weight))
    grips = (
        Grip("left", 0.0, modes[0], GripPose.checked(left, q_left or ident, "left")),
        Grip("right", length, modes[1], GripPose.checked(right, q_right or ident, "right")),
    )
    return Problem(string, grips, gravity=np.array(gravity, dtype=float), loads=loads, obstacles=obstacles)
