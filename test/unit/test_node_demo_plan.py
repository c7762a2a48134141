"""The demo's plan, without a node: the dual-arm targets, the demo scene, and when the job counts the
final model as settled (test/ros/test_node_demo.py runs the demo over real DDS)."""
from __future__ import annotations

from dlo_ros.node.demo import KEYFRAMES, targets_at, write_demo_scene


def test_demo_targets_are_continuous_and_reachable():
    import numpy as np

    prev = None
    for t in np.linspace(0.0, KEYFRAMES[-1][0], 901):
        (lp, lq), (rp, rq) = targets_at(t)
        assert np.linalg.norm(rp - lp) < 1.0  # within the 1 m cable's reach
        assert abs(np.linalg.norm(lq) - 1) < 1e-12 and abs(np.linalg.norm(rq) - 1) < 1e-12
        if prev is not None:
            assert np.linalg.norm(rp - prev) < 0.01  # smooth: < 1 cm per 10 ms
        prev = rp


def test_demo_scene(tmp_path):
    from dlo_ros.scene import load_scene

    scene = load_scene(write_demo_scene(tmp_path))
    assert [o.type for o in scene.problem.obstacles] == ["halfspace", "sphere"]
    assert scene.problem.obstacles[-1].name == "post"


def test_settled_means_the_final_shape_checked_and_met_or_the_richest_order():
    from dlo_ros.node.demo import model_settled
    from dlo_ros.solver.auto import ORDERS

    auto = {"model.auto": "True", "model.checked": "True", "model.tolerance_met": "True", "model.order": "16",
            "model.checked_updates_ago": "0"}
    assert model_settled(auto)
    assert not model_settled({**auto, "model.checked": "False"})  # the estimate describes an earlier model
    # a check of a shape 3 updates before the final one: settled only after 3 solves of the last target
    assert not model_settled({**auto, "model.checked_updates_ago": "3"})
    assert not model_settled({**auto, "model.checked_updates_ago": "3"}, held=2)
    assert model_settled({**auto, "model.checked_updates_ago": "3"}, held=3)
    assert not model_settled({**auto, "model.checked_updates_ago": "None"}, held=5)
    assert not model_settled({**auto, "model.tolerance_met": "False"})  # a richer order is coming
    assert model_settled({**auto, "model.tolerance_met": "False", "model.order": str(ORDERS[-1])})  # nothing richer
    assert model_settled({"model.auto": "False", "model.order": "16"})  # a fixed model has nothing to settle
