"""solver.update_time_limit bounds a warm update's fallbacks: no IPOPT attempt starts after it, the update
answers ``failed`` naming the limit, and the stream keeps its last shape.  A cold solve is not limited.

The jump (the default cable's right grip 0.36 m at once) leaves the Newton path: unlimited, IPOPT answers
it; with a limit of 1 ms the update has used it up before its first IPOPT attempt."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import dlo_ros.solver.update.attempts as attempts
from dlo_ros.scene import load_scene, scene_from_dict
from dlo_ros.solver import ShapeSolver, SolverOptions
from dlo_ros.solver.update.ipopt import TIME_LIMIT

SCENE = load_scene("default_cable")
Q = SCENE.problem.grip("right").pose.orientation
START = np.asarray(SCENE.problem.grip("right").pose.position)
JUMP = {"right": (START + np.array([-0.3, 0.0, 0.2]), Q)}


def solver(limit: float) -> ShapeSolver:
    return ShapeSolver(SCENE.problem, replace(SCENE.options, model="full", update_time_limit=limit), compile="off")


def test_a_warm_update_past_its_limit_starts_no_ipopt_attempt_and_keeps_the_last_shape(monkeypatch):
    s = solver(1e-3)
    held = s.solve()
    assert held.ok
    calls = []
    original = attempts.call
    monkeypatch.setattr(attempts, "call", lambda *a, **k: calls.append(1) or original(*a, **k))
    r = s.solve(JUMP)
    assert r.status == "failed" and r.ipopt_status == TIME_LIMIT
    assert r.message.startswith("no answer within solver.update_time_limit (0.001 s)"), r.message
    assert calls == []
    again = s.solve({"right": (START, Q)})  # the warm start is the held shape: the same answer
    assert again.ok
    np.testing.assert_allclose(again.points, held.points, atol=1e-9)


def test_without_a_limit_the_same_update_is_answered_and_a_cold_solve_is_never_limited():
    s = solver(0.0)
    assert s.solve().ok
    warm = s.solve(JUMP)
    assert warm.ok and warm.stable and warm.ipopt_status != "Newton", warm.message
    cold = solver(1e-3).solve(JUMP)  # no committed shape: a cold solve
    assert cold.ok and cold.stable and not cold.warm_started, cold.message
    assert cold.energy["total"] == pytest.approx(warm.energy["total"], rel=1e-8)


@pytest.mark.parametrize("value", [-1.0, 1e9])
def test_an_out_of_range_limit_is_refused_naming_the_field(value):
    with pytest.raises(ValueError, match="solver.update_time_limit"):
        SolverOptions(update_time_limit=value).validate()
    with pytest.raises(ValueError, match="update_time_limit"):
        scene_from_dict({**SCENE_DICT, "solver": {"update_time_limit": value}})


SCENE_DICT = {
    "string": {"length": 1.0, "bend_stiffness": 0.01, "weight_per_length": 0.1},
    "grips": [{"name": "left", "s": 0.0, "mode": "clamp", "position": [0, 0, 0], "orientation": [0, 0, 0, 1]},
              {"name": "right", "s": 1.0, "mode": "clamp", "position": [0.8, 0, 0], "orientation": [0, 0, 0, 1]}],
}
