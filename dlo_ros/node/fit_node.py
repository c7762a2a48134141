"""The node's identification: ``~/observed``, ``~/fit`` and the ``<node>: fit`` status.

Present when ``fit.enabled`` (msg_docs/node.md "Fitting").

Threads: every callback here runs in the node's executor thread, and only checks, copies and hands
over.  A fit runs in its own worker process (one, spawned at start-up, kept; its own equilibrium
solvers), never in the solver thread, so the stream keeps publishing meanwhile.  When the worker is
done, a guard condition wakes the executor, which applies the estimate through the node's own
parameter path (``set_parameters_atomically``: the same checks and re-solve as ``ros2 param set``),
logs it, records it and reports it.  One fit at a time: ``~/fit`` answers at once, ``success`` true
when a fit started (its outcome goes to the diagnostics, the log and the recording), false with the
reason when one is already running, no cloud has arrived or the solver is not built yet.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

from ..identify.objective import FitSettings
from ..model.problem import StringProperties
from ..solver.results.uncertainty import Uncertainty
from ..solver.parallel.worker_pool import process_pool, stop_pool
from . import conversions as conv
from . import params as P
from .cloud import cloud_bytes_limit, cloud_points
from .engine import ShapeEngine
from .fitting import (
    Application,
    CloudSnapshot,
    FitConfig,
    FitHealth,
    fit_payload,
    plan_application,
    run_fit,
)
from .health import Health
from .qos import CLOUD_QOS
from .stream_log import StreamLog
from .validation import TargetError, safe_text


@dataclass(frozen=True)
class FitterLinks:
    """What a NodeFitter uses of its node, besides rclpy's public Node API on ``node``.

    ``node``: parameters, logger, clock, entities and ``set_parameters_atomically`` (an estimate is
    applied through the node's own parameter checks).  ``engine``: the targets, the solver's scene
    and its state.  ``health``: the node's warning throttle.  ``log``: the recorder and the update
    number.  ``string_now()``: the string's properties as the parameters hold them now.
    ``worker_compile``: the compile mode of worker processes.  ``closing()``: true once the node is
    shutting down.  ``publish_diagnostics(immediate)``: publish the node's statuses.
    ``on_uncertainty(u)``: gets the covariance of each fit the node applied (the envelope's).
    ``refusal()``: why fits are refused now ('' = allowed): a managed node that is not active.
    """

    node: Node
    frame_id: str
    engine: ShapeEngine
    health: Health
    log: StreamLog
    string_now: Callable[[], StringProperties]
    worker_compile: str
    closing: Callable[[], bool]
    publish_diagnostics: Callable[[bool], None]
    on_uncertainty: Callable[[Uncertainty], None] = lambda u: None
    refusal: Callable[[], str] = lambda: ""


def warm_fit_worker() -> bool:
    """Import the fit's modules (CasADi) in the fit worker before the first fit asks for them.

    Runs in the worker process; a function-local import, as importing is its whole job.
    """
    # not at the top: importing (it loads CasADi) is this function's whole job
    import dlo_ros.identify.fit  # noqa: F401 - imported for its side effect

    return True


class NodeFitter:
    """Serve ``~/observed``, ``~/fit`` and the continuous fit timer; see the module docstring.

    ``links``: what it uses of the node (:class:`FitterLinks`).
    """

    def __init__(self, links: FitterLinks) -> None:
        node = links.node
        self.links = links
        self.node = node
        self.health = FitHealth()
        self.max_points = int(node.get_parameter("fit.max_points").value)
        self._latest: CloudSnapshot | None = None
        self._running: CloudSnapshot | None = None
        self._last_fitted = 0  # number of the newest cloud a fit started on
        self._done: list[tuple[Future, CloudSnapshot, FitConfig]] = []
        self._done_lock = threading.Lock()
        self._pool = process_pool(1, background=True)
        self._wake = node.create_guard_condition(self._on_fit_done)
        self._sub = node.create_subscription(
            PointCloud2, "~/observed", self._on_cloud, CLOUD_QOS, raw=True
        )
        self._srv = node.create_service(Trigger, "~/fit", self._on_fit)
        period = float(node.get_parameter("fit.period_s").value)
        self._timer = node.create_timer(period, self._on_timer) if period > 0 else None

    # ---- inputs (executor thread) ---------------------------------------------------------------
    def _on_cloud(self, data: bytes) -> None:
        where = "observed"
        node = self.node
        try:
            limit = cloud_bytes_limit(self.max_points)
            if len(data) > limit:
                raise TargetError(
                    "size",
                    f"{where}: message of {len(data)} bytes is over the limit of {limit} bytes "
                    f"(fit.max_points {self.max_points} × {limit // self.max_points} bytes); "
                    "it was not read",
                )
            try:
                msg = deserialize_message(data, PointCloud2)
            except Exception as exc:  # noqa: BLE001 - a malformed buffer is bad input, not a bug
                raise TargetError(
                    "invalid", f"{where}: not a readable PointCloud2 ({type(exc).__name__})"
                ) from None
            points = cloud_points(msg, self.links.frame_id, self.max_points, where)
        except TargetError as exc:
            self._reject(exc)
            return
        stamp = conv.time_to_ns(msg.header.stamp) or node.get_clock().now().nanoseconds
        number = self.health.clouds_received + 1
        self._latest = CloudSnapshot(points, self.links.engine.targets(), stamp, number)
        self.health.cloud(len(points), stamp)

    def _reject(self, exc: TargetError) -> None:
        node, log = self.node, self.links.log
        text = safe_text(exc)
        self.health.rejected(f"{exc.kind}: {text}")
        log.recorder.log_rejected(
            f"{exc.kind}: {text}",
            update=log.update,
            ros_time_ns=node.get_clock().now().nanoseconds,
        )
        if self.links.health.should_warn(f"observed:{exc.kind}"):
            node.get_logger().warning(
                f"rejected observed cloud ({exc.kind}): {text}; no fit uses it (the stream "
                "is unaffected)"
            )
        self.links.publish_diagnostics(True)

    def _on_fit(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        refused = self.links.refusal()
        if refused:  # a fit would change the string of a node that is not active
            response.success, response.message = False, refused
            return response
        response.success, response.message = self.start(self._latest)
        return response

    def _on_timer(self) -> None:
        latest = self._latest
        if self.links.refusal():
            return
        if latest is not None and latest.number > self._last_fitted and self._running is None:
            ok, message = self.start(latest)
            if not ok and self.links.health.should_warn("fit:continuous"):
                self.node.get_logger().warning(f"continuous fit: {message}")

    # ---- a fit ----------------------------------------------------------------------------------
    def config(self) -> FitConfig:
        """Read the fit's settings from the ``fit.*`` parameters now."""
        g = self.node.get_parameter
        return FitConfig(
            parameters=tuple(g("fit.parameters").value),
            point_sigma=float(g("fit.point_sigma").value),
            total_mass=float(g("fit.total_mass").value),
            apply_max_rel_sigma=float(g("fit.apply_max_rel_sigma").value),
            max_iterations=int(g("fit.max_iterations").value),
            compile=self.links.worker_compile,
        )

    def start(self, snapshot: CloudSnapshot | None) -> tuple[bool, str]:
        """Start a fit of ``snapshot`` in the worker process (executor thread).

        Returns (whether it started, the message that says what or why not).
        """
        if self._running is not None:
            return (
                False,
                f"busy: the fit of cloud {self._running.number} is running; try again when it "
                "is done",
            )
        if snapshot is None:
            return (
                False,
                "no cloud received on ~/observed yet (or every one was rejected: see the "
                "diagnostics)",
            )
        scene = self.links.engine.query_scene()
        if scene is None:
            return False, f"the solver is not ready ({self.links.engine.state})"
        problem, options = scene
        # the string as the node's parameters hold it now (the solver thread may not have applied a
        # change made just before): the fit starts there, and plan_application compares with the
        # same values
        problem = replace(problem, string=self.links.string_now())
        config = self.config()
        payload = fit_payload(problem, options, snapshot, config)
        try:
            job = self._pool.submit(run_fit, payload)
        except BrokenProcessPool:  # the worker died while idle (e.g. killed): a new one
            self.node.get_logger().warning("the fit worker process had died; starting a new one")
            self._new_pool()
            job = self._pool.submit(run_fit, payload)
        self._running, self._last_fitted = snapshot, snapshot.number
        self.health.started()
        job.add_done_callback(lambda f: self._finished(f, snapshot, config))
        message = (
            f"fitting {', '.join(config.parameters)} to cloud {snapshot.number} "
            f"({len(snapshot.points)} points, σ {config.point_sigma:g} m); the estimate goes to "
            f"/diagnostics ('{self.node.get_fully_qualified_name()}: fit') and is applied if its "
            "relative σ <= fit.apply_max_rel_sigma"
        )
        self.node.get_logger().info(message)
        self.links.publish_diagnostics(True)
        return True, message

    def _finished(self, job: Future, snapshot: CloudSnapshot, config: FitConfig) -> None:
        """Hand the finished fit to the executor thread (runs in the pool's thread)."""
        with self._done_lock:
            self._done.append((job, snapshot, config))
        if not self.links.closing():
            self._wake.trigger()

    def _on_fit_done(self) -> None:
        with self._done_lock:
            done, self._done = self._done, []
        for job, snapshot, config in done:
            self._running = None
            if job.cancelled() or self.links.closing():
                continue
            self._report(job, snapshot, config)

    def _report(self, job: Future, snapshot: CloudSnapshot, config: FitConfig) -> None:
        """Apply (if σ allows), log, record and report one finished fit (executor thread)."""
        node = self.node
        try:
            result, error = job.result(timeout=0), ""
        # any exception: ObservationError (a request the scene cannot fit) or a worker crash
        except Exception as exc:
            result, error = None, safe_text(f"{type(exc).__name__}: {exc}")
            if isinstance(
                exc, BrokenProcessPool
            ):  # e.g. a crash inside IPOPT: the next fit gets a new worker
                error += " (the fit worker process died; the next fit starts a new one)"
                self._new_pool()
        application = None
        if result is not None:
            current = {n: float(node.get_parameter(n).value) for n in P.STRING_FIELDS}
            application = plan_application(result, current, config.apply_max_rel_sigma)
            if application.applied:
                application = self._apply(application)
            if application.applied and result.ok:
                try:
                    self.links.on_uncertainty(result.uncertainty())
                except ValueError:  # nothing fitted with a covariance: the envelope keeps its own
                    pass
        self.health.finished(result, snapshot, application, error)
        text = self._summary(snapshot, result, error, application)
        ok = result is not None and result.ok
        if ok:
            node.get_logger().info(text)
        else:
            node.get_logger().warning(text)
        fitted = result.observations[0] if result is not None and result.observations else None
        self.links.log.recorder.log_fit(
            snapshot.points,
            fitted.shape if fitted else [],
            fitted.feet if fitted else [],
            sigma=config.point_sigma,
            huber=FitSettings().huber,
            text=text,
            ok=ok,
            update=self.links.log.update,
            ros_time_ns=snapshot.stamp_ns,
        )
        self.links.publish_diagnostics(True)

    def _apply(self, application: Application) -> Application:
        """Set the parameters of ``application`` at once, through the node's parameter checks."""
        node = self.node
        result = node.set_parameters_atomically(
            [Parameter(n, value=v) for n, v in application.values.items()]
        )
        if not result.successful:
            return Application(
                {},
                f"not applied: the node refused {sorted(application.values)}: "
                f"{safe_text(result.reason)} ({application.reason})",
            )
        return application

    @staticmethod
    def _summary(
        snapshot: CloudSnapshot, result: Any, error: str, application: Application | None
    ) -> str:
        """Summarise one fit in a line: its estimates, fit quality and what was applied."""
        head = f"fit of cloud {snapshot.number} ({len(snapshot.points)} points)"
        if result is None:
            return f"{head}: failed: {error}"
        parts = [
            f"{name} = {est.value:.6g} ± {est.std:.2g} {est.unit}"
            for name, est in {**result.parameters, **result.ratios}.items()
        ]
        if result.not_identifiable:
            parts.append(f"not identifiable: {', '.join(result.not_identifiable)}")
        rms = f", rms {result.observations[0].rms_m * 1e3:.3g} mm" if result.observations else ""
        return (
            f"{head}: {result.status} ({result.message}) in {result.time_s:.2f} s, "
            f"{result.equilibrium_solves} solves{rms}: {'; '.join(parts) or 'no estimate'}; "
            f"{application.reason if application else ''}"
        )

    # ---- diagnostics, warm-up, shutdown ---------------------------------------------------------
    def status(self, hardware_id: str) -> DiagnosticStatus:
        """Build the ``<node>: fit`` diagnostics status."""
        level, message = self.health.level_and_message()
        values = {
            k: safe_text(v, 2000) if isinstance(v, str) else v
            for k, v in self.health.values().items()
        }
        return conv.diagnostic_status(
            f"{self.node.get_fully_qualified_name()}: fit",
            level,
            safe_text(message, 2000),
            hardware_id,
            values,
        )

    def warm(self) -> None:
        """Start the worker process and its imports now (after the node's first shape)."""
        self._pool.submit(warm_fit_worker)

    def _new_pool(self) -> None:
        stop_pool(self._pool, 1.0)
        self._pool = process_pool(1, background=True)

    def close(self, timeout: float) -> None:
        """Stop the fit worker process (bounded by ``timeout`` [s])."""
        stop_pool(self._pool, timeout)
