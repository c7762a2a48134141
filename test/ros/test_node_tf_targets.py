"""Grip targets from tf2 frames (grips.<grip>.tf_frame, #40) in a node process: without tf2_ros (the
PyPI wheels have none) a frame set is a clear start-up error; a grip the scene does not have is one
too; with tf2_ros (a ROS installation) the shape follows a broadcast frame."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from dlo_ros.node.client import allocate_domain_id, ros_env, running_node
from support.node import node_args

try:
    import tf2_ros  # noqa: F401
    HAVE_TF2 = True
except ImportError:
    HAVE_TF2 = False


def run_node(*args: str) -> subprocess.CompletedProcess:
    with allocate_domain_id() as lease:
        return subprocess.run([sys.executable, "-m", "dlo_ros.node", *args], env=ros_env(lease.domain_id),
                              capture_output=True, text=True, timeout=60, start_new_session=True)


def test_a_grip_the_scene_lacks_is_named():
    done = run_node(*node_args("grips.middle.tf_frame:=tool0"))
    assert done.returncode == 2, done.stdout + done.stderr
    assert "grips.middle.tf_frame" in done.stderr and "no grip 'middle'" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.skipif(HAVE_TF2, reason="tf2_ros is importable: the node reads the frame (next test)")
def test_a_tf_frame_without_tf2_is_a_clear_error():
    done = run_node(*node_args("grips.right.tf_frame:=tool0"))
    assert done.returncode == 2, done.stdout + done.stderr
    assert "grips.right.tf_frame='tool0'" in done.stderr and "tf2_ros" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.skipif(not HAVE_TF2, reason="tf2_ros is not importable here (not on PyPI)")
def test_the_shape_follows_a_broadcast_frame(tmp_path):
    from geometry_msgs.msg import TransformStamped
    from tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster

    with running_node(*node_args("grips.right.tf_frame:=tool0"), log_path=tmp_path / "node.log") as (proc, cl):
        t = TransformStamped()
        t.header.stamp = cl.node.get_clock().now().to_msg()
        t.header.frame_id, t.child_frame_id = "world", "tool0"
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = 0.5, 0.1, 0.35
        t.transform.rotation.w = 1.0
        broadcaster = StaticTransformBroadcaster(cl.node)
        broadcaster.sendTransform(t)
        ev = cl.wait_for_path(30.0, where=lambda e: np.allclose(e.points[-1], (0.5, 0.1, 0.35), atol=1e-6))
        assert ev is not None, proc.output()


def test_a_tf_frame_needs_use_tf():
    done = run_node(*node_args("use_tf:=false", "grips.right.tf_frame:=tool0"))
    assert done.returncode == 2, done.stdout + done.stderr
    assert "grips.right.tf_frame='tool0'" in done.stderr and "use_tf" in done.stderr


def test_an_invalid_planning_scene_topic_is_named():
    done = run_node(*node_args("planning_scene.topic:=bad topic!!"))
    assert done.returncode == 2, done.stdout + done.stderr
    assert "planning_scene.topic" in done.stderr and "Traceback" not in done.stderr
