"""A contact force stays where it acts when the rows move between meshes (``update/warm_start.py``,
``adapt/transfer.py``, ``contact/obstacle_points.carried_forces``).

With the obstacle rows on the nodes of an element mesh (auto's element models), a refined mesh
has its rows at other arc lengths.  The warm start matched them by row index, so a table's force
went to whichever node had the old one's index, Newton's first update on the new mesh started
from a wrong active set, and on #37's table path the update at a mesh switch fell back to IPOPT.
Now each old row's force goes to the new row nearest along s.

The default cable lying on its table (grips lowered 0.32 m), solved on one mesh, adopted by
another: the total contact force is kept, each new pressing row lies within one node gap of an
old one, and the first update on the new mesh (the right grip moved 2 mm) is a Newton update that
equals that mesh's cold solve of the same targets.  Both transfer paths: across models
(``ShapeSolver.adopt_warm_start``, what auto's switches use) and the mesh transfer of
``adapt/transfer.py``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.adapt.transfer import transferred_state
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.contact.obstacle_points import carried_forces

SCENE = load_scene(
    Path(__file__).resolve().parents[2] / "config" / "scenes" / "default_cable.yaml"
)
DOWN = np.array([0.0, 0.0, 0.32])
OPTIONS = replace(SCENE.options, model="full", order=12, obstacle_points="nodes")
OLD = MeshSpec((0.5,), (12, 12))
#: an h-refinement (each element split) and a p-refinement (more nodes, all interior ones moved)
NEW = [MeshSpec((0.25, 0.5, 0.75), (12, 12, 12, 12)), MeshSpec((0.5,), (14, 14))]


def lowered():
    p = SCENE.problem
    return p.with_grip_poses(
        {g.name: GripPose(g.pose.position - DOWN, g.pose.orientation) for g in p.grips}
    )


def row_forces(solver, state) -> np.ndarray:
    """The table rows' forces [N] (SI multipliers) of ``state``."""
    nlp = solver.nlp
    lam = state.lam_g / (np.asarray(nlp.row_scale) * nlp.sigma)
    return lam[np.asarray(nlp.obstacle_rows[0])]


def test_carried_forces_go_to_the_nearest_row():
    out = carried_forces(
        np.array([0.0, 0.1, 0.2, 0.3]), np.array([0.0, 2.0, 3.0, 0.0]), np.array([0.0, 0.12, 0.5])
    )
    assert out.tolist() == [0.0, 5.0, 0.0]  # 0.1 and 0.2 are nearest 0.12: their forces add


@pytest.fixture(scope="module")
def solved_old():
    problem = lowered()
    old = ShapeSolver(problem, OPTIONS, compile="off", mesh=OLD)
    first = old.solve()
    assert first.ok, first.message
    forces = row_forces(old, old.committed_state)
    assert forces.max() > 1e-3  # it lies on the table
    return problem, old, forces


def check_carried(old, forces_old, new, forces_new):
    assert forces_new.sum() == pytest.approx(forces_old.sum(), rel=1e-12)
    gap = np.max(np.diff(new.nlp.obstacle_s))
    for s in new.nlp.obstacle_s[forces_new > 1e-6]:
        assert np.min(np.abs(old.nlp.obstacle_s[forces_old > 1e-6] - s)) <= gap


@pytest.mark.parametrize("mesh", NEW)
def test_adopted_start_keeps_the_force_where_it_acts(solved_old, mesh):
    """(The row-index match sent both first updates to IPOPT: Solve_Succeeded, 14-15 iterations.)"""
    problem, old, forces_old = solved_old
    new = ShapeSolver(problem, OPTIONS, compile="off", mesh=mesh)
    assert new.adopt_warm_start(old)
    check_carried(old, forces_old, new, row_forces(new, new.committed_state))
    right = problem.grip("right").pose
    targets = {"right": GripPose(right.position + [-0.002, 0.0, 0.0], right.orientation)}
    warm = new.solve(targets)
    assert warm.ok and warm.ipopt_status == "Newton", (warm.status, warm.ipopt_status)
    cold = ShapeSolver(problem, OPTIONS, compile="off", mesh=mesh).solve(targets)
    assert cold.ok
    mirror = cold.points * np.array([1.0, -1.0, 1.0])  # the sag may buckle to either side
    assert (
        min(np.max(np.linalg.norm(c - warm.points, axis=1)) for c in (cold.points, mirror)) < 1e-6
    )


@pytest.mark.parametrize("mesh", NEW)
def test_mesh_transfer_keeps_the_force_where_it_acts(solved_old, mesh):
    problem, old, forces_old = solved_old
    new = ShapeSolver(problem, OPTIONS, compile="off", mesh=mesh)
    moved = transferred_state(old, new)
    assert moved is not None
    check_carried(old, forces_old, new, row_forces(new, moved.state))


def test_a_line_load_is_carried_onto_every_row_under_it():
    """Rows 3-7 of 11 (spacing 0.1 m) carry 2 N/m, row 5 not pressing (a coarse shape lifting
    off between two nodes): onto rows 0.025 m apart, every row from 0.3 to 0.7 m takes its share
    of that load, the total is kept, and no row outside the run takes any."""
    src = np.linspace(0.0, 1.0, 11)
    forces = np.zeros(11)
    forces[[3, 4, 6, 7]] = 2.0 * 0.1  # q w: the trapezoid weight of an inner row is 0.1 m
    dst = np.linspace(0.0, 1.0, 41)
    out = carried_forces(src, forces, dst)
    inside = (dst > 0.3 - 1e-12) & (dst < 0.7 + 1e-12)
    assert out.sum() == pytest.approx(forces.sum(), rel=1e-12)
    assert np.all(out[~inside] == 0.0) and np.all(out[inside] > 0.0)
    # the load is uniform: every row under it holds the same force (its weight is the same)
    assert np.ptp(out[inside]) == pytest.approx(0.0, abs=1e-15)
    # the rows' own quadrature weights: a load q w_j on rows of weights w_j is carried as q
    w_src, w_dst = np.full(11, 0.1), np.full(41, 0.025)
    out = carried_forces(src, forces, dst, w_src, w_dst)
    assert np.allclose(out[inside] / w_dst[inside], out[inside][0] / 0.025)
    # the same rows with the same weights copy their forces, bit for bit
    assert np.array_equal(carried_forces(src, forces, src, w_src, w_src), forces)


def test_a_refined_mesh_under_the_floor_starts_where_newton_converges():
    """The paper's Fig. 3 strip (ρ = 3000) on its floor: solved on 4 elements, adopted by the
    8-element mesh auto's refinement goes to next, and solved again at the same targets.  Carried
    row by row to the nearest node, the floor's force left most rows of the finer mesh's run
    without one; Newton added them five at a time and gave up, and IPOPT answered in 72
    iterations.  Carried as a line load, Newton answers, and its answer is the finer mesh's cold
    solve (IPOPT from the initial guess)."""
    from dlo_ros.scene.reading import scene_from_dict
    from dlo_ros.scene.writing import scene_to_dict

    d = scene_to_dict(load_scene("bench_fig3_floor"))
    d["string"]["weight_per_length"] = 3000.0
    scene = scene_from_dict(d)
    options = replace(scene.options, model="planar", basis="elements", obstacle_points="nodes")
    coarse = MeshSpec((0.253, 0.636, 0.711), (8, 8, 8, 8))
    fine = MeshSpec((0.237, 0.253, 0.52, 0.636, 0.666, 0.711, 0.77), (9, 8, 8, 8, 8, 8, 8, 8))
    old = ShapeSolver(scene.problem, options, compile="off", mesh=coarse)
    assert old.solve().status in ("ok", "unverified")
    new = ShapeSolver(scene.problem, options, compile="off", mesh=fine)
    assert new.adopt_warm_start(old)
    warm = new.solve()
    assert warm.ok and warm.ipopt_status == "Newton", (warm.status, warm.ipopt_status)
    cold = ShapeSolver(scene.problem, options, compile="off", mesh=fine).solve()
    assert cold.ok and cold.ipopt_status != "Newton"
    assert np.max(np.linalg.norm(cold.points - warm.points, axis=1)) < 1e-8
