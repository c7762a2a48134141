"""The shape and tension envelope of the newest shape, at its own rate (never in the stream's way).

With an uncertainty — the scene's ``string.uncertainty``, or the covariance of the newest fit the
node applied (``fit.enabled``) — a timer at ``envelope.rate`` asks the solver thread for the
envelope of the newest published shape (``solver/results/envelope.py``: first order, from the KKT
sensitivities at the answer, no extra solve) through ``ShapeEngine.when_idle``: it runs only when
no target and no control job waits, so a target arriving meanwhile waits for at most one envelope.
An envelope of a shape the stream has already moved on from is unavailable and simply skipped.

Each envelope is published as a MarkerArray on ``~/envelope`` (a ``SPHERE_LIST`` per band of
equal radius would lose the per-point radius, so one translucent ``SPHERE`` per output point,
diameter 2 k σ(s), k = ``envelope.k``), summarised in the ``<node>: envelope`` diagnostics status,
and recorded (``Recorder.log_envelope``).
"""

from __future__ import annotations

import threading
from concurrent.futures import Future
from typing import Any, Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from visualization_msgs.msg import Marker, MarkerArray

from ..solver.results.envelope import Envelope, EnvelopeUnavailable, Uncertainty, envelope
from . import conversions as conv
from .engine import ShapeEngine, Update
from .qos import LATCHED_QOS
from .shape_outputs import ShapeOutputs
from .stream_log import StreamLog
from .validation import safe_text

NAMESPACE = "envelope"
RGBA = (1.0, 0.55, 0.1, 0.25)  # translucent orange: the cable stays visible inside


def tube_markers(
    spread: Envelope, k: float, frame_id: str, stamp_ns: int, ns: str = NAMESPACE
) -> MarkerArray:
    """Return the k-σ tube: a DELETEALL of ``ns``, then a SPHERE of diameter 2 k σ(s) per point."""
    head = conv.header(frame_id, stamp_ns)
    out = [Marker(header=head, ns=ns, action=Marker.DELETEALL)]
    r, g, b, a = RGBA
    for i, (p, sigma) in enumerate(zip(spread.points, spread.sigma)):
        m = Marker(header=head, ns=ns, id=i, type=Marker.SPHERE, action=Marker.ADD)
        m.pose = conv.arrays_to_pose(p, (0.0, 0.0, 0.0, 1.0))
        m.scale.x = m.scale.y = m.scale.z = max(2.0 * k * float(sigma), 1e-6)
        m.color.r, m.color.g, m.color.b, m.color.a = r, g, b, a
        out.append(m)
    return MarkerArray(markers=out)


def summary_values(spread: Envelope | EnvelopeUnavailable, k: float) -> dict[str, object]:
    """Return the diagnostics values of an envelope: its largest σ and each grip's σ."""
    if isinstance(spread, EnvelopeUnavailable):
        return {"available": False, "reason": spread.reason}
    values: dict[str, object] = {
        "available": True,
        "k": k,
        "max sigma m": spread.max_sigma,
        "parameters": ",".join(spread.names),
        "note": spread.note,
    }
    for name, g in spread.grips.items():  # component σ: the bounds are F ± k σ, T ± k σ
        values[f"{name} force N"] = _vector(g.force)
        values[f"{name} force sigma N"] = _vector(g.force_sigma)
        values[f"{name} tension sigma N"] = g.tension_sigma
        if g.torque_sigma is not None:
            values[f"{name} torque N m"] = _vector(g.torque)
            values[f"{name} torque sigma N m"] = _vector(g.torque_sigma)
    return values


def _vector(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{float(x):.6g}" for x in v) + "]"


class EnvelopePublisher:
    """Ask for, publish and report the newest shape's envelope (module docstring).

    ``uncertainty``: the scene's (None: nothing is computed until a fit gives one).  ``quiet()``:
    true while nothing may be published.
    """

    def __init__(
        self,
        node: Node,
        frame_id: str,
        links: tuple[ShapeEngine, ShapeOutputs, StreamLog],
        uncertainty: Uncertainty | None,
        quiet: Callable[[], bool],
    ) -> None:
        value = node.get_parameter
        self.node, self.frame_id, self.quiet = node, frame_id, quiet
        self.engine, self.outputs, self.log = links
        self.uncertainty = uncertainty
        self.k = float(value("envelope.k").value)
        self.latest: Envelope | EnvelopeUnavailable | None = None
        self.computed = 0  # envelopes computed (available or not)
        self._lock = threading.Lock()
        self._asked: Update | None = None  # the update whose envelope was asked for last
        self._pending: Future | None = None
        self._pub = node.create_publisher(MarkerArray, "~/envelope", LATCHED_QOS)
        rate = float(value("envelope.rate").value)
        self._timer = node.create_timer(1.0 / rate, self.tick) if rate > 0 else None

    def set_uncertainty(self, uncertainty: Uncertainty | None) -> None:
        """Use ``uncertainty`` from the next envelope on (a fit's covariance)."""
        with self._lock:
            self.uncertainty = uncertainty
            self._asked = None  # the newest shape again, with the new covariance

    def tick(self) -> None:
        """Ask for the newest shape's envelope when it changed and none is being computed."""
        with self._lock:
            u, uncertainty = self.outputs.latest, self.uncertainty
            busy = self._pending is not None and not self._pending.done()
            if u is None or uncertainty is None or busy or u is self._asked or self.quiet():
                return
            self._asked = u
            job = self.engine.when_idle(lambda solver: envelope(solver, u.result, uncertainty))
            self._pending = job
        job.add_done_callback(lambda f: self._done(f, u))

    def _done(self, job: Future, u: Update) -> None:
        """Publish, record and keep an envelope (solver thread)."""
        if job.cancelled() or self.quiet() or not self.node.context.ok():
            return
        error = job.exception()
        spread = (
            EnvelopeUnavailable(f"the envelope raised {type(error).__name__}: {error}")
            if error is not None
            else job.result()
        )
        self.computed += 1
        if isinstance(spread, EnvelopeUnavailable) and "committed equilibrium" in spread.reason:
            return  # the stream moved on before the solver was idle: the next tick asks again
        self.latest = spread
        stamp = u.stamp_ns or 0
        if isinstance(spread, Envelope):
            try:
                self._pub.publish(tube_markers(spread, self.k, self.frame_id, stamp))
            except Exception:  # noqa: BLE001 - the context was shut down under this envelope
                if self.node.context.ok():
                    raise
                return
            self.log.recorder.log_envelope(
                spread.points,
                self.k * spread.sigma,
                text=safe_text(self.text(spread)),
                update=self.log.update,
                ros_time_ns=stamp or None,
            )

    def text(self, spread: Envelope | EnvelopeUnavailable) -> str:
        """One line: the largest k σ and each grip's force σ, or why there is none."""
        if isinstance(spread, EnvelopeUnavailable):
            return f"no envelope: {spread.reason}"
        forces = ", ".join(
            f"{n} {np.linalg.norm(g.force_sigma):.3g} N" for n, g in spread.grips.items()
        )
        return (
            f"{self.k:g} sigma tube up to {self.k * spread.max_sigma:.3g} m; force sigma {forces}"
        )

    def status(self, hardware_id: str) -> DiagnosticStatus:
        """Build the ``<node>: envelope`` diagnostics status."""
        spread = self.latest
        name = f"{self.node.get_fully_qualified_name()}: envelope"
        if spread is None:
            why = "no uncertainty" if self.uncertainty is None else "not computed yet"
            return conv.diagnostic_status(name, "ok", why, hardware_id, {})
        values: dict[str, Any] = {
            k: safe_text(v, 2000) if isinstance(v, str) else v
            for k, v in summary_values(spread, self.k).items()
        }
        level = "ok" if isinstance(spread, Envelope) else "warn"
        return conv.diagnostic_status(
            name, level, safe_text(self.text(spread)), hardware_id, values
        )
