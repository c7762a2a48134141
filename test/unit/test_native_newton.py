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
