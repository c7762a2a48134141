"""The node's shape outputs: ``~/centerline``, ``~/grips/<grip>/wrench`` and ``~/markers``.

The centreline and the wrenches are published by the solver thread as soon as a shape is solved,
pre-serialised (no per-pose Python objects).  The markers are drawn by a timer
(``markers_period``) from the newest shape, only when it changed: building a MarkerArray in Python
holds the GIL the solver needs.
"""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import Callable

from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from . import conversions as conv
from . import markers
from .engine import Update
from .qos import LATCHED_QOS, WRENCH_QOS


class ShapeOutputs:
    """Publish each streaming shape and keep the newest for the markers timer.

    ``closing()``: true once the node is shutting down, or while a managed node is inactive (then
    no markers are drawn).
    """

    def __init__(
        self, node: Node, frame_id: str, grip_names: list[str], closing: Callable[[], bool]
    ) -> None:
        self.node = node
        self.frame_id = frame_id
        self.closing = closing
        self.latest: Update | None = None  # newest published streaming update, stamped
        self._stamp_ns = 0  # its stamp [ns]
        self._dirty = False
        self._lock = threading.Lock()
        self._path_pub = node.create_publisher(Path, "~/centerline", LATCHED_QOS)
        self._marker_pub = node.create_publisher(MarkerArray, "~/markers", LATCHED_QOS)
        self._wrench_pubs = {
            n: node.create_publisher(WrenchStamped, f"~/grips/{n}/wrench", WRENCH_QOS)
            for n in grip_names
        }
        self._timer = node.create_timer(
            node.get_parameter("markers_period").value, self.publish_markers
        )

    def publish_shape(self, u: Update, stamp_ns: int) -> None:
        """Publish the centreline and the grip wrenches of ``u`` (solver thread)."""
        r = u.result
        self._path_pub.publish(conv.result_path_cdr(r, self.frame_id, stamp_ns))
        for name, wrench in r.grips.items():
            pub = self._wrench_pubs.get(name)
            if pub is not None:
                pub.publish(conv.wrench_cdr(wrench, self.frame_id, stamp_ns))

    def hold(self, u: Update, stamp_ns: int) -> None:
        """Keep ``u`` (stamped) as the newest shape; the next markers tick draws it."""
        with self._lock:
            self.latest = replace(u, stamp_ns=stamp_ns)
            self._stamp_ns = stamp_ns
            self._dirty = True

    def republish(self) -> None:
        """Publish the newest shape again (a node activated); its markers at the next tick."""
        with self._lock:
            u, stamp_ns = self.latest, self._stamp_ns
            self._dirty = u is not None
        if u is not None:
            self.publish_shape(u, stamp_ns)

    def redraw(self) -> None:
        """Draw the newest shape again at the next tick (a marker setting changed)."""
        with self._lock:
            self._dirty = self.latest is not None

    def publish_markers(self) -> None:
        """Publish the markers of the newest shape if it changed since the last tick (timer)."""
        with self._lock:
            u, stamp_ns, dirty = self.latest, self._stamp_ns, self._dirty
            self._dirty = False
        if u is None or not dirty or self.closing():
            return
        value = self.node.get_parameter
        self._marker_pub.publish(
            markers.result_markers(
                u.result,
                u.problem,
                self.frame_id,
                stamp_ns,
                force_scale=value("markers.force_scale").value,
                energy_scale=value("markers.energy_scale").value,
            )
        )
