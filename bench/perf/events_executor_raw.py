"""rclpy.experimental.EventsExecutor on this machine's rclpy (issue #38, "A lean hot path in the node").

Three questions, each answered by child processes in their own ROS_DOMAIN_ID (discovery on localhost):

1. Delivery.  A child subscribes geometry_msgs/PoseArray with the node's TARGET_QOS, ``raw=True`` (the
   callback gets the CDR bytes) or ``raw=False``, and has a 50 ms timer; it is spun by
   SingleThreadedExecutor or EventsExecutor, with ``executor.spin()`` or a ``spin_once(timeout_sec=0.1)``
   loop.  This process publishes 20 PoseArrays once the child's reader is matched.  A reporter thread in
   the child prints what arrived (count, Python type), the timer's ticks and the process CPU time.
   Then the real DloNode (default_cable, compile off) under each executor (``spin_once`` loop): do its
   raw target callbacks run?
2. Coroutine services.  A child serves std_srvs/Trigger with a plain callback or an ``async def`` one
   (returning at once, or awaiting an rclpy Future completed by another thread the way the node's
   ``shape_services.await_job`` does, or by a timer) and calls it from a second context.
3. Cost.  A closed loop: this process publishes a PoseArray (2 poses, pre-serialised) and waits for the
   echo child to send the same bytes back (the echo deserialises each one, as the node does, then
   publishes the raw bytes).  The echo's node is
     bare  1 raw subscription + 1 publisher, no parameter or type-description services and no QoS-event
           handlers (wait set: 1 subscription + the executor's 2 guard conditions);
     lean  the same with rclpy's default QoS-event handlers (2 per publisher and subscription: +6
           waitables);
     dlo   a copy of the dlo node's wait set (counted on DloNode, default_cable): 3 raw subscriptions,
           4 timers (0.1, 0.5, 1, 1 s), 9 services (rclpy's 7 + 2), 8 publishers, 22 QoS-event waitables.
   Configurations alternate run by run (same window); the client (this process: bare node,
   SingleThreadedExecutor) is the same in all.  Reported: round trip p50/p99 and the echo process's CPU
   time per message (all its threads, between two marker messages), with ratios to SingleThreadedExecutor
   + dlo.  An in-process figure with no DDS: SingleThreadedExecutor's cost of one wake-up (a guard
   condition triggered, spin_once) for each wait set.

    bash scripts/dlo-env run python bench/perf/events_executor_raw.py [--n 300] [--rounds 3] [--out FILE]

Writes bench/results/events_executor_raw.md (machine, load average, git HEAD).  About a minute.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import signal
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

EXECUTORS = ("single", "events")
SHAPES = ("bare", "lean", "dlo")
COST_CONFIGS = (("single", "dlo"), ("single", "lean"), ("single", "bare"), ("events", "dlo"), ("events", "bare"))
SERVICE_CASES = ("sync", "async_no_await", "async_await_thread", "async_await_timer")
NAMES = {"single": "SingleThreadedExecutor", "events": "EventsExecutor"}
PING, PONG = "/ping", "/pong"


# ---------------------------------------------------------------------------------------------------
# helpers shared by the children
def _executor(kind: str, context):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor

    return SingleThreadedExecutor(context=context) if kind == "single" else EventsExecutor(context=context)


def _no_events():
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks

    return PublisherEventCallbacks(use_default_callbacks=False), SubscriptionEventCallbacks(use_default_callbacks=False)


def strip_waitables(node) -> None:
    """Take the node's QoS-event handlers out of its wait set (``destroy`` puts them back first, since
    rclpy's ``destroy_node`` removes each publisher's handlers from the node's list)."""
    node._stripped = list(node.waitables)
    for w in node._stripped:
        node.remove_waitable(w)


def destroy(node) -> None:
    for w in getattr(node, "_stripped", []):
        node.add_waitable(w)
    node.destroy_node()


def build_node(shape: str, on_ping, context=None, name: str = "echo"):
    """The echo's node in one of SHAPES; returns (node, pong publisher)."""
    from geometry_msgs.msg import PoseArray, PoseStamped
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from dlo_ros.node.qos import LATCHED_QOS, TARGET_QOS

    if shape in ("bare", "lean"):
        node = Node(name, context=context, start_parameter_services=False,
                    parameter_overrides=[Parameter("start_type_description_service", value=False)])
        if shape == "bare":  # the /parameter_events publisher's two QoS-event handlers
            strip_waitables(node)
            pub_ev, sub_ev = _no_events()
            pong = node.create_publisher(PoseArray, PONG, TARGET_QOS, event_callbacks=pub_ev)
            node.create_subscription(PoseArray, PING, on_ping, TARGET_QOS, raw=True, event_callbacks=sub_ev)
        else:
            pong = node.create_publisher(PoseArray, PONG, TARGET_QOS)
            node.create_subscription(PoseArray, PING, on_ping, TARGET_QOS, raw=True)
        return node, pong
    node = Node(name, context=context)  # rclpy's 7 services, /parameter_events
    pong = node.create_publisher(PoseArray, PONG, TARGET_QOS)
    node.create_subscription(PoseArray, PING, on_ping, TARGET_QOS, raw=True)
    for g in ("left", "right"):
        node.create_subscription(PoseStamped, f"~/grips/{g}/target", lambda _d: None, TARGET_QOS, raw=True)
    for k in range(6):  # the node's other publishers: markers, two wrenches, capsules, diagnostics, envelope
        node.create_publisher(PoseArray, f"~/out{k}", LATCHED_QOS)
    for s in ("query_shape", "reset"):
        node.create_service(Trigger, f"~/{s}", lambda _q, r: r)
    for period in (0.1, 0.5, 1.0, 1.0):
        node.create_timer(period, lambda: None)
    return node, pong


def wait_set_size(node) -> dict:
    return {"subscriptions": len(list(node.subscriptions)), "timers": len(list(node.timers)),
            "services": len(list(node.services)), "guards": len(list(node.guards)),
            "waitables": len(list(node.waitables)),
            "events": sum(w.get_num_entities().num_events for w in node.waitables)}


def _spin_forever(executor, kind: str, context) -> None:
    from rclpy.executors import ExternalShutdownException

    try:
        if kind == "single":
            executor.spin()
        else:  # EventsExecutor.spin() livelocks on these wheels (part 1): spin_once with a timeout
            while context.ok():
                executor.spin_once(timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


# ---------------------------------------------------------------------------------------------------
# child roles
def role_deliver(args) -> int:
    """Part 1's subscriber: print a JSON status line every 0.25 s from a side thread."""
    import rclpy
    from geometry_msgs.msg import PoseArray
    from rclpy.node import Node

    from dlo_ros.node.qos import TARGET_QOS

    rclpy.init(args=[])
    context = rclpy.get_default_context()
    node = Node("deliver")
    got: list[str] = []
    ticks = [0]
    node.create_subscription(PoseArray, "/targets", lambda m: got.append(type(m).__name__), TARGET_QOS,
                             raw=bool(args.raw))
    node.create_timer(0.05, lambda: ticks.__setitem__(0, ticks[0] + 1))
    ex = _executor(args.executor, context)
    ex.add_node(node)
    t0 = time.process_time()

    def report():
        while True:
            print(json.dumps({"received": len(got), "types": sorted(set(got)), "ticks": ticks[0],
                              "cpu_s": round(time.process_time() - t0, 3)}), flush=True)
            time.sleep(0.25)

    threading.Thread(target=report, daemon=True).start()
    if args.spin == "spin":
        try:
            ex.spin()
        except Exception:  # noqa: BLE001 - ExternalShutdownException / KeyboardInterrupt
            pass
    else:
        _spin_once_loop(ex, context)
    return 0


def _spin_once_loop(ex, context) -> None:
    try:
        while context.ok():
            ex.spin_once(timeout_sec=0.1)
    except Exception:  # noqa: BLE001
        pass


def role_service(args) -> int:
    """Part 2: serve /probe (executor under test, spin_once loop in a thread), call it from a second
    context; print one JSON line."""
    import rclpy
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.task import Future
    from std_srvs.srv import Trigger

    domain = int(os.environ["ROS_DOMAIN_ID"])
    cs, cc = Context(), Context()
    rclpy.init(context=cs, domain_id=domain)
    rclpy.init(context=cc, domain_id=domain)
    srv_node, cli_node = Node("srv", context=cs), Node("cli", context=cc)
    ex = _executor(args.executor, cs)

    def node_future():  # dlo_ros.node.shape_services.await_job's pattern
        done = Future(executor=srv_node.executor)
        done.add_done_callback(lambda _f: None)  # completing it schedules a task: that wakes the executor
        return done

    def sync(_req, resp):
        resp.success, resp.message = True, "sync"
        return resp

    async def async_no_await(_req, resp):
        resp.success, resp.message = True, "async, returned at once"
        return resp

    async def async_await_thread(_req, resp):
        done = node_future()
        threading.Timer(0.05, lambda: done.set_result("thread")).start()
        resp.success, resp.message = True, f"async, awaited a Future completed by a {await done}"
        return resp

    async def async_await_timer(_req, resp):
        done = node_future()
        timer = []

        def fire():
            timer[0].cancel()
            done.set_result("timer")

        timer.append(srv_node.create_timer(0.05, fire))
        resp.success, resp.message = True, f"async, awaited a Future completed by a {await done}"
        return resp

    callback = {"sync": sync, "async_no_await": async_no_await, "async_await_thread": async_await_thread,
                "async_await_timer": async_await_timer}[args.case]
    srv_node.create_service(Trigger, "/probe", callback, callback_group=ReentrantCallbackGroup())
    ex.add_node(srv_node)
    client = cli_node.create_client(Trigger, "/probe")
    cex = SingleThreadedExecutor(context=cc)
    cex.add_node(cli_node)
    errors: list[str] = []
    stop = threading.Event()

    def serve():
        while not stop.is_set() and cs.ok():
            try:
                ex.spin_once(timeout_sec=0.1)
            except Exception as exc:  # noqa: BLE001 - reported
                where = traceback.extract_tb(exc.__traceback__)[-1]
                errors.append(f"{type(exc).__name__}({exc}) in {Path(where.filename).name}:{where.lineno} "
                              f"{where.name}")
                time.sleep(0.05)

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    client.wait_for_service(timeout_sec=5.0)
    t0 = time.monotonic()
    future = client.call_async(Trigger.Request())
    cex.spin_until_future_complete(future, timeout_sec=3.0)
    dt = time.monotonic() - t0
    stop.set()
    th.join(1.0)
    res = future.result() if future.done() else None
    print(json.dumps({"answered": res is not None, "ms": round(dt * 1e3, 1),
                      "message": res.message if res else None, "errors": errors}), flush=True)
    os._exit(0)  # skip teardown: an EventsExecutor with a failed callback may not shut down cleanly


def role_dlonode(args) -> int:
    """Part 1b: the real DloNode (default_cable, compile off) spun by the executor under test in a
    ``spin_once(timeout_sec=0.2)`` loop; a second context publishes 5 PoseArray targets on
    /dlo/grips/targets.  Counts the node's target callbacks (wrapped) and its 'targets received'."""
    import rclpy
    from geometry_msgs.msg import Pose, PoseArray
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from dlo_ros.node.dlo_node import DloNode
    from dlo_ros.node.qos import TARGET_QOS

    domain = int(os.environ["ROS_DOMAIN_ID"])
    cn, cc = Context(), Context()
    rclpy.init(context=cn, domain_id=domain)
    rclpy.init(context=cc, domain_id=domain)
    node = DloNode(context=cn, parameter_overrides=[Parameter("scene", value="default_cable"),
                                                    Parameter("compile", value="off")])
    calls: dict[str, int] = {}
    types: set[str] = set()
    for sub in node.subscriptions:
        def wrapped(data, cb=sub.callback, name=sub.topic_name):
            calls[name] = calls.get(name, 0) + 1
            types.add(type(data).__name__)
            return cb(data)
        sub.callback = wrapped
    ex = _executor(args.executor, cn)
    ex.add_node(node)
    errors: list[str] = []

    def spin():
        while cn.ok():
            try:
                ex.spin_once(timeout_sec=0.2)
            except Exception as exc:  # noqa: BLE001 - reported
                errors.append(repr(exc)[:160])
                time.sleep(0.2)

    threading.Thread(target=spin, daemon=True).start()
    cli = Node("targets", context=cc)
    pub = cli.create_publisher(PoseArray, "/dlo/grips/targets", TARGET_QOS)
    end = time.monotonic() + 30.0
    while pub.get_subscription_count() == 0 and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(0.5)
    msg = PoseArray()
    msg.header.frame_id = "world"
    msg.poses = [Pose(), Pose()]
    for i in range(5):
        msg.header.stamp.nanosec = 1000 + i
        pub.publish(msg)
        time.sleep(0.5)
    print(json.dumps({"calls": calls, "types": sorted(types), "errors": errors,
                      "targets_received": node.core.health.targets_received}), flush=True)
    os._exit(0)  # the node's solver thread and pools: not the point here


def role_echo(args) -> int:
    """Part 3's echo: deserialise each ping (as the node does), send its bytes back on /pong.
    frame_id 'reset' starts the CPU count, 'report' answers with it (JSON in frame_id)."""
    import rclpy
    from geometry_msgs.msg import PoseArray
    from rclpy.serialization import deserialize_message, serialize_message

    rclpy.init(args=[])
    context = rclpy.get_default_context()
    state = {"cpu0": time.process_time(), "n": 0}
    pong = [None]

    def on_ping(data: bytes) -> None:
        msg = deserialize_message(data, PoseArray)
        fid = msg.header.frame_id
        if fid == "reset":
            state["cpu0"], state["n"] = time.process_time(), 0
        elif fid == "report":
            msg.header.frame_id = json.dumps({"cpu_s": time.process_time() - state["cpu0"], "n": state["n"]})
            pong[0].publish(serialize_message(msg))
            return
        else:
            state["n"] += 1
        pong[0].publish(data)

    node, pong[0] = build_node(args.shape, on_ping)
    ex = _executor(args.executor, context)
    ex.add_node(node)
    print(json.dumps({"ready": True, "wait_set": wait_set_size(node)}), flush=True)
    _spin_forever(ex, args.executor, context)
    return 0


# ---------------------------------------------------------------------------------------------------
# the driver
class Child:
    """A child role of this script in its own domain; its stdout lines collected by a thread."""

    def __init__(self, role_args: list[str]):
        from dlo_ros.node.client import allocate_domain_id, ros_env

        self.lease = allocate_domain_id()
        self.domain = self.lease.domain_id
        self.proc = subprocess.Popen([sys.executable, __file__, *role_args], env=ros_env(self.domain),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())

    def json_lines(self) -> list[dict]:
        out = []
        for ln in list(self.lines):
            if ln.startswith("{"):
                try:
                    out.append(json.loads(ln))
                except ValueError:
                    pass
        return out

    def wait_json(self, key: str, timeout: float) -> dict | None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for d in self.json_lines():
                if key in d:
                    return d
            if self.proc.poll() is not None and not any(key in d for d in self.json_lines()):
                time.sleep(0.1)
                return next((d for d in self.json_lines() if key in d), None)
            time.sleep(0.02)
        return None

    def stop(self) -> str:
        """SIGINT, then SIGKILL after 3 s; returns how it ended."""
        how = "exited"
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(3.0)
                how = "stopped by SIGINT"
            except subprocess.TimeoutExpired:
                self.proc.kill()  # this child only (its own pid)
                self.proc.wait(5.0)
                how = "did not stop on SIGINT within 3 s: killed"
        self.lease.release()
        return how


def client_context(domain: int):
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    return context


def part_delivery() -> list[dict]:
    from geometry_msgs.msg import Pose, PoseArray
    from rclpy.node import Node

    from dlo_ros.node.qos import TARGET_QOS

    rows = []
    for executor in EXECUTORS:
        for raw in (1, 0):
            for spin in ("spin", "spin_once"):
                child = Child(["--role", "deliver", "--executor", executor, "--raw", str(raw), "--spin", spin])
                context = client_context(child.domain)
                node = Node("publisher", context=context)
                pub = node.create_publisher(PoseArray, "/targets", TARGET_QOS)
                end = time.monotonic() + 10.0
                while pub.get_subscription_count() == 0 and time.monotonic() < end:
                    time.sleep(0.02)
                matched = pub.get_subscription_count() > 0
                time.sleep(0.3)  # the child's executor has registered its subscription
                msg = PoseArray()
                msg.header.frame_id = "world"
                msg.poses = [Pose(), Pose()]
                for i in range(20):
                    msg.header.stamp.nanosec = i
                    pub.publish(msg)
                    time.sleep(0.01)
                time.sleep(1.0)
                status = child.json_lines()
                last = status[-1] if status else {}
                first = next((d for d in status if d.get("cpu_s") is not None), {})
                how = child.stop()
                node.destroy_node()
                context.try_shutdown()
                rows.append({"executor": executor, "raw": bool(raw), "spin": spin, "matched": matched,
                             "received": last.get("received"), "types": last.get("types"),
                             "ticks": last.get("ticks"), "cpu_s": last.get("cpu_s"),
                             "cpu_first": first.get("cpu_s"), "stop": how})
                print(rows[-1], flush=True)
    return rows


def part_dlonode() -> list[dict]:
    rows = []
    for executor in EXECUTORS:
        child = Child(["--role", "dlonode", "--executor", executor])
        res = child.wait_json("calls", 90.0) or {"calls": {}, "errors": ["no result"], "types": []}
        child.stop()
        rows.append({"executor": executor, **res})
        print(rows[-1], flush=True)
    return rows


def part_services() -> list[dict]:
    rows = []
    for executor in EXECUTORS:
        for case in SERVICE_CASES:
            child = Child(["--role", "service", "--executor", executor, "--case", case])
            res = child.wait_json("answered", 15.0) or {"answered": False, "errors": ["no result (child hung)"]}
            child.stop()
            rows.append({"executor": executor, "case": case, **res})
            print(rows[-1], flush=True)
    return rows


def one_cost_run(executor: str, shape: str, n: int) -> dict:
    from geometry_msgs.msg import Pose, PoseArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message, serialize_message

    from dlo_ros.node.qos import TARGET_QOS

    child = Child(["--role", "echo", "--executor", executor, "--shape", shape])
    ready = child.wait_json("ready", 20.0)
    if ready is None:
        child.stop()
        raise RuntimeError(f"echo {executor}/{shape} did not start: {child.lines[-5:]}")
    context = client_context(child.domain)
    node = Node("client", context=context, start_parameter_services=False,
                parameter_overrides=[Parameter("start_type_description_service", value=False)])
    strip_waitables(node)
    pub_ev, sub_ev = _no_events()
    inbox: list[bytes] = []
    pub = node.create_publisher(PoseArray, PING, TARGET_QOS, event_callbacks=pub_ev)
    node.create_subscription(PoseArray, PONG, inbox.append, TARGET_QOS, raw=True, event_callbacks=sub_ev)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)

    msg = PoseArray()
    msg.poses = [Pose(), Pose()]

    def ping(frame: str, i: int) -> bytes:
        msg.header.frame_id = frame
        msg.header.stamp.sec, msg.header.stamp.nanosec = i // 1_000_000_000, i % 1_000_000_000
        return serialize_message(msg)

    def exchange(data: bytes, timeout: float) -> bytes | None:
        inbox.clear()
        pub.publish(data)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=timeout)
            if inbox:
                return inbox[-1]
        return None

    # warm up: until the echo answers (VOLATILE: pings before the match are lost)
    end = time.monotonic() + 15.0
    while exchange(ping("world", 0), 0.2) is None:
        if time.monotonic() > end:
            raise RuntimeError(f"echo {executor}/{shape} never answered")
    for i in range(20):
        exchange(ping("world", i), 1.0)
    exchange(ping("reset", 0), 1.0)
    pings = [ping("world", i + 1) for i in range(n)]
    rtt, lost = [], 0
    load0 = os.getloadavg()[0]
    for data in pings:
        t0 = time.perf_counter_ns()
        back = exchange(data, 1.0)
        t1 = time.perf_counter_ns()
        if back == data:
            rtt.append((t1 - t0) / 1e6)
        else:
            lost += 1
    report = exchange(ping("report", 0), 2.0)
    stats = json.loads(deserialize_message(report, PoseArray).header.frame_id) if report else {}
    child.stop()
    ex.shutdown(timeout_sec=1.0)
    destroy(node)
    context.try_shutdown()
    return {"executor": executor, "shape": shape, "rtt_ms": rtt, "lost": lost, "load": load0,
            "wait_set": ready["wait_set"], "echo_cpu_ms_per_msg": 1e3 * stats["cpu_s"] / max(stats["n"], 1)
            if stats else float("nan"), "echo_n": stats.get("n")}


def part_wakeup(iterations: int = 400) -> dict:
    """SingleThreadedExecutor, in-process, no DDS traffic: time of one spin_once woken by a guard
    condition, for each node shape (median, µs)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from dlo_ros.node.client import allocate_domain_id

    out = {}
    with allocate_domain_id() as lease:
        context = client_context(lease.domain_id)
        for shape in SHAPES:
            node, _pub = build_node(shape, lambda _d: None, context=context, name=f"wake_{shape}")
            gc = node.create_guard_condition(lambda: None)
            ex = SingleThreadedExecutor(context=context)
            ex.add_node(node)
            ts = []
            for _ in range(iterations):
                gc.trigger()
                t0 = time.perf_counter_ns()
                ex.spin_once(timeout_sec=1.0)
                ts.append((time.perf_counter_ns() - t0) / 1e3)
            out[shape] = {"median_us": float(np.median(ts)), "p90_us": float(np.percentile(ts, 90)),
                          "wait_set": wait_set_size(node)}
            ex.shutdown(timeout_sec=1.0)
            destroy(node)
        rclpy.try_shutdown(context=context)
    return out


def wheel_facts() -> list[str]:
    import importlib.metadata as md

    import rclpy

    facts = []
    for dist in ("ros-jazzy-rclpy", "ros-rclpy"):
        try:
            facts.append(f"{dist} {md.version(dist)}")
        except md.PackageNotFoundError:
            pass
    so = next(Path(rclpy.__file__).parent.glob("_rclpy_pybind11*.so"), None)
    if so is not None:
        try:
            syms = subprocess.run(["objdump", "-T", str(so)], capture_output=True, text=True, timeout=30).stdout
            facts.append("its `_rclpy_pybind11` imports `pthread_cond_clockwait`: "
                         + ("yes" if "pthread_cond_clockwait" in syms else "no (only `pthread_cond_timedwait`)"))
        except (OSError, subprocess.SubprocessError):
            pass
        wheel = next(Path(rclpy.__file__).parent.parent.glob("ros_rclpy-*.dist-info/WHEEL"), None)
        if wheel is not None:
            tags = [ln.split(":", 1)[1].strip() for ln in wheel.read_text().splitlines() if ln.startswith("Tag:")]
            facts.append("wheel tag " + ", ".join(tags))
    return facts


# ---------------------------------------------------------------------------------------------------
def fmt(x: float, nd: int = 2) -> str:
    return "–" if x != x else f"{x:.{nd}f}"


def report(args, delivery, dlonode, services, runs, wake, loads, facts, minutes) -> list[str]:
    from bench.common import machine

    m = machine()
    lines = ["# EventsExecutor, raw subscriptions and the cost of the wait set (issue #38)", ""]
    lines += [f"Measured {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')} in {minutes:.1f} min: {m.get('cpu')}, "
              f"{m.get('cpus')} CPUs shared with other work (load average {loads[0]:.2f} at the start, "
              f"{loads[1]:.2f} at the end), Python {m.get('python')}, {'; '.join(facts)}, Fast DDS, "
              f"discovery on localhost; git {m.get('git')}.", ""]

    if delivery:
        lines += part1_lines(delivery, dlonode)
    if services:
        lines += part2_lines(services)
    if runs:
        lines += part3_lines(args, runs, wake)
    if delivery or services:
        lines += NOTES.splitlines()
    return lines


def part1_lines(delivery, dlonode) -> list[str]:
    lines = ["## 1. Do raw subscriptions deliver under EventsExecutor?", "",
              "A child subscribes PoseArray (TARGET_QOS: reliable, volatile, keep last 1) and has a 50 ms timer; "
              "this process publishes 20 PoseArrays after the match and waits 1 s. Child CPU: process time "
              "over its whole life (about 2 s).", "",
              "| executor | raw | spun by | received | Python type | timer ticks | child CPU [s] | stop |",
              "| --- | --- | --- | ---: | --- | ---: | ---: | --- |"]
    for r in delivery:
        lines.append(f"| {NAMES[r['executor']]} | {r['raw']} | `{'spin()' if r['spin'] == 'spin' else 'spin_once(0.1) loop'}` "
                     f"| {r['received']}/20 | {', '.join(r['types'] or []) or '–'} | {r['ticks']} | {r['cpu_s']} | {r['stop']} |")
    if dlonode:
        lines += ["", "The real `DloNode` (scene default_cable, compile off) in a child, spun by a "
                  "`spin_once(timeout_sec=0.2)` loop; 5 PoseArray targets (2 identity poses: the node may "
                  "reject or fail to solve them, what counts here is that its callback runs):", "",
                  "| executor | target callbacks run (topic: count) | Python type | node's 'targets received' "
                  "| executor raised |", "| --- | --- | --- | ---: | --- |"]
        for r in dlonode:
            calls = ", ".join(f"{k}: {v}" for k, v in r.get("calls", {}).items()) or "none"
            err = r.get("errors") or []
            lines.append(f"| {NAMES[r['executor']]} | {calls} | {', '.join(r.get('types') or []) or '–'} "
                         f"| {r.get('targets_received', '–')} | {err[0] if err else '–'} |")
    return lines + [""]


def part2_lines(services) -> list[str]:
    lines = ["## 2. Coroutine (async def) service callbacks", "",
              "Server spun by the executor under test (`spin_once(0.1)` loop, ReentrantCallbackGroup), client in "
              "a second context; 3 s to answer.", "",
              "| executor | callback | answered | time [ms] | server executor raised |",
              "| --- | --- | --- | ---: | --- |"]
    for r in services:
        err = r.get("errors") or []
        lines.append(f"| {NAMES[r['executor']]} | {r['case']} | {'yes: ' + repr(r.get('message')) if r['answered'] else 'no'} "
                     f"| {r.get('ms') if r['answered'] else '–'} | {(err[0] + (f' (x{len(err)})' if len(err) > 1 else '')) if err else '–'} |")
    return lines + [""]


def part3_lines(args, runs, wake) -> list[str]:
    lines = ["## 3. Cost: closed-loop round trip and the echo's CPU per message", "",
              f"{args.rounds} rounds of {args.n} round trips per configuration, configurations alternating; "
              "the client is the same bare node with SingleThreadedExecutor in every run. Ratios: against "
              "SingleThreadedExecutor + dlo (the node today), same window. Echo CPU: all of the echo process's "
              "threads, per message, median over the runs.", "",
              "| echo executor | echo node (wait set) | round trips | RTT p50 [ms] | RTT p99 [ms] | p50 ratio | p99 ratio "
              "| echo CPU / msg [ms] | CPU ratio | per-run p50 [ms] | load |",
              "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |"]
    agg = {}
    for cfg in COST_CONFIGS:
        rs = [r for r in runs if (r["executor"], r["shape"]) == cfg]
        rtt = np.concatenate([r["rtt_ms"] for r in rs]) if rs else np.array([])
        agg[cfg] = {"p50": float(np.median(rtt)) if rtt.size else float("nan"),
                    "p99": float(np.percentile(rtt, 99)) if rtt.size else float("nan"),
                    "cpu": float(np.median([r["echo_cpu_ms_per_msg"] for r in rs])) if rs else float("nan"),
                    "n": int(rtt.size), "lost": sum(r["lost"] for r in rs), "runs": rs}
    base = agg[("single", "dlo")]
    for cfg in COST_CONFIGS:
        a = agg[cfg]
        ws = a["runs"][0]["wait_set"] if a["runs"] else {}
        wtxt = (f"{cfg[1]}: {ws.get('subscriptions')} subs, {ws.get('timers')} timers, {ws.get('services')} services, "
                f"{ws.get('waitables')} QoS-event waitables") if ws else cfg[1]
        per_run = ", ".join(fmt(float(np.median(r["rtt_ms"]))) for r in a["runs"])
        loads_txt = ", ".join(f"{r['load']:.1f}" for r in a["runs"])
        lost_txt = f" ({a['lost']} lost)" if a["lost"] else ""
        lines.append(f"| {NAMES[cfg[0]]} | {wtxt} | {a['n']}{lost_txt} "
                     f"| {fmt(a['p50'])} | {fmt(a['p99'])} | {fmt(a['p50'] / base['p50'])} | {fmt(a['p99'] / base['p99'])} "
                     f"| {fmt(a['cpu'], 3)} | {fmt(a['cpu'] / base['cpu'])} | {per_run} | {loads_txt} |")
    lines += ["", "SingleThreadedExecutor, in this process, no DDS traffic: one wake-up (a guard condition triggered, "
              "`spin_once`: wait-set rebuild, wait, dispatch of an empty callback), median of 400:", "",
              "| node | wait set | median [µs] | p90 [µs] |", "| --- | --- | ---: | ---: |"]
    for shape, w in wake.items():
        ws = w["wait_set"]
        lines.append(f"| {shape} | {ws['subscriptions']} subs, {ws['timers']} timers, {ws['services']} services, "
                     f"{ws['guards']} guard (+2 of the executor), {ws['waitables']} waitables | {w['median_us']:.0f} | {w['p90_us']:.0f} |")
    sd, sb, ed = agg[("single", "dlo")], agg[("single", "bare")], agg[("events", "dlo")]
    if wake:
        lines += ["", f"Reading: the dlo node's wait set costs SingleThreadedExecutor "
                  f"{wake['dlo']['median_us'] - wake['bare']['median_us']:.0f} µs more per wake-up than a bare "
                  f"one-subscription node, in-process; across processes the bare echo answers "
                  f"{sd['p50'] - sb['p50']:.2f} ms sooner (p50) and spends {sd['cpu'] - sb['cpu']:.3f} ms less "
                  f"CPU per message; EventsExecutor answers {sb['p50'] - ed['p50']:.2f} ms sooner than the bare "
                  "SingleThreadedExecutor echo and its cost does not depend on the wait set (dlo ≈ bare)."]
    return lines + [""]


NOTES = """## Why

- **EventsExecutor.spin() livelocks on these wheels; raw or not does not matter.** The events
  executor's C++ queue (rclpy/src/rclpy/events_executor/events_queue.cpp) implements `Run()` as
  `RunUntil(std::chrono::steady_clock::time_point::max())`, which waits with
  `cv_.wait_until(lock, deadline, pred)`.  The PyPI wheels are built for manylinux_2_28 (glibc 2.28),
  without `pthread_cond_clockwait` (glibc 2.30); libstdc++ then waits on the system clock and converts
  the steady deadline by adding it to `system_clock::now()`: `time_point::max()` overflows to a negative
  absolute time (seen with gdb: `pthread_cond_timedwait` called in a loop with `tv_sec = -7426813791`,
  a negative `tv_nsec`), the wait returns at once without releasing the queue's mutex, and libstdc++
  reports "no timeout" because `steady_clock::now() < max()`, so the predicate loop never ends.  One
  core spins, the mutex stays held: DDS listener threads block in `Enqueue` (nothing is ever
  dispatched: subscriptions, timers, services), and a Python thread that touches the executor while
  holding the GIL (a `Future` completed from another thread, an in-process publish) freezes the whole
  process.  `spin()`, `spin_once()` with no timeout and `spin_until_future_complete()` with no timeout
  take this path; `spin_once(timeout_sec=t)` uses `steady_clock::now() + t` and works.
- **Coroutine services** raise `TypeError` in `Service.send_response`: the executor sends the coroutine
  object as the response (ros2/rclpy#1473, fixed on rolling by ros2/rclpy#1478; not in the Jazzy
  branch's CHANGELOG.rst, 7.1.4 to 7.1.9).  Plain (sync) service callbacks work.
- EventsExecutor also refuses nodes with guard conditions (`spin_once` raises RuntimeError "Guard
  conditions not supported"; the node's fitter has one) and ignores callback groups.
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=300, help="round trips per run (default 300)")
    ap.add_argument("--rounds", type=int, default=3, help="runs per configuration (default 3)")
    ap.add_argument("--skip", nargs="*", default=[], choices=["delivery", "services", "cost"])
    ap.add_argument("--out", default=None, help="report file (default bench/results/events_executor_raw.md)")
    ap.add_argument("--role", choices=["deliver", "service", "echo", "dlonode"], help=argparse.SUPPRESS)
    ap.add_argument("--executor", choices=EXECUTORS, default="single", help=argparse.SUPPRESS)
    ap.add_argument("--shape", choices=SHAPES, default="bare", help=argparse.SUPPRESS)
    ap.add_argument("--raw", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--spin", choices=["spin", "spin_once"], default="spin_once", help=argparse.SUPPRESS)
    ap.add_argument("--case", choices=SERVICE_CASES, default="sync", help=argparse.SUPPRESS)
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    if args.role == "deliver":
        return role_deliver(args)
    if args.role == "service":
        return role_service(args)
    if args.role == "echo":
        return role_echo(args)
    if args.role == "dlonode":
        return role_dlonode(args)

    from bench.common import RESULTS, write_report

    t_start, load_start = time.monotonic(), os.getloadavg()[0]
    facts = wheel_facts()
    delivery = part_delivery() if "delivery" not in args.skip else []
    dlonode = part_dlonode() if "delivery" not in args.skip else []
    services = part_services() if "services" not in args.skip else []
    runs = []
    wake = {}
    if "cost" not in args.skip:
        for rnd in range(args.rounds):
            order = COST_CONFIGS if rnd % 2 == 0 else tuple(reversed(COST_CONFIGS))
            for executor, shape in order:
                r = one_cost_run(executor, shape, args.n)
                runs.append(r)
                print(f"round {rnd + 1}: {executor}/{shape}: p50 {np.median(r['rtt_ms']):.3f} ms, "
                      f"p99 {np.percentile(r['rtt_ms'], 99):.3f} ms, echo CPU {r['echo_cpu_ms_per_msg']:.3f} ms/msg, "
                      f"lost {r['lost']}, load {r['load']:.2f}", flush=True)
        wake = part_wakeup()
    lines = report(args, delivery, dlonode, services, runs, wake, (load_start, os.getloadavg()[0]), facts,
                   (time.monotonic() - t_start) / 60)
    out = Path(args.out) if args.out else RESULTS / "events_executor_raw.md"
    argv_out = [a for a in (sys.argv[1:] if argv is None else argv)]
    write_report(lines, out, "bench/perf/events_executor_raw.py", argv_out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
