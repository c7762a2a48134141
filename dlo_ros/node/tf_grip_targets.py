"""Grip targets from tf2 frames: ``grips.<grip>.tf_frame`` (executor thread).

A grip whose parameter ``grips.<grip>.tf_frame`` names a frame (e.g. a gripper's ``tool0``) takes
that frame's pose, in the node's frame, as its target: a timer at ``tf_targets.rate`` reads the
newest transform of each such frame through the target inputs' tf2 buffer (``PoseReader``: the same
checks as a target message's pose, named ``grips.<grip>.tf_frame``) and hands the grips that moved
to the engine, as one target set.  A frame tf2 cannot transform yet is a refused input (counted,
logged throttled); the last good shape stays.  Nothing is read while the node refuses targets (a
managed node that is not active).  The target topics keep working beside it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from rclpy.node import Node

from ..model.problem import GripPose
from .target_inputs import TargetInputs
from .validation import TargetError

#: a grip's target is handed on only when it moved by more than this [m] or rotated by more than
#: this (quaternion components): tf2 republishes unchanged transforms at its own rate
MOVED = 1e-9

#: reads the pose of a frame in the node's frame: (frame, where) -> GripPose, or TargetError
ReadFrame = Callable[[str, str], GripPose]


class TfGripTargets:
    """Poll each grip's tf frame and submit the moved ones (module docstring).

    ``frames``: grip -> tf frame (non-empty only); ``read``: the pose of a frame in the node's
    frame; ``inputs``: where targets go and refusals are reported.
    """

    def __init__(
        self,
        node: Node,
        frames: dict[str, str],
        read: ReadFrame,
        inputs: TargetInputs,
        rate_hz: float,
    ) -> None:
        self.frames = dict(frames)
        self.read = read
        self.inputs = inputs
        self.sent: dict[str, GripPose] = {}  # the newest target handed on per grip
        self._timer = node.create_timer(1.0 / rate_hz, self.tick)

    def tick(self) -> None:
        """Read every frame; hand the grips that moved to the engine (timer)."""
        if self.inputs.refusal():
            return
        moved: dict[str, GripPose] = {}
        for grip, frame in self.frames.items():
            try:
                pose = self.read(frame, f"grips.{grip}.tf_frame ({frame})")
            except TargetError as exc:
                self.inputs.reject(exc)
                continue
            last = self.sent.get(grip)
            if last is None or not _same(last, pose):
                moved[grip] = pose
        if moved:
            self.sent.update(moved)
            self.inputs.take(moved, None)


def _same(a: GripPose, b: GripPose) -> bool:
    return bool(
        np.abs(a.position - b.position).max() <= MOVED
        and np.abs(a.orientation - b.orientation).max() <= MOVED
    )
