"""The warm update as one compiled call (dlo_ros.solver.native_newton, #14): the C Newton loop around
the compiled contact-free KKT function takes the same steps as the Python path (fused CasADi call plus
Python steps on the interpreted functions), so a stream gives the same shapes to 1e-10, and results say
which derivatives ran."""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.compiled import compiler
from dlo_ros.solver.newton import regularised
from dlo_ros.solver.options import SolverOptions

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler")


def targets(scene, count: int) -> list[np.ndarray]:
    """The right grip along a small arc in the x–z plane and out of it (steps of 1 % of L)."""
    start = scene.problem.grip("right").pose.position
    a = np.linspace(0.0, 1.0, count)
    return [start + 0.08 * np.array([np.cos(2 * t) - 1.0, 0.3 * np.sin(3 * t), np.sin(2 * t)]) for t in a]


@pytest.fixture(scope="module")
def solvers(tmp_path_factory):
    import os

    os.environ["DLO_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    os.environ.pop("DLO_NO_COMPILE", None)
    scene = load_scene("default_cable")
    options = SolverOptions(model="full", order=12)
    native = ShapeSolver(scene.problem, options, compile="blocking")
    interpreted = ShapeSolver(scene.problem, options, compile="off")
    yield scene, native, interpreted
    os.environ.pop("DLO_CACHE_DIR", None)


def test_a_stream_with_the_compiled_loop_equals_the_interpreted_one(solvers):
    scene, native, interpreted = solvers
    assert native.functions.newton_native is not None and interpreted.functions.newton_native is None
    rot = scene.problem.grip("right").pose.orientation
    a, b = native.solve(), interpreted.solve()
    assert a.derivatives == "compiled" and b.derivatives == "interpreted"
    newton = 0
    for x in targets(scene, 25):
        a, b = native.solve({"right": (x, rot)}), interpreted.solve({"right": (x, rot)})
        assert a.status == b.status == "ok" and a.ipopt_status == b.ipopt_status
        newton += a.ipopt_status == "Newton"
        np.testing.assert_allclose(a.points, b.points, atol=1e-10)
        assert a.iterations == b.iterations
        assert a.energy["total"] == pytest.approx(b.energy["total"], rel=1e-10)
    assert newton >= 20  # the compiled loop was what ran


def test_one_call_takes_the_python_steps(solvers):
    """From the same start the C loop's iterate, Newton matrix and energies equal those of the
    regularised steps taken here in numpy on the interpreted function (to rounding)."""
    scene, native, interpreted = solvers
    native.solve()
    state, nlp = native.snapshot(), native.nlp
    n, nf = state.z.size, nlp.n_free_rows
    rot = scene.problem.grip("right").pose.orientation
    p = native.pack_parameters(scene.problem.with_grip_poses({"right": GripPose(targets(scene, 3)[1], rot)}), state.z)
    kkt, residual, _, _ = (np.asarray(v) for v in nlp.kkt_free_fn(state.z, p, state.lam_g[:nf]))
    u = np.concatenate([state.z, state.lam_g[:nf]])
    out = native.functions.newton_native(u, p, kkt, residual[:, 0], 10)
    assert out.code == 0 and out.steps >= 3
    k, r = kkt, residual[:, 0]
    for _ in range(out.steps):
        u = u - np.linalg.solve(regularised(k, n), r)
        k, r, _, energies = (np.asarray(v) for v in nlp.kkt_free_fn(u[:n], p, u[n:]))
        r = r[:, 0]
    np.testing.assert_allclose(out.u, u, atol=1e-12)
    np.testing.assert_allclose(out.kkt, k, atol=1e-9 * np.abs(k).max())
    np.testing.assert_allclose(out.energies, energies.ravel(), rtol=1e-12)
    assert np.abs(out.residual[:n]).max() < 1e-9 and np.abs(out.residual[n:]).max() < 1e-11


@pytest.mark.parametrize("options", [SolverOptions(model="planar", order=12),
                                     SolverOptions(model="full", rotation="euler", order=16)],
                         ids=["planar", "euler"])
def test_the_euler_angle_models_stream_with_the_compiled_loop(options, tmp_path, monkeypatch):
    """The planar and Euler-angle models' assembled contact-free functions get the same C loop: a stream
    (in the plane for the planar model) equals the interpreted path to 1e-10."""
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    scene = load_scene("default_cable")
    native = ShapeSolver(scene.problem, options, compile="blocking")
    interpreted = ShapeSolver(scene.problem, options, compile="off")
    assert native.functions.newton_native is not None and interpreted.functions.newton_native is None
    rot = scene.problem.grip("right").pose.orientation
    a, b = native.solve(), interpreted.solve()
    assert a.status == b.status == "ok"
    newton = 0
    for x in targets(scene, 15):
        if options.model == "planar":
            x = x * np.array([1.0, 0.0, 1.0])
        a, b = native.solve({"right": (x, rot)}), interpreted.solve({"right": (x, rot)})
        assert a.status == b.status == "ok" and a.ipopt_status == b.ipopt_status
        newton += a.ipopt_status == "Newton"
        np.testing.assert_allclose(a.points, b.points, atol=1e-10)
        assert a.energy["total"] == pytest.approx(b.energy["total"], rel=1e-10)
    assert newton >= 12


def lowered(drop: float, rot) -> dict:
    """Both grips of the default cable lowered by ``drop`` [m] from 0.4 m (0.04 m and more: the sag
    rests on the table), the right one 5 cm out of the vertical plane: in that plane the cable pressed
    onto the table is a saddle, and which side it leaves to would be decided by rounding."""
    return {"left": ((0.0, 0.0, 0.4 - drop), rot), "right": ((0.6, 0.05, 0.4 - drop), rot)}


def test_contact_updates_with_the_compiled_active_set_loop_equal_the_numpy_loop(solvers):
    """The director model lowered onto the table, slid along it and raised: the updates with obstacle rows
    active run the C loop of ``native_newton.ActiveNewton`` and give the numpy loop's shapes to 1e-10."""
    scene, native, interpreted = solvers
    assert native.functions.newton_active is not None and interpreted.functions.newton_active is None
    calls = []
    loop = native.functions.newton_active
    native.functions.newton_active = lambda *a: calls.append(1) or loop(*a)
    try:
        rot = scene.problem.grip("right").pose.orientation
        native.reset(), interpreted.reset()
        a, b = native.solve(lowered(0.03, rot)), interpreted.solve(lowered(0.03, rot))
        drops = list(np.arange(0.035, 0.0651, 0.005)) + [0.065] * 6 + list(np.arange(0.06, 0.0299, -0.005))
        touching = 0
        for k, drop in enumerate(drops):
            targets = lowered(float(drop), rot)
            if k >= 7 and k < 13:  # slide the right grip along x while resting on the table
                targets["right"] = ((0.6 - 0.01 * (k - 6), 0.05 + 0.01 * (k - 6), 0.4 - drop), rot)
            a, b = native.solve(targets), interpreted.solve(targets)
            assert a.status == b.status == "ok" and a.ipopt_status == b.ipopt_status, (drop, a.message)
            np.testing.assert_allclose(a.points, b.points, atol=1e-10)
            assert a.energy["total"] == pytest.approx(b.energy["total"], rel=1e-10)
            force = sum(a.contact_forces.values(), np.zeros(3))
            touching += bool(np.linalg.norm(force) > 1e-6) and a.ipopt_status == "Newton"
        assert touching >= 8 and len(calls) >= 8, (touching, len(calls))
    finally:
        native.functions.newton_active = loop


def test_one_active_call_takes_the_numpy_steps(solvers):
    """From a state resting on the table, with its active rows held, the C loop's iterate, multipliers
    and derivatives equal those of newton._active_steps on the interpreted function (to rounding)."""
    from dlo_ros.solver.newton import _active_steps, active_rows

    scene, native, interpreted = solvers
    rot = scene.problem.grip("right").pose.orientation
    native.reset()
    assert native.solve(lowered(0.06, rot)).ok
    state, nlp = native.snapshot(), native.nlp
    g0 = np.asarray(nlp.g_fn(state.z, state.p)).ravel()
    active = active_rows(nlp, state.lam_g, g0)
    assert np.any(active[nlp.n_free_rows:])  # obstacle rows are held
    p = native.pack_parameters(scene.problem.with_grip_poses(
        {"right": GripPose(np.array([0.58, 0.06, 0.34]), rot), "left": GripPose(np.array([0.0, 0.0, 0.34]), rot)}),
        state.z)
    lam = np.where(active, state.lam_g, 0.0)
    switchable = nlp.contact_row & ~nlp.equality
    out = native.functions.newton_active(state.z, lam, p, active, nlp.ubg, switchable, 4, 10)
    z, lam_ref, grad, g, jac, hess, energies, steps, active_ref = _active_steps(
        lambda *a: [np.asarray(v) for v in nlp.kkt_fn(*a)], state.z.copy(), lam.copy(), p, active, nlp.ubg,
        switchable, 4, 10, None)
    assert out.code == 0 and out.steps == steps >= 2
    np.testing.assert_array_equal(out.active, active_ref)
    np.testing.assert_allclose(out.z, z, atol=1e-12)
    np.testing.assert_allclose(out.lam, lam_ref, atol=1e-9 * np.abs(lam_ref).max())
    np.testing.assert_allclose(out.hessian, hess, atol=1e-9 * np.abs(hess).max())
    np.testing.assert_allclose(out.jacobian, jac, atol=1e-12)
    np.testing.assert_allclose(out.energies, np.ravel(energies), rtol=1e-12)
