"""Warm Newton updates with two nearly parallel active rows (update/kkt.py, ``regularised``).

Two obstacle rows on the nodes at the end of a short element sit 0.3 mm apart on the string, and
when both press on the table their Jacobian rows are nearly parallel (J_A's smallest singular value
3.5e-3 against 0.13 for the next).  The rows' block of the Newton matrix was shifted by the same δ
as the unknowns' (1e-10·max|K|, there 4e-6, above the KKT matrix's smallest |eigenvalue| 1.2e-6):
each step then left a primal residual δ·Δλ, Newton converged linearly (a rate of 0.6 per step),
and 71 of 150 updates of the stream below fell back to IPOPT.  The rows' shift is now scaled as
the Schur complement J H⁻¹ Jᵀ it perturbs.

* the Newton step of ``regularised`` solves the unshifted system to round-off when that system is
  regular, however nearly parallel two rows are, and stays bounded on exactly equal rows;
* the default cable lying on the table, on an element mesh with short elements at the contact
  (the mesh auto reached on #37's 3D path), streamed: every update is a Newton update, a verified
  equilibrium, and the last one equals the cold solve of its targets.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.update.kkt import kkt_step

SCENE = load_scene(
    Path(__file__).resolve().parents[2] / "config" / "scenes" / "default_cable.yaml"
)


def system(gap: float, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(H, J): a stiff, well-posed H (entries up to 4e4) and 6 rows, the last two ``gap`` apart."""
    rng = np.random.default_rng(seed)
    n = 40
    a = rng.standard_normal((n, n))
    h = a @ a.T + n * np.eye(n)
    h *= 4e4 / np.abs(h).max()
    j = rng.standard_normal((6, n))
    j[5] = j[4] + gap * rng.standard_normal(n)
    return h, j / np.abs(j).max()


@pytest.mark.parametrize("gap", [1e-1, 1e-2, 1e-3])
def test_step_solves_the_unshifted_system(gap):
    """Rows ``gap`` apart (the stream below: 3.5e-3), residuals a step of the unknowns can remove."""
    h, j = system(gap)
    rng = np.random.default_rng(7)
    r_dual, r_prim = rng.standard_normal(h.shape[0]), -j @ (1e-4 * rng.standard_normal(h.shape[0]))
    step = kkt_step(h, j, r_dual, r_prim)
    assert step is not None
    n = h.shape[0]
    dz, dl = step[:n], step[n:]
    # the rows: J Δz = −r_prim to round-off (the old shift left δ·Δλ there)
    assert np.abs(j @ dz + r_prim).max() < 1e-6 * np.abs(r_prim).max()
    assert np.abs(h @ dz + j.T @ dl + r_dual).max() < 1e-6 * np.abs(r_dual).max()


def test_equal_rows_give_a_bounded_step():
    h, j = system(0.0)
    rng = np.random.default_rng(8)
    r_prim = 1e-6 * rng.standard_normal(j.shape[0])
    r_prim[5] = r_prim[4]  # consistent: the same row twice, the same residual
    step = kkt_step(h, j, rng.standard_normal(h.shape[0]), r_prim)
    assert step is not None and np.all(np.isfinite(step))
    n = h.shape[0]
    assert np.abs(j @ step[:n] + r_prim).max() < 1e-10
    assert np.abs(step[n:]).max() < 1e6


#: the mesh auto reached after 200 updates of #37's path on the table (short elements at the
#: contact's end, their end nodes 0.3 mm apart)
MESH = MeshSpec(
    (0.38735327352690446, 0.39609056541097, 0.4023777172428901, 0.45198270631623993, 0.5),
    (19, 8, 8, 14, 8, 18),
)
DOWN = np.array([0.0, 0.0, 0.32])


def lowered(problem):
    return problem.with_grip_poses(
        {g.name: GripPose(g.pose.position - DOWN, g.pose.orientation) for g in problem.grips}
    )


def right_target(k: int, start: np.ndarray, q: np.ndarray) -> dict:
    """The right grip moved 0.5 mm per update toward the left one (the sag slides on the table)."""
    return {"right": GripPose(start + 5e-4 * k * np.array([-1.0, 0.0, 0.0]), q)}


def test_stream_on_the_table_stays_on_newton():
    problem = lowered(SCENE.problem)
    options = replace(SCENE.options, model="full", order=12, obstacle_points="nodes")
    solver = ShapeSolver(problem, options, compile="off", mesh=MESH)
    first = solver.solve()
    assert first.ok, first.message
    right = problem.grip("right").pose
    methods, last, targets = [], first, None
    for k in range(1, 16):
        targets = right_target(k, right.position, right.orientation)
        last = solver.solve(targets)
        assert last.ok, (k, last.message)
        methods.append(last.ipopt_status)
    assert methods == ["Newton"] * len(methods)
    # the table holds the string: some obstacle row is active at the end
    assert any(np.linalg.norm(f) > 1e-3 for f in last.contact_forces.values())
    cold = ShapeSolver(problem, options, compile="off", mesh=MESH).solve(targets)
    assert cold.ok, cold.message
    # the scene is symmetric about the grips' vertical plane y = 0 (the sag buckles to either side)
    mirror = cold.points * np.array([1.0, -1.0, 1.0])
    gap = min(np.max(np.linalg.norm(c - last.points, axis=1)) for c in (cold.points, mirror))
    assert gap < 1e-6
