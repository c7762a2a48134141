"""A warm Newton update that lands on a saddle continues downhill by shifted Newton steps
(newton.leave_saddle) instead of leaving for IPOPT.

The default cable on the 3D model, both grips lowered in their vertical plane: when the sag is pressed
onto the table, the in-plane shape is unstable out of the plane, and Newton, which finds the stationary
point nearest its start, lands on that saddle.  The update must still return the stable shape: the one
a fresh solver finds cold (IPOPT from the initial guess, then its own escape), up to the mirror image
across the plane (the scene is symmetric, so both sides are the same minimum)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.update import attempts as AT
from dlo_ros.solver.update import ladder as LD
from dlo_ros.solver.update import linking as LK

SCENE = load_scene("default_cable")
Q = SCENE.problem.grip("right").pose.orientation
L = SCENE.problem.string.length
OPTIONS = replace(SCENE.options, model="full")


def lowered(drop: float) -> dict:
    return {"left": ((0.0, 0.0, 0.4 - drop), Q), "right": ((0.6, 0.0, 0.4 - drop), Q)}


def mirrored_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest point distance [m] between two centrelines, the second also mirrored across y = 0."""
    flip = b * np.array([1.0, -1.0, 1.0])
    return float(min(np.linalg.norm(a - b, axis=1).max(), np.linalg.norm(a - flip, axis=1).max()))


@pytest.mark.parametrize("compile_mode", ["off", "blocking"])
def test_a_warm_update_onto_the_saddle_leaves_it_on_the_newton_path(compile_mode, tmp_path, monkeypatch):
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    solver = ShapeSolver(SCENE.problem, OPTIONS, compile=compile_mode)
    assert solver.solve(lowered(0.045)).ok
    calls = []
    original = LD.leave_saddle
    monkeypatch.setattr(LD, "leave_saddle", lambda *a, **k: calls.append(1) or original(*a, **k))
    linking = []  # leaving a saddle is a jump: the linking number of the clamped span is checked
    check = LK.linking_jump
    monkeypatch.setattr(LK, "linking_jump", lambda *a: linking.append(check(*a)) or linking[-1])
    warm = solver.solve(lowered(0.05))
    assert calls, "Newton did not land on the saddle: the scene no longer tests what it says"
    assert linking == [None]
    assert warm.ok and warm.stable and warm.warm_started, warm.message
    assert warm.ipopt_status == "Newton" and "left an unstable equilibrium" in warm.message
    assert np.abs(warm.points[:, 1]).max() > 0.02  # out of the plane
    assert np.linalg.norm(sum(warm.contact_forces.values(), np.zeros(3))) > 0.1  # still on the table

    cold = ShapeSolver(SCENE.problem, OPTIONS, compile="off").solve(lowered(0.05))
    assert cold.ok and cold.stable and not cold.warm_started and cold.ipopt_status != "Newton", cold.message
    assert warm.energy["total"] == pytest.approx(cold.energy["total"], rel=1e-8)
    assert mirrored_distance(warm.points, cold.points) < 1e-6 * L


def test_the_saddle_itself_is_what_plain_newton_finds():
    """The premise: without leaving, this update's Newton answer is the in-plane, unstable equilibrium."""
    from dlo_ros.solver.update.newton import newton

    solver = ShapeSolver(SCENE.problem, OPTIONS, compile="off")
    assert solver.solve(lowered(0.045)).ok
    start = solver.snapshot()
    poses = {name: GripPose(np.array(pos), Q) for name, (pos, _) in lowered(0.05).items()}
    p = solver.pack_parameters(SCENE.problem.with_grip_poses(poses), start.z)
    ok, state, _, _ = newton(solver.nlp, solver.functions, start, p)
    assert ok
    saddle = AT.result(solver.update_context(), SCENE.problem, state, "Newton", 0, 0.0, True, 0)
    assert saddle.status == "ok" and saddle.stable is False and saddle.min_eigenvalue < 0
    assert np.abs(saddle.points[:, 1]).max() < 1e-9


def circling(updates: int) -> list[dict]:
    """The right grip's targets of bench/perf/solver_speed.py: steps of 1 % of L around an ellipse of
    radius 0.08 L in the x–z plane (one lap every 50 updates; the sag touches down once per lap)."""
    start = SCENE.problem.grip("right").pose.position
    radius, dtheta = 0.08 * L, 0.01 * L / (0.08 * L)
    return [{"right": (start + radius * np.array([np.cos(i * dtheta) - 1.0, 0.0, np.sin(i * dtheta)]), Q)}
            for i in range(1, updates + 1)]


@pytest.mark.parametrize("compile_mode", ["off", "blocking"])
def test_a_lower_saddle_reached_by_the_newton_steps_is_left_from_there(compile_mode, tmp_path, monkeypatch):
    """At the 330th update of that stream the shifted Newton steps, which hold the table's contacts,
    stop on a lower saddle.  IPOPT's warm start from the update's start fell back onto the first saddle,
    whose four escapes each ran to ESCAPE_MAX_ITERATIONS (711 iterations, 3 s, before the update was
    solved cold).  Leaving the lower saddle instead keeps the update's cost bounded, and its answer is
    the stable shape a cold solve finds (up to the mirror image)."""
    from dlo_ros.solver.update.ipopt import ESCAPE_MAX_ITERATIONS

    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    solver = ShapeSolver(SCENE.problem, SCENE.options, compile=compile_mode)
    assert solver.solve().ok
    targets = circling(330)
    for poses in targets[:-1]:
        r = solver.solve(poses)
        assert r.ok and r.stable, r.message
    escapes = []
    original = LD.escape_unstable
    monkeypatch.setattr(LD, "escape_unstable", lambda *a: escapes.append(a[2].min_eigenvalue) or original(*a))
    warm = solver.solve(targets[-1])
    assert warm.ok and warm.stable and warm.warm_started, warm.message
    assert len(escapes) == 1 and escapes[0] < 0, "no lower saddle: the stream no longer tests what it says"
    assert warm.iterations < ESCAPE_MAX_ITERATIONS and "solved cold" not in warm.message

    cold = ShapeSolver(SCENE.problem, SCENE.options, compile="off").solve(targets[-1])
    assert cold.ok and cold.stable and not cold.warm_started, cold.message
    assert warm.energy["total"] == pytest.approx(cold.energy["total"], rel=1e-8)
    assert mirrored_distance(warm.points, cold.points) < 1e-6 * L
