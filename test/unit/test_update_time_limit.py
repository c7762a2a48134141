"""solver.update_time_limit bounds a streamed update only (#37, solver/update/time_limit.py).

A streamed update (warm, committed) past its limit starts no IPOPT attempt, answers ``failed``
naming the limit, and the stream keeps its last shape.  A cold solve, a ``check_now`` re-solve and
a query (``commit=False``) are never limited, nor are ``auto``'s re-solves and checks inside them:
with a limit of 1e-9 s they answer what they answer with the limit off, to 1e-9 m.

The jump (the default cable's right grip 0.36 m at once) leaves the Newton path: unlimited, IPOPT
answers it; with a limit of 1 ms the update has used it up before its first IPOPT attempt.  The
sheet is the paper's (paper_rect_paper) over a floor 30 mm below its clamps, at chord 70 mm: its
cold ``auto`` solve escalates through warm re-solves on richer models.  Before #37 those re-solves
were limited: at 1e-9 s that cold solve answered ``failed`` ("no answer within
solver.update_time_limit"), and a query from 140 mm answered ``failed`` too (measured on 39a046b).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import dlo_ros.solver.update.attempts as attempts
from dlo_ros.model import Obstacle
from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene, scene_from_dict
from dlo_ros.solver import ShapeSolver, SolverOptions, make_solver
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


# ---- #37: the limit never changes a cold solve's, a check_now re-solve's or a query's answer ----
TINY = 1e-9  # s: every limited solve is past it before its first IPOPT attempt
SHEET = load_scene("paper_rect_paper")
SHEET_Q = SHEET.problem.grip("right").pose.orientation
FLOOR = Obstacle("halfspace", np.array([0.0, 0.0, -0.03, 0.0, 0.0, 1.0]), "floor")


def sheet_at(chord: float) -> dict:
    return {"right": GripPose(np.array([chord, 0.0, 0.0]), SHEET_Q)}


def sheet_solver(model: str, limit: float, chord: float):
    problem = replace(SHEET.problem.with_grip_poses(sheet_at(chord)), obstacles=(FLOOR,))
    options = replace(SHEET.options, model=model, update_time_limit=limit)
    if model == "auto":
        return make_solver(problem, options, compile="off", checks="sync")
    return make_solver(problem, options, compile="off")


def assert_same_answer(tiny, off):
    """The same status, stability, shape (to 1e-9 m) and, for auto, the same checked estimate."""
    assert tiny.status == off.status and tiny.stable == off.stable, (tiny.message, off.message)
    np.testing.assert_allclose(tiny.points, off.points, rtol=0.0, atol=1e-9)
    if off.model is not None and off.model.estimated_error_m is not None:
        assert tiny.model.estimated_error_m == pytest.approx(off.model.estimated_error_m, rel=1e-9)


@pytest.mark.parametrize("model", ["auto", "full"])
def test_a_cold_solve_answers_as_with_the_limit_off(model):
    """The sheet on its floor at chord 70 mm, cold.  Fails before #37 for auto ('failed')."""
    off = sheet_solver(model, 0.0, 0.07).solve()
    assert off.ok and off.stable, off.message
    tiny = sheet_solver(model, TINY, 0.07).solve()
    assert tiny.ok, tiny.message
    assert_same_answer(tiny, off)
    if model == "auto":  # its checks finished: the estimate is known and within the tolerance
        assert tiny.model.estimated_error_m is not None and tiny.model.tolerance_met


@pytest.mark.parametrize("model", ["auto", "full"])
def test_a_query_answers_as_with_the_limit_off(model):
    """From the shape held at 140 mm, a query at 70 mm, then the same target re-solved with
    ``check_now`` (the node's re-solve after a parameter change).  Before #37 auto's query answered
    'failed' under the limit; the full model's query of the jump below did too."""
    answers = {}
    for limit in (0.0, TINY):
        solver = sheet_solver(model, limit, 0.14)
        assert solver.solve().ok
        query = solver.solve(sheet_at(0.07), commit=False)
        checked = solver.solve(sheet_at(0.07), check_now=True)
        answers[limit] = query, checked
    (q_off, c_off), (q_tiny, c_tiny) = answers[0.0], answers[TINY]
    assert q_off.status in ("ok", "unverified") and q_off.points.size, q_off.message
    assert_same_answer(q_tiny, q_off)
    if model == "auto":  # check_now: a fixed model has no checks to run
        assert c_off.status in ("ok", "unverified") and c_off.points.size, c_off.message
        assert_same_answer(c_tiny, c_off)


def test_a_full_query_of_the_jump_is_not_limited_but_the_streamed_update_is():
    """The full model's query of the jump needs IPOPT: under the limit it answers as unlimited
    (it answered 'failed' before #37); the same target streamed is cut."""
    off, tiny = solver(0.0), solver(TINY)
    assert off.solve().ok and tiny.solve().ok
    q_off, q_tiny = off.solve(JUMP, commit=False), tiny.solve(JUMP, commit=False)
    assert q_off.ok and q_off.ipopt_status != "Newton", q_off.message
    assert_same_answer(q_tiny, q_off)
    streamed = tiny.solve(JUMP)
    assert streamed.status == "failed" and streamed.ipopt_status == TIME_LIMIT, streamed.message
    assert streamed.message.startswith("no answer within solver.update_time_limit (1e-09 s)")


def test_an_auto_streamed_update_is_cut_and_keeps_the_last_shape():
    """auto, streamed: the default cable's right grip 0.4 m in and 0.3 m down leaves Newton's path
    (unlimited: IPOPT answers it); under the limit the update answers 'failed' naming it, and the
    stream keeps the shape it held (the same as the held one on returning to the start)."""
    down = {"right": (START + np.array([-0.4, 0.0, -0.3]), Q)}
    options = replace(SCENE.options, model="auto")
    off = make_solver(SCENE.problem, replace(options, update_time_limit=0.0), compile="off",
                      checks="sync")
    assert off.solve().ok
    reached = off.solve(down)
    assert reached.status in ("ok", "unverified"), reached.message
    assert reached.ipopt_status != "Newton", reached.ipopt_status
    tiny = make_solver(SCENE.problem, replace(options, update_time_limit=TINY), compile="off",
                       checks="sync")
    held = tiny.solve()
    assert held.ok
    cut = tiny.solve(down)
    assert cut.status == "failed", cut.message
    assert cut.message.startswith("no answer within solver.update_time_limit (1e-09 s)")
    again = tiny.solve({"right": (START, Q)})
    assert again.ok, again.message
    np.testing.assert_allclose(again.points, held.points, atol=1e-9)
