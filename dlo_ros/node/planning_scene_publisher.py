"""Publish the newest shape as a chain of capsules: ``~/capsules`` and MoveIt's collision object.

A timer at ``planning_scene.rate`` takes the newest streaming shape (``ShapeOutputs.latest``) when
it changed, builds its capsule chain (``capsules.capsule_chain``: the string's radius plus
``planning_scene.padding``) and publishes it as a MarkerArray on ``~/capsules`` and, when
``moveit_msgs`` is importable, as a ``moveit_msgs/CollisionObject`` on ``planning_scene.topic``.
A padding too small for the shape's sampling is reported (throttled) and nothing is published for
that shape.  msg_docs/planning_scene.md has the guarantees and the MoveIt use.
"""

from __future__ import annotations

from typing import Callable

from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from .capsules import capsule_chain
from .planning_scene import (
    capsule_markers,
    collision_object,
    collision_removal,
    moveit_collision_object_type,
    removal_markers,
)
from .qos import LATCHED_QOS
from .shape_outputs import ShapeOutputs
from .validation import safe_text


class PlanningScenePublisher:
    """The capsules of the newest shape at their own rate (module docstring).

    ``quiet()``: true while nothing may be published (closing, or a managed node inactive).
    """

    def __init__(
        self,
        node: Node,
        frame_id: str,
        outputs: ShapeOutputs,
        quiet: Callable[[], bool],
        warn_throttle_s: float,
    ) -> None:
        value = node.get_parameter
        self.node, self.frame_id, self.outputs, self.quiet = node, frame_id, outputs, quiet
        self.padding = float(value("planning_scene.padding").value)
        self.warn_throttle_s = max(warn_throttle_s, 1e-3)
        self.published = 0  # chains published
        self.last_error = ""
        self._drawn: object = None  # the Update drawn last
        self._markers = node.create_publisher(MarkerArray, "~/capsules", LATCHED_QOS)
        kind = moveit_collision_object_type()
        self._objects = (
            None
            if kind is None
            else node.create_publisher(kind, value("planning_scene.topic").value, LATCHED_QOS)
        )
        self._timer = node.create_timer(1.0 / float(value("planning_scene.rate").value), self.tick)

    def tick(self) -> None:
        """Publish the newest shape's capsules when it changed since the timer last ran."""
        u = self.outputs.latest
        if u is None or u is self._drawn or self.quiet():
            return
        self._drawn = u
        try:
            chain = capsule_chain(u.result.points, u.problem.string.radius, self.padding)
        except ValueError as exc:  # the padding is too small for the sampling, or the cap
            self.last_error = safe_text(exc)
            self.node.get_logger().warning(
                f"planning_scene: no capsules for this shape: {self.last_error}",
                throttle_duration_sec=self.warn_throttle_s,
            )
            return
        self._markers.publish(capsule_markers(chain, self.frame_id, u.stamp_ns or 0))
        if self._objects is not None:
            self._objects.publish(collision_object(chain, self.frame_id, u.stamp_ns or 0))
        self.published += 1

    def withdraw(self) -> None:
        """Clear the capsules and remove the collision object (the node stops tracking)."""
        stamp = self.node.get_clock().now().nanoseconds
        self._drawn = None  # draw the newest shape again when publishing resumes
        try:
            self._markers.publish(removal_markers(self.frame_id, stamp))
            if self._objects is not None:
                self._objects.publish(collision_removal(self.frame_id, stamp))
        except Exception:  # noqa: BLE001 - the context may be shutting down: nothing to withdraw
            pass
