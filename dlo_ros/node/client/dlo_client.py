"""A client of a running dlo node, in its own rclpy context, with a spinning thread.

:class:`DloClient` publishes targets, records every centreline with its arrival time, keeps the
latest diagnostics and wrenches, and calls the node's services and its parameter service.
"""

from __future__ import annotations

import collections
import threading
import time
from functools import partial
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.serialization import serialize_message
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from ..cloud import points_to_cloud
from ..conversions import (
    arrays_to_pose,
    header,
    path_from_cdr,
    path_to_arrays,
    pose_stamped,
    time_to_ns,
    wrench_to_arrays,
)
from ..qos import CLOUD_QOS, LATCHED_QOS, TARGET_QOS, WRENCH_QOS
from ..query_reply import QueryAnswer, decode
from ..validation import Vector
from .executors import make_executor

SERVICE_SETTLE_S = 0.5  # wait after a service is first discovered, before the first call
POLL_S = 0.02  # how often ``call`` looks at its ``answered`` evidence [s]


@dataclass
class PathEvent:
    """A centreline as received: arrival (ROS time and monotonic, ns), header stamp, arrays."""

    received_ns: int
    received_mono_ns: int
    stamp_ns: int
    points: np.ndarray
    orientations: np.ndarray
    frame_id: str


class DloClient:
    """A client of the node ``node_name`` (fully qualified, e.g. '/dlo') in its own rclpy context.

    Everything it receives is recorded by its own spinning thread; the methods are safe to call
    from the caller's thread.  Use as a context manager or call ``close()``.  ``executor``:
    'single' (rclpy's SingleThreadedExecutor, default) or 'events'
    (rclpy.experimental.EventsExecutor) spins that thread.
    """

    def __init__(
        self,
        domain_id: int,
        *,
        node_name: str = "/dlo",
        grip_names: Sequence[str] = ("left", "right"),
        frame_id: str = "world",
        client_name: str = "dlo_client",
        keep_paths: int = 100_000,
        executor: str = "single",
    ):
        self._rclpy = rclpy
        self.node_name = node_name.rstrip("/")
        self.grip_names = list(grip_names)
        self.frame_id = frame_id
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(client_name, context=self.context)
        self._cond = threading.Condition()
        self.paths: collections.deque[PathEvent] = collections.deque(maxlen=keep_paths)
        self.path_count = 0
        self.malformed_paths = 0  # centreline messages that were not a readable Path (ignored)
        self.diagnostics = None  # latest DiagnosticStatus '<node>: shape' of the node
        self.other_diagnostics: dict[
            str, object
        ] = {}  # the node's other statuses by name (e.g. '<node>: fit')
        self.diagnostics_count = 0
        self.wrenches: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}
        self.markers = None
        self.marker_count = 0
        self._subscribe()
        n, base = self.node, self.node_name
        self._targets_pub = n.create_publisher(PoseArray, f"{base}/grips/targets", TARGET_QOS)
        self._grip_pubs = {
            g: n.create_publisher(PoseStamped, f"{base}/grips/{g}/target", TARGET_QOS)
            for g in self.grip_names
        }
        self._query = n.create_client(GetPlan, f"{base}/query_shape")
        self._reset = n.create_client(Trigger, f"{base}/reset")
        self._fit_client = self._cloud_publisher = (
            None  # ~/fit, ~/observed: made on first use (fewer DDS
        )
        # entities to discover for the clients that never fit)
        self._set_params = n.create_client(SetParameters, f"{base}/set_parameters")
        self._get_params = n.create_client(GetParameters, f"{base}/get_parameters")
        self._msgs = {
            "PoseArray": PoseArray,
            "PoseStamped": PoseStamped,
            "GetPlan": GetPlan,
            "Trigger": Trigger,
            "SetParameters": SetParameters,
            "GetParameters": GetParameters,
        }
        self._stopping = False
        self._settled: set = set()  # service clients past their first call (see _call)
        self.executor = make_executor(executor, self.context)
        self.executor.add_node(n)
        self._thread = threading.Thread(target=self._spin, name="dlo-client", daemon=True)
        self._thread.start()

    def _subscribe(self) -> None:
        """Subscribe to the node's centreline, diagnostics, markers and wrenches."""
        n, base = self.node, self.node_name
        # raw: the Path decoded from its bytes with numpy (conversions.path_from_cdr), not by rclpy
        n.create_subscription(PathMsg, f"{base}/centerline", self._on_path, LATCHED_QOS, raw=True)
        n.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)
        n.create_subscription(MarkerArray, f"{base}/markers", self._on_markers, LATCHED_QOS)
        for g in self.grip_names:
            n.create_subscription(
                WrenchStamped,
                f"{base}/grips/{g}/wrench",
                partial(self._on_wrench, g),
                WRENCH_QOS,
            )

    # ---- receiving (spin thread) ----------------------------------------------------------------
    def _spin(self) -> None:
        try:
            while self.context.ok() and not self._stopping:
                self.executor.spin_once(timeout_sec=0.05)
        except (ExternalShutdownException, KeyboardInterrupt):
            pass
        except Exception:  # noqa: BLE001 - the context was shut down under us
            if self.context.ok():
                raise

    def _now_ns(self) -> int:
        return self.node.get_clock().now().nanoseconds

    def _on_path(self, data: bytes) -> None:
        now, mono = self._now_ns(), time.monotonic_ns()
        try:
            stamp, frame, pts, qs = path_from_cdr(data)
        except (
            ValueError
        ):  # conversions.CdrError: not a Path (another publisher on the topic); counted
            with self._cond:
                self.malformed_paths += 1
            return
        ev = PathEvent(now, mono, stamp, pts, qs, frame)
        with self._cond:
            self.paths.append(ev)
            self.path_count += 1
            self._cond.notify_all()

    def _on_diagnostics(self, msg) -> None:
        for st in msg.status:
            if st.name.startswith(f"{self.node_name}:"):
                with self._cond:
                    if st.name == f"{self.node_name}: shape":
                        self.diagnostics = st
                        self.diagnostics_count += 1
                    else:
                        self.other_diagnostics[st.name] = st
                    self._cond.notify_all()

    def _on_wrench(self, grip: str, msg) -> None:
        f, t = wrench_to_arrays(msg)
        with self._cond:
            self.wrenches[grip] = (time_to_ns(msg.header.stamp), f, t)
            self._cond.notify_all()

    def _on_markers(self, msg) -> None:
        with self._cond:
            self.markers = msg
            self.marker_count += 1
            self._cond.notify_all()

    def collect(self, msg_type: type, topic: str, qos=LATCHED_QOS) -> list:
        """Subscribe to the node's ``topic`` (e.g. 'capsules'); return the list messages go to.

        Appended under the client's lock: read it inside :meth:`wait_for`'s predicate.
        """
        received: list = []

        def on_message(msg) -> None:
            with self._cond:
                received.append(msg)
                self._cond.notify_all()

        self.node.create_subscription(msg_type, f"{self.node_name}/{topic}", on_message, qos)
        return received

    # ---- waiting --------------------------------------------------------------------------------
    def wait_for(self, predicate: Callable[[], object], timeout: float) -> object:
        """Wait until ``predicate()`` (called with the lock held) is truthy; return its value.

        Returns None on timeout.
        """
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                value = predicate()
                if value:
                    return value
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(min(left, 0.1))

    def latest_path(self) -> PathEvent | None:
        with self._cond:
            return self.paths[-1] if self.paths else None

    def wait_for_path(
        self, timeout: float, after: int = 0, where: Callable[[PathEvent], bool] | None = None
    ) -> PathEvent | None:
        """Wait for the newest centreline numbered > ``after`` (path_count) that fits ``where``."""

        def ready():
            if self.path_count <= after or not self.paths:
                return None
            ev = self.paths[-1]
            return ev if where is None or where(ev) else None

        event = self.wait_for(ready, timeout)
        return event if isinstance(event, PathEvent) else None

    def diagnostic_values(self) -> dict[str, str]:
        with self._cond:
            st = self.diagnostics
        return {} if st is None else {kv.key: kv.value for kv in st.values}

    def wait_for_diagnostics(
        self, where: Callable[[dict[str, str], object], bool], timeout: float
    ):
        """Wait for the first '<node>: shape' status for which ``where(values, status)`` holds.

        Returns (values dict, status), or None on timeout.
        """

        def ready():
            st = self.diagnostics
            if st is None:
                return None
            values = {kv.key: kv.value for kv in st.values}
            return (values, st) if where(values, st) else None

        return self.wait_for(ready, timeout)

    def wait_for_fit_diagnostics(
        self, where: Callable[[dict[str, str], object], bool], timeout: float
    ):
        """As :meth:`wait_for_diagnostics`, for the status '<node>: fit' (fit.enabled)."""

        def ready():
            st = self.other_diagnostics.get(f"{self.node_name}: fit")
            if st is None:
                return None
            values = {kv.key: kv.value for kv in st.values}
            return (values, st) if where(values, st) else None

        return self.wait_for(ready, timeout)

    def wait_for_subscribers(self, timeout: float = 10.0, settle: float = 0.5) -> bool:
        """Wait until the node's target subscriptions matched our publishers, then ``settle`` s.

        Matching is seen from the publisher's side only; the node's reader may match our writer a
        moment later, and a volatile reader drops what arrives before that.  The settle time covers
        it.
        """
        pubs = [self._targets_pub, *self._grip_pubs.values()]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in pubs):
                time.sleep(settle)
                return True
            time.sleep(0.02)
        return False

    # ---- sending --------------------------------------------------------------------------------
    def _pose(self, position, orientation):
        return arrays_to_pose(position, orientation)

    def publish_targets(
        self,
        poses: Iterable[tuple[Vector, Vector]],
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> int:
        """Publish a PoseArray (one (position, quaternion) per grip); return its stamp [ns]."""
        stamp = self._now_ns() if stamp_ns is None else stamp_ns
        msg = self._msgs["PoseArray"](
            header=header(self.frame_id if frame_id is None else frame_id, stamp)
        )
        msg.poses = [self._pose(p, q) for p, q in poses]
        self._targets_pub.publish(msg)
        return stamp

    def publish_oversized_targets(self, n_poses: int) -> int:
        """Publish a PoseArray of ``n_poses`` zero poses; return its size in bytes.

        Serialised here without building the poses in Python (one pose, its count patched, zeros
        appended).
        """
        msg = self._msgs["PoseArray"](header=header(self.frame_id, self._now_ns()))
        msg.poses = [self._pose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))]
        one = serialize_message(msg)
        count_at = len(one) - 56 - 4  # the sequence length precedes the single 56-byte pose
        data = one[:count_at] + int(n_poses).to_bytes(4, "little") + bytes(56 * n_poses)
        self._targets_pub.publish(data)
        return len(data)

    def publish_grip(
        self,
        grip: str,
        position,
        orientation,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> int:
        stamp = self._now_ns() if stamp_ns is None else stamp_ns
        msg = self._msgs["PoseStamped"](
            header=header(self.frame_id if frame_id is None else frame_id, stamp),
            pose=self._pose(position, orientation),
        )
        self._grip_pubs[grip].publish(msg)
        return stamp

    def call(self, client, request, timeout: float, answered: Callable[[], bool] | None = None):
        """Call the service of rclpy ``client``; return its response or raise TimeoutError.

        ``answered``: other evidence that the call took effect (polled every POLL_S); once it is
        true before the response came, None is returned (a response lost on the way).
        """
        if not client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f"service {client.srv_name} not available")
        if client not in self._settled:
            # the service is discovered before its response writer has matched this client's
            # reader, and Fast DDS drops a response it cannot deliver within 100 ms
            # (ros2/rclpy#1181, ros2/rmw_fastrtps#467): a quick answer to a first call could be
            # lost
            time.sleep(SERVICE_SETTLE_S)
            self._settled.add(client)
        future = client.call_async(request)
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        deadline = time.monotonic() + timeout
        while not done.wait(min(POLL_S, max(deadline - time.monotonic(), 0.0))):
            if answered is not None and answered():
                client.remove_pending_request(future)
                return None
            if time.monotonic() >= deadline:
                client.remove_pending_request(future)
                raise TimeoutError(f"service {client.srv_name}: no response within {timeout} s")
        return future.result()

    def query(
        self, start: tuple, goal: tuple, *, frame_id: str | None = None, timeout: float = 30.0
    ):
        """Call ~/query_shape; return (points, orientations) of a verified shape.

        Any other answer gives empty arrays (see :meth:`query_shape` for which).
        """
        answer = self.query_shape(start, goal, frame_id=frame_id, timeout=timeout)
        if answer.verified:
            return answer.points, answer.orientations
        return np.zeros((0, 3)), np.zeros((0, 4))

    def query_shape(
        self, start: tuple, goal: tuple, *, frame_id: str | None = None, timeout: float = 30.0
    ) -> QueryAnswer:
        """Call ~/query_shape; return the reply decoded (``query_reply.decode``).

        Its ``status`` is 'verified' (a verified, stable equilibrium), 'unverified' (a shape, not
        verified), 'no_equilibrium', 'unstable', 'failed', 'invalid', 'busy' or 'not_ready'
        (msg_docs/node.md).
        """
        frame = self.frame_id if frame_id is None else frame_id
        req = self._msgs["GetPlan"].Request()
        req.start = pose_stamped(start[0], start[1], frame, 0)
        req.goal = pose_stamped(goal[0], goal[1], frame, 0)
        resp = self.call(self._query, req, timeout)
        return decode(resp.plan.header.frame_id, *path_to_arrays(resp.plan))

    @property
    def _cloud_pub(self):
        if self._cloud_publisher is None:
            self._cloud_publisher = self.node.create_publisher(
                PointCloud2, f"{self.node_name}/observed", CLOUD_QOS
            )
        return self._cloud_publisher

    @property
    def _fit(self):
        if self._fit_client is None:
            self._fit_client = self.node.create_client(
                self._msgs["Trigger"], f"{self.node_name}/fit"
            )
        return self._fit_client

    def publish_cloud(
        self, points, *, frame_id: str | None = None, stamp_ns: int | None = None
    ) -> int:
        """Publish ``points`` (N, 3) [m] as a float32 PointCloud2 on ~/observed; its stamp [ns]."""
        stamp = self._now_ns() if stamp_ns is None else stamp_ns
        self._cloud_pub.publish(
            points_to_cloud(points, self.frame_id if frame_id is None else frame_id, stamp)
        )
        return stamp

    def publish_cloud_msg(self, msg) -> None:
        """Publish any PointCloud2 (or its serialised bytes) on ~/observed."""
        self._cloud_pub.publish(msg)

    def wait_for_cloud_subscriber(self, timeout: float = 10.0, settle: float = 0.5) -> bool:
        """Wait until the node's ~/observed reader matched, then ``settle`` s more.

        See :meth:`wait_for_subscribers`.
        """
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._cloud_pub.get_subscription_count() > 0:
                time.sleep(settle)
                return True
            time.sleep(0.02)
        return False

    def fit(self, timeout: float = 30.0) -> tuple[bool, str]:
        """Call ~/fit; return whether a fit started, and why not (it answers at once)."""
        resp = self.call(self._fit, self._msgs["Trigger"].Request(), timeout)
        return resp.success, resp.message

    def reset(self, timeout: float = 30.0):
        resp = self.call(self._reset, self._msgs["Trigger"].Request(), timeout)
        return resp.success, resp.message

    def set_parameters(self, values: dict, timeout: float = 10.0) -> list[tuple[bool, str]]:
        """Set parameters one by one (each may be refused on its own): [(successful, reason)]."""
        req = self._msgs["SetParameters"].Request()
        req.parameters = [Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
        resp = self.call(self._set_params, req, timeout)
        return [(r.successful, r.reason) for r in resp.results]

    def get_parameters(self, names: Sequence[str], timeout: float = 10.0) -> dict:
        req = self._msgs["GetParameters"].Request()
        req.names = list(names)
        resp = self.call(self._get_params, req, timeout)
        return {n: parameter_value_to_python(v) for n, v in zip(names, resp.values)}

    # ---- teardown -------------------------------------------------------------------------------
    def close(self) -> None:
        if self._stopping:
            return
        self._stopping = True
        self._thread.join(5.0)
        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        except Exception:  # noqa: BLE001 - already gone with the context
            pass
        self._rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> "DloClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
