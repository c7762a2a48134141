"""The main job: run_demo_job starts the node, drives the dual-arm manoeuvre over real DDS, prints the
summary, and leaves no process behind."""
from __future__ import annotations

import os
import re

from dlo_ros.node.client import group_processes
from dlo_ros.node.demo import KEYFRAMES, POST, run_demo_job, targets_at, write_demo_scene


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


def test_run_demo_job(capsys):
    code = run_demo_job(["--speed", "2"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "summary" in out and "latency target->path" in out and "stable shapes" in out
    m = re.search(r"failures\s+(\d+) failed solves, (\d+) rejected inputs", out)
    assert m and m.group(1) == "0" and m.group(2) == "0", out
    m = re.search(r"stable shapes\s+(\d+) of (\d+)", out)
    assert m and int(m.group(2)) > 10 and int(m.group(1)) == int(m.group(2)), out
    assert "resting on the post" in out, out
    assert "exit code 0)" in out
    pid = int(re.search(r"node pid (\d+)", out).group(1))
    assert not os.path.exists(f"/proc/{pid}"), "the node process is still there"
    assert not group_processes(pid), f"left behind: {group_processes(pid)}"
    assert POST["type"] == "sphere"
