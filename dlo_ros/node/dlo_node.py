"""The `dlo` ROS 2 node: streams the predicted static shape of a cable for changing grip targets.

Interfaces (all documented in msg_docs/node.md):

  subscribes  ~/grips/<grip>/target  geometry_msgs/PoseStamped       one grip's target
              ~/grips/targets        geometry_msgs/PoseArray         all grips, configuration order
              ~/observed             sensor_msgs/PointCloud2         observed cable points
                                                                     (fit.enabled only)
  publishes   ~/centerline           nav_msgs/Path                   reliable, transient local
              ~/markers              visualization_msgs/MarkerArray
              ~/grips/<grip>/wrench  geometry_msgs/WrenchStamped
              /diagnostics           diagnostic_msgs/DiagnosticArray
  services    ~/query_shape          nav_msgs/srv/GetPlan            what-if query, never touches
                                                                     the stream
              ~/reset                std_srvs/srv/Trigger            forget the warm start,
                                                                     re-solve cold
              ~/fit                  std_srvs/srv/Trigger            identify the string from the
                                                                     newest cloud (fit.enabled)

Threads: the main single-threaded executor (timers, parameters, and the services as coroutines)
only checks inputs and hands them on; the target subscriptions have a small hidden node of their
own (``hot_path``), spun by an EventsExecutor in the target thread, which checks each target and
hands it straight to the engine's slot, so that a target never waits for the main executor's large
wait set.  The ShapeEngine's single worker thread runs every solve and publishes the centreline
and wrenches.  Markers are published by a timer from the latest shape.  Fits (``fit.enabled``) run
in their own worker process (fit_node.py).

The node's features live in their own modules: ``startup`` (parameters, scene, first problem),
``hot_path`` (the target thread), ``target_inputs``, ``shape_outputs``, ``diagnostics``,
``shape_services``, ``live_parameters``, ``stream_log`` (recording and model changes) and
``fit_node``.  :class:`DloCore` wires them to the engine and reports the engine's updates and
failures; :class:`DloNode` is the plain node that builds one at once, ``managed.ManagedDloNode``
the lifecycle node that builds it on ``configure``; ``run`` has the entry point.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import replace
from typing import Any

from rclpy.node import Node

from ..model.problem import Problem
from ..solver.options import SolverOptions
from .diagnostics import DiagnosticsPublisher
from .engine import ShapeEngine, Update, build_solver
from .fit_node import FitterLinks, NodeFitter
from .health import Health, model_text
from .hot_path import HotPath
from .envelope_publisher import EnvelopePublisher
from . import params as P
from .live_parameters import LiveParameters
from .planning_scene_publisher import PlanningScenePublisher
from .shape_outputs import ShapeOutputs
from .shape_services import ShapeServices
from .startup import StartupError, prepare, start_recorder
from .stream_log import StreamLog
from .target_inputs import PoseReader, TargetInputs
from .tf_grip_targets import TfGripTargets
from .validation import TEXT_LIMIT, safe_text

NODE_NAME = "dlo"

__all__ = ["DloCore", "DloNode", "NODE_NAME", "StartupError"]


class DloNode(Node):
    """The plain (unmanaged) dlo node: a ``DloCore`` built and active from the constructor.

    Keyword arguments go to rclpy.node.Node (context, namespace, ...).  Raises StartupError for an
    unusable scene or parameter.  ``managed.ManagedDloNode`` is the lifecycle alternative.
    """

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.core = DloCore(self)

    def close(self, timeout: float = 10.0) -> bool:
        """Stop the core's workers and engine; return whether the solver thread ended in time."""
        return self.core.close(timeout)


class DloCore:
    """The dlo node's parts on ``node`` and the engine's callbacks (module docstring).

    Built on a plain node (``DloNode``) or by a managed node's ``configure`` (``active=False``:
    shapes are solved and held, but neither published nor are targets accepted until
    ``activate``).  Raises StartupError for an unusable scene or parameter.
    """

    def __init__(self, node: Node, *, active: bool = True, recording: int = 1) -> None:
        self.node = node
        self.closing = False
        self.active = active  # a managed node's lifecycle state is 'active'
        # held while a shape is published and kept, and while the lifecycle state changes: an
        # activation then republishes the newest shape, never one older than a concurrent update
        self._gate = threading.Lock()
        settings = prepare(node)
        scene, problem, options = settings.scene, settings.problem, settings.options
        self.scene = scene
        self.frame_id = settings.frame_id
        self.grip_names = settings.grip_names
        self.compile_mode = settings.compile_mode
        self.health = Health(
            scene=safe_text(scene.name),
            frame_id=safe_text(self.frame_id),
            grips=tuple(safe_text(n) for n in self.grip_names),
            throttle_s=self.node.get_parameter("warn_throttle").value,
        )
        # the recorded scene is the effective one (parameters applied), so that `dlo replay
        # --resolve` repeats the node's solves
        effective = replace(scene, problem=problem, options=options)
        self.stream_log = StreamLog(effective, self.health, self.node.get_logger())
        self.engine = ShapeEngine(
            problem,
            options,
            make_solver=self._make_solver,
            on_update=self._on_update,
            on_failure=self._on_failure,
            on_state=self._on_state,
        )
        try:
            self._add_interfaces(problem)
            self.stream_log.recorder = start_recorder(
                node, self.stream_log.scene, self.frame_id, recording
            )  # the last check
            self.shape_services.start_workers()  # replaces a dead or stuck worker
        except BaseException:  # undo what would outlive a failed start (a managed node's)
            if getattr(self, "hot", None) is not None:
                self.hot.close(1.0)
            if getattr(self, "live", None) is not None:
                self.live.close()
            fitter = getattr(self, "fitter", None)
            if fitter is not None:
                fitter.close(1.0)
            if getattr(self, "shape_services", None) is not None:
                self.shape_services.close(1.0)
            raise
        self.node.get_logger().info(
            f"scene '{safe_text(scene.name)}' ({safe_text(scene.source)}): grips "
            f"{self.grip_names}, {len(problem.obstacles)} obstacle(s), frame "
            f"'{safe_text(self.frame_id)}'; building the solver"
        )
        self._t_start = time.monotonic()
        self.engine.start()
        # last: a target needs the recorder and the engine, and the thread must not outlive a
        # failed start
        self.hot.start()

    def _add_interfaces(self, problem: Problem) -> None:
        """Create the node's publishers, subscriptions, services, timers and fitter."""
        closing = self.is_closing
        self.outputs = ShapeOutputs(self.node, self.frame_id, self.grip_names, self.is_quiet)
        self.planning_scene: PlanningScenePublisher | None = None
        if self.node.get_parameter("planning_scene.enabled").value:
            self.planning_scene = PlanningScenePublisher(
                self.node,
                self.frame_id,
                self.outputs,
                self.is_quiet,
                float(self.node.get_parameter("warn_throttle").value),
            )
        self.diagnostics = DiagnosticsPublisher(
            self.node, self.health, self.engine, safe_text(self.scene.name), closing
        )
        self.envelope = EnvelopePublisher(
            self.node,
            self.frame_id,
            (self.engine, self.outputs, self.stream_log),
            self.scene.uncertainty,
            self.is_quiet,
        )
        self.diagnostics.extra.append(self.envelope.status)
        poses = PoseReader(self.node, self.frame_id, bool(self.node.get_parameter("use_tf").value))
        self.hot = HotPath(self.node)
        self.inputs = TargetInputs(
            self.node,
            self.hot,
            poses,
            self.grip_names,
            self.engine,
            self.stream_log,
            self.health,
            self.diagnostics.publish,
            self.refusal,
        )
        frames = {g: self.node.get_parameter(P.grip_tf_frame(g)).value for g in self.grip_names}
        self.tf_targets = None
        if any(frames.values()):
            self.tf_targets = TfGripTargets(
                self.node,
                {g: f for g, f in frames.items() if f},
                poses.frame_pose,
                self.inputs,
                float(self.node.get_parameter("tf_targets.rate").value),
            )
        self.shape_services = ShapeServices(
            self.node,
            poses,
            self.grip_names,
            self.engine,
            self.health,
            self.worker_compile,
            self.refusal,
        )
        self.live = LiveParameters(
            self.node, problem, self.engine, self.stream_log, self.health, self.outputs, closing
        )
        self.fitter: NodeFitter | None = None
        if self.node.get_parameter("fit.enabled").value:
            self.fitter = NodeFitter(
                FitterLinks(
                    node=self.node,
                    frame_id=self.frame_id,
                    engine=self.engine,
                    health=self.health,
                    log=self.stream_log,
                    string_now=lambda: self.live.string,
                    worker_compile=self.worker_compile,
                    closing=closing,
                    publish_diagnostics=self.diagnostics.publish,
                    on_uncertainty=self.envelope.set_uncertainty,
                    refusal=self.refusal,
                )
            )
            self.diagnostics.extra.append(self.fitter.status)

    def is_closing(self) -> bool:
        """Return whether the node is shutting down (``close`` was called)."""
        return self.closing

    def is_quiet(self) -> bool:
        """Return whether no shape may be published now: closing, or a managed node inactive."""
        return self.closing or not self.active

    def refusal(self) -> str:
        """Return why targets and services are refused now; '' while active."""
        if self.active:
            return ""
        return (
            "the node is inactive (lifecycle state 'inactive'): targets and queries are refused "
            "until it is activated"
        )

    def activate(self) -> None:
        """Accept targets and publish shapes; publish the newest shape (solved while inactive)."""
        with self._gate:
            self.active = True
            self.outputs.republish()
        self.health.set_lifecycle("active")
        self.diagnostics.publish(immediate=True)

    def deactivate(self) -> None:
        """Refuse targets and queries; withdraw the capsules; the centreline stays latched."""
        with self._gate:
            self.active = False
        self.withdraw()
        self.health.set_lifecycle("inactive")
        self.diagnostics.publish(immediate=True)

    def withdraw(self) -> None:
        """Take the cable out of planning scenes (a managed node deactivated or cleaned up)."""
        if self.planning_scene is not None:
            self.planning_scene.withdraw()

    @property
    def worker_compile(self) -> str:
        """Return the compile mode of worker processes: compiled derivatives from the cache only.

        Query and fit workers never start gcc ('off' stays 'off').
        """
        return "off" if self.compile_mode == "off" else "cached"

    def _make_solver(self, problem: Problem, options: SolverOptions) -> Any:
        """Build the engine's solver (solver thread); a new solver has a new model history."""
        t0 = time.monotonic()
        solver = build_solver(problem, options, compile=self.compile_mode)
        self.stream_log.new_solver()
        self.node.get_logger().info(
            f"solver ready in {time.monotonic() - t0:.1f} s (compile: {self.compile_mode}, "
            f"solver.model: {options.model})"
        )
        return solver

    # ---- the engine's callbacks (solver thread) -------------------------------------------------
    def _on_state(self, state: str) -> None:
        state = safe_text(state)
        self.health.set_state(state)
        if state.startswith("failed"):
            self.node.get_logger().error(f"solver: {state}")
        self.diagnostics.publish(immediate=True)

    def _on_update(self, u: Update) -> None:
        if self.closing:
            return
        try:
            self._publish_update(u)
        except Exception:
            if self._stopping():  # SIGINT shut the context down under this update: drop it
                return
            raise

    def _stopping(self) -> bool:
        """Return whether the node is closing, or its context was shut down.

        A signal reaches rclpy's handler before ``close``; an update in flight then finds its
        publishers invalid.
        """
        return self.closing or not self.node.context.ok()

    def _publish_update(self, u: Update) -> None:
        r = u.result
        stamp = u.stamp_ns if u.stamp_ns else self.node.get_clock().now().nanoseconds
        with self._gate:  # the shape first: bookkeeping need not delay it
            if self.active:
                self.outputs.publish_shape(u, stamp)
            self.outputs.hold(u, stamp)
        model_changed = self.stream_log.record_update(u, stamp)
        latency = None if u.received_ns is None else (time.monotonic_ns() - u.received_ns) / 1e6
        self.health.set_targets(self.engine.targets_received, self.engine.targets_coalesced)
        was_error = self.health.newest_is_error or self.health.updates == 0
        self.health.update(r, u.trigger, latency)
        if self.health.updates == 1:
            self.node.get_logger().info(
                f"first shape {'published' if self.active else 'solved (published when active)'} "
                f"{time.monotonic() - self._t_start:.1f} s after start "
                f"({r.status}, stable={r.stable}; model "
                f"{model_text(r.model_dict()) or 'not reported'})"
            )
            # the workers build their solvers after the node's own first shape, so that they do
            # not compete with its start-up for the cores
            if self.fitter is not None:
                self.fitter.warm()
            self.shape_services.warm_workers()
        if r.stable is False and self.health.should_warn("unstable"):
            self.node.get_logger().warning(
                f"the published equilibrium is unstable (min eigenvalue {r.min_eigenvalue:.3g}): "
                "the cable would not stay in this shape"
            )
        if was_error or model_changed:
            self.diagnostics.publish(immediate=True)

    def _on_failure(self, kind: str, message: str, u: Update | None) -> None:
        if self._stopping():
            return
        if u is not None:
            self.stream_log.record_update(
                u, u.stamp_ns if u.stamp_ns else self.node.get_clock().now().nanoseconds
            )
        self.health.set_targets(self.engine.targets_received, self.engine.targets_coalesced)
        first_line = safe_text(message.splitlines()[0] if message else kind)
        if self.health.error(kind, first_line, rejected=False):
            if kind == "internal":  # with its traceback, escaped into one line (a bug report)
                self.node.get_logger().error(
                    f"solver error: {safe_text(message, 20 * TEXT_LIMIT)}"
                )
            else:
                self.node.get_logger().warning(
                    f"no equilibrium ({kind}): {first_line}; the last good shape stays published"
                )
        self.diagnostics.publish(immediate=True)

    # ---- shutdown -------------------------------------------------------------------------------
    def close(self, timeout: float = 10.0) -> bool:
        """Stop the target thread, the workers and the engine (after the solve in progress).

        Returns whether the solver thread and the target thread ended within ``timeout`` [s].
        """
        self.closing = True
        hot_stopped = self.hot.close(timeout)  # first: no target reaches the engine any more
        self.live.close()
        self.shape_services.close(timeout)
        if self.fitter is not None:
            self.fitter.close(timeout)
        stopped = self.engine.stop(timeout)
        try:
            self.stream_log.recorder.close(
                timeout
            )  # bounded: the recording file is complete afterwards
        except Exception as exc:  # noqa: BLE001 - shutdown must go on
            print(f"dlo_node: warning: closing the recording failed: {exc}", file=sys.stderr)
        if not hot_stopped:
            print(
                f"dlo_node: warning: the target thread did not stop within {timeout:g} s",
                file=sys.stderr,
            )
        return stopped and hot_stopped
