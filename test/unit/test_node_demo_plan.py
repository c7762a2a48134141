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


class FakeNode:
    """The node's side of the hold: every target is solved at once; auto's checks describe the
    final shape after ``needed`` solves of it; diagnostics show the newest state (no period)."""

    def __init__(self, base: int, needed: int):
        self.received, self.base, self.needed = base, base, needed
        self.published = 0

    def publish_targets(self, target) -> int:
        self.received += 1
        self.published += 1
        return self.received

    def wait_for_path(self, timeout, where=None):
        return ("path", self.received)

    def wait_for_diagnostics(self, where, timeout):
        held = self.received - self.base
        values = {
            "model.auto": "True",
            "model.checked": str(held >= self.needed),
            "model.checked_updates_ago": str(max(held - self.needed, 0)),
            "model.tolerance_met": "True",
            "targets received": str(self.received),
        }
        return (values, None) if where(values, None) else None


def test_the_hold_republishes_until_the_final_shape_is_checked():
    """auto applies a verdict a fixed number of updates after the shape it checked, so the hold
    stops right after the solve that brought the checked final shape, counted from the node's own
    diagnostics ('targets received'), however many solves that takes."""
    from dlo_ros.node.demo import _settle

    for needed in (1, 12, 40):
        node = FakeNode(base=451, needed=needed)
        values = {"model.auto": "True", "model.checked": "False", "targets received": "451"}
        out = _settle(node, values, timeout=60.0, rate=1000.0)
        assert out is not None
        final_values, final, _, held = out
        assert held == node.published == needed, (needed, held)
        assert final_values["model.checked"] == "True" and final == ("path", 451 + needed)
