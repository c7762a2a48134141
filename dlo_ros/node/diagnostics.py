"""The node's ``/diagnostics`` publisher: the ``<node>: shape`` status, and the fit's when fitting.

The content comes from :class:`~dlo_ros.node.health.Health`; this module only builds the message
and publishes it, periodically (``diagnostics_period``) and at once after an event (at most every
``IMMEDIATE_DIAGNOSTICS_MIN_S``).
"""

from __future__ import annotations

import threading
import time
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node

from . import conversions as conv
from .engine import ShapeEngine
from .health import Health
from .qos import DIAGNOSTICS_QOS
from .validation import TEXT_LIMIT, safe_text

#: shortest interval [s] between two event-driven publications (a burst of rejections is one)
IMMEDIATE_DIAGNOSTICS_MIN_S = 0.1


class DiagnosticsPublisher:
    """Publish the node's statuses on ``/diagnostics`` (any thread; serialised by a lock).

    ``hardware_id``: the scene's name.  ``closing()``: true once the node is shutting down (then
    nothing is published).  :attr:`extra` holds more status makers (the fitter's), each called with
    the hardware id.
    """

    def __init__(
        self,
        node: Node,
        health: Health,
        engine: ShapeEngine,
        hardware_id: str,
        closing: Callable[[], bool],
    ) -> None:
        self.node = node
        self.health = health
        self.engine = engine
        self.hardware_id = hardware_id
        self.closing = closing
        self.extra: list[Callable[[str], DiagnosticStatus]] = []
        self._lock = threading.Lock()
        self._last_immediate = 0.0
        self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self._timer = node.create_timer(
            node.get_parameter("diagnostics_period").value, lambda: self.publish()
        )

    def publish(self, immediate: bool = False) -> None:
        """Publish every status now; ``immediate`` (after an event) is throttled."""
        if self.closing():
            return
        now = time.monotonic()
        with self._lock:
            if immediate:
                if now - self._last_immediate < IMMEDIATE_DIAGNOSTICS_MIN_S:
                    return
                self._last_immediate = now
            self.health.set_targets(self.engine.targets_received, self.engine.targets_coalesced)
            statuses = [self.shape_status()]
            statuses += [make(self.hardware_id) for make in self.extra]
            msg = DiagnosticArray(
                header=conv.header("", self.node.get_clock().now().nanoseconds), status=statuses
            )
            try:
                self._pub.publish(msg)
            except Exception:  # noqa: BLE001 - the context may be shutting down
                pass

    def shape_status(self) -> DiagnosticStatus:
        """Build the ``<node>: shape`` status from the health's level, message and values."""
        level, message = self.health.level_and_message()
        # every text value escaped and capped (user-controlled pieces were capped to TEXT_LIMIT
        # where they entered; the model's own reasons may be longer, hence the larger cap here)
        values = {
            k: safe_text(v, 5 * TEXT_LIMIT) if isinstance(v, str) else v
            for k, v in self.health.values().items()
        }
        return conv.diagnostic_status(
            f"{self.node.get_fully_qualified_name()}: shape",
            level,
            safe_text(message),
            self.hardware_id,
            values,
        )
