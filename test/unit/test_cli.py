"""Tests for the `dlo` command line (dlo_ros.cli), run as subprocesses: `python -m dlo_ros.cli ...`."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dlo_ros import cli
from dlo_ros.paths import available_scenes

REPO = Path(__file__).resolve().parents[2]


def run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.setdefault("DLO_NO_COMPILE", "1")  # no ~1 min gcc build per scene structure in tests
    return subprocess.run(
        [sys.executable, "-m", "dlo_ros.cli", *args],
        capture_output=True, text=True, timeout=timeout, cwd=REPO, env=env,
    )


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


UNREACHABLE = """\
name: unreachable
description: grips 2 m apart on a 1 m string
string: {length: 1.0, bend_stiffness: 0.02, weight_per_length: 0.5}
grips:
  - {name: left, s: 0.0, mode: clamp, position: [0, 0, 0.5]}
  - {name: right, s: 1.0, mode: clamp, position: [2.0, 0, 0.5]}
"""


@pytest.fixture(scope="module")
def default_json() -> tuple[subprocess.CompletedProcess, dict]:
    done = run("solve", "default_cable", "--json")
    return done, json.loads(done.stdout)


# ---- solve --json --------------------------------------------------------------------------------------
def test_solve_json_exit_code_and_keys(default_json):
    done, out = default_json
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert set(cli.JSON_KEYS) <= set(out)
    assert out["scene"] == "default_cable" and out["frame_id"] == "world"
    assert out["status"] == "ok" and isinstance(out["message"], str)
    assert out["stable"] in (True, False)


def test_solve_json_arrays_and_units(default_json):
    _, out = default_json
    points, quats, s = np.array(out["points"]), np.array(out["orientations"]), np.array(out["s"])
    n = len(s)
    assert n == 51  # solver.output_points default
    assert points.shape == (n, 3) and quats.shape == (n, 4)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0)
    assert np.allclose(np.linalg.norm(quats, axis=1), 1.0)
    assert np.allclose(points[0], [0, 0, 0.4], atol=1e-6) and np.allclose(points[-1], [0.6, 0, 0.4], atol=1e-6)
    assert points[:, 2].min() > 0.005  # hangs above the table
    assert set(out["energy"]) == {"bend", "twist", "stretch", "gravity", "external_work", "total"}
    assert set(out["grips"]) == {"left", "right"}
    for wrench in out["grips"].values():
        assert len(wrench["force"]) == 3 and len(wrench["torque"]) == 3
    # the grips carry the weight: D L = 0.5 N
    fz = sum(w["force"][2] for w in out["grips"].values())
    assert fz == pytest.approx(0.5, rel=1e-6)
    assert set(out["contact_forces"]) == {"0"}
    assert {"iterations", "time_ms", "basis", "order", "constraint_violation", "warm_started",
            "continuation_steps", "ipopt_status", "derivatives"} <= set(out["solver"])
    assert out["solver"]["derivatives"] in ("compiled", "interpreted")
    from dlo_ros.solver import SolverOptions

    # auto's planar model is on spectral elements (#37); its 3D director model reports the default
    assert out["solver"]["basis"] == ("elements" if out["model"]["planar"] else "chebyshev")
    assert SolverOptions().model == "auto"
    # model 'auto' reports the order it chose and its a-posteriori error estimate
    assert out["solver"]["order"] == out["model"]["order"]
    assert {"planar", "twist", "stretch", "gravity", "order", "obstacles", "estimated_error_m"} <= set(out["model"])
    assert out["model"]["estimated_error_m"] <= out["model"]["tolerance_m"]


def test_solve_json_is_strict_json(default_json):
    done, _ = default_json
    json.loads(done.stdout, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert done.stdout.count("\n") == 1  # one document, one line


def test_solve_overrides():
    done = run("solve", "elastica_clamped", "--json", "--points", "7", "--basis", "fourier", "--order", "16",
               "--model", "planar")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert np.array(out["points"]).shape == (7, 3)
    assert (out["solver"]["basis"], out["solver"]["order"]) == ("fourier", 16)


def test_a_basis_the_model_would_ignore_is_refused():
    """--order implies --model full, the 3D director model, which has no Ritz basis: --basis fourier there
    would be reported and silently not used."""
    done = run("solve", "elastica_clamped", "--json", "--basis", "fourier", "--order", "16")
    assert done.returncode == 2 and "--basis" in done.stderr and "rotation 'euler'" in done.stderr, done.stderr


# ---- exit codes ----------------------------------------------------------------------------------------
def test_unreachable_grips_exit_1(tmp_path):
    path = write(tmp_path, "unreachable.yaml", UNREACHABLE)
    done = run("solve", str(path), "--json")
    assert done.returncode == 1, done.stderr
    out = json.loads(done.stdout)
    assert out["status"] == "unreachable"
    assert out["points"] == [] and out["stable"] is None
    assert "Traceback" not in done.stderr


def test_unreachable_human_summary_exit_1(tmp_path):
    path = write(tmp_path, "unreachable.yaml", UNREACHABLE)
    done = run("solve", str(path))
    assert done.returncode == 1
    assert "unreachable" in done.stdout


def test_malformed_scene_exit_2_names_the_key(tmp_path):
    path = write(tmp_path, "bad.yaml", UNREACHABLE.replace("bend_stiffness: 0.02", "bend_stiffness: -0.02"))
    done = run("solve", str(path), "--json")
    assert done.returncode == 2
    assert done.stdout == ""
    assert "string.bend_stiffness" in done.stderr and f"{path}:3" in done.stderr
    assert "Traceback" not in done.stderr


def test_unknown_key_exit_2(tmp_path):
    path = write(tmp_path, "typo.yaml", UNREACHABLE.replace("mode: clamp, position: [2.0", "mode: clmap, position: [2.0"))
    done = run("solve", str(path))
    assert done.returncode == 2
    assert done.stderr.startswith("dlo: error: grips[1].mode:")


def test_yaml_syntax_error_exit_2(tmp_path):
    path = write(tmp_path, "broken.yaml", "name: x\nstring: {length: 1, bend_stiffness: 1\ngrips: []\n")
    done = run("solve", str(path))
    assert done.returncode == 2
    assert f"{path}:3:" in done.stderr and "YAML syntax error" in done.stderr
    assert "Traceback" not in done.stderr


def test_unknown_scene_exit_2():
    done = run("solve", "no_such_scene")
    assert done.returncode == 2
    assert "no_such_scene" in done.stderr and "default_cable" in done.stderr


@pytest.mark.parametrize("args,needle", [
    ((), "COMMAND"),
    (("solve",), "SCENE"),
    (("bogus",), "invalid choice"),
    (("solve", "default_cable", "--order", "1"), "--order"),
    (("solve", "default_cable", "--points", "1"), "--points"),
    (("solve", "default_cable", "--basis", "spline"), "--basis"),
])
def test_usage_errors_exit_2(args, needle):
    done = run(*args)
    assert done.returncode == 2
    assert needle in done.stderr
    assert "Traceback" not in done.stderr


# ---- human output, scenes, demo ------------------------------------------------------------------------
def test_solve_human_summary():
    done = run("solve", "default_cable")
    assert done.returncode == 0, done.stderr
    text = done.stdout
    for needle in ("status  ok", "stable  True", "bend", "twist", "gravity", "total", "left", "right",
                   "force", "torque", "sag", "iterations", "ms"):
        assert needle in text, needle


def test_scenes_lists_every_shipped_scene():
    done = run("scenes")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    names = [ln.split()[0] for ln in lines]
    assert names == available_scenes()
    assert all(len(ln.split(None, 1)) == 2 for ln in lines)  # each has a description line


def test_demo_runs():
    done = run("demo", "--solver-only", "--steps", "3")
    assert done.returncode == 0, done.stderr
    for needle in ("default_cable", "cold", "median", "p90", "iterations", "stable 3/3"):
        assert needle in done.stdout, needle


def test_demo_json():
    done = run("demo", "--solver-only", "--scene", "elastica_clamped", "--steps", "2", "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["scene"] == "elastica_clamped" and out["steps"] == 2 and out["ok"] is True
    assert out["cold"]["status"] == "ok"
    assert len(out["warm"]["time_ms"]) == 2 and out["warm"]["ok_count"] == 2


def test_run_demo_in_process(monkeypatch):
    monkeypatch.setenv("DLO_NO_COMPILE", "1")
    summary = cli.run_demo("default_cable", 2)
    assert summary["moving_grip"] == "right"
    assert summary["cold"]["status"] == "ok"
    assert summary["warm"]["ok_count"] == 2 and summary["ok"]
    assert summary["warm"]["median_ms"] > 0 and summary["final_sag_m"] > 0
    assert "median" in cli.format_demo(summary)


def test_demo_path_is_small_and_reachable():
    from dlo_ros.scene import load_scene

    scene = load_scene("default_cable")
    name, targets = cli.demo_path(scene, 50)
    assert name == "right" and len(targets) == 50
    steps = np.diff(np.vstack([scene.problem.grip("right").pose.position, *targets]), axis=0)
    assert np.all(np.linalg.norm(steps, axis=1) < 0.005)
    assert all(np.linalg.norm(t - scene.problem.grip("left").pose.position) < 1.0 for t in targets)


# ---- subcommand registry -------------------------------------------------------------------------------
def test_subcommand_registry(monkeypatch, capsys):
    assert {"solve", "scenes", "demo"} <= set(cli.SUBCOMMANDS)
    monkeypatch.setattr(cli, "SUBCOMMANDS", dict(cli.SUBCOMMANDS))
    calls = []

    def add(p):
        p.add_argument("--rate", type=float, default=1.0)

    def handler(args):
        calls.append(args.rate)
        return 0

    cli.register_subcommand("node", "run the node", add, handler)
    assert cli.main(["node", "--rate", "5"]) == 0
    assert calls == [5.0]
    assert "node" in cli.build_parser().format_help()


def test_max_sag():
    pts = np.array([[0, 0, 1.0], [0.5, 0, 0.2], [1, 0, 0.8]])
    assert cli.max_sag(pts, [pts[0], pts[2]], np.array([0, 0, -9.8])) == pytest.approx(0.6)
