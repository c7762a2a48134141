"""The node is not wedged by one target it cannot follow (issue #35; the library's side:
test/unit/test_stream_recovery.py).

Real DDS, the node with ``solver.model: auto`` (as shipped) on default_cable: both grips sent to
one point (a closed loop, one well-formed PoseArray) is refused ('failed' in /diagnostics, no
centreline); the ordinary targets published after it are answered, without any ~/reset: each
centreline stamped with its target ends at the right grip's target (1e-6 m). Before the fix every
one of them was refused and the centreline stayed frozen. The scene is default_cable with
``solver.update_time_limit: 0``, so that a slow machine's timing never decides what is published
(the test asserts answers, not timings)."""
from __future__ import annotations

import numpy as np
import yaml

from dlo_ros.paths import scene_path
from support.node import clean_node

Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)
LOOP = [((0.3, 0.0, 0.4), Q), ((0.3, 0.0, 0.4), Q)]
ORDINARY = [(0.6, 0.0, 0.4), (0.55, 0.0, 0.4), (0.58, 0.03, 0.42), (0.5, 0.0, 0.38)]


def scene_without_time_limit(tmp_path) -> str:
    data = yaml.safe_load(scene_path("default_cable").read_text())
    data["solver"] = {**data.get("solver", {}), "update_time_limit": 0.0}
    path = tmp_path / "default_cable_no_limit.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_ordinary_targets_after_a_closed_loop_are_published(tmp_path):
    args = ("--scene", scene_without_time_limit(tmp_path), "--ros-args", "-p", "compile:=off",
            "-p", "solver.model:=auto", "-p", "diagnostics_period:=0.2")
    with clean_node(*args, log_path=tmp_path / "node.log") as (proc, cl):
        assert cl.wait_for_subscribers(), proc.output()
        stamp = cl.publish_targets([LEFT, ((0.6, 0.0, 0.4), Q)])
        first = cl.wait_for_path(60.0, where=lambda e: e.stamp_ns == stamp)
        assert first is not None, proc.output()

        loop = cl.publish_targets(LOOP)
        refused = cl.wait_for_diagnostics(lambda v, _: v.get("status") == "failed", 60.0)
        assert refused is not None, (cl.diagnostic_values(), proc.output())
        # the refusal published nothing
        assert cl.wait_for_path(0.5, where=lambda e: e.stamp_ns == loop) is None

        for x in ORDINARY:
            stamp = cl.publish_targets([LEFT, (x, Q)])
            ev = cl.wait_for_path(60.0, where=lambda e, stamp=stamp: e.stamp_ns == stamp)
            assert ev is not None, (x, cl.diagnostic_values(), proc.output())
            assert np.linalg.norm(ev.points[-1] - np.array(x)) < 1e-6, (x, ev.points[-1])
            assert np.linalg.norm(ev.points[0] - np.array(LEFT[0])) < 1e-6, ev.points[0]
