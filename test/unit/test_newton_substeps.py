"""A warm update Newton cannot take in one go (a first step over NEWTON_MAX_STEP) is taken by Newton in
2, then 4 substeps (ShapeSolver._newton_in_substeps) before IPOPT is called, and lands where a cold
solve (IPOPT from the initial guess, an independent path) lands.

The default cable on the 3D model; the right grip jumps up to 12 cm and turns up to 1.2 rad about a
random axis in one update (seeded)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.update import linking as LK
from dlo_ros.solver.update import substeps as SS

SCENE = load_scene("default_cable")
OPTIONS = replace(SCENE.options, model="full")
L = SCENE.problem.string.length


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    (x1, y1, z1, w1), (x2, y2, z2, w2) = a, b
    return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])


def jumps(count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(1)
    grip = SCENE.problem.grip("right").pose
    out = []
    for _ in range(count):
        x = np.asarray(grip.position) + rng.uniform(-0.12, 0.12, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(0.0, 1.2)
        out.append((x, quat_multiply(np.r_[np.sin(angle / 2) * axis, np.cos(angle / 2)], np.asarray(grip.orientation))))
    return out


@pytest.mark.parametrize("k", range(3))
def test_a_jump_newton_takes_in_substeps_equals_the_cold_solve(k, monkeypatch):
    x, q = jumps(3)[k]
    solver = ShapeSolver(SCENE.problem, OPTIONS, compile="off")
    assert solver.solve().ok
    calls = []
    original = SS.newton_in_substeps
    monkeypatch.setattr(SS, "newton_in_substeps", lambda *a: calls.append(original(*a)) or calls[-1])
    linking = []  # substeps go far from the committed shape: the linking number is checked
    check = LK.linking_jump
    monkeypatch.setattr(LK, "linking_jump", lambda *a: linking.append(check(*a)) or linking[-1])
    warm = solver.solve({"right": (x, q)})
    assert calls and calls[0][0], "one Newton update took the jump: the case no longer tests substeps"
    assert linking == [None]
    assert warm.ok and warm.stable and warm.warm_started and warm.ipopt_status == "Newton", warm.message
    cold = ShapeSolver(SCENE.problem, OPTIONS, compile="off").solve({"right": (x, q)})
    assert cold.ok and cold.ipopt_status != "Newton"
    assert warm.energy["total"] == pytest.approx(cold.energy["total"], rel=1e-9)
    assert np.abs(warm.points - cold.points).max() < 1e-8 * L
    for name in ("left", "right"):
        np.testing.assert_allclose(warm.grips[name].force, cold.grips[name].force, atol=1e-6)
