"""The node's hot path (#38): the target subscriptions on a small hidden node with its own executor and
thread.  Topic names unchanged (namespace, name), targets delivered without the main executor, the
thread made and ended with the core (plain node, every managed transition), and both executors stopped
cleanly by SIGINT and SIGTERM while targets stream, with nothing left behind."""
from __future__ import annotations

import signal
import threading
import time

import pytest
import rclpy
from geometry_msgs.msg import PoseArray
from rclpy.context import Context
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter

from dlo_ros.node.client import DloClient, NodeProcess, allocate_domain_id
from dlo_ros.node.client.lifecycle import LifecycleClient
from dlo_ros.node.conversions import arrays_to_pose, header
from dlo_ros.node.dlo_node import DloNode
from dlo_ros.node.hot_path import THREAD_NAME, HotPath
from dlo_ros.node.managed import ManagedDloNode
from dlo_ros.node.qos import TARGET_QOS
from support.node import TEST_SCENE, assert_stopped_cleanly, group_processes, node_args, wait_until

LEFT = ((0.0, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))
RIGHT = ((0.55, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))
OK = TransitionCallbackReturn.SUCCESS
OVERRIDES = [Parameter("scene", value=TEST_SCENE), Parameter("compile", value="off"),
             Parameter("query_workers", value=0)]


def target_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == THREAD_NAME]


def send_targets(pub_node: Node, topic: str, frame: str, received, before: int) -> None:
    """Publish PoseArray targets on ``topic`` until ``received()`` exceeds ``before`` (10 s at most)."""
    pub = pub_node.create_publisher(PoseArray, topic, TARGET_QOS)
    try:
        assert wait_until(lambda: pub.get_subscription_count() >= 1, 10.0), f"nobody subscribes {topic}"
        msg = PoseArray(header=header(frame, time.time_ns()), poses=[arrays_to_pose(p, q) for p, q in (LEFT, RIGHT)])
        assert wait_until(lambda: pub.publish(msg) or received() > before, 10.0, period=0.1)
    finally:
        pub_node.destroy_publisher(pub)


@pytest.fixture
def context(request):
    """An rclpy context in its own domain; the test's parameter: its command-line arguments."""
    with allocate_domain_id() as lease:
        ctx = Context()
        rclpy.init(args=getattr(request, "param", []), context=ctx, domain_id=lease.domain_id)
        try:
            yield ctx
        finally:
            ctx.try_shutdown()


REMAPPED = ["--ros-args", "-r", "__node:=cable", "-r", "__ns:=/cell1", "-r", "/cell1/cable/grips/targets:=/robot/targets"]


@pytest.mark.parametrize("context", [REMAPPED], indirect=True)
def test_targets_arrive_on_a_hidden_node_under_the_nodes_own_topic_names(context):
    """Name, namespace and a topic remapped on the command line: the small node is hidden beside the
    node (the `__node` remap does not rename it too) and subscribes to the node's resolved names.
    Nothing spins the main node here: a target reaches the engine through the hot path alone."""
    assert not target_threads()
    node = DloNode(context=context, parameter_overrides=OVERRIDES)
    helper = Node("helper", context=context, use_global_arguments=False)
    try:
        assert node.get_fully_qualified_name() == "/cell1/cable"
        hot = node.core.hot
        assert hot.node.get_fully_qualified_name() == "/cell1/_cable_hot"
        grips = node.core.grip_names
        expected = {f"/cell1/cable/grips/{g}/target" for g in grips} | {"/robot/targets"}
        assert {s.topic_name for s in hot.node.subscriptions} == expected
        assert not expected & {s.topic_name for s in node.subscriptions}, "a target topic on the main node"
        assert not list(hot.node.services) and not list(hot.node.timers) and not list(hot.node.guards)
        assert len(target_threads()) == 1 and hot.alive
        engine = node.core.engine
        send_targets(helper, "/robot/targets", node.core.frame_id, lambda: engine.targets_received, 0)
    finally:
        helper.destroy_node()
        assert node.close()
        node.destroy_node()
    assert not target_threads(), "the target thread outlived close()"
    assert not hot.alive


def test_a_failing_callback_is_logged_and_the_thread_goes_on(context):
    main = Node("main", context=context)
    helper = Node("helper", context=context)
    hot = HotPath(main)
    calls = []

    def callback(data: bytes) -> None:
        calls.append(data)
        if len(calls) == 1:
            raise RuntimeError("a bug")

    try:
        hot.subscribe(PoseArray, "~/in", callback, TARGET_QOS)
        hot.start()
        send_targets(helper, "/main/in", "world", lambda: len(calls), 1)
        assert hot.alive and isinstance(calls[-1], bytes)
    finally:
        assert hot.close()
        helper.destroy_node()
        main.destroy_node()
    assert not hot.alive and not target_threads()


def test_a_managed_node_makes_and_ends_the_target_thread_with_each_core(context):
    node = ManagedDloNode(context=context, parameter_overrides=OVERRIDES)
    helper = Node("helper", context=context)
    try:
        assert not target_threads()  # unconfigured: no target subscriptions at all
        for _ in range(2):
            assert node.trigger_configure() == OK
            assert len(target_threads()) == 1
            core = node.core
            assert core is not None and core.hot.node.get_fully_qualified_name() == "/_dlo_hot"
            # inactive: a target reaches the callback and is refused, as before the hot path
            health = core.health
            send_targets(helper, "/dlo/grips/targets", core.frame_id, lambda: health.rejected, health.rejected)
            assert health.last_error_kind == "inactive", health.last_error
            assert core.engine.targets_received == 0
            assert node.trigger_activate() == OK
            send_targets(helper, "/dlo/grips/targets", core.frame_id, lambda: core.engine.targets_received, 0)
            assert node.trigger_deactivate() == OK
            hot = core.hot
            assert node.trigger_cleanup() == OK
            assert not target_threads() and not hot.alive
        assert node.trigger_configure() == OK
        assert len(target_threads()) == 1
        assert node.trigger_shutdown() == OK
        assert not target_threads()
    finally:
        helper.destroy_node()
        node.close()
        node.destroy_node()


@pytest.mark.parametrize("managed", [False, True], ids=["plain", "managed"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_targets_stream_stops_both_executors(tmp_path, sig, managed):
    """The signal lands while targets arrive at about 200 Hz: exit code 0 within the stop timeout, no
    traceback, no warning that a thread did not stop, nothing left in the process group."""
    log = tmp_path / "node.log"
    with allocate_domain_id() as lease:
        args = ["--managed", *node_args()] if managed else list(node_args())
        proc = NodeProcess(args, lease.domain_id, log_path=log)
        try:
            with DloClient(lease.domain_id) as client:
                if managed:
                    lc = LifecycleClient(client)
                    assert lc.state(30.0) == "unconfigured"
                    assert lc.change("configure", 60.0) and lc.change("activate"), proc.output()
                assert client.wait_for_path(60.0) is not None, proc.output()
                assert client.wait_for_subscribers(10.0)
                for i in range(200):
                    client.publish_targets([LEFT, ((0.5 + 0.05 * (i % 2), 0.0, 0.4), RIGHT[1])])
                    if i == 100:
                        t0 = time.monotonic()
                        proc.send_signal(sig)
                    time.sleep(0.005)
            assert_stopped_cleanly(proc, t0, 15.0, 10.0)
        finally:
            proc.stop()
    text = log.read_text()
    assert "Traceback" not in text and "did not stop" not in text and "target callback failed" not in text, text

