"""A stand-in for the dlo node that answers every target at once without solving: the floor of node_latency.py.

To a :class:`dlo_ros.node.client.DloClient` it looks like the node: node name ``dlo``; it subscribes
``~/grips/targets`` (PoseArray) and ``~/grips/<grip>/target`` (PoseStamped) serialised (``raw``) with the
node's ``TARGET_QOS`` and deserialises each message as the node does; for each one it publishes on
``~/centerline`` (``LATCHED_QOS``) a nav_msgs/Path of ``--points`` poses (default 51, the node's output
points) with the target's header stamp, built by the node's own CDR builder (``conversions.path_cdr``), so
serialisation costs the same.  No checks, no solve, no thread hand-off: the answer is published from the
subscription callback.  One Path (stamp 0) is published at start-up, as the node publishes its first shape,
so :func:`running_node`'s wait for the first centreline works unchanged.

    python -m bench.perf.echo_node [--executor single|events] [--points 51]

It is started like the node (:func:`dlo_ros.node.client.running_node` with ``module=``: its own
ROS_DOMAIN_ID, discovery on localhost) and stops on SIGINT/SIGTERM.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import rclpy
from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Path
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from dlo_ros.node.client import make_executor
from dlo_ros.node.conversions import path_cdr, time_to_ns
from dlo_ros.node.qos import LATCHED_QOS, TARGET_QOS

NODE_NAME = "dlo"
GRIPS = ("left", "right")
FRAME_ID = "world"
EXECUTORS = ("single", "events")  # dlo_ros.node.client.make_executor


def straight_path(n_points: int, length: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) [m], quaternions (n, 4)) of a straight cable of ``length`` [m] along x: any shape
    serialises to the same number of bytes, so the values do not matter."""
    points = np.zeros((n_points, 3))
    points[:, 0] = np.linspace(0.0, length, n_points)
    orientations = np.tile([0.0, 0.0, 0.0, 1.0], (n_points, 1))
    return points, orientations


class EchoNode:
    """The rclpy node: every target message in, one Path with its stamp out."""

    def __init__(self, n_points: int):
        self.node = Node(NODE_NAME)
        self.points, self.orientations = straight_path(n_points)
        self.answered = 0
        self._path_pub = self.node.create_publisher(Path, "~/centerline", LATCHED_QOS)
        # raw, then deserialize_message, as the node does (it checks the size before deserialising)
        self._subs = [self.node.create_subscription(PoseArray, "~/grips/targets",
                                                    lambda data: self._echo(data, PoseArray), TARGET_QOS, raw=True)]
        self._subs += [self.node.create_subscription(PoseStamped, f"~/grips/{g}/target",
                                                     lambda data: self._echo(data, PoseStamped), TARGET_QOS, raw=True)
                       for g in GRIPS]
        self.publish(0)

    def publish(self, stamp_ns: int) -> None:
        """One Path with header stamp ``stamp_ns`` [ns], pre-serialised like the node's."""
        self._path_pub.publish(path_cdr(self.points, self.orientations, FRAME_ID, stamp_ns))

    def _echo(self, data: bytes, kind: type) -> None:
        msg = deserialize_message(data, kind)
        # counted before the Path goes out: a client that has it may stop the echo at once, and the stop
        # can interrupt this callback right after the publish
        self.answered += 1
        self.publish(time_to_ns(msg.header.stamp))


def spin(executor, kind: str) -> None:
    """Spin until the context shuts down (SIGINT/SIGTERM)."""
    if kind == "single":
        executor.spin()  # as the node does
        return
    # EventsExecutor.spin() (rclpy 7.1.5) dispatched nothing here, neither subscriptions (raw or not) nor
    # timers; spin_once in a loop, as DloClient spins, delivers both
    while rclpy.ok():
        executor.spin_once(timeout_sec=0.1)


def main(argv: list[str] | None = None) -> int:
    """Run the echo until SIGINT/SIGTERM; returns the exit code."""
    ap = argparse.ArgumentParser(prog="python -m bench.perf.echo_node", description=__doc__.split("\n\n")[0])
    ap.add_argument("--executor", choices=EXECUTORS, default="single", help="rclpy executor (default single)")
    ap.add_argument("--points", type=int, default=51, help="poses per Path (default 51, the node's output points)")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)

    rclpy.init(args=[])  # the domain comes from ROS_DOMAIN_ID in the environment, as for the node
    echo = executor = None
    try:
        echo = EchoNode(args.points)
        executor = make_executor(args.executor)
        executor.add_node(echo.node)
        print(f"echo_node: ready ({args.executor} executor, {args.points} poses per Path)", flush=True)
        spin(executor, args.executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if echo is not None:
            print(f"echo_node: answered {echo.answered} targets", flush=True)
            if executor is not None:
                executor.shutdown(timeout_sec=2.0)
            echo.node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
