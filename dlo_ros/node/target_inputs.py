"""The node's target inputs: ``~/grips/<grip>/target`` and ``~/grips/targets`` (target thread).

The subscriptions live on the node's hot path (``hot_path.HotPath``: a small hidden node with its
own executor and thread), so that a target wakes a wait set of its own rather than the main
executor's; their topic names are the main node's.  A target message is read raw (serialised): it
is refused by its size before rclpy builds Python objects from it (a huge PoseArray costs seconds
and memory to deserialise).  Each pose is checked (finite, unit quaternion, frame) and
transformed into the node's frame, then handed to the engine's "latest pending targets" slot.  A
refused message is logged (throttled), recorded and counted in the diagnostics; the last good
shape stays published.
"""

from __future__ import annotations

import time
from functools import partial
from typing import Any, Callable

import rclpy
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from ..model.problem import GripPose
from . import conversions as conv
from .engine import ShapeEngine
from .health import Health
from .hot_path import HotPath
from .qos import TARGET_QOS
from .stream_log import StreamLog
from .validation import (
    TargetError,
    check_count,
    check_frame_size,
    check_message_size,
    check_pose,
    safe_text,
)

try:  # optional: not on PyPI; present in a full ROS installation
    import tf2_ros
except ImportError:  # pragma: no cover - depends on the installation
    tf2_ros = None


IDENTITY = Pose()  # a frame's own origin and axes (geometry_msgs' default quaternion is w = 1)


class PoseReader:
    """Check a pose message and bring it into the node's frame (with tf2 when ``use_tf``)."""

    def __init__(self, node: Node, frame_id: str, use_tf: bool) -> None:
        self.frame_id = frame_id
        self._tf_buffer: Any = None
        if use_tf and tf2_ros is not None:
            self._tf_buffer = tf2_ros.Buffer()
            self._tf_listener = tf2_ros.TransformListener(self._tf_buffer, node)

    def _lookup(self, target: str, source: str) -> tuple[tuple, tuple]:
        """Return (translation, rotation) from ``source`` into ``target``: tf2's latest."""
        t = self._tf_buffer.lookup_transform(target, source, rclpy.time.Time())
        tr, rot = t.transform.translation, t.transform.rotation
        return (tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w)

    def frame_pose(self, frame: str, where: str) -> GripPose:
        """Return tf2 frame ``frame``'s pose in the node's frame; TargetError naming ``where``."""
        return self.checked(IDENTITY, frame, where)

    def checked(self, pose_msg: Any, frame_id: str, where: str) -> GripPose:
        """Return ``pose_msg`` (in ``frame_id``) checked and in the node's frame.

        Raises TargetError naming ``where`` for a bad frame, a non-finite value, a quaternion that
        is not a unit one, or a frame no transform is known for.
        """
        check_frame_size(frame_id, where)  # a 10 MB frame_id goes no further (logs, tf2)
        position, orientation = conv.pose_to_arrays(pose_msg)
        pose = check_pose(position, orientation, where)  # before any transform: named as sent
        position, orientation = conv.in_frame(
            frame_id,
            self.frame_id,
            pose.position,
            pose.orientation,
            where,
            self._lookup if self._tf_buffer is not None else None,
        )
        return GripPose(position, orientation)


def read_message(data: bytes, kind: type, where: str) -> Any:
    """Deserialise the message of type ``kind`` in ``data``, once its size is within the limit.

    Raises TargetError ('size' or 'invalid') naming ``where``.
    """
    check_message_size(len(data), where)
    try:
        return deserialize_message(data, kind)
    except Exception as exc:  # noqa: BLE001 - a malformed buffer is bad input, not a bug
        raise TargetError(
            "invalid", f"{where}: not a readable {kind.__name__} ({type(exc).__name__})"
        ) from None


class TargetInputs:
    """Subscribe to the grip targets on ``hot`` and hand the checked poses to the engine.

    The callbacks run in the hot path's thread, :meth:`take` also in the main executor's (tf2
    targets): both only read ``refusal`` and use thread-safe parts (the engine's slot, the health,
    the recorder, the diagnostics).  ``node`` (the main node) gives the logger and the clock.
    """

    def __init__(
        self,
        node: Node,
        hot: HotPath,
        poses: PoseReader,
        grip_names: list[str],
        engine: ShapeEngine,
        log: StreamLog,
        health: Health,
        publish_diagnostics: Callable[[bool], None],
        refusal: Callable[[], str] = lambda: "",
    ) -> None:
        self.node = node
        self.refusal = refusal  # why targets are refused now ('' = accepted): a lifecycle state
        self.poses = poses
        self.grip_names = grip_names
        self.engine = engine
        self.log = log
        self.health = health
        self.publish_diagnostics = publish_diagnostics
        self._grip_subs = [
            hot.subscribe(
                PoseStamped, f"~/grips/{n}/target", partial(self.on_grip_target, n), TARGET_QOS
            )
            for n in grip_names
        ]
        self._all_sub = hot.subscribe(PoseArray, "~/grips/targets", self.on_targets, TARGET_QOS)

    def on_grip_target(self, name: str, data: bytes) -> None:
        """Take one grip's target (a serialised PoseStamped)."""
        received = time.monotonic_ns()
        where = f"grips/{name}/target"
        msg = None
        try:
            self.check_accepting()
            msg = read_message(data, PoseStamped, where)
            pose = self.poses.checked(msg.pose, msg.header.frame_id, where)
        except TargetError as exc:
            self.reject(exc, conv.time_to_ns(msg.header.stamp) if msg is not None else 0)
            return
        self.take({name: pose}, conv.time_to_ns(msg.header.stamp) or None, received)

    def on_targets(self, data: bytes) -> None:
        """Take every grip's target at once (a serialised PoseArray in configuration order)."""
        received = time.monotonic_ns()
        where = "grips/targets"
        msg = None
        try:
            self.check_accepting()
            msg = read_message(data, PoseArray, where)
            check_count(len(msg.poses), self.grip_names, where)
            poses = {
                n: self.poses.checked(p, msg.header.frame_id, f"{where}[{i}] ({n})")
                for i, (n, p) in enumerate(zip(self.grip_names, msg.poses))
            }
        except TargetError as exc:
            self.reject(exc, conv.time_to_ns(msg.header.stamp) if msg is not None else 0)
            return
        self.take(poses, conv.time_to_ns(msg.header.stamp) or None, received)

    def take(
        self, poses: dict[str, GripPose], stamp_ns: int | None, received: int | None = None
    ) -> None:
        """Record checked poses in the node's frame and hand them to the engine.

        ``received``: when their message arrived (monotonic ns); None: now (poses read from tf2).
        """
        received = time.monotonic_ns() if received is None else received
        self.log.recorder.log_targets(poses, update=self.log.update, ros_time_ns=stamp_ns)
        self.engine.submit_targets(poses, stamp_ns, received)

    def check_accepting(self) -> None:
        """Raise TargetError('inactive') while the node refuses targets (a lifecycle state)."""
        reason = self.refusal()
        if reason:
            raise TargetError("inactive", reason)

    def reject(self, exc: TargetError, stamp_ns: int = 0) -> None:
        """Record, count and (throttled) log a refused target."""
        text = safe_text(exc)  # it may quote a frame_id or a transform error: escaped and capped
        self.log.recorder.log_rejected(
            f"{exc.kind}: {text}",
            update=self.log.update,
            ros_time_ns=stamp_ns or self.node.get_clock().now().nanoseconds,
        )
        if self.health.error(exc.kind, text, rejected=True):
            self.node.get_logger().warning(
                f"rejected target ({exc.kind}): {text}; the last good shape stays published"
            )
        self.publish_diagnostics(True)
