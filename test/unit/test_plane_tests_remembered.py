"""The plane tests a planar stream runs on every target remember their verdicts, never stale ones.

``reference_frame.planarity_violation`` keeps the verdict of what does not move with the grips
(gravity, loads, offsets, obstacles) by the bytes of those inputs and the plane, and
``reach.imposes_twist`` its verdict by the clamps' quaternions and the frame: each changed input
must give its own verdict, the same as a scene seen for the first time (a fresh ``Problem`` with
the same values), whatever was asked before.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model import GripPose, Load
from dlo_ros.model.obstacles import Obstacle
from dlo_ros.model.rotations import matrix_to_quat, quat_to_matrix
from dlo_ros.scene import load_scene
from dlo_ros.solver.auto.reach import imposes_twist, not_planar
from dlo_ros.solver.build.reference_frame import planarity_violation

SCENE = load_scene("default_cable").problem
NORMAL = np.array([0.0, 1.0, 0.0])  # the default cable hangs in the x-z plane
R0 = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]]).T


def _sphere(y: float) -> Obstacle:
    return Obstacle("sphere", np.array([0.3, y, 0.1, 0.05]))


def test_each_changed_non_grip_input_gets_its_own_verdict():
    base = replace(SCENE, obstacles=(_sphere(0.0),))
    assert planarity_violation(base, NORMAL) == ""
    off = replace(base, obstacles=(_sphere(0.02),))  # the same sphere moved out of the plane
    assert "obstacles[0]" in planarity_violation(off, NORMAL)
    assert planarity_violation(base, NORMAL) == ""  # and back: the first verdict again
    tilted = replace(base, gravity=np.array([0.0, 0.3, -1.0]))
    assert planarity_violation(tilted, NORMAL) == "gravity.direction is not in the plane"
    pushed = replace(base, loads=(Load(0.2, force=np.array([0.0, 1.0, 0.0])),))
    assert planarity_violation(pushed, NORMAL) == "loads[0].force is not in the plane"
    # a grip moved out of the plane is never hidden by the kept verdict of the rest
    right = SCENE.grip("right").pose
    moved = base.with_grip_poses(
        {"right": GripPose(right.position + np.array([0.0, 0.01, 0.0]), right.orientation)}
    )
    assert planarity_violation(moved, NORMAL) == "grips[1].position is 0.01 m out of the plane"


@pytest.mark.parametrize("tolerance", [1e-9, 1e-7])
def test_the_verdict_is_a_fresh_scenes(tolerance):
    for y in (0.0, 1e-9, 1e-6, 0.02):
        asked = replace(SCENE, obstacles=(_sphere(y),))
        fresh = replace(SCENE, obstacles=(Obstacle("sphere", np.array([0.3, y, 0.1, 0.05])),))
        assert planarity_violation(asked, NORMAL, tolerance) == planarity_violation(
            fresh, NORMAL, tolerance
        )


def test_a_clamp_turned_about_its_tangent_imposes_twist_and_turned_back_does_not():
    right = SCENE.grip("right").pose
    assert not imposes_twist(SCENE, R0)
    # the clamp's frame turned 0.6 rad about its own x axis (the tangent)
    about_x = np.array([[1, 0, 0], [0, np.cos(0.6), -np.sin(0.6)], [0, np.sin(0.6), np.cos(0.6)]])
    turned_q = matrix_to_quat(quat_to_matrix(right.orientation) @ about_x)
    turned = SCENE.with_grip_poses({"right": GripPose(right.position, turned_q)})
    assert imposes_twist(turned, R0)
    assert not_planar(turned, (), R0) == "the clamps impose twist"
    assert not imposes_twist(SCENE, R0)
