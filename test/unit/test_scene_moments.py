"""Scene files with point moments about any axis (#37, "Random scenes").

The director models ('auto' and 'full' with the default rotation) take a point moment about any
axis (msg_docs/model_and_solver.md, "Point moments about any axis"); only the Euler-angle models
('planar', rotation 'euler') are limited to the working-plane normal.  The scene reader refused
such a moment for every model, so random scene 97 (test/random_scenes.py: two clamps, a force and
a moment off the plane, a table), which the Python API solves, exited 2 under ``dlo solve``.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from random_scenes import random_scene

from dlo_ros.scene import Scene, SceneError, scene_from_dict, scene_to_dict
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

REPO = Path(__file__).resolve().parents[2]
OFF_PLANE = [{"s": 0.5, "moment": [0.1, 0.0, 0.0]}]  # the default chord is +x, n = -y


def two_clamps(solver: dict | None = None) -> dict:
    """A 1 m string between two clamps 0.6 m apart, with a moment about the chord (x)."""
    scene = {
        "name": "t",
        "string": {"length": 1.0, "bend_stiffness": 0.02, "twist_stiffness": 0.01},
        "grips": [
            {"name": "left", "s": 0.0, "mode": "clamp", "position": [0, 0, 0.4]},
            {"name": "right", "s": 1.0, "mode": "clamp", "position": [0.6, 0, 0.4]},
        ],
        "loads": copy.deepcopy(OFF_PLANE),
    }
    if solver is not None:
        scene["solver"] = solver
    return scene


@pytest.mark.parametrize("solver", [{"rotation": "euler"}, {"model": "planar"}])
def test_euler_models_refuse_a_moment_off_the_working_plane(solver):
    with pytest.raises(SceneError) as info:
        scene_from_dict(two_clamps(solver))
    assert str(info.value).startswith("loads[0].moment: only moments about the working-plane")


@pytest.mark.parametrize("solver", [None, {"model": "full"}, {"model": "auto"}])
def test_director_models_take_a_moment_about_any_axis(solver):
    scene = scene_from_dict(two_clamps(solver))
    assert np.allclose(scene.problem.loads[0].moment, [0.1, 0.0, 0.0])


def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.setdefault("DLO_NO_COMPILE", "1")  # no gcc build per scene structure in tests
    return subprocess.run(
        [sys.executable, "-m", "dlo_ros.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
        env=env,
    )


@pytest.mark.parametrize("model", ["full", "auto"])
def test_random_scene_97_solves_from_a_scene_file(tmp_path, model):
    """Seed 97 written as a scene file: ``dlo solve`` answers ok, and its centreline agrees with
    the full model at order 24 solved cold in-process (the tighter model) within 1e-3 L."""
    problem = random_scene(97)
    moment = problem.loads[0].moment
    assert np.linalg.norm(np.cross(moment, [0.0, 1.0, 0.0])) > 0.1 * np.linalg.norm(moment)
    scene = Scene(name="random97", problem=problem, options=SolverOptions(model=model))
    path = tmp_path / "random97.yaml"
    path.write_text(yaml.safe_dump(scene_to_dict(scene), sort_keys=False))
    done = run_cli("solve", str(path), "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    answer = json.loads(done.stdout)
    assert answer["status"] == "ok" and answer["stable"] is not None, answer["message"]
    reference = ShapeSolver(
        problem, SolverOptions(model="full", order=24, update_time_limit=0.0), compile="off"
    ).solve()
    assert reference.ok, reference.message
    s = np.asarray(answer["s"])
    points = np.asarray(answer["points"])
    ref = np.column_stack([np.interp(s, reference.s, reference.points[:, k]) for k in range(3)])
    assert np.max(np.linalg.norm(points - ref, axis=1)) <= 1e-3 * problem.string.length
