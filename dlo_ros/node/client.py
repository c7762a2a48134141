"""Drive a running dlo node from another process: the demo, the benchmark and the tests use this.

* :func:`allocate_domain_id` reserves a ROS_DOMAIN_ID no other process on this machine uses (lock
  files),
  so several nodes (demos, benchmarks, tests) can run side by side.
* :class:`NodeProcess` starts ``python -m dlo_ros.node`` (or another module that stands in for it)
  as a
  subprocess in its own process group and always stops it (SIGINT, then SIGTERM, then SIGKILL of
  the group).
* :class:`DloClient` is an rclpy node in its own context (its own domain) with a spinning thread:
  it publishes targets, records every centreline with its arrival time, keeps the latest
  diagnostics and wrenches, and calls the services and the parameter service.
* :func:`running_node` does all three: the node in its own domain, a client, the first centreline.

The tests' own harness (which scene and model they run on, process-group checks) is in
test/support/.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Sequence

import numpy as np

if TYPE_CHECKING:
    from .query_reply import QueryAnswer

#: Domain ids that keep Fast DDS's UDP ports valid (0 is left to interactive use).
DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
_LOCK_DIR = Path(tempfile.gettempdir()) / "dlo_ros_domains"
_counter = 0


class DomainLease:
    """A reserved ROS_DOMAIN_ID; ``release()`` (or process exit) frees it."""

    def __init__(self, domain_id: int, fd: int):
        self.domain_id, self._fd = domain_id, fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "DomainLease":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def allocate_domain_id() -> DomainLease:
    """Reserve a free domain id (flock on a file per id; the order starts at a pid- and
    counter-derived offset, so concurrent processes rarely even contend).
    """
    global _counter
    _LOCK_DIR.mkdir(parents=True, exist_ok=True)
    _counter += 1
    start = (os.getpid() * 7 + _counter * 13) % len(DOMAIN_IDS)
    for k in range(len(DOMAIN_IDS)):
        domain = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
        fd = os.open(_LOCK_DIR / f"{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EAGAIN, errno.EACCES):
                continue
            raise
        return DomainLease(domain, fd)
    raise RuntimeError("no free ROS_DOMAIN_ID (all are reserved by other processes)")


def ros_env(domain_id: int, base: dict | None = None) -> dict:
    """The environment for a node process in ``domain_id``, discovery limited to this machine."""
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy; conflicts with the setting above
    return env


class NodeProcess:
    """``python -m <module> <args>`` (default module ``dlo_ros.node``) in a new process group;
    output goes to ``log_path``.  ``env``: the base environment (default this process's) that
    :func:`ros_env` completes.
    """

    def __init__(
        self,
        args: Sequence[str],
        domain_id: int,
        *,
        log_path: str | os.PathLike | None = None,
        env: dict | None = None,
        module: str = "dlo_ros.node",
    ):
        self.args = list(args)
        self.domain_id = domain_id
        if log_path is None:
            fd, log_path = tempfile.mkstemp(prefix="dlo_node_", suffix=".log")
            os.close(fd)
            self._own_log = True
        else:
            self._own_log = False
        self.log_path = Path(log_path)
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", module, *self.args],
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=ros_env(domain_id, env),
            start_new_session=True,
        )
        self.returncode: int | None = None

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def rss_bytes(self) -> int:
        """Resident set size of the node process (VmRSS from /proc)."""
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
        raise RuntimeError("no VmRSS")

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def send_signal(self, sig: int) -> None:
        if self.alive():
            self.proc.send_signal(sig)

    def wait(self, timeout: float) -> int | None:
        try:
            self.returncode = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None
        return self.returncode

    def stop(self, timeout: float = 15.0, sig: int = signal.SIGINT) -> int:
        """Stop the node (``sig``, then SIGTERM, then SIGKILL of its process group); its return
        code.
        """
        if self.alive():
            self.send_signal(sig)
            if self.wait(timeout) is None:
                self._killpg(signal.SIGTERM)
                if self.wait(5.0) is None:
                    self._killpg(signal.SIGKILL)
                    self.wait(5.0)
        self.returncode = self.proc.wait()
        self._killpg(signal.SIGKILL)  # anything the node started (none expected) goes too
        self._log.close()
        return self.returncode

    def _killpg(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def close(self) -> None:
        if self.returncode is None or not self._log.closed:
            self.stop()
        if self._own_log:
            self.log_path.unlink(missing_ok=True)

    def __enter__(self) -> "NodeProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


SERVICE_SETTLE_S = 0.5  # wait after a service is first discovered, before the first call


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
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
        from nav_msgs.msg import Path as PathMsg
        from nav_msgs.srv import GetPlan
        from rclpy.node import Node
        from rcl_interfaces.srv import GetParameters, SetParameters
        from std_srvs.srv import Trigger
        from visualization_msgs.msg import MarkerArray

        from .conversions import path_from_cdr, path_to_arrays, time_to_ns, wrench_to_arrays
        from .qos import LATCHED_QOS, TARGET_QOS, WRENCH_QOS

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
        self._path_to_arrays, self._time_to_ns, self._wrench_to_arrays = (
            path_to_arrays,
            time_to_ns,
            wrench_to_arrays,
        )
        self._path_from_cdr = path_from_cdr

        n = self.node
        base = self.node_name
        self._targets_pub = n.create_publisher(PoseArray, f"{base}/grips/targets", TARGET_QOS)
        self._grip_pubs = {
            g: n.create_publisher(PoseStamped, f"{base}/grips/{g}/target", TARGET_QOS)
            for g in self.grip_names
        }
        # raw: the Path decoded from its bytes with numpy (conversions.path_from_cdr), not by rclpy
        n.create_subscription(PathMsg, f"{base}/centerline", self._on_path, LATCHED_QOS, raw=True)
        n.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)
        n.create_subscription(MarkerArray, f"{base}/markers", self._on_markers, LATCHED_QOS)
        for g in self.grip_names:
            n.create_subscription(
                WrenchStamped,
                f"{base}/grips/{g}/wrench",
                lambda msg, g=g: self._on_wrench(g, msg),
                WRENCH_QOS,
            )
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

    # ---- receiving (spin thread) ----------------------------------------------------------------
    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

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
            stamp, frame, pts, qs = self._path_from_cdr(data)
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
        f, t = self._wrench_to_arrays(msg)
        with self._cond:
            self.wrenches[grip] = (self._time_to_ns(msg.header.stamp), f, t)
            self._cond.notify_all()

    def _on_markers(self, msg) -> None:
        with self._cond:
            self.markers = msg
            self.marker_count += 1
            self._cond.notify_all()

    # ---- waiting --------------------------------------------------------------------------------
    def wait_for(self, predicate: Callable[[], object], timeout: float) -> object:
        """Wait until ``predicate()`` (called with the lock held) is truthy; return it, or None on
        timeout.
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
        """The newest centreline numbered > ``after`` (path_count) that satisfies ``where``."""

        def ready():
            if self.path_count <= after or not self.paths:
                return None
            ev = self.paths[-1]
            return ev if where is None or where(ev) else None

        return self.wait_for(ready, timeout)

    def diagnostic_values(self) -> dict[str, str]:
        with self._cond:
            st = self.diagnostics
        return {} if st is None else {kv.key: kv.value for kv in st.values}

    def wait_for_diagnostics(
        self, where: Callable[[dict[str, str], object], bool], timeout: float
    ):
        """The first diagnostics status (values dict, status) for which ``where(values, status)``
        holds.
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
        """Wait until the node's target subscriptions have matched our publishers, then ``settle``
        s more.

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
        from .conversions import arrays_to_pose

        return arrays_to_pose(position, orientation)

    def publish_targets(
        self,
        poses: Iterable[tuple[Sequence[float], Sequence[float]]],
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> int:
        """Publish a PoseArray (one (position, quaternion) per grip); returns the header stamp used
        [ns].
        """
        from .conversions import header

        stamp = self._now_ns() if stamp_ns is None else stamp_ns
        msg = self._msgs["PoseArray"](
            header=header(self.frame_id if frame_id is None else frame_id, stamp)
        )
        msg.poses = [self._pose(p, q) for p, q in poses]
        self._targets_pub.publish(msg)
        return stamp

    def publish_oversized_targets(self, n_poses: int) -> int:
        """Publish a PoseArray of ``n_poses`` zero poses, serialised here without building them in
        Python (one pose, its count patched, zeros appended); returns its size in bytes.
        """
        from rclpy.serialization import serialize_message

        from .conversions import header

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
        from .conversions import header

        stamp = self._now_ns() if stamp_ns is None else stamp_ns
        msg = self._msgs["PoseStamped"](
            header=header(self.frame_id if frame_id is None else frame_id, stamp),
            pose=self._pose(position, orientation),
        )
        self._grip_pubs[grip].publish(msg)
        return stamp

    def _call(self, client, request, timeout: float):
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
        if not done.wait(timeout):
            client.remove_pending_request(future)
            raise TimeoutError(f"service {client.srv_name}: no response within {timeout} s")
        return future.result()

    def query(
        self, start: tuple, goal: tuple, *, frame_id: str | None = None, timeout: float = 30.0
    ):
        """Call ~/query_shape; returns (points, orientations) of a verified shape, empty arrays for
        any other answer (see :meth:`query_shape` for which).
        """
        answer = self.query_shape(start, goal, frame_id=frame_id, timeout=timeout)
        if answer.verified:
            return answer.points, answer.orientations
        return np.zeros((0, 3)), np.zeros((0, 4))

    def query_shape(
        self, start: tuple, goal: tuple, *, frame_id: str | None = None, timeout: float = 30.0
    ) -> "QueryAnswer":
        """Call ~/query_shape; the reply decoded (``query_reply.decode``): its ``status`` is
        'verified' (a verified, stable equilibrium), 'unverified' (a shape, not verified),
        'no_equilibrium', 'unstable', 'failed', 'invalid', 'busy' or 'not_ready'
        (msg_docs/node.md).
        """
        from .conversions import pose_stamped
        from .query_reply import decode

        frame = self.frame_id if frame_id is None else frame_id
        req = self._msgs["GetPlan"].Request()
        req.start = pose_stamped(start[0], start[1], frame, 0)
        req.goal = pose_stamped(goal[0], goal[1], frame, 0)
        resp = self._call(self._query, req, timeout)
        return decode(resp.plan.header.frame_id, *self._path_to_arrays(resp.plan))

    @property
    def _cloud_pub(self):
        if self._cloud_publisher is None:
            from sensor_msgs.msg import PointCloud2

            from .qos import CLOUD_QOS

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
        """Publish ``points`` (N, 3) [m] as a float32 x, y, z PointCloud2 on ~/observed; returns
        the stamp [ns].
        """
        from .cloud import points_to_cloud

        stamp = self._now_ns() if stamp_ns is None else stamp_ns
        self._cloud_pub.publish(
            points_to_cloud(points, self.frame_id if frame_id is None else frame_id, stamp)
        )
        return stamp

    def publish_cloud_msg(self, msg) -> None:
        """Publish any PointCloud2 (or its serialised bytes) on ~/observed."""
        self._cloud_pub.publish(msg)

    def wait_for_cloud_subscriber(self, timeout: float = 10.0, settle: float = 0.5) -> bool:
        """Wait until the node's ~/observed reader matched (then ``settle`` s more, see
        wait_for_subscribers).
        """
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._cloud_pub.get_subscription_count() > 0:
                time.sleep(settle)
                return True
            time.sleep(0.02)
        return False

    def fit(self, timeout: float = 30.0) -> tuple[bool, str]:
        """Call ~/fit (it answers at once: whether a fit started, and why not)."""
        resp = self._call(self._fit, self._msgs["Trigger"].Request(), timeout)
        return resp.success, resp.message

    def reset(self, timeout: float = 30.0):
        resp = self._call(self._reset, self._msgs["Trigger"].Request(), timeout)
        return resp.success, resp.message

    def set_parameters(self, values: dict, timeout: float = 10.0) -> list[tuple[bool, str]]:
        """Set parameters one by one (each may be refused on its own): [(successful, reason)]."""
        from rclpy.parameter import Parameter

        req = self._msgs["SetParameters"].Request()
        req.parameters = [Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
        resp = self._call(self._set_params, req, timeout)
        return [(r.successful, r.reason) for r in resp.results]

    def get_parameters(self, names: Sequence[str], timeout: float = 10.0) -> dict:
        from rclpy.parameter import parameter_value_to_python

        req = self._msgs["GetParameters"].Request()
        req.names = list(names)
        resp = self._call(self._get_params, req, timeout)
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


def make_executor(kind: str, context=None):
    """A new rclpy executor in ``context`` (default: the default context): 'single'
    (SingleThreadedExecutor, what the node uses) or 'events'
    (rclpy.experimental.EventsExecutor).
    """
    if kind == "single":
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    raise ValueError(f"executor {kind!r}: expected 'single' or 'events'")


class NodeStartError(RuntimeError):
    """The node published no centreline in time; the message carries its output."""


@contextlib.contextmanager
def running_node(
    *node_args: str,
    startup_timeout: float = 60.0,
    log_path: str | os.PathLike | None = None,
    client_name: str = "dlo_test_client",
    stop_signal: int = signal.SIGINT,
    module: str = "dlo_ros.node",
    env: dict | None = None,
    **client_kwargs,
):
    """Start the node (own domain), a client, wait for the first centreline; yield (NodeProcess,
    DloClient).

    On exit the client is closed and the node stopped with ``stop_signal`` (then SIGTERM/SIGKILL of
    its process group); ``proc.returncode`` and ``proc.output()`` stay readable afterwards when
    ``log_path`` is given.  ``module`` and ``env`` go to :class:`NodeProcess` (a stand-in for the
    node, e.g. the benchmark's echo, started the same way).
    """
    lease = allocate_domain_id()
    proc = client = None
    try:
        proc = NodeProcess(
            list(node_args), lease.domain_id, log_path=log_path, env=env, module=module
        )
        client = DloClient(lease.domain_id, client_name=client_name, **client_kwargs)
        deadline = time.monotonic() + startup_timeout
        first = None
        while first is None and proc.alive() and time.monotonic() < deadline:
            first = client.wait_for_path(0.25)
        if first is None:
            raise NodeStartError(
                f"the node published no centreline within {startup_timeout:.0f} s "
                f"(alive: {proc.alive()}); output:\n{proc.output()}"
            )
        if not client.wait_for_subscribers(10.0):
            raise NodeStartError(
                f"the node's target subscriptions did not match; output:\n{proc.output()}"
            )
        yield proc, client
    finally:
        if client is not None:
            client.close()
        if proc is not None:
            proc.stop(sig=stop_signal)
            if log_path is None:
                proc.close()
        lease.release()
