"""Grip targets from tf2 frames (grips.<grip>.tf_frame, #40), without a ROS graph: only grips that
moved are handed on, a frame tf2 cannot transform is a refused input, nothing is read while the node
refuses targets; and the parameter's start-up checks (tf2_ros is not on PyPI: a frame set without it
is a clear error, as is a grip the scene does not have)."""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.node import params as P
from dlo_ros.node.tf_grip_targets import TfGripTargets
from dlo_ros.node.validation import TargetError


class FakeNode:
    def create_timer(self, period, callback):
        self.period, self.callback = period, callback
        return object()


class FakeInputs:
    def __init__(self):
        self.refused, self.taken, self.rejected = "", [], []

    def refusal(self):
        return self.refused

    def take(self, poses, stamp_ns):
        self.taken.append(dict(poses))

    def reject(self, exc, stamp_ns=0):
        self.rejected.append((exc.kind, str(exc)))


def pose(x):
    return GripPose(np.array([x, 0.0, 0.4]), np.array([0.0, 0.0, 0.0, 1.0]))


def test_only_moved_grips_are_handed_on_and_unknown_frames_are_refused():
    world = {"tool_l": pose(0.0), "tool_r": pose(0.6)}
    reads = []

    def read(frame, where):
        reads.append(where)
        if frame not in world:
            raise TargetError("frame", f"{where}: no transform from '{frame}' to 'world'")
        return world[frame]

    inputs = FakeInputs()
    node = FakeNode()
    tf = TfGripTargets(node, {"left": "tool_l", "right": "tool_r"}, read, inputs, 50.0)
    assert node.period == pytest.approx(0.02)
    tf.tick()
    assert list(inputs.taken[0]) == ["left", "right"]
    tf.tick()
    assert len(inputs.taken) == 1  # nothing moved: nothing handed on
    world["tool_r"] = pose(0.55)
    tf.tick()
    assert list(inputs.taken[1]) == ["right"] and inputs.taken[1]["right"].position[0] == 0.55
    world["tool_r"] = pose(0.55 + 1e-12)  # below MOVED: tf2 republishing the same transform
    tf.tick()
    assert len(inputs.taken) == 2
    del world["tool_l"]
    tf.tick()
    assert inputs.rejected == [("frame", "grips.left.tf_frame (tool_l): no transform from 'tool_l' to 'world'")]
    inputs.refused = "inactive"
    n = len(reads)
    world["tool_l"] = pose(0.1)
    tf.tick()
    assert len(reads) == n and len(inputs.taken) == 2  # a refusing node reads nothing


def test_the_tf_frame_parameters_are_checked_before_the_node_starts():
    assert P.unknown_reason("grips.left.tf_frame") == ""
    assert P.check_value("grips.left.tf_frame", "tool0") == ""
    assert "not a usable frame id" in P.check_value("grips.left.tf_frame", "tool 0")
    assert "not a parameter" in P.unknown_reason("grips.left.tf_frames")
    with pytest.raises(P.ParamsError, match="grips.left.tf_frame"):
        P.prepare_node_args(["--ros-args", "-p", "grips.left.tf_frame:=a b"])
    P.prepare_node_args(["--ros-args", "-p", "grips.left.tf_frame:=tool0"])
