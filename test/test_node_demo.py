"""The main job: run_demo_job starts the node, drives the dual-arm manoeuvre over real DDS, prints the
summary, and leaves no process behind."""
from __future__ import annotations

import os
import re

from dlo_ros.node.demo import KEYFRAMES, POST, run_demo_job, targets_at, write_demo_scene
from support.node import group_processes


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


def test_settled_means_checked_and_met_or_the_richest_order():
    from dlo_ros.node.demo import _settled
    from dlo_ros.solver.auto import ORDERS

    auto = {"model.auto": "True", "model.checked": "True", "model.tolerance_met": "True", "model.order": "16"}
    assert _settled(auto)
    assert not _settled({**auto, "model.checked": "False"})  # the estimate describes an earlier model
    assert not _settled({**auto, "model.tolerance_met": "False"})  # a richer order is coming
    assert _settled({**auto, "model.tolerance_met": "False", "model.order": str(ORDERS[-1])})  # nothing richer
    assert _settled({"model.auto": "False", "model.order": "16"})  # a fixed model has nothing to settle


def test_run_demo_job(capsys):
    code = run_demo_job(["--speed", "2"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "summary" in out and "latency target->path" in out and "stable shapes" in out
    m = re.search(r"failures\s+(\d+) failed solves, (\d+) rejected inputs", out)
    assert m and m.group(1) == "0" and m.group(2) == "0", out
    # every published shape is a stable equilibrium, or published as unverified and said so
    m = re.search(r"stable shapes\s+(\d+) of (\d+)(?: \((\d+) published unverified)?", out)
    assert m and int(m.group(2)) > 10 and int(m.group(1)) + int(m.group(3) or 0) == int(m.group(2)), out
    assert "resting on the post" in out, out
    # after the manoeuvre the job holds the last target until auto has checked the final shape's model
    settling = re.search(r"settling\s+(checked|NOT checked within \d+ s): held the last target", out)
    assert settling, out
    if settling.group(1) == "checked":
        assert re.search(r"model\s+auto: .*estimated error [0-9.e-]+ m \(tolerance 0.001 m: (met|NOT met)\)", out), out
    assert "exit code 0)" in out
    pid = int(re.search(r"node pid (\d+)", out).group(1))
    assert not os.path.exists(f"/proc/{pid}"), "the node process is still there"
    assert not group_processes(pid), f"left behind: {group_processes(pid)}"
    assert POST["type"] == "sphere"
