"""The assembled KKT functions of the Euler-angle models (dlo_ros.solver.build.assembled_euler, #14): the planar
model and the 3D Euler-angle model equal the KKT system differentiated here from the whole flattened NLP
(CasADi SX AD of ``StringNLP.nlp``'s objective and rows, with ``energy_fn``), for the contact-free rows
and for every row, on scenes with each feature the models support; and their compiled C equals them."""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from dlo_ros.model.obstacles import Obstacle
from dlo_ros.model.problem import Grip, GripPose, Load, RelativePosition
from dlo_ros.model.profile import Profile
from dlo_ros.scene import load_scene
from dlo_ros.solver.build.compiled import NativeFunction, compiled, compiler
from dlo_ros.solver.build.nlp import StringNLP
from dlo_ros.solver.options import SolverOptions
from random_scenes import random_scene
from support.problems import quat_about
from test_assembled_kkt import assert_equal_systems, flattened, stretched_scene


def planar_scene(stretch: bool = True, obstacles: bool = True):
    """default_cable (the x-z plane) with a clamp, a pin and a tangent grip (turned in the plane), a
    piecewise-linear Rf, stretch, a relative position, a point load with a force in the plane and a moment
    about its normal, and obstacles of every type that fit the plane (the table, a sphere, a capsule and a
    turned box centred on it)."""
    problem = load_scene("default_cable").problem
    L = problem.string.length
    string = dataclasses.replace(problem.string, bend_stiffness=Profile.table([(0.0, 0.02), (0.5 * L, 0.05), (L, 0.03)]),
                                 stretch_stiffness=Profile.constant(50.0) if stretch else None)
    grips = (Grip("left", 0.0, "clamp", GripPose.checked([0.0, 0.0, 0.4], quat_about("y", 0.2), "left")),
             Grip("middle", 0.4 * L, "pin", GripPose.checked([0.25, 0.0, 0.2], [0, 0, 0, 1], "middle")),
             Grip("right", L, "tangent", GripPose.checked([0.6, 0.0, 0.4], quat_about("y", -0.3), "right")))
    extra = ()
    if obstacles:
        extra = (Obstacle.from_dict({"type": "sphere", "center": [0.3, 0.0, 0.1], "radius": 0.05}),
                 Obstacle.from_dict({"type": "capsule", "a": [0.0, 0.0, 0.1], "b": [0.3, 0.0, 0.15], "radius": 0.04}),
                 Obstacle.from_dict({"type": "box", "center": [0.2, 0.0, 0.3], "half_extents": [0.1, 0.2, 0.05],
                                     "orientation": [0.0, 0.2, 0.0, 0.98]}))
    return dataclasses.replace(
        problem, string=string, grips=grips, obstacles=(problem.obstacles + extra) if obstacles else (),
        relative_positions=(RelativePosition(0.2 * L, 0.7 * L, np.array([0.1, 0.0, 0.05]) * L),),
        loads=(Load(0.55 * L, np.array([0.1, 0.0, -0.3]), np.array([0.0, 0.02, 0.0])),))


def build(case: str) -> StringNLP:
    """The NLP of a named case: 'planar <scene>', 'planar features', 'euler seed N', 'euler stretched N'."""
    if case.startswith("planar features"):
        problem = planar_scene(stretch="inextensible" not in case)
        return StringNLP(problem, SolverOptions(model="planar", order=10, obstacle_slots=2))
    if case.startswith("planar "):
        scene = load_scene(case.split()[1])
        return StringNLP(scene.problem, dataclasses.replace(scene.options, model="planar"))
    if case.startswith("euler seed"):
        return StringNLP(random_scene(int(case.split()[2])), SolverOptions(model="full", rotation="euler"))
    if case.startswith("euler stretched"):
        return StringNLP(stretched_scene(int(case.split()[2])), SolverOptions(model="full", rotation="euler"))
    if case.startswith("euler features"):  # the planar scene on the 3D model, two clamps: twist held
        problem = planar_scene()
        grips = (problem.grips[0], problem.grips[1], dataclasses.replace(problem.grips[2], mode="clamp"))
        return StringNLP(dataclasses.replace(problem, grips=grips), SolverOptions(model="full", rotation="euler"))
    raise ValueError(case)


CASES = ["planar default_cable", "planar paper_fig5_force", "planar paper_fig2_transition", "planar features",
         "planar features inextensible", "euler seed 3", "euler stretched 4", "euler features"]


@pytest.mark.parametrize("case", CASES)
def test_the_assembled_contact_free_system_equals_the_flattened_one(case):
    nlp = build(case)
    assert not nlp.director and nlp.planar == case.startswith("planar")
    assert_equal_systems(nlp.kkt_free_fn, nlp)


@pytest.mark.parametrize("case", CASES)
def test_the_assembled_system_of_every_row_equals_the_flattened_one(case):
    nlp = build(case)
    reference = flattened(nlp)
    jacobian = ca.Function("flat_jacobian", [nlp.z_sym, nlp.p_sym], [ca.jacobian(nlp.g_sym, nlp.z_sym)])
    values = ca.Function("g", [nlp.z_sym, nlp.p_sym], [nlp.g_sym[nlp.n_free_rows:]])
    rng = np.random.default_rng(11)
    rows = nlp.g_sym.shape[0]
    for _ in range(2):
        z, p, lam = rng.normal(size=nlp.z_sym.shape[0]), rng.uniform(0.5, 1.5, nlp.p_sym.shape[0]), rng.normal(size=rows)
        got = list(nlp.kkt_fn(z, p, lam)) + [nlp.jac_g_fn(z, p), nlp.hessian_fn(z, p, lam)]
        want = list(reference(z, p, lam)) + [jacobian(z, p), reference(z, p, lam)[3]]
        for name, a, b in zip(["grad f", "g", "jacobian", "hessian", "jac_g_fn", "hessian_fn"],
                              got[:4] + got[5:], want):
            a, b = ca.DM(a).full(), ca.DM(ca.densify(b)).full()
            assert np.max(np.abs(a - b)) <= 1e-12 * (1.0 + np.max(np.abs(b))), name
        energies = ca.DM(got[4]).full().ravel()
        np.testing.assert_allclose(energies, np.asarray(nlp.energy_fn(z, p), dtype=float).ravel(), rtol=1e-12, atol=1e-12)
        if nlp.obstacle_g_fn is not None:
            a, b = ca.DM(nlp.obstacle_g_fn(z, p)).full(), ca.DM(values(z, p)).full()
            assert np.max(np.abs(a - b)) <= 1e-12 * (1.0 + np.max(np.abs(b))), "obstacle_g"


def test_the_planar_feature_scene_has_every_row_kind():
    """The feature scene exercises what it claims: 3 grip modes, relative rows, a moment, 4 obstacle types."""
    nlp = build("planar features")
    kinds = {k[0] if k[0] != "grip" else f"grip {k[2] if k[2] != 'position' else 'position'}" for k in nlp.row_kind}
    assert kinds == {"grip position", "grip phi", "relative", "obstacle", "slot"}
    assert {ob.type for ob in nlp.problem.obstacles} == {"halfspace", "sphere", "capsule", "box"}
    assert nlp.stretch and len(nlp.problem.loads) == 1 and nlp.obstacle_g_fn is not None


@pytest.mark.skipif(compiler() is None, reason="no C compiler")
@pytest.mark.parametrize("case", ["planar features", "euler features"])
def test_the_compiled_assembled_system_equals_the_interpreted_one(case, tmp_path, monkeypatch):
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    nlp = build(case)
    rng = np.random.default_rng(3)
    z, p = rng.normal(size=nlp.z_sym.shape[0]), rng.uniform(0.5, 1.5, nlp.p_sym.shape[0])
    for fn, args in ((nlp.kkt_free_fn, [z, p, rng.normal(size=nlp.n_free_rows)]),
                     (nlp.kkt_fn, [z, p, rng.normal(size=nlp.g_sym.shape[0])]), (nlp.obstacle_g_fn, [z, p])):
        native, ok = compiled(fn)
        assert ok and isinstance(native, NativeFunction)
        outputs = native(*args)
        outputs = outputs if isinstance(outputs, (list, tuple)) else [outputs]
        assert len(outputs) == fn.n_out()
        for got, want in zip(outputs, fn.call(args)):
            want = np.asarray(want)
            assert np.max(np.abs(got - want)) <= 1e-10 * (1.0 + np.max(np.abs(want)))
