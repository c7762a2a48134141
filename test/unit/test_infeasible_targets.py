"""Targets that admit no shape (the default cable's right grip put 5 cm under its table) answer
``infeasible`` from a warm update at the cost of two IPOPT attempts: the warm one and the cold one, which
agree.  The continuation that used to follow solved each of its steps before its last one failed the
same way (15 IPOPT calls, 6.5 s)."""
from __future__ import annotations

from dataclasses import replace

import pytest

import dlo_ros.solver.update.attempts as attempts
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver

SCENE = load_scene("default_cable")
Q = SCENE.problem.grip("right").pose.orientation
UNDER_THE_TABLE = {"right": ((0.5, 0.0, -0.05), Q)}


@pytest.mark.parametrize("warm", [True, False], ids=["stream", "cold"])
def test_targets_under_the_table_are_infeasible_after_two_attempts(warm, monkeypatch):
    solver = ShapeSolver(SCENE.problem, replace(SCENE.options, model="full"), compile="off")
    held = solver.solve()
    assert held.ok
    statuses = []
    original = attempts.call
    monkeypatch.setattr(attempts, "call", lambda *a, **k: statuses.append((out := original(*a, **k))[2]) or out)
    r = solver.solve(UNDER_THE_TABLE, warm=warm)
    assert r.status == "infeasible" and "grip 'right' position" in r.message, r.message
    assert statuses == (["Infeasible_Problem_Detected"] * (2 if warm else 1))
    assert r.points is None or len(r.points) == 0
