"""A strip: two bending stiffnesses (string.lateral_bend_stiffness) against closed forms.

Cold and streamed.  The material frame (t, d1, d2) is held at a clamp as the grip's (x, y, z)
axes: the strip's width runs along d1, bend_stiffness Rf acts about d1 and lateral_bend_stiffness
Rl about d2 (model/problem.py).  References: the linear cantilever under a small tip load,
δ = P L³ / (3 R) about either axis, and Prandtl's lateral-torsional buckling of a cantilever strip
loaded at its tip through the centroid in its stiff plane, P_cr = 4.013 √(Rf Rt) / L² for Rl ≫ Rf
(Timoshenko & Gere, Theory of Elastic Stability, 2nd ed., sec. 6.2: γ₁ = 4.013), where the
smallest reduced-Hessian eigenvalue of the in-plane state changes sign and with it the verdict
``stable``.  The equilibrium residual (both the one-call output function and the numpy path) must
be near zero on every answer: it is built from R diag(Rt, Rf, Rl) Ω and would not be with Rf
about d2.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.scene import scene_from_dict
from dlo_ros.scene.writing import scene_to_dict
from dlo_ros.solver.build.reference_frame import planarity_violation
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.results.stability import is_stable
from dlo_ros.solver.state import SolverState
from dlo_ros.solver.update.ipopt import LEFT_SADDLE
from dlo_ros.solver.shape_solver import ShapeSolver

RF, RT, L = 1.0, 1.5, 1.0
IDENT = (0.0, 0.0, 0.0, 1.0)


def strip(force, lateral: float, twist: float = RT, q=IDENT) -> Problem:
    """A weightless strip clamped at s = 0 (width along the grip's y-axis), a force at its tip."""
    string = StringProperties(
        L,
        Profile.constant(RF),
        Profile.constant(twist),
        Profile.constant(0.0),
        lateral_bend_stiffness=Profile.constant(lateral),
    )
    grip = Grip("clamp", 0.0, "clamp", GripPose.checked((0.0, 0.0, 0.0), q, "clamp"))
    return Problem(string, (grip,), loads=(Load(L, force=np.asarray(force, dtype=float)),))


def numpy_residual(solver: ShapeSolver) -> float:
    """The committed state's equilibrium residual [m] through the numpy path (wrenches.py)."""
    fns = solver.functions
    saved, fns.outputs = fns.outputs, None
    try:
        state = solver.committed_state
        r = solver.outputs.result(solver.problem, solver.problem, state, "", 0, 0.0, True, 0, None)
    finally:
        fns.outputs = saved
    return r.equilibrium_residual_m


def solved(problem: Problem, how: str, ramp: list[Problem], order: int = 12):
    """Solve ``problem`` cold, or as the last of warm updates through ``ramp``."""
    solver = ShapeSolver(
        ramp[0] if how == "stream" else problem,
        SolverOptions(model="full", order=order),
        compile="off",
    )
    if how == "cold":
        return solver, solver.solve()
    assert solver.solve().ok
    result = None
    for prob in ramp[1:] + [problem]:
        solver.set_problem(prob)
        result = solver.solve()
        assert result.ok and result.warm_started, result.message
    return solver, result


@pytest.mark.parametrize("how", ["cold", "stream"])
@pytest.mark.parametrize("axis, stiffness", [(2, RF), (1, 100.0 * RF)])
def test_cantilever_tip_deflection_about_each_axis(how, axis, stiffness):
    """Tip load P e_z bends about d1 (Rf), P e_y about d2 (Rl = 100 Rf): δ = P L³ / (3 R)."""
    P = 1e-3 * stiffness / L**2  # P L² / R = 1e-3: the nonlinear correction is ~1e-7 relative
    force = np.zeros(3)
    force[axis] = P
    ramp = [strip(force * k, 100.0 * RF) for k in (0.2, 0.6)]
    solver, r = solved(strip(force, 100.0 * RF), how, ramp)
    assert r.ok and r.stable, r.message
    exact = P * L**3 / (3 * stiffness)
    assert r.points[-1, axis] == pytest.approx(exact, rel=1e-5)
    assert abs(r.points[-1, 3 - axis]) < 1e-12  # no coupling into the other axis
    assert r.equilibrium_residual_m < 1e-10 * L
    assert numpy_residual(solver) < 1e-10 * L


@pytest.mark.parametrize("how", ["cold", "stream"])
def test_bent_and_twisted_strip_is_an_equilibrium(how):
    """A large oblique tip load: a 3D shape that bends about both axes and twists; residual ~ 0."""
    force = np.array([0.0, 6.0, -3.0])
    ramp = [strip(force * k, 10.0 * RF) for k in (0.25, 0.5, 0.75)]
    solver, r = solved(strip(force, 10.0 * RF), how, ramp, order=16)
    assert r.ok and r.stable, r.message
    assert abs(r.points[-1, 1]) > 0.05 and abs(r.points[-1, 2]) > 0.2  # both axes bent
    assert r.equilibrium_residual_m < 1e-8 * L
    assert numpy_residual(solver) < 1e-8 * L
    # the isotropic rod under the same load bends in the load's plane: the strip does not
    iso = ShapeSolver(
        replace(
            strip(force, 10.0 * RF),
            string=replace(strip(force, 10.0).string, lateral_bend_stiffness=None),
        ),
        SolverOptions(model="full", order=16),
        compile="off",
    ).solve()
    tip = iso.points[-1]
    assert abs(tip[1] * force[2] - tip[2] * force[1]) < 1e-8
    strip_tip = r.points[-1]
    assert abs(strip_tip[1] * force[2] - strip_tip[2] * force[1]) > 1e-2


def in_plane_state(solver: ShapeSolver, below: SolverState, p: np.ndarray) -> SolverState:
    """The in-plane equilibrium at parameters ``p``: Newton's KKT steps from ``below``'s in-plane
    state (no lateral unknown moves: the system keeps the plane's symmetry), independent of the
    solver's update stages and their saddle escapes."""
    nlp, nf = solver.nlp, solver.nlp.n_free_rows
    z, lam = below.z.copy(), below.lam_g.copy()
    for _ in range(6):
        kkt, res, _, _ = solver.functions.kkt_free(z, p, lam[:nf])
        res = np.asarray(res).ravel() - np.concatenate([np.zeros(z.size), nlp.lbg[:nf]])
        step = np.linalg.solve(np.asarray(kkt), -res)
        z, lam[:nf] = z + step[: z.size], lam[:nf] + step[z.size :]
    assert np.abs(res).max() < 1e-12
    return SolverState(z, lam, below.lam_x.copy(), p)


@pytest.mark.parametrize("how", ["cold", "stream"])
def test_prandtl_lateral_torsional_buckling(how):
    """The in-plane state is stable below P_cr = 4.013 √(Rf Rt) / L² (Rl = 1e4 Rf), unstable above.

    λ_min changes sign there and the verdict ``stable`` with it; past P_cr the solver leaves the
    in-plane saddle for a stable laterally buckled shape of lower energy."""
    p_cr = 4.013 * np.sqrt(RF * RT) / L**2
    ramp = [strip([0.0, k * p_cr, 0.0], 1e4 * RF) for k in (0.5, 0.8, 0.9, 0.95)]
    below_solver, below = solved(strip([0.0, 0.98 * p_cr, 0.0], 1e4 * RF), how, ramp)
    assert below.ok and below.stable is True and below.min_eigenvalue > 0, below.message
    assert abs(below.points[-1, 2]) < 1e-10 and LEFT_SADDLE not in below.message  # in-plane
    assert below.equilibrium_residual_m < 1e-9 * L
    above_solver, above = solved(strip([0.0, 1.02 * p_cr, 0.0], 1e4 * RF), how, ramp)
    # the in-plane state at 1.02 P_cr, judged as the solver judges a result (outputs.result): the
    # roll mode sees |v|ᵀ|H||v| ~ 5e2 while the stiff axis makes max|H| ~ 3e6 (stability.is_stable)
    saddle_state = in_plane_state(
        below_solver, below_solver.committed_state, above_solver.committed_state.p
    )
    saddle = below_solver.outputs.result(
        above_solver.problem, above_solver.problem, saddle_state, "", 0, 0.0, True, 0, None
    )
    assert abs(saddle.points[-1, 2]) < 1e-10 and saddle.equilibrium_residual_m < 1e-9 * L
    assert saddle.min_eigenvalue < 0 and saddle.stable is False, saddle.min_eigenvalue
    # the solver's own answer left it: stable, verified, out of the plane and lower
    assert above.ok and above.stable is True and LEFT_SADDLE in above.message, above.message
    # (its residual, 1.3e-8 L at order 12, is the truncation of a bent and twisted shape)
    assert above.equilibrium_residual_m < 1e-6 * L and abs(above.points[-1, 2]) > 0.1 * L
    assert above.energy["total"] < saddle.energy["total"]
    # linear interpolation of λ_min between the two loads: its zero within 0.2 % of P_cr
    root = 0.98 + 0.04 * below.min_eigenvalue / (below.min_eigenvalue - saddle.min_eigenvalue)
    assert root == pytest.approx(1.0, abs=2e-3)


def test_the_verdict_scales_with_the_stiffness_the_mode_sees():
    """H = diag(3e6, 1): a mode along the soft unknown at λ = −0.023 is unstable (3e6 · 1e-8 = 0.03
    would call it neutral); round-off of the same size along the stiff unknown stays neutral."""
    h = np.diag([3.0e6, 1.0])
    soft, stiff = np.array([0.0, 1.0]), np.array([-1.0, 0.0])
    assert not is_stable(-0.023, h, soft)
    assert is_stable(-0.023, h, stiff)  # 0.023 / 3e6 ~ 8e-9: within the stiff unknown's round-off
    assert is_stable(-1e-9, h, soft) and is_stable(0.5, h, None)
    assert not is_stable(-1e-7, h, None)  # no mode known: the strict floor 1
    # the mode's scale is |v|ᵀ|H||v| of the unit vector: coupling entries count, the length not
    coupled = np.array([[1.0, -0.9], [-0.9, 1.0]])
    assert is_stable(-1.5e-8, coupled, 10.0 * np.array([1.0, 1.0]))  # scale 1.9
    assert not is_stable(-2.5e-8, coupled, np.array([1.0, 1.0]))


def test_absent_lateral_stiffness_is_the_isotropic_rod():
    """No lateral_bend_stiffness: the parameters carry no Rl and the model is not a strip."""
    prob = strip([0.0, 0.0, -1.0], 1.0)
    rod = replace(prob, string=replace(prob.string, lateral_bend_stiffness=None))
    solver = ShapeSolver(rod, SolverOptions(model="full", order=8), compile="off")
    assert not solver.nlp.model.lateral and "Rl" not in solver.nlp.params.slices
    assert not solver.nlp.model.layout.frame  # one clamp, isotropic: the tangent model as before
    strip_solver = ShapeSolver(prob, SolverOptions(model="full", order=8), compile="off")
    assert strip_solver.nlp.model.lateral and strip_solver.nlp.model.layout.frame
    # a stream that turns the rod into a strip rebuilds the NLP (its parameters carry Rl)
    assert solver.solve().ok
    solver.set_problem(prob)
    r = solver.solve()
    assert r.ok and solver.nlp.model.lateral, r.message


def scene_dict(**string) -> dict:
    return {
        "name": "strip",
        "string": {"length": 1.0, "bend_stiffness": 1.0, "twist_stiffness": 1.5, **string},
        "grips": [
            {
                "name": "a",
                "s": 0.0,
                "mode": "clamp",
                "position": [0, 0, 0],
                "orientation": [0, 0, 0, 1],
            }
        ],
    }


@pytest.mark.parametrize(
    "value, words",
    [
        (-1.0, "string.lateral_bend_stiffness"),
        (0.0, "string.lateral_bend_stiffness"),
        (float("nan"), "string.lateral_bend_stiffness"),
        ({"table": [[0.0, 1.0], [1.0, -2.0]]}, r"string.lateral_bend_stiffness.table\[1\]\[1\]"),
    ],
)
def test_bad_lateral_stiffness_is_refused_naming_the_field(value, words):
    with pytest.raises(ValueError, match=words):
        scene_from_dict(scene_dict(lateral_bend_stiffness=value))


def test_strip_without_twist_stiffness_or_with_euler_angles_is_refused():
    with pytest.raises(ValueError, match=r"lateral_bend_stiffness: needs twist_stiffness > 0"):
        scene_from_dict(scene_dict(lateral_bend_stiffness=100.0, twist_stiffness=0.0))
    prob = strip([0.0, 0.0, -1.0], 100.0)
    with pytest.raises(ValueError, match=r"lateral_bend_stiffness: the Euler-angle model"):
        ShapeSolver(
            prob, SolverOptions(model="full", rotation="euler", basis="chebyshev"), compile="off"
        )


def test_scene_round_trip_keeps_the_lateral_stiffness_and_omits_it_when_absent():
    table = {"table": [[0.0, 50.0], [1.0, 80.0]]}
    scene = scene_from_dict(scene_dict(lateral_bend_stiffness=table))
    d = scene_to_dict(scene)
    assert d["string"]["lateral_bend_stiffness"] == table
    assert scene_from_dict(d).problem.string == scene.problem.string
    assert "lateral_bend_stiffness" not in scene_to_dict(scene_from_dict(scene_dict()))["string"]


def test_planar_model_needs_the_width_normal_to_the_plane():
    """The planar model bends about the plane's normal: right for a strip whose width is it."""
    flat = strip([0.0, 0.0, -1.0], 100.0)  # width along y, the plane x-z (normal y)
    assert planarity_violation(flat, np.array([0.0, 1.0, 0.0])) == ""
    rolled = strip([0.0, 0.0, -1.0], 100.0, q=(np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)))
    assert "strip's width" in planarity_violation(rolled, np.array([0.0, 1.0, 0.0]))
    rod = replace(rolled, string=replace(rolled.string, lateral_bend_stiffness=None))
    assert planarity_violation(rod, np.array([0.0, 1.0, 0.0])) == ""
