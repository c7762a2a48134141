"""The `dlo` ROS 2 node: streams the predicted static shape of a cable for changing grip targets.

Interfaces (all documented in msg_docs/node.md):
  subscribes  ~/grips/<grip>/target  geometry_msgs/PoseStamped   one grip's target
              ~/grips/targets        geometry_msgs/PoseArray     all grips at once, configuration
              order ~/observed             sensor_msgs/PointCloud2     observed cable points
              (fit.enabled only)
  publishes   ~/centerline           nav_msgs/Path               reliable, transient local
              ~/markers              visualization_msgs/MarkerArray
              ~/grips/<grip>/wrench  geometry_msgs/WrenchStamped
              /diagnostics           diagnostic_msgs/DiagnosticArray
  services    ~/query_shape          nav_msgs/srv/GetPlan        what-if query, never touches the
  stream
              ~/reset                std_srvs/srv/Trigger        forget the warm start, re-solve
              cold ~/fit                  std_srvs/srv/Trigger        identify the string from the
              newest cloud
                                                                 (fit.enabled only; fit_node.py)

Threads: a single-threaded executor (subscriptions, timers, parameters, and the services as
coroutines) only checks inputs and hands them to the ShapeEngine's single worker thread, which runs
every solve and publishes the centreline and wrenches.  Markers are published by a 10 Hz timer from
the latest shape.  Fits (``fit.enabled``) run in their own worker process (fit_node.py).
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import threading
import time
from concurrent.futures import Future
from dataclasses import fields, replace

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future as RclpyFuture
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from ..model.problem import GripPose, Problem
from ..text import one_line_warnings
from . import conversions as conv
from . import params as P
from . import query_reply
from .engine import ShapeEngine, Update, build_solver, target_miss, options_with_output_points
from .signals import exit_on_second_signal, node_starting, terminate_children
from .health import Health, model_text, new_model_changes
from .validation import (
    TEXT_LIMIT,
    TargetError,
    check_count,
    check_frame_size,
    check_message_size,
    check_pose,
    normalise_frame,
    safe_text,
)

try:  # optional: not on PyPI; present in a full ROS installation
    import tf2_ros  # type: ignore
except ImportError:  # pragma: no cover - depends on the installation
    tf2_ros = None

NODE_NAME = "dlo"
TARGET_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
WRENCH_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: ~/observed: sensors publish clouds best effort (rclpy's qos_profile_sensor_data); a best-effort
# reader : matches both best-effort and reliable writers.  Only the newest cloud matters.
CLOUD_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
STOP_TIMEOUT_S = 5.0  # how long shutdown waits for the solve in progress
QUERIES_PER_WORKER = (
    2  # ~/query_shape calls pending per query worker before new ones are refused ("busy")
)
IMMEDIATE_DIAGNOSTICS_MIN_S = 0.1
_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_KINDS = {
    "string": ParameterType.PARAMETER_STRING,
    "bool": ParameterType.PARAMETER_BOOL,
    "integer": ParameterType.PARAMETER_INTEGER,
    "double": ParameterType.PARAMETER_DOUBLE,
    "string_array": ParameterType.PARAMETER_STRING_ARRAY,
}


class StartupError(Exception):
    """The node cannot start (bad scene or parameters); the message says why.  main() exits with
    2.
    """


def _descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(
        name=spec.name,
        type=_KINDS[spec.kind],
        description=spec.description,
        read_only=spec.read_only,
        additional_constraints=spec.constraints,
        dynamic_typing=spec.dynamic,
    )
    if spec.low is not None and spec.kind == "double":
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
        ]
    if spec.low is not None and spec.kind == "integer":
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    return d


class DloNode(Node):
    """See the module docstring.  Keyword arguments go to rclpy.node.Node (context, namespace,
    ...).
    """

    def __init__(self, node_name: str = NODE_NAME, **kwargs):
        super().__init__(node_name, **kwargs)
        self._closing = False
        self._declare(P.STATIC[:-1])
        self._declare(P.FIT)
        scene = self._load_scene(self.get_parameter("scene").value)
        self.scene = scene
        frame_param = self.get_parameter("frame_id").value
        reason = P.check_value(
            "frame_id", frame_param
        )  # also checked before rclpy (params.prepare_node_args)
        if reason:
            raise StartupError(f"parameter frame_id: {reason}")
        self.frame_id = normalise_frame(frame_param or scene.frame_id or "world")
        if not self.frame_id.strip("/") or P.check_value("frame_id", self.frame_id):
            raise StartupError(
                f"scene frame_id '{safe_text(scene.frame_id, 60)}' ({safe_text(scene.source)}) is not a "
                "usable frame id; set the parameter frame_id"
            )
        self.grip_names = [g.name for g in scene.problem.grips]
        for name in self.grip_names:
            if not _TOKEN.match(name):
                raise StartupError(
                    f"grip name '{safe_text(name, 60)}' cannot be used in a topic name (letters, "
                    "digits, '_'; not starting with a digit)"
                )

        defaults = P.scene_values(scene.problem, scene.options.output_points)
        self.declare_parameter(
            "grip_names",
            defaults["grip_names"],
            _descriptor(P.SPECS["grip_names"]),
            ignore_override=True,
        )
        self._declare([replace(s, default=defaults.get(s.name, s.default)) for s in P.LIVE])
        problem, options = self._initial_problem(scene)
        self._check_problem = (
            problem  # the problem parameter checks run against (string props applied)
        )
        # rerun recording (record.rrd / record.connect; off when both are empty).  The recorded
        # scene is the effective one (parameters applied), so that `dlo replay --resolve` repeats
        # the node's solves.
        self._record_scene = replace(scene, problem=problem, options=options)
        self._record_n = (
            0  # update counter of the recording: one per streaming solve (ok or failed)
        )
        self._record_last: Update | None = None
        self.recorder = None
        self._model_changes_seen = (
            0  # len(ShapeResult.model.changes) of the current solver, seen so far
        )
        self._tolerance_warned = False

        self.health = Health(
            scene=safe_text(scene.name),
            frame_id=safe_text(self.frame_id),
            grips=tuple(safe_text(n) for n in self.grip_names),
            throttle_s=self.get_parameter("warn_throttle").value,
        )
        self._diag_lock = threading.Lock()
        self._last_immediate_diag = 0.0
        self._latest: Update | None = None  # newest published streaming update (markers timer)
        self._markers_dirty = False
        self._latest_lock = threading.Lock()

        try:
            self.compile_mode = P.compile_mode(self.get_parameter("compile").value)
        except ValueError as exc:
            raise StartupError(f"parameter {exc}") from None
        if self.compile_mode == "off":
            os.environ["DLO_NO_COMPILE"] = (
                "1"  # read by dlo_ros.solver.build.compiled (this process only)
            )

        self._tf_buffer = None
        if self.get_parameter("use_tf").value and tf2_ros is not None:
            self._tf_buffer = tf2_ros.Buffer()
            self._tf_listener = tf2_ros.TransformListener(self._tf_buffer, self)

        # ---- interfaces ------------------------------------------------------------------------------------
        self._path_pub = self.create_publisher(Path, "~/centerline", LATCHED_QOS)
        self._marker_pub = self.create_publisher(MarkerArray, "~/markers", LATCHED_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self._wrench_pubs = {
            n: self.create_publisher(WrenchStamped, f"~/grips/{n}/wrench", WRENCH_QOS)
            for n in self.grip_names
        }
        # raw (serialised) targets: a message is refused by its size before rclpy builds Python
        # objects from it (a huge PoseArray costs seconds and memory to deserialise)
        self._target_subs = [
            self.create_subscription(
                PoseStamped,
                f"~/grips/{n}/target",
                lambda data, n=n: self._on_grip_target(n, data),
                TARGET_QOS,
                raw=True,
            )
            for n in self.grip_names
        ]
        self._targets_sub = self.create_subscription(
            PoseArray, "~/grips/targets", self._on_targets, TARGET_QOS, raw=True
        )
        # The services are coroutines that await the solver thread.  They get their own callback
        # group: a pending coroutine keeps its group busy, and the default (mutually exclusive)
        # group must stay free for the subscriptions, timers and parameter services meanwhile.
        services = MutuallyExclusiveCallbackGroup()
        # queries answered by worker processes may be pending side by side (up to
        # QUERIES_PER_WORKER each)
        self._query_workers = int(self.get_parameter("query_workers").value)
        queries = ReentrantCallbackGroup() if self._query_workers else services
        self._query_srv = self.create_service(
            GetPlan, "~/query_shape", self._on_query, callback_group=queries
        )
        self._reset_srv = self.create_service(
            Trigger, "~/reset", self._on_reset, callback_group=services
        )
        self._diag_timer = self.create_timer(
            self.get_parameter("diagnostics_period").value, lambda: self._publish_diagnostics()
        )
        self._marker_timer = self.create_timer(
            self.get_parameter("markers_period").value, self._publish_markers
        )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self._fitter = None
        if self.get_parameter("fit.enabled").value:
            from .fit_node import NodeFitter

            self._fitter = NodeFitter(self)

        self.recorder = self._start_recorder()  # last start-up check: nothing can fail after it
        self.engine = ShapeEngine(
            problem,
            options,
            make_solver=self._make_solver,
            on_update=self._on_update,
            on_failure=self._on_failure,
            on_state=self._on_state,
        )
        self._queries_pending = 0
        self._query_pool = None
        if self._query_workers:
            from ..solver.parallel.worker_pool import (
                WorkerPool,
            )  # replaces a dead or stuck worker; dies with the node

            self._query_pool = WorkerPool(self._query_workers, background=True)
        self.get_logger().info(
            f"scene '{safe_text(scene.name)}' ({safe_text(scene.source)}): grips {self.grip_names}, "
            f"{len(problem.obstacles)} obstacle(s), frame '{safe_text(self.frame_id)}'; building the solver"
        )
        self._t_start = time.monotonic()
        self.engine.start()

    # ---- start-up -----------------------------------------------------------------------------------------
    def _declare(self, specs) -> None:
        for spec in specs:
            try:
                self.declare_parameter(spec.name, spec.default, _descriptor(spec))
            except ParameterException as exc:  # wrong type or out of range in the params file / -p
                raise StartupError(f"parameter {spec.name}: {safe_text(exc, 500)}") from None

    def _start_recorder(self):
        from ..recording import Recorder, RecordingUnavailable

        rrd = self.get_parameter("record.rrd").value or None
        connect = self.get_parameter("record.connect").value or None
        try:
            recorder = Recorder(rrd=rrd, connect=connect)
        except (RecordingUnavailable, ValueError, RuntimeError, OSError) as exc:
            raise StartupError(
                f"parameters record.rrd='{safe_text(rrd or '')}' / record.connect='{safe_text(connect or '')}': "
                f"{safe_text(exc, 500)}"
            ) from None
        if recorder.enabled:
            try:
                recorder.log_scene(self._record_scene, frame_id=self.frame_id)
            except Exception:
                recorder.close()
                raise
            where = " and ".join(
                x for x in (str(recorder.rrd) if recorder.rrd else "", recorder.url or "") if x
            )
            self.get_logger().info(f"recording to {safe_text(where)}")
        return recorder

    def _load_scene(self, name: str):
        from ..scene import (
            SceneError,
            load_scene,
        )  # lazy: the scene module is optional for imports

        try:
            return load_scene(name)
        except (SceneError, FileNotFoundError, OSError) as exc:
            raise StartupError(
                f"parameter scene='{safe_text(name)}': {safe_text(exc, 1000)}"
            ) from None

    def _initial_problem(self, scene):
        values = {name: self.get_parameter(name).value for name in P.STRING_FIELDS}
        try:
            string = P.apply_string(scene.problem.string, values)
            problem = replace(scene.problem, string=string)
            problem.validate()
            options = options_with_output_points(
                scene.options, self.get_parameter("output_points").value
            )
            model = self.get_parameter("solver.model").value
            if model:
                if "model" not in {f.name for f in fields(options)}:
                    raise ValueError("solver.model: this solver has no model option")
                options = replace(options, model=model)
            options.validate()
        except ValueError as exc:
            raise StartupError(f"parameters: {safe_text(exc, 500)}") from None
        return problem, options

    def _make_solver(self, problem, options):
        t0 = time.monotonic()
        solver = build_solver(problem, options, compile=self.compile_mode)
        self._model_changes_seen = (
            0  # a new solver: a new history of model changes (solver thread)
        )
        self.get_logger().info(
            f"solver ready in {time.monotonic() - t0:.1f} s (compile: {self.compile_mode}, "
            f"solver.model: {options.model})"
        )
        return solver

    # ---- inputs (executor thread) --------------------------------------------------------------------------
    def _tf_lookup(self, target: str, source: str):
        """(translation, rotation) from ``source`` into ``target``: the latest transform tf2
        has.
        """
        t = self._tf_buffer.lookup_transform(target, source, rclpy.time.Time())
        tr, rot = t.transform.translation, t.transform.rotation
        return (tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w)

    def _checked(self, pose_msg, frame_id: str, where: str) -> GripPose:
        check_frame_size(
            frame_id, where
        )  # a 10 MB frame_id goes no further (logs, diagnostics, tf2)
        position, orientation = conv.pose_to_arrays(pose_msg)
        pose = check_pose(
            position, orientation, where
        )  # before any transform: NaN etc. named as sent
        position, orientation = conv.in_frame(
            frame_id,
            self.frame_id,
            pose.position,
            pose.orientation,
            where,
            self._tf_lookup if self._tf_buffer is not None else None,
        )
        return GripPose(position, orientation)

    def _read(self, data: bytes, kind: type, where: str):
        """The message of type ``kind`` serialised in ``data``, once its size is within the
        limit.
        """
        check_message_size(len(data), where)
        try:
            return deserialize_message(data, kind)
        except Exception as exc:  # noqa: BLE001 - a malformed buffer is bad input, not a bug
            raise TargetError(
                "invalid", f"{where}: not a readable {kind.__name__} ({type(exc).__name__})"
            ) from None

    def _on_grip_target(self, name: str, data: bytes) -> None:
        received = time.monotonic_ns()
        where = f"grips/{name}/target"
        msg = None
        try:
            msg = self._read(data, PoseStamped, where)
            pose = self._checked(msg.pose, msg.header.frame_id, where)
        except TargetError as exc:
            self._reject(exc, conv.time_to_ns(msg.header.stamp) if msg is not None else 0)
            return
        stamp = conv.time_to_ns(msg.header.stamp) or None
        self.recorder.log_targets({name: pose}, update=self._record_n, ros_time_ns=stamp)
        self.engine.submit_targets({name: pose}, stamp, received)

    def _on_targets(self, data: bytes) -> None:
        received = time.monotonic_ns()
        where = "grips/targets"
        msg = None
        try:
            msg = self._read(data, PoseArray, where)
            check_count(len(msg.poses), self.grip_names, where)
            poses = {
                n: self._checked(p, msg.header.frame_id, f"{where}[{i}] ({n})")
                for i, (n, p) in enumerate(zip(self.grip_names, msg.poses))
            }
        except TargetError as exc:
            self._reject(exc, conv.time_to_ns(msg.header.stamp) if msg is not None else 0)
            return
        stamp = conv.time_to_ns(msg.header.stamp) or None
        self.recorder.log_targets(poses, update=self._record_n, ros_time_ns=stamp)
        self.engine.submit_targets(poses, stamp, received)

    def _reject(self, exc: TargetError, stamp_ns: int = 0) -> None:
        text = safe_text(exc)  # it may quote a frame_id or a transform error: escaped and capped
        self.recorder.log_rejected(
            f"{exc.kind}: {text}",
            update=self._record_n,
            ros_time_ns=stamp_ns or self.get_clock().now().nanoseconds,
        )
        if self.health.error(exc.kind, text, rejected=True):
            self.get_logger().warning(
                f"rejected target ({exc.kind}): {text}; the last good shape stays published"
            )
        self._publish_diagnostics(immediate=True)

    # ---- services (coroutines: they await the solver thread without blocking the executor) ----------------
    async def _await_job(self, job: Future):
        """Await a ShapeEngine job from a service coroutine; returns its result (or raises its
        exception).

        The executor keeps spinning meanwhile (targets, timers, parameters): the coroutine is
        resumed when the solver thread completes the job, which wakes the executor through an rclpy
        Future.
        """
        executor = self.executor
        done = RclpyFuture(executor=executor)
        done.add_done_callback(
            lambda _f: None
        )  # completing it schedules a task: that wakes the executor
        job.add_done_callback(lambda _job: done.set_result(None))
        await done
        return job.result(timeout=0)

    async def _on_query(
        self, request: GetPlan.Request, response: GetPlan.Response
    ) -> GetPlan.Response:
        now = self.get_clock().now().nanoseconds
        response.plan = Path(header=conv.header(self.frame_id, now))
        try:
            poses = {}
            for name, ps, label in zip(
                self.grip_names, (request.start, request.goal), ("start", "goal")
            ):
                poses[name] = self._checked(
                    ps.pose, ps.header.frame_id, f"query_shape.{label} ({name})"
                )
        except TargetError as exc:
            return self._query_failed(response, f"{exc}", "invalid")
        if not self.engine.ready:
            return self._query_failed(
                response, f"the solver is not ready ({self.engine.state})", "not_ready"
            )
        if self._queries_pending >= QUERIES_PER_WORKER * max(self._query_workers, 1):
            return self._query_failed(
                response,
                f"busy: {self._queries_pending} queries are being answered; try again",
                "busy",
            )  # bounded: a flood never builds a queue
        self._queries_pending += 1
        try:
            result = await self._await_job(self._query_job(poses))
        except Exception as exc:  # noqa: BLE001 - cancelled at shutdown, or a solver exception
            return self._query_failed(response, f"{type(exc).__name__}: {exc}", "failed")
        finally:
            self._queries_pending -= 1
        # the reply's status is in plan.header.frame_id (dlo_ros/node/query_reply.py,
        # msg_docs/node.md)
        kind = query_reply.result_kind(result)
        if kind == "unstable":
            return self._query_failed(
                response,
                f"the equilibrium found is unstable (min eigenvalue {result.min_eigenvalue:.3g})",
                kind,
            )
        if kind != query_reply.VERIFIED:
            if query_reply.carries_shape(kind):  # the shape, marked as not verified
                response.plan = conv.result_to_path(
                    result, query_reply.reply_frame(self.frame_id, kind), now
                )
            return self._query_failed(
                response, f"{kind} ({result.status}): {result.message}", kind
            )
        response.plan = conv.result_to_path(result, self.frame_id, now)
        self.health.query(True)
        return response

    def _query_job(self, poses: dict[str, GripPose]) -> Future:
        """The query's ShapeResult as a Future: from a worker process (query_workers > 0; the scene
        is the solver's at the current targets), else from the solver thread.
        """
        if self._query_pool is None:
            return self.engine.query(poses)
        problem, job = self._to_query_worker([poses])
        answer: Future = Future()

        def done(f: Future) -> None:
            try:
                result = f.result()[0]
            except BaseException as exc:  # noqa: BLE001 - handed to the service coroutine
                answer.set_exception(exc)
                return
            miss = target_miss(
                result, problem, {**{g.name: g.pose for g in problem.grips}, **poses}
            )
            if miss:
                result.status, result.message = "failed", miss
            answer.set_result(result)

        job.add_done_callback(done)
        return answer

    def _warm_query_workers(self) -> None:
        """Each query worker builds its solver and the held shape now, and the fit worker imports
        the fit, after the node's own first shape (so that they do not compete with the node's
        start-up for the cores).
        """
        if self._fitter is not None:
            self._fitter.warm()
        if self._query_pool is None:
            return
        for _ in range(self._query_workers):
            self._to_query_worker([])

    def _to_query_worker(self, queries: list[dict[str, GripPose]]) -> tuple[Problem, Future]:
        """Submit ``queries`` to the query workers in the engine's current scene: (that scene's
        problem, the Future of their ShapeResults).
        """
        from ..solver import make_solver
        from ..solver.parallel.batch import scene_payload, solve_chunk

        problem, options = self.engine.query_scene()
        # checks beside the queries: the workers' held shape follows the stream, and auto's check
        # due on one of its updates, run in front of a query, made that query wait 0.2–0.6 s
        # (CHANGELOG) the warm-up (no queries) builds the solver: not limited.  A query is a pure
        # function of its scene and targets: one whose worker died under it (or just before) runs
        # once more
        timeout = (float(self.get_parameter("query_timeout").value) or None) if queries else None
        return problem, self._query_pool.submit(
            solve_chunk,
            scene_payload(make_solver, problem, options),
            queries,
            self._worker_compile,
            "background",
            timeout=timeout,
            retries=1,
        )

    @property
    def _worker_compile(self) -> str:
        """Query workers never start gcc: compiled derivatives only from the cache (or none when
        'off').
        """
        return "off" if self.compile_mode == "off" else "cached"

    def _query_failed(self, response, reason: str, kind: str):
        """A reply that is not a verified shape: ``plan.header.frame_id`` gets the ``#<kind>``
        suffix (query_reply.py); its poses, if any, are already in ``response.plan``.
        """
        response.plan.header.frame_id = query_reply.reply_frame(self.frame_id, kind)
        reason = safe_text(reason)
        self.health.query(False, reason)
        # throttled per call site by rclpy (a client can call the service in a loop); counted in
        # the diagnostics
        what = "unverified plan" if response.plan.poses else "empty plan"
        self.get_logger().warning(
            f"query_shape: {what}: {reason}",
            throttle_duration_sec=max(float(self.health.throttle_s), 1e-9),
        )
        return response

    async def _on_reset(
        self, request: Trigger.Request, response: Trigger.Response
    ) -> Trigger.Response:
        if not self.engine.ready:
            response.success, response.message = (
                False,
                f"the solver is not ready ({self.engine.state})",
            )
            return response
        try:
            result = await self._await_job(self.engine.reset())
        except Exception as exc:  # noqa: BLE001
            response.success, response.message = False, f"{type(exc).__name__}: {exc}"
            return response
        if result is None:
            response.success, response.message = (
                False,
                "warm start cleared; the cold solve raised (see the log)",
            )
        else:
            response.success = result.ok
            response.message = (
                f"warm start cleared; cold solve: {result.status}: {result.message}"
                + ("" if result.ok else " (the last good shape stays published)")
            )
        self.get_logger().info(f"reset: {safe_text(response.message)}")
        return response

    # ---- parameters -----------------------------------------------------------------------------------------
    def _on_set_parameters(self, parameters) -> SetParametersResult:
        strings = {}
        for p in parameters:
            reason = P.check_live(p.name, p.value, self._check_problem)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            if p.name in P.STRING_FIELDS:
                strings[p.name] = p.value
        if strings:  # the combination must be valid too
            try:
                replace(
                    self._check_problem, string=P.apply_string(self._check_problem.string, strings)
                ).validate()
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, parameters) -> None:
        names = {p.name for p in parameters}
        if names & set(P.STRING_FIELDS):
            values = {n: self.get_parameter(n).value for n in P.STRING_FIELDS}
            self._check_problem = replace(
                self._check_problem, string=P.apply_string(self._check_problem.string, values)
            )
            text = "string properties changed: " + ", ".join(
                f"{n}={self.get_parameter(n).value:g}"
                for n in sorted(names & set(P.STRING_FIELDS))
            )

            def edit(problem):  # runs in the solver thread, before the re-solve it triggers
                new = replace(problem, string=P.apply_string(problem.string, values))
                self._record_model_change(text, problem=new)
                return new

            self.engine.change_problem(edit).add_done_callback(self._job_done("string properties"))
            self.get_logger().info(text)
        if "output_points" in names:
            n = self.get_parameter("output_points").value

            def edit_options(options):  # solver thread, before the rebuild and its re-solve
                new = options_with_output_points(options, n)
                if new != options:
                    self._record_model_change(f"output_points={n}: solver rebuilt", options=new)
                return new

            self.engine.change_options(edit_options).add_done_callback(
                self._job_done("output_points")
            )
            self.get_logger().info(
                f"output_points={n}: rebuilding the solver (the next solve is cold)"
            )
        if "warn_throttle" in names:
            self.health.throttle_s = self.get_parameter("warn_throttle").value
        if names & {"markers.force_scale", "markers.energy_scale"}:
            with self._latest_lock:
                self._markers_dirty = self._latest is not None

    def _record_model_change(
        self, text: str, *, problem=None, options=None, ros_time_ns: int | None = None
    ) -> None:
        """Record a model event at the current update (solver thread): a change of the solved
        problem / options, with the new scene, so that the recording stays re-solvable from the
        next update on; or, with neither, a change of model the solver made itself (solver.model:
        auto; the scene is the same).
        """
        scene = None
        if problem is not None:
            self._record_scene = scene = replace(self._record_scene, problem=problem)
        if options is not None:
            self._record_scene = scene = replace(self._record_scene, options=options)
        self.recorder.log_model_change(
            text, update=self._record_n, ros_time_ns=ros_time_ns, scene=scene
        )

    def _job_done(self, what: str):
        """A done-callback logging a parameter change the solver thread could not apply."""

        def done(future) -> None:
            if future.cancelled() or self._closing:
                return
            exc = future.exception()
            if exc is not None:
                self.get_logger().error(
                    f"applying {what} failed: {type(exc).__name__}: {safe_text(exc)}"
                )

        return done

    # ---- outputs (worker thread) --------------------------------------------------------------------------------
    def _on_state(self, state: str) -> None:
        state = safe_text(state)
        self.health.set_state(state)
        if state.startswith("failed"):
            self.get_logger().error(f"solver: {state}")
        self._publish_diagnostics(immediate=True)

    def _on_update(self, u: Update) -> None:
        if self._closing:
            return
        try:
            self._publish_update(u)
        except Exception:
            if (
                self._stopping()
            ):  # SIGINT shut the context down under this update: nothing left to publish to
                return
            raise

    def _stopping(self) -> bool:
        """The node is closing, or its context was shut down (a signal reaches rclpy's handler
        before ``close``; an update in flight then finds its publishers invalid).
        """
        return self._closing or not self.context.ok()

    def _publish_update(self, u: Update) -> None:
        r = u.result
        stamp = u.stamp_ns if u.stamp_ns else self.get_clock().now().nanoseconds
        # the shape first: recording and bookkeeping need not delay it
        self._path_pub.publish(
            conv.result_path_cdr(r, self.frame_id, stamp)
        )  # pre-serialised: no per-pose objects
        for name, wrench in r.grips.items():
            pub = self._wrench_pubs.get(name)
            if pub is not None:
                pub.publish(conv.wrench_cdr(wrench, self.frame_id, stamp))
        model_changed = self._record_update(u, stamp)
        latency = None if u.received_ns is None else (time.monotonic_ns() - u.received_ns) / 1e6
        self.health.set_targets(self.engine.targets_received, self.engine.targets_coalesced)
        was_error = self.health.newest_is_error or self.health.updates == 0
        self.health.update(r, u.trigger, latency)
        with self._latest_lock:
            self._latest = replace(u, stamp_ns=stamp)
            self._markers_dirty = True
        if self.health.updates == 1:
            self.get_logger().info(
                f"first shape published {time.monotonic() - self._t_start:.1f} s after start "
                f"({r.status}, stable={r.stable}; model {model_text(r.model_dict()) or 'not reported'})"
            )
            self._warm_query_workers()
        if r.stable is False and self.health.should_warn("unstable"):
            self.get_logger().warning(
                f"the published equilibrium is unstable (min eigenvalue {r.min_eigenvalue:.3g}): "
                "the cable would not stay in this shape"
            )
        if was_error or model_changed:
            self._publish_diagnostics(immediate=True)

    def _record_update(self, u: Update, stamp_ns: int) -> bool:
        """One streaming solve into the model diagnostics and the recording (solver thread); the
        update counter advances.  Returns whether the solver changed its model.
        """
        if (
            u is self._record_last
        ):  # on_update raised after recording it: on_failure gets the same update
            return False
        self._record_last = u
        changes = self._observe_model(u.result, stamp_ns)
        self.recorder.log_update(
            u.result,
            update=self._record_n,
            problem=u.problem,
            ros_time_ns=stamp_ns,
            warm=u.trigger not in ("initial", "reset", "rebuild"),
        )
        self._record_n += 1
        return bool(changes)

    def _observe_model(self, result, stamp_ns: int) -> list[str]:
        """The model of a streaming solve (ok or failed) into the diagnostics; each change of model
        it made is logged (INFO) and recorded in events/model at this update, with its reason.
        """
        model = result.model_dict()
        changes = []
        if model:
            changes, self._model_changes_seen = new_model_changes(model, self._model_changes_seen)
        now = model_text(model)
        for reason in changes:
            self.get_logger().info(f"model change (update {self._record_n}): {reason}")
            self._record_model_change(f"model change: {reason}", ros_time_ns=stamp_ns)
        if changes:  # the model after all of them
            self.get_logger().info(f"model now (update {self._record_n}): {now}")
            self._record_model_change(f"model now: {now}", ros_time_ns=stamp_ns)
        self.health.set_model(model, changes, stamp_ns=stamp_ns, update=self._record_n)
        problem = self.health.tolerance_problem()
        if bool(problem) != self._tolerance_warned:
            self._tolerance_warned = bool(problem)
            if problem:
                self.get_logger().warning(problem)
            else:
                self.get_logger().info(f"model meets its error tolerance again: {now}")
        return changes

    def _on_failure(self, kind: str, message: str, u: Update | None) -> None:
        if self._stopping():
            return
        if u is not None:
            self._record_update(
                u, u.stamp_ns if u.stamp_ns else self.get_clock().now().nanoseconds
            )
        self.health.set_targets(self.engine.targets_received, self.engine.targets_coalesced)
        first_line = safe_text(message.splitlines()[0] if message else kind)
        if self.health.error(kind, first_line, rejected=False):
            if (
                kind == "internal"
            ):  # with its traceback, escaped into one line (a bug report, not a log line)
                self.get_logger().error(f"solver error: {safe_text(message, 20 * TEXT_LIMIT)}")
            else:
                self.get_logger().warning(
                    f"no equilibrium ({kind}): {first_line}; the last good shape stays published"
                )
        self._publish_diagnostics(immediate=True)

    def _publish_markers(self) -> None:
        with self._latest_lock:
            u, dirty = self._latest, self._markers_dirty
            self._markers_dirty = False
        if u is None or not dirty or self._closing:
            return
        self._marker_pub.publish(
            conv.result_markers(
                u.result,
                u.problem,
                self.frame_id,
                u.stamp_ns,
                force_scale=self.get_parameter("markers.force_scale").value,
                energy_scale=self.get_parameter("markers.energy_scale").value,
            )
        )

    def _publish_diagnostics(self, immediate: bool = False) -> None:
        if self._closing:
            return
        now = time.monotonic()
        with self._diag_lock:
            if immediate:
                if now - self._last_immediate_diag < IMMEDIATE_DIAGNOSTICS_MIN_S:
                    return
                self._last_immediate_diag = now
            if hasattr(self, "engine"):
                self.health.set_targets(
                    self.engine.targets_received, self.engine.targets_coalesced
                )
            level, message = self.health.level_and_message()
            # every text value escaped and capped (user-controlled pieces were capped to TEXT_LIMIT
            # where they entered; the model's own reasons may be longer, hence the larger cap here)
            values = {
                k: safe_text(v, 5 * TEXT_LIMIT) if isinstance(v, str) else v
                for k, v in self.health.values().items()
            }
            status = conv.diagnostic_status(
                f"{self.get_fully_qualified_name()}: shape",
                level,
                safe_text(message),
                safe_text(self.scene.name),
                values,
            )
            statuses = [status]
            if getattr(self, "_fitter", None) is not None:
                statuses.append(self._fitter.status(safe_text(self.scene.name)))
            msg = DiagnosticArray(
                header=conv.header("", self.get_clock().now().nanoseconds), status=statuses
            )
            try:
                self._diag_pub.publish(msg)
            except Exception:  # noqa: BLE001 - the context may be shutting down
                pass

    # ---- shutdown -----------------------------------------------------------------------------------------------
    def close(self, timeout: float = 10.0) -> bool:
        """Stop the worker (after the solve in progress); True if it ended within ``timeout``."""
        self._closing = True
        pool = getattr(self, "_query_pool", None)
        if pool is not None:
            from ..solver.parallel.worker_pool import stop_pool

            stop_pool(pool, timeout)
        fitter = getattr(self, "_fitter", None)
        if fitter is not None:
            fitter.close(timeout)
        stopped = self.engine.stop(timeout) if hasattr(self, "engine") else True
        recorder = getattr(self, "recorder", None)
        if recorder is not None:
            try:
                recorder.close(timeout)  # bounded: the recording file is complete afterwards
            except Exception as exc:  # noqa: BLE001 - shutdown must go on
                print(f"dlo_node: warning: closing the recording failed: {exc}", file=sys.stderr)
        return stopped


# ---- entry point --------------------------------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    return P.node_argument_parser("python -m dlo_ros.node")


def _default_params_file() -> str | None:
    try:
        from ..paths import config_path

        path = config_path("dlo_node.yaml")
    except (FileNotFoundError, OSError):
        return None
    return str(path) if path.is_file() else None


def new_executor(context=None) -> SingleThreadedExecutor:
    """The node's executor (on ``context``, default rclpy's).  A SIGINT or SIGTERM during rclpy's
    constructor (which shuts the context down under it) leaves a half-built executor whose
    ``__del__`` reads an attribute the constructor had not set yet: "Exception ignored ...
    AttributeError: ... '_sigint_gc'" with a traceback at exit.  The attribute is set first, so a
    failed construction leaves nothing for ``__del__`` to trip on.
    """
    executor = SingleThreadedExecutor.__new__(SingleThreadedExecutor)
    executor._sigint_gc = None
    executor.__init__(context=context)
    return executor


def main(argv: list[str] | None = None, prog: str = "python -m dlo_ros.node") -> int:
    """Run the node until Ctrl-C / SIGINT / SIGTERM / shutdown; returns the exit code.

    argv: command-line arguments without the program name (default: sys.argv[1:]); ROS arguments
    (--ros-args ...) are passed through to rclpy after :func:`params.prepare_node_args` checked
    them (exit code 2 and one line naming the file / parameter when they are unusable).
    ``--check`` stops after those checks and loading the scene.  ``prog``: the name in usage
    messages.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    one_line_warnings()
    # Every params file and -p value is checked here, in Python, before rcl reads them: rcl reports
    # a broken file only as "Failed to parse global arguments", ignores misspelt names and accepts
    # any frame.
    try:
        prepared = P.prepare_node_args(argv, _default_params_file(), prog=prog)
    except P.ParamsError as exc:
        print(f"dlo_node: error: {safe_text(exc, 1000)}", file=sys.stderr)
        return 2
    if prepared.check:
        from ..scene import SceneError, load_scene

        try:
            scene = load_scene(prepared.scene)
        except (SceneError, FileNotFoundError) as exc:
            print(
                f"dlo_node: error: parameter scene={safe_text(prepared.scene)!r}: {safe_text(exc, 1000)}",
                file=sys.stderr,
            )
            return 2
        files = ", ".join(safe_text(f) for f in prepared.params_files) or "none"
        print(
            f"dlo_node: ok: params files {files}; scene '{safe_text(scene.name)}' ({safe_text(scene.source)}), "
            f"grips {[safe_text(g.name) for g in scene.problem.grips]}; the node would start"
        )
        return 0

    node = executor = None
    code = 0
    try:
        node_starting()
        try:
            rclpy.init(args=prepared.ros_args)
        # noqa: BLE001 - rcl refused the ROS arguments (the files were checked above)
        except Exception as exc:
            print(
                f"dlo_node: error: ROS arguments {safe_text(' '.join(argv), 300)!r}: {safe_text(exc)}",
                file=sys.stderr,
            )
            return 2
        node = DloNode()
        # One thread: it only converts and checks messages (the solver has its own thread, and the
        # services await it as coroutines).  rclpy's MultiThreadedExecutor is slower per message
        # here and competes with the solver thread for the GIL. rclpy.experimental.EventsExecutor
        # (rclpy 7.1.6 here) cannot serve this node: its raw target subscriptions delivered nothing
        # under it, and coroutine services do not run (ros2/rclpy#1473).
        executor = new_executor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        print(f"dlo_node: error: {safe_text(exc, 1000)}", file=sys.stderr)
        code = 2
    except Exception:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM during start-up shut the context down under the node's constructor: a
        # clean stop
    finally:
        exit_on_second_signal(code)  # a second Ctrl-C while stopping: leave at once
        stuck = False
        try:
            if node is not None:
                stuck = not node.close(STOP_TIMEOUT_S)
                if stuck:
                    print(
                        f"dlo_node: warning: the solver thread is still busy after {STOP_TIMEOUT_S:g} s (a long "
                        "solve or a compile); exiting without waiting for it",
                        file=sys.stderr,
                    )
                if executor is not None:
                    executor.shutdown(timeout_sec=2.0)
                node.destroy_node()
            rclpy.try_shutdown()
        except KeyboardInterrupt:  # a second Ctrl-C while shutting down
            pass
        # e.g. a background compile's gcc: nothing the node started outlives it
        terminate_children()
        if stuck:
            # Interpreter finalisation with a thread still inside CasADi/IPOPT (C++) can abort the
            # process ("terminate called without an active exception"); leave without it, and take
            # our own children (a gcc compiling the solver's derivatives) along.
            terminate_children()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    return code
