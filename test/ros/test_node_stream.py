"""The node over real DDS (node in a subprocess, its own ROS_DOMAIN_ID per test): streaming targets.

* a target published from this process gives a centreline whose end poses are the targets, and a
  WrenchStamped per grip equal to what a ShapeSolver in this process computes for the same targets;
* a late subscriber receives the current centreline (and markers) without anything new being sent.
"""
from __future__ import annotations


import numpy as np
import pytest

from dlo_ros.node.client import DloClient
from support.node import clean_node, node_args
from support.problems import quat_about

NODE_ARGS = node_args("diagnostics_period:=0.2")
Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)


def same_rotation(q1, q2, atol=1e-6) -> bool:
    return abs(abs(float(np.dot(q1, q2))) - 1.0) < atol


@pytest.fixture
def node(tmp_path):
    with clean_node(*NODE_ARGS, log_path=tmp_path / "node.log") as proc_client:
        yield proc_client


@pytest.fixture
def reference(node_scene):
    """A fresh solver of the node's model on its scene, in this process, after a first solve."""
    scene, build_solver = node_scene

    def make():
        solver = build_solver(scene.problem, scene.options)
        assert solver.solve().ok
        return solver
    return make


def test_target_gives_centreline_and_wrenches(node, reference):
    proc, cl = node
    right = ((0.5, 0.05, 0.45), quat_about("z", 0.2))
    stamp = cl.publish_targets([LEFT, right])
    ev = cl.wait_for_path(15.0, where=lambda e: e.stamp_ns == stamp)
    assert ev is not None, proc.output()
    assert ev.frame_id == "world" and len(ev.points) == 51
    np.testing.assert_allclose(ev.points[0], LEFT[0], atol=1e-7)
    np.testing.assert_allclose(ev.points[-1], right[0], atol=1e-7)
    assert same_rotation(ev.orientations[0], LEFT[1]) and same_rotation(ev.orientations[-1], right[1])
    wrenches = cl.wait_for(lambda: len(cl.wrenches) == 2 and all(w[0] == stamp for w in cl.wrenches.values())
                           and dict(cl.wrenches), 5.0)
    assert wrenches, cl.wrenches

    ref = reference()
    r = ref.solve({"left": LEFT, "right": right})
    assert r.ok and r.stable
    np.testing.assert_allclose(ev.points, r.points, atol=1e-7)
    scale = max(np.abs(r.grips["left"].force).max(), 1e-3)
    for grip in ("left", "right"):
        _, force, torque = wrenches[grip]
        np.testing.assert_allclose(force, r.grips[grip].force, atol=1e-6 * scale, rtol=1e-6)
        np.testing.assert_allclose(torque, r.grips[grip].torque, atol=1e-6 * scale, rtol=1e-6)
    # equilibrium of the whole string: grip forces carry its weight (D L = 0.5 N), nothing else acts
    total = wrenches["left"][1] + wrenches["right"][1]
    np.testing.assert_allclose(total, [0.0, 0.0, 0.5], atol=1e-6)

    # one grip's own topic: the other grip keeps its target
    right2 = ((0.45, 0.05, 0.5), quat_about("z", 0.3))
    stamp2 = cl.publish_grip("right", *right2)
    ev2 = cl.wait_for_path(15.0, where=lambda e: e.stamp_ns == stamp2)
    assert ev2 is not None
    np.testing.assert_allclose(ev2.points[0], LEFT[0], atol=1e-7)
    np.testing.assert_allclose(ev2.points[-1], right2[0], atol=1e-7)
    r2 = ref.solve({"right": right2})
    np.testing.assert_allclose(ev2.points, r2.points, atol=1e-7)
    values, status = cl.wait_for_diagnostics(lambda v, st: v.get("updates") == "3", 5.0)
    assert status.level == b"\x00" and values["stable"] == "true" and values["warm started"] == "true"
    assert values["status"] == "ok" and values["errors.internal"] == "0"
    # the node's own memory, as the OS counts it (VmRSS), is in the diagnostics
    assert abs(float(values["rss MB"]) - proc.rss_bytes() / 2**20) < 0.2 * proc.rss_bytes() / 2**20
    assert float(values["equilibrium residual m"]) < 1e-3


def test_late_subscriber_gets_the_current_centreline(node):
    proc, cl = node
    right = ((0.55, -0.05, 0.35), quat_about("z", -0.1))
    stamp = cl.publish_targets([LEFT, right])
    ev = cl.wait_for_path(15.0, where=lambda e: e.stamp_ns == stamp)
    assert ev is not None
    assert cl.wait_for(lambda: cl.markers is not None and cl.marker_count, 5.0)
    with DloClient(proc.domain_id, client_name="late_subscriber") as late:
        got = late.wait_for_path(10.0)
        assert got is not None, "a late subscriber got no centreline"
        assert got.stamp_ns == stamp and late.path_count == 1
        np.testing.assert_array_equal(got.points, ev.points)
        markers = late.wait_for(lambda: late.markers, 5.0)
        assert markers is not None
        namespaces = {m.ns for m in markers.markers}
        assert {"string", "grips", "forces", "obstacles"} <= namespaces
    assert proc.alive()


def test_markers_follow_markers_period(tmp_path):
    """markers_period sets how often ~/markers is published while shapes stream in (never per update)."""
    import time

    with clean_node(*node_args("diagnostics_period:=0.2", "markers_period:=0.5"),
                    log_path=tmp_path / "node.log") as (proc, cl):
        assert cl.wait_for(lambda: cl.marker_count, 10.0)
        before, paths = cl.marker_count, cl.path_count
        t0 = time.monotonic()
        k = 0
        while time.monotonic() - t0 < 3.0:  # a 50 Hz stream of small moves
            k += 1
            cl.publish_targets([LEFT, ((0.55 + 0.02 * np.sin(0.2 * k), 0.0, 0.38), Q)])
            time.sleep(0.02)
        streamed = cl.path_count - paths
        markers = cl.marker_count - before
        assert streamed >= 30, streamed  # the stream did run
        assert 3 <= markers <= 8, markers  # 3 s at 0.5 s, with the timer's phase
