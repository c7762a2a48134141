"""A solved state carried to another element mesh (dlo_ros.solver.adapt.transfer, #37).

Exact: nodal fields that are polynomials of degree < every old element's node count are the old
mesh's element polynomials, so the new nodes get p(s)/|p(s)| (rotations) and p(s) (ε) to
rounding.  Real: a heavy string clamped at both ends with a point force in 3D, solved on a coarse
mesh and carried to a refined one, converges there in a few Newton steps (no IPOPT) to the
refined mesh's own cold answer within 1e-9 L, cold and then streamed.
"""

from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.director import DirectorModel
from dlo_ros.model.elements import ElementMesh
from dlo_ros.model.problem import GripPose, Load
from dlo_ros.solver.adapt.transfer import (
    nodal_matrix,
    transfer_z,
    transferred_state,
    warm_start_from,
)
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver
from support.problems import clamped_pair, quat_about
from test_adapt_loop import bar_scene

LENGTH = 1.3


def field(s: np.ndarray, width: int) -> np.ndarray:
    """A smooth nodal field of degree 4 with no zero on [0, L] (each row's norm ≥ 0.5)."""
    u = s / LENGTH
    rows = [1.0 + 0.3 * u - 0.2 * u**4, 0.4 * u**2 - 0.1 * u**3, 0.2 - 0.5 * u, 0.1 * u**4]
    return np.stack(rows[:width], axis=1)


@pytest.mark.parametrize("frame", [True, False], ids=["quaternions", "tangents"])
def test_polynomial_fields_transfer_exactly(frame):
    old = DirectorModel(
        LENGTH, ElementMesh(LENGTH, [0.4, 0.9], 8, 4, counts=(5, 7, 6)), frame, True
    )
    new = DirectorModel(
        LENGTH, ElementMesh(LENGTH, [0.2, 0.4, 1.1], 8, 4, counts=(9, 4, 12, 5)), frame, True
    )
    width = old.layout.width
    z = np.zeros(old.layout.size)
    z[0:3] = [0.1, -0.2, 0.3]
    z[old.layout.rotation] = field(old.mesh.nodes, width).ravel()
    z[old.layout.eps] = 1e-3 * (1 - (old.mesh.nodes / LENGTH) ** 3)
    moved = transfer_z(old, new, z)
    want = field(new.mesh.nodes, width)
    want /= np.linalg.norm(want, axis=1)[:, None]
    assert np.abs(new.node_values(moved) - want).max() < 1e-13
    assert (
        np.abs(moved[new.layout.eps] - 1e-3 * (1 - (new.mesh.nodes / LENGTH) ** 3)).max() < 1e-15
    )
    assert np.array_equal(moved[0:3], z[0:3])
    # the map itself, before normalising: the polynomial's values at the new nodes
    T = nodal_matrix(old.mesh, new.mesh)
    assert np.abs(T @ field(old.mesh.nodes, width) - field(new.mesh.nodes, width)).max() < 1e-13


def test_quaternion_signs_stay_continuous():
    """A field turning by 300° about z: its quaternions pass w = 0; the new ones keep one sign."""
    old = DirectorModel(1.0, ElementMesh(1.0, [], 8, 4, counts=(12,)), True, False)
    new = DirectorModel(1.0, ElementMesh(1.0, [0.5], 8, 4, counts=(9, 9)), True, False)
    half = 0.5 * np.radians(300) * old.mesh.nodes
    q = np.stack([0 * half, 0 * half, np.sin(half), np.cos(half)], axis=1)
    z = np.concatenate([[0.0, 0.0, 0.0], q.ravel()])
    values = new.node_values(transfer_z(old, new, z))
    assert np.all(np.sum(values[1:] * values[:-1], axis=1) > 0)
    assert np.allclose(values[0], q[0])


def test_a_mesh_map_refuses_another_length_or_model():
    with pytest.raises(ValueError, match="meshes of 1.0 m and 2.0 m"):
        nodal_matrix(ElementMesh(1.0, [], 6), ElementMesh(2.0, [], 6))
    frame = DirectorModel(1.0, ElementMesh(1.0, [], 6), True, False)
    tangent = DirectorModel(1.0, ElementMesh(1.0, [], 6), False, False)
    with pytest.raises(ValueError, match="models differ"):
        transfer_z(frame, tangent, np.zeros(frame.layout.size))


def hanging_problem():
    """Clamped at both ends, 0.7 m apart, heavy, an end turned 40° about z, a point force off
    the middle (a breakpoint of the scene at s = 0.6 m)."""
    force = Load(0.6, np.array([0.0, 0.3, -0.5]))
    return clamped_pair(
        right=(0.7, 0.1, -0.1),
        q_right=quat_about("z", np.radians(40)),
        length=1.0,
        bend=0.05,
        twist=0.04,
        weight=0.8,
        loads=(force,),
    )


OPTIONS = SolverOptions(model="full", order=12)
COARSE = MeshSpec((0.6,), (7, 6))
FINE = MeshSpec((0.3, 0.6), (8, 8, 10))
STREAM = [(0.68, 0.12, -0.1), (0.66, 0.14, -0.12)]


def test_a_solved_shape_carried_to_a_refined_mesh_converges_warm_to_its_cold_answer():
    problem = hanging_problem()
    coarse = ShapeSolver(problem, OPTIONS, compile="off", mesh=COARSE)
    first = coarse.solve()
    assert first.ok, first.message
    fine = ShapeSolver(problem, OPTIONS, compile="off", mesh=FINE)
    assert warm_start_from(coarse, fine) and fine.has_warm_start
    warm = fine.solve()
    cold = ShapeSolver(problem, OPTIONS, compile="off", mesh=FINE).solve()
    assert warm.ok and cold.ok, (warm.message, cold.message)
    assert warm.warm_started and warm.ipopt_status == "Newton" and warm.iterations <= 6
    assert not cold.warm_started and cold.iterations > warm.iterations
    # the meshes differ enough that the transfer had work to do
    assert np.abs(first.points - cold.points).max() > 1e-6
    assert np.abs(warm.points - cold.points).max() < 1e-9 * problem.string.length
    # streamed on from there: each update agrees with the refined mesh's cold answer
    for target in STREAM:
        pose = GripPose.checked(target, quat_about("z", np.radians(40)), "right")
        step = fine.solve({"right": pose})
        alone = ShapeSolver(
            problem.with_grip_poses({"right": pose}), OPTIONS, compile="off", mesh=FINE
        ).solve()
        assert step.ok and step.warm_started and alone.ok
        assert np.abs(step.points - alone.points).max() < 1e-9 * problem.string.length


def test_nothing_committed_nothing_handed_over():
    problem = hanging_problem()
    coarse = ShapeSolver(problem, OPTIONS, compile="off", mesh=COARSE)
    fine = ShapeSolver(problem, OPTIONS, compile="off", mesh=FINE)
    assert not warm_start_from(coarse, fine) and not fine.has_warm_start


def test_contact_multipliers_are_carried_by_row():
    """A cable resting on a bar (test_adapt_loop's scene): the grip rows, the obstacle samples'
    rows and the contact slot keep their SI multipliers on the new mesh, and the contact's is
    within 2 % of the refined mesh's own at its equilibrium (it moves with the discretisation)."""
    sc = bar_scene(16)
    coarse = ShapeSolver(sc.problem, sc.options, compile="off")
    assert coarse.solve().ok
    fine = ShapeSolver(sc.problem, sc.options, compile="off", mesh=MeshSpec((0.4,), (10, 12)))
    moved = transferred_state(coarse, fine)
    assert moved is not None and moved.unmatched_rows == 0

    def si(solver, lam):
        nlp = solver.nlp
        return {k: v for k, v in zip(nlp.row_kind, lam / (nlp.row_scale * nlp.sigma))}

    old, new = si(coarse, coarse.committed_state.lam_g), si(fine, moved.state.lam_g)
    carried = [k for k in new if k[0] in ("grip", "obstacle", "slot")]
    assert any(k[0] == "slot" and new[k] != 0 for k in carried)  # the contact itself
    for k in carried:
        assert new[k] == pytest.approx(old[k], rel=1e-12, abs=1e-15), k
    assert warm_start_from(coarse, fine)
    result = fine.solve()
    assert result.ok and result.ipopt_status == "Newton"
    final = si(fine, fine.committed_state.lam_g)
    slot = [k for k in carried if k[0] == "slot" and new[k] != 0][0]
    assert final[slot] == pytest.approx(new[slot], rel=0.02)
