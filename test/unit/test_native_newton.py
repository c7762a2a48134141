"""The warm update as one compiled call (dlo_ros.solver.native.newton, #14): the C loop around the
compiled contact-free KKT function takes chord steps (K factored once, the residual alone evaluated per
step) to the root the Python path's Newton steps (fused CasADi call plus Python steps on the interpreted
functions) converge to, so a stream gives the same shapes to 1e-10; the active-set loop takes the Python
path's own steps until its set settles, then chord steps, to the same KKT point; results say which
derivatives ran."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model import Grip, Profile
from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.compiled import compiler
from dlo_ros.solver.update.kkt import regularised
from dlo_ros.solver.native.settings import (NEWTON_CHORD_CONTRACTION, NEWTON_CHORD_START, NEWTON_CHORD_STEPS,
                                NEWTON_CHORD_TOLERANCE, NEWTON_DUAL_TOLERANCE, NEWTON_MAX_STEP,
                                NEWTON_PRIMAL_TOLERANCE)
from dlo_ros.solver.options import SolverOptions

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler")


def targets(scene, count: int) -> list[np.ndarray]:
    """The right grip along a small arc in the x–z plane and out of it (steps of 1 % of L)."""
    start = scene.problem.grip("right").pose.position
    a = np.linspace(0.0, 1.0, count)
    return [start + 0.08 * np.array([np.cos(2 * t) - 1.0, 0.3 * np.sin(3 * t), np.sin(2 * t)]) for t in a]


@pytest.fixture(scope="module")
def solvers(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DLO_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.delenv("DLO_NO_COMPILE", raising=False)
        scene = load_scene("default_cable")
        options = SolverOptions(model="full", order=12)
        native = ShapeSolver(scene.problem, options, compile="blocking")
        interpreted = ShapeSolver(scene.problem, options, compile="off")
        yield scene, native, interpreted


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
        assert a.energy["total"] == pytest.approx(b.energy["total"], rel=1e-10)
        assert a.min_eigenvalue == pytest.approx(b.min_eigenvalue, rel=1e-8)
    assert newton >= 20  # the compiled loop was what ran
    assert native.committed_state.reduced_eigen is not None  # the last eigenvalue came from the compiled call


def chord_reference(nlp, u, p, kkt, residual, max_evaluations: int):
    """The C loop's contract in numpy on the interpreted functions (native_newton's module docstring):
    (u, K, energies at the answer, steps, evaluations of K)."""
    n = nlp.z_sym.shape[0]
    k, r, energies = kkt, residual, None
    lu = regularised(k, n)
    previous, evaluations, steps, fresh, here = np.inf, 0, 0, True, True

    def evaluate(u):
        k, r, _, energies = (np.asarray(v) for v in nlp.kkt_free_fn(u[:n], p, u[n:]))
        return k, r[:, 0], energies

    while steps < NEWTON_CHORD_STEPS:
        step = np.linalg.solve(lu, r)
        big = np.abs(step[:n]).max()
        if big > NEWTON_MAX_STEP:
            assert not here and evaluations < max_evaluations, "the reference refused the step"
            (k, r, energies), evaluations = evaluate(u), evaluations + 1
            lu, previous, fresh, here = regularised(k, n), np.inf, True, True
            continue
        u, steps, here = u - step, steps + 1, False
        shrinking = big <= NEWTON_CHORD_CONTRACTION * previous
        if (big > NEWTON_CHORD_START or (not shrinking and big > NEWTON_CHORD_TOLERANCE)) and \
                evaluations < max_evaluations:
            (k, r, energies), evaluations = evaluate(u), evaluations + 1
            lu, previous, fresh, here = regularised(k, n), np.inf, True, True
        else:
            r, previous, fresh = np.asarray(nlp.residual_free_fn(u[:n], p, u[n:]))[:, 0], big, False
        if np.abs(r[:n]).max() < NEWTON_DUAL_TOLERANCE and np.abs(r[n:]).max() < NEWTON_PRIMAL_TOLERANCE and \
                (big <= NEWTON_CHORD_TOLERANCE or not shrinking):
            if not fresh:
                (k, r, energies), evaluations = evaluate(u), evaluations + 1
            return u, k, energies, steps, evaluations
    raise AssertionError("the reference did not converge")


def newton_root(nlp, u, p, kkt, residual):
    """The root of r by plain regularised Newton steps in numpy, to round-off."""
    n = nlp.z_sym.shape[0]
    k, r = kkt, residual
    for _ in range(12):
        u = u - np.linalg.solve(regularised(k, n), r)
        k, r, _, _ = (np.asarray(v) for v in nlp.kkt_free_fn(u[:n], p, u[n:]))
        r = r[:, 0]
    return u


@pytest.mark.parametrize("move", [0.01, 0.06], ids=["1%L", "6%L"])
def test_one_call_takes_the_chord_steps_to_the_newton_root(solvers, move):
    """From the same start the C loop's iterate, Newton matrix, energies and counts equal those of the
    chord steps taken here in numpy on the interpreted functions (to rounding), and its answer is the
    root plain Newton steps converge to.  At 6 % of L the first steps exceed NEWTON_CHORD_START and are
    Newton's own (K evaluated on the way)."""
    scene, native, interpreted = solvers
    native.solve()
    state, nlp = native.snapshot(), native.nlp
    n, nf = state.z.size, nlp.n_free_rows
    rot = scene.problem.grip("right").pose.orientation
    target = scene.problem.grip("right").pose.position + move * np.array([-1.0, 0.4, 1.0]) / np.sqrt(2.16)
    p = native.pack_parameters(scene.problem.with_grip_poses({"right": GripPose(target, rot)}), state.z)
    kkt, residual, _, _ = (np.asarray(v) for v in nlp.kkt_free_fn(state.z, p, state.lam_g[:nf]))
    u0 = np.concatenate([state.z, state.lam_g[:nf]])
    native.functions.newton_native.lapack.inertia = 0  # the eigenpair, not the inertia's verdict
    try:
        out = native.functions.newton_native(u0, p, kkt, residual[:, 0], 10)
    finally:
        native.functions.newton_native.lapack.inertia = 1
    u, k, energies, steps, evaluations = chord_reference(nlp, u0, p, kkt, residual[:, 0], 10)
    assert out.code == 0 and (out.steps, out.evaluations) == (steps, evaluations)
    assert evaluations >= (2 if move > 0.05 else 1) and steps >= 3
    np.testing.assert_allclose(out.u, u, atol=1e-12)
    np.testing.assert_allclose(out.kkt, k, atol=1e-9 * np.abs(k).max())
    np.testing.assert_allclose(out.energies, energies.ravel(), rtol=1e-12)
    assert np.abs(out.residual[:n]).max() < 1e-9 and np.abs(out.residual[n:]).max() < 1e-11
    np.testing.assert_allclose(out.u[:n], newton_root(nlp, u0, p, kkt, residual[:, 0])[:n], atol=1e-11)
    # the stability eigenpair the call computed at the answer, against an SVD null space and a full
    # symmetric eigendecomposition of the reduced Hessian of the same K
    import scipy.linalg

    basis = scipy.linalg.null_space(out.kkt[n:, :n])
    values, vectors = np.linalg.eigh(basis.T @ out.kkt[:n, :n] @ basis)
    assert values[1] - values[0] > 1e-6 * abs(values).max()  # a simple eigenvalue: its vector is defined
    value, direction = out.eigen
    assert value == pytest.approx(values[0], rel=1e-10, abs=1e-12 * abs(values).max())
    assert abs(direction @ (basis @ vectors[:, 0])) == pytest.approx(1.0, abs=1e-10)


def test_the_compiled_loop_refuses_a_step_the_python_path_refuses(solvers):
    """A start whose first step exceeds NEWTON_MAX_STEP ends the call without an answer (code 3), as
    the Python path gives up there (then substeps or IPOPT take over)."""
    from dlo_ros.solver.native.newton import STEP_TOO_LARGE

    scene, native, _ = solvers
    native.solve()
    state, nlp = native.snapshot(), native.nlp
    nf = nlp.n_free_rows
    rot = scene.problem.grip("right").pose.orientation
    u0 = np.concatenate([state.z, state.lam_g[:nf]])
    far = native.pack_parameters(scene.problem.with_grip_poses(
        {"right": GripPose(np.array([0.1, 0.3, 0.9]), rot)}), state.z)
    kkt, residual, _, _ = (np.asarray(v) for v in nlp.kkt_free_fn(state.z, far, state.lam_g[:nf]))
    out = native.functions.newton_native(u0, far, kkt, residual[:, 0], 10)
    assert out.code == STEP_TOO_LARGE and out.largest > 0.5


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


def test_one_active_call_reaches_the_numpy_loops_answer(solvers):
    """From a state resting on the table, with its active rows held and the grips moved, the C loop's
    chord steps end at the KKT point active_set.active_steps (regularised Newton steps in numpy on the
    interpreted function) ends at: the same active set, iterate and multipliers (to rounding), with the
    derivatives evaluated there."""
    from dlo_ros.solver.update.active_set import active_steps
    from dlo_ros.solver.update.kkt import active_rows

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
    native.functions.newton_active.lapack.inertia = 0  # the eigenpair, not the inertia's verdict
    try:
        out = native.functions.newton_active(state.z, lam, p, active, nlp.ubg, switchable, 4, 10)
    finally:
        native.functions.newton_active.lapack.inertia = 1
    z, lam_ref, grad, g, jac, hess, energies, steps, active_ref = active_steps(
        lambda *a: [np.asarray(v) for v in nlp.kkt_fn(*a)], state.z.copy(), lam.copy(), p, active, nlp.ubg,
        switchable, 4, 10, None)
    assert out.code == 0 and steps >= 2 and out.steps >= steps
    assert out.evaluations < steps  # chord steps: fewer evaluations of the full function than Newton's
    np.testing.assert_array_equal(out.active, active_ref)
    np.testing.assert_allclose(out.z, z, atol=1e-11)
    np.testing.assert_allclose(out.lam, lam_ref, atol=1e-8 * np.abs(lam_ref).max())
    here = [np.asarray(v) for v in nlp.kkt_fn(out.z, p, out.lam)]
    np.testing.assert_allclose(out.hessian, here[3], atol=1e-9 * np.abs(here[3]).max())
    np.testing.assert_allclose(out.jacobian, here[2], atol=1e-12)
    np.testing.assert_allclose(out.gradient, here[0].ravel(), atol=1e-12)
    np.testing.assert_allclose(out.energies, here[4].ravel(), rtol=1e-12)
    # the stability eigenpair the call computed at the answer, on the rows stability.py holds there,
    # against an SVD null space and a full symmetric eigendecomposition of the reduced Hessian
    import scipy.linalg

    held = nlp.equality | (np.abs(out.lam) > 1e-9) | (out.g > nlp.ubg - 1e-9)
    assert np.any(held[nlp.n_free_rows:])  # the table's rows are among them
    basis = scipy.linalg.null_space(out.jacobian[held])
    values, vectors = np.linalg.eigh(basis.T @ out.hessian @ basis)
    assert values[1] - values[0] > 1e-6 * abs(values).max()  # a simple eigenvalue: its vector is defined
    value, direction = out.eigen
    assert value == pytest.approx(values[0], rel=1e-10, abs=1e-12 * abs(values).max())
    assert abs(direction @ (basis @ vectors[:, 0])) == pytest.approx(1.0, abs=1e-10)


def test_a_warm_update_is_one_compiled_call(solvers):
    """On the table and off it, a stream's Newton updates call no compiled function but their loop: the
    obstacle rows, the stability eigenpair and the outputs come from the loop's own call
    (``native_newton.UpdateOutputs``), and those outputs are the outputs' function's values at the
    answer, to the bit.  (An update whose Newton lands on a saddle leaves it by steps in Python:
    ``newton.leave_saddle``.)  The interpreted solver's stream gives the same shapes, wrenches and
    eigenvalues."""
    from dlo_ros.solver.build import compiled as C
    from dlo_ros.solver.native import newton as NN

    scene, native, interpreted = solvers
    fns = native.functions
    assert fns.outputs_compiled and fns.newton_native.after is not None and fns.newton_active.after is not None
    rot = scene.problem.grip("right").pose.orientation
    native.reset(), interpreted.reset()
    native.solve(lowered(0.02, rot)), interpreted.solve(lowered(0.02, rot))
    other, loops = [], {"free": 0, "active": 0}
    wrapped = [(C.NativeFunction, "__call__"), (NN.WithNodePart, "__call__")]
    saved = [getattr(cls, name) for cls, name in wrapped]
    free, active = NN.NativeNewton.__call__, NN.ActiveNewton.__call__

    def counting(kind, call):
        def run(*a, **k):
            loops[kind] += 1
            return call(*a, **k)
        return run

    try:
        for (cls, name), call in zip(wrapped, saved):
            setattr(cls, name, lambda *a, _cls=cls.__name__, _call=call, **k: other.append(_cls) or _call(*a, **k))
        NN.NativeNewton.__call__, NN.ActiveNewton.__call__ = counting("free", free), counting("active", active)
        results, single = [], 0
        for drop in list(np.arange(0.025, 0.0651, 0.005)) + list(np.arange(0.06, 0.0199, -0.005)):
            other.clear()
            results.append(native.solve(lowered(float(drop), rot)))
            assert results[-1].ipopt_status == "Newton", results[-1].message
            if "left an unstable equilibrium" not in results[-1].message:
                assert not other, other  # no compiled call beside the loop's
                state = native.committed_state
                assert state.outputs is not None and state.reduced_eigen is not None
                single += 1
    finally:
        for (cls, name), call in zip(wrapped, saved):
            setattr(cls, name, call)
        NN.NativeNewton.__call__, NN.ActiveNewton.__call__ = free, active
    assert loops["free"] >= 3 and loops["active"] >= 3, loops  # both loops ran, off and on the table
    assert single >= len(results) - 2, (single, len(results))
    nlp, state = native.nlp, native.committed_state
    lam_si = state.lam_g / (nlp.row_scale * nlp.sigma)
    direct = fns.outputs(state.z, state.p, lam_si, fns.output_function.profiles(native.problem.string))
    for mine, theirs in zip(state.outputs.values, direct):
        np.testing.assert_array_equal(mine, theirs)
    interpreted.reset()
    interpreted.solve(lowered(0.02, rot))
    for drop, a in zip(list(np.arange(0.025, 0.0651, 0.005)) + list(np.arange(0.06, 0.0199, -0.005)), results):
        b = interpreted.solve(lowered(float(drop), rot))
        assert a.status == b.status == "ok" and a.stable == b.stable
        np.testing.assert_allclose(a.points, b.points, atol=1e-10)
        np.testing.assert_allclose(a.orientations, b.orientations, atol=1e-9)
        for name in a.grips:
            np.testing.assert_allclose(a.grips[name].force, b.grips[name].force, atol=1e-7)
        assert a.min_eigenvalue == pytest.approx(b.min_eigenvalue, rel=1e-8)
        assert a.equilibrium_residual_m == pytest.approx(b.equilibrium_residual_m, rel=1e-6, abs=1e-12)


def test_a_query_whose_chord_steps_outnumber_newtons_cap_is_still_a_newton_answer(solvers):
    """A grip moved 8 cm takes the compiled loop more chord steps than the ten Newton steps the Python
    path allows; the converged answer is still taken (not handed to substeps and IPOPT) and equals the
    interpreted path's."""
    scene, native, interpreted = solvers
    held = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}  # the scene's own
    native.reset(), interpreted.reset()
    native.solve(held), interpreted.solve(held)
    rot = scene.problem.grip("right").pose.orientation
    x = scene.problem.grip("right").pose.position + 0.08 * np.array([-0.6, 0.5, 0.6])
    calls = []
    loop = native.functions.newton_native
    native.functions.newton_native = lambda *a: calls.append(loop(*a)) or calls[-1]
    try:
        a = native.solve({"right": (x, rot)}, commit=False)
    finally:
        native.functions.newton_native = loop
    b = interpreted.solve({"right": (x, rot)}, commit=False)
    assert len(calls) == 1 and calls[0].code == 0 and calls[0].steps > 10, [(c.code, c.steps) for c in calls]
    assert a.status == b.status == "ok" and a.ipopt_status == b.ipopt_status == "Newton"
    np.testing.assert_allclose(a.points, b.points, atol=1e-10)


@pytest.mark.parametrize("model", ["full", "planar", "full, stretch, 2 elements"])
def test_the_node_blocks_hold_the_node_map_exactly_in_small_dgemm_calls(model):
    """``NodeBlocks``, from which the compiled loops add Eᵀ W: its blocks put back together are E, entry for
    entry, each column in one group; and no dgemm call multiplies more than ``CHUNK_WORK`` (so OpenBLAS
    keeps it on the calling thread)."""
    from dlo_ros.solver.native.newton import CHUNK_WORK, NodeBlocks
    from dlo_ros.solver.build.nlp import StringNLP

    scene = load_scene("default_cable")
    problem, options = scene.problem, replace(scene.options, model=model.split(",")[0], order=16)
    if "stretch" in model:
        middle = Grip("middle", 0.5, "pin", GripPose.checked([0.3, 0.0, 0.2], [0, 0, 0, 1], "middle"))
        problem = replace(problem, string=replace(problem.string, stretch_stiffness=Profile.constant(50.0)),
                          grips=problem.grips + (middle,))
    nlp = StringNLP(problem, options)
    E = nlp.node_map
    blocks = NodeBlocks(E, nlp.node_width)
    rebuilt = np.zeros_like(E)
    row = col = block = 0
    for g in range(blocks.count.size // 2):
        R, C = blocks.count[2 * g], blocks.count[2 * g + 1]
        rows, cols = blocks.row[row:row + R], blocks.col[col:col + C]
        assert not rebuilt[:, cols].any()  # each column in one group
        rebuilt[np.ix_(rows, cols)] = blocks.block[block:block + R * C].reshape(R, C, order="F")
        assert blocks.chunk * C * E.shape[1] <= CHUNK_WORK or blocks.chunk == 1
        row, col, block = row + R, col + C, block + R * C
    np.testing.assert_array_equal(rebuilt, E)


def test_the_compiled_stability_rows_follow_the_one_python_setting(solvers, tmp_path, monkeypatch):
    """The rows the stability eigenvalue holds are set once, in ``native_settings``: with
    STABILITY_BOUND_TOLERANCE raised to 5e-3 (scaled), inactive table rows within that of their
    bound join them, in the C of the active-set loop (a library keyed by the new value, compiled
    for it) and in ``stability.min_reduced_eigenvalue`` alike; both against an SVD null space and a
    full eigendecomposition of the reduced Hessian on the rows that tolerance holds.  (Before #36
    the C held its own 1e-9: its eigenvalue then missed by 0.1 of 3.0.)"""
    import scipy.linalg

    from dlo_ros.solver.native import settings as native_settings

    from dlo_ros.solver.results import stability
    from dlo_ros.solver.native.newton import active_library_path
    from dlo_ros.solver.update.kkt import active_rows
    from dlo_ros.solver.state import SolverState

    scene, native, _ = solvers
    before = active_library_path(native.nlp.kkt_split_fn)
    tol = 5e-3
    monkeypatch.setattr(native_settings, "STABILITY_BOUND_TOLERANCE", tol)
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    solver = ShapeSolver(scene.problem, SolverOptions(model="full", order=12), compile="blocking")
    nlp = solver.nlp
    assert active_library_path(nlp.kkt_split_fn).name != before.name  # keyed by the setting
    assert solver.functions.newton_active is not None
    rot = scene.problem.grip("right").pose.orientation
    assert solver.solve(lowered(0.06, rot)).ok
    state = solver.snapshot()
    active = active_rows(nlp, state.lam_g, np.asarray(nlp.g_fn(state.z, state.p)).ravel())
    moved = {"right": GripPose(np.array([0.58, 0.06, 0.34]), rot),
             "left": GripPose(np.array([0.0, 0.0, 0.34]), rot)}
    p = solver.pack_parameters(scene.problem.with_grip_poses(moved), state.z)
    lam = np.where(active, state.lam_g, 0.0)
    solver.functions.newton_active.lapack.inertia = 0  # the eigenpair, not the inertia's verdict
    out = solver.functions.newton_active(state.z, lam, p, active, nlp.ubg,
                                         nlp.contact_row & ~nlp.equality, 4, 10)
    assert out.code == 0 and out.eigen is not None

    def lowest(held):
        basis = scipy.linalg.null_space(out.jacobian[held])
        values = np.linalg.eigvalsh(basis.T @ out.hessian @ basis)
        assert values[1] - values[0] > 1e-6 * abs(values).max()  # simple: a well-defined value
        return values[0]

    base = nlp.equality | (np.abs(out.lam) > 1e-9)
    held, default = base | (out.g > nlp.ubg - tol), base | (out.g > nlp.ubg - 1e-9)
    assert np.count_nonzero(held & ~default) >= 1  # the setting changes which rows are held
    expected, other = lowest(held), lowest(default)
    assert abs(expected - other) > 1e-6 * abs(other)  # ... and the eigenvalue
    assert out.eigen[0] == pytest.approx(expected, rel=1e-10, abs=1e-12 * abs(expected))
    fresh = SolverState(out.z, out.lam, state.lam_x, p, hessian=out.hessian, jacobian=out.jacobian,
                        energies=out.energies, gradient=out.gradient, g=out.g)
    value = stability.min_reduced_eigenvalue(nlp, solver.functions, fresh)
    assert value == pytest.approx(expected, rel=1e-10, abs=1e-12 * abs(expected))


def test_the_library_keys_change_with_the_c_and_with_every_setting(solvers, monkeypatch):
    """A compiled loop is never loaded for C or settings other than its own: both library names
    hash the assembled C (``native_build.driver_digest``) and the ``-D`` values
    (``native_settings``)."""
    from dlo_ros.solver.native import build as native_build
    from dlo_ros.solver.native import settings as native_settings
    from dlo_ros.solver.native.newton import active_library_path, library_path

    _, native, _ = solvers
    nlp = native.nlp

    def names():
        return library_path(nlp.kkt_free_split_fn).name, active_library_path(nlp.kkt_split_fn).name

    first = names()
    assert names() == first  # stable
    for setting in ("STABILITY_MULTIPLIER_TOLERANCE", "STABILITY_BOUND_TOLERANCE",
                    "CONTACT_APPEARED_TOLERANCE"):
        with monkeypatch.context() as m:
            m.setattr(native_settings, setting, 2 * getattr(native_settings, setting))
            changed = names()
        assert changed[0] != first[0] and changed[1] != first[1], setting
    read = native_build.read
    for edited in ("dlo_common.h", "dlo_eigen.h", "dlo_inertia.h", "newton_free.c", "newton_active.c"):
        with monkeypatch.context() as m:
            m.setattr(native_build, "read",
                      lambda name, e=edited: read(name) + ("\n/* */" if name == e else ""))
            changed = names()
        # a header both drivers include changes both names; a driver only its own
        expected = (edited != "newton_active.c", edited != "newton_free.c")
        assert (changed[0] != first[0], changed[1] != first[1]) == expected, edited
    assert names() == first
