"""``adapt/contact_shift.PositionJacobian``: the centreline's Jacobian from one sweep over z.

It relies on the models' centreline being linear in their tangents at the quadrature nodes
(x(s) = x₀ + W(s) Tᵀ) and differentiates (x₀, T) once.  The reference here differentiates the
positions themselves, point by point, by central differences of ``model.positions`` (what
the module did before): both models (the planar Ritz model on elements, the 3D director model),
at arc lengths inside elements and on breakpoints, at a solved state and at a perturbed one.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver.adapt.contact_shift import Z_STEP, PositionJacobian
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.shape_solver import ShapeSolver


def direct_jacobian(model, z: np.ndarray, s: np.ndarray) -> np.ndarray:
    """∂x(s)/∂z (len(s), 3, n) by central differences of the positions at s."""
    out = np.zeros((len(s), 3, z.size))
    for k in range(z.size):
        step = np.zeros(z.size)
        step[k] = Z_STEP
        plus = np.asarray(model.positions(z + step, s)).reshape(-1, 3)
        minus = np.asarray(model.positions(z - step, s)).reshape(-1, 3)
        out[:, :, k] = (plus - minus) / (2 * Z_STEP)
    return out


def solved(scene_name: str, model: str, mesh: MeshSpec):
    scene = load_scene(scene_name)
    options = replace(scene.options, model=model)
    solver = ShapeSolver(scene.problem, options, compile="off", mesh=mesh)
    assert solver.solve().status in ("ok", "unverified")
    return solver.nlp.model, np.asarray(solver.committed_state.z, dtype=float), scene


@pytest.mark.parametrize(
    "scene_name, model, mesh",
    [
        ("bench_fig3_floor", "planar", MeshSpec((0.3,), (6, 7))),
        ("default_cable", "full", MeshSpec((0.4,), (6, 6))),
    ],
)
def test_one_sweep_equals_the_positions_differentiated_point_by_point(scene_name, model, mesh):
    model_, z, scene = solved(scene_name, model, mesh)
    length = scene.problem.string.length
    rng = np.random.default_rng(3)
    s = np.array([0.0, 0.1, 0.3, 0.4, 0.55, 0.97, 1.0]) * length
    for state in (z, z + 1e-2 * rng.standard_normal(z.size)):
        jacobian = PositionJacobian(model_, state)
        for points in (s, s[[2]], np.array([0.123 * length])):
            x, jx = jacobian.at(points)
            np.testing.assert_allclose(
                x, np.asarray(model_.positions(state, points)).reshape(-1, 3), atol=1e-14
            )
            np.testing.assert_allclose(jx, direct_jacobian(model_, state, points), atol=1e-8)
            np.testing.assert_allclose(
                jacobian.positions(points), np.asarray(model_.positions(state, points)), atol=1e-14
            )
        # the Jacobian is not trivial: it moves the points
        assert np.abs(jx).max() > 1e-3 * length


@pytest.mark.parametrize("stretch", [False, True])
def test_the_batched_sweep_is_the_one_at_a_time_sweep_bit_for_bit(stretch, monkeypatch):
    """A director model's sweep from ``shifted_tangents`` (every z ± Z_STEP e_k at once) gives
    the numbers of ``positions_at_rows`` at each shifted z, one k at a time, to the last bit (the
    refinement decides meshes on these differences: another rounding moved a predicted touch by
    1.5e-6 m and a tight tolerance's meshes with it).  Quaternion nodes, and the strain field's
    unknowns too."""
    from dlo_ros.model.director import DirectorModel
    from dlo_ros.model.problem import Profile

    scene = load_scene("default_cable")
    problem = scene.problem
    if stretch:
        string = replace(problem.string, stretch_stiffness=Profile.constant(50.0))
        problem = replace(problem, string=string)
    solver = ShapeSolver(problem, replace(scene.options, model="full", order=12), compile="off")
    assert solver.solve().ok
    model = solver.nlp.model
    assert isinstance(model, DirectorModel) and model.layout.stretch == stretch
    z = np.asarray(solver.committed_state.z, dtype=float)
    z = z + 1e-3 * np.random.default_rng(5).standard_normal(z.size)  # off the equilibrium too
    batched = PositionJacobian(model, z)._differences(model.B.shape[0])
    monkeypatch.delattr(DirectorModel, "shifted_tangents")
    one_at_a_time = PositionJacobian(model, z)._differences(model.B.shape[0])
    assert np.array_equal(batched, one_at_a_time)
    assert np.abs(batched).max() > 0.1
