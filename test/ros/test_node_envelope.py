"""The node's shape and tension envelope (#40) over real DDS: with string.uncertainty in the scene,
~/envelope carries the k-sigma tube of the published shape, equal to the envelope an independent
in-process solver of the same scene computes for the same targets; the diagnostics report it and the
recording holds it.  Without an uncertainty nothing is computed."""
from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from dlo_ros.node.client import running_node
from dlo_ros.node.qos import LATCHED_QOS
from dlo_ros.paths import config_path
from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver
from dlo_ros.solver.results.envelope import envelope
from support.node import TEST_MODEL, node_args
from visualization_msgs.msg import Marker, MarkerArray

Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)
RIGHT = ((0.5, 0.1, 0.35), Q)
SIGMA = {"bend_stiffness": 0.002, "weight_per_length": 0.025}
K = 2.0


def uncertain_scene(tmp_path: Path) -> Path:
    """default_cable with string.uncertainty."""
    d = yaml.safe_load(config_path("scenes/default_cable.yaml").read_text())
    d["name"] = "uncertain_cable"
    d["string"]["uncertainty"] = dict(SIGMA)
    path = tmp_path / "uncertain_cable.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def reference_sigma(scene_path: Path, targets) -> np.ndarray:
    """The envelope of the same targets from an in-process solver of the scene (cold solve)."""
    scene = load_scene(str(scene_path))
    options = replace(scene.options, model=TEST_MODEL)
    solver = make_solver(scene.problem, options, compile="off")
    result = solver.solve({"left": targets[0], "right": targets[1]})
    assert result.ok
    spread = envelope(solver, result, scene.uncertainty)
    assert spread.available, spread
    return spread.sigma


def test_the_node_publishes_the_envelope_of_its_shape(tmp_path):
    scene = uncertain_scene(tmp_path)
    rrd = tmp_path / "run.rrd"
    args = ["--scene", str(scene), *node_args("envelope.rate:=20.0", f"envelope.k:={K}",
                                               f"record.rrd:={rrd}")[2:]]
    with running_node(*args, log_path=tmp_path / "node.log") as (proc, client):
        got = client.collect(MarkerArray, "envelope")  # appended under the client's lock
        n = client.path_count
        stamp = client.publish_targets([LEFT, RIGHT])
        assert client.wait_for(lambda: client.path_count > n, 30.0)
        assert client.wait_for_path(15.0, where=lambda e: e.stamp_ns == stamp) is not None

        def of_stamp():
            return next((m for m in reversed(got) if m.markers[-1].header.stamp.sec ==
                         stamp // 1_000_000_000 and m.markers[-1].header.stamp.nanosec ==
                         stamp % 1_000_000_000), None)

        msg = client.wait_for(of_stamp, 20.0)
        assert msg is not None, proc.output()
        spheres = [m for m in msg.markers if m.type == Marker.SPHERE]
        path = client.latest_path()
        assert len(spheres) == len(path.points)
        centres = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in spheres])
        assert np.abs(centres - path.points).max() < 1e-9
        radii = np.array([m.scale.x / 2 for m in spheres])
        sigma = reference_sigma(scene, [LEFT, RIGHT])
        assert sigma.max() > 1e-4  # a visible envelope
        np.testing.assert_allclose(radii, np.maximum(K * sigma, 5e-7), rtol=1e-4, atol=1e-8)

        def reported():  # the diagnostics of that envelope (the first shape's came before)
            status = client.other_diagnostics.get("/dlo: envelope")
            values = {} if status is None else {kv.key: kv.value for kv in status.values}
            maximum = float(values.get("max sigma m") or 0.0)
            return values if abs(maximum - sigma.max()) < 1e-6 * max(1.0, maximum) else None

        values = client.wait_for(reported, 10.0)
        assert values and values["available"] == "true", client.other_diagnostics
        assert "left force sigma N" in values and "right tension sigma N" in values
    assert proc.returncode == 0, proc.output()
    rerun = str(Path(sys.executable).parent / "rerun")
    printed = subprocess.run([rerun, "rrd", "print", str(rrd)], capture_output=True, text=True, timeout=120)
    assert "world/envelope" in printed.stdout + printed.stderr


def test_no_uncertainty_no_envelope(tmp_path):
    with running_node(*node_args("envelope.rate:=20.0"), log_path=tmp_path / "node.log") as (proc, client):
        got = []
        client.node.create_subscription(MarkerArray, "/dlo/envelope", got.append, LATCHED_QOS)
        client.publish_targets([LEFT, RIGHT])
        status = client.wait_for(lambda: client.other_diagnostics.get("/dlo: envelope"), 10.0)
        assert status.message == "no uncertainty"
        assert not got
