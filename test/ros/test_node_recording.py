"""The node records to rerun (parameter record.rrd): node in a subprocess, its own ROS_DOMAIN_ID.

Targets published over DDS give centrelines; after a clean stop the .rrd file verifies with
`rerun rrd verify`, holds at least one update per shape received, and its last recorded shape is the
last published centreline.
"""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun", reason="rerun-sdk needs Python >= 3.11")

from dlo_ros.node.client import running_node  # noqa: E402
from dlo_ros.recording.replay import read_recording  # noqa: E402
from support.node import TEST_MODEL, TEST_SCENE  # noqa: E402

RERUN = str(Path(sys.executable).parent / "rerun")
Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)


def qz(angle: float):
    return (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2))


def test_node_records_every_shape_it_publishes(tmp_path):
    rrd = tmp_path / "run.rrd"
    log = tmp_path / "node.log"
    received = []
    with running_node("--scene", TEST_SCENE, "--ros-args", "-p", "compile:=off", "-p", f"solver.model:={TEST_MODEL}",
                      "-p", "diagnostics_period:=0.2", "-p", f"record.rrd:={rrd}", log_path=log) as (proc, cl):
        for k in range(4):
            right = ((0.55 - 0.03 * k, 0.02 * k, 0.42), qz(0.05 * k))
            stamp = cl.publish_targets([LEFT, right])
            ev = cl.wait_for_path(15.0, where=lambda e, stamp=stamp: e.stamp_ns == stamp)
            assert ev is not None, proc.output()
            received.append(ev)
        # a rejected input is recorded too (and changes nothing)
        cl.publish_targets([LEFT, ((math.nan, 0.0, 0.4), Q)])
        assert cl.wait_for_diagnostics(lambda v, st: v.get("rejected inputs") == "1", 5.0), proc.output()
        paths = list(cl.paths)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert "Traceback" not in text, text
    assert rrd.is_file(), text

    done = subprocess.run([RERUN, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr

    rec = read_recording(rrd)
    assert len(rec.updates) >= len(paths) >= len(received)
    assert rec.scene_yaml and rec.results
    assert all(r.status == "ok" for r in rec.results)
    assert rec.results[0].warm_call is False and all(r.warm_call for r in rec.results[1:])
    assert rec.rejected and "non_finite" in rec.rejected[-1][1]
    assert len(rec.targets) >= len(received)

    last = paths[-1]  # the last published centreline: the answer to the last target
    assert last.stamp_ns == received[-1].stamp_ns
    final = rec.results[-1]
    assert final.ros_time_ns == last.stamp_ns
    np.testing.assert_allclose(final.points, last.points, atol=1e-6, rtol=0)
    np.testing.assert_allclose(rec.centrelines[final.update], last.points, atol=1e-6, rtol=0)
    np.testing.assert_allclose(final.targets["right"][0], last.points[-1], atol=1e-6)
