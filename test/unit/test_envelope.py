"""The shape and grip-wrench envelope (dlo_ros/solver/results/envelope.py, uncertainty.py).

The linearised spread is checked against Monte-Carlo (the parameters drawn from their covariance,
fixed seed, each draw solved cold and as a warm stream of updates from the nominal) and against
central differences of solves; the inputs' validation (API, scene key ``string.uncertainty``,
``dlo solve --uncertainty``) names the field; a result with no envelope says why.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from support.problems import clamped_pair

from dlo_ros import cli
from dlo_ros.identify import fit
from dlo_ros.identify.observations import load_observations
from dlo_ros.identify.results import FitResult
from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties
from dlo_ros.model.rotations import matrix_to_quat
from dlo_ros.scene import SceneError, load_scene, scene_from_dict, scene_to_dict
from dlo_ros.solver import ShapeResult, ShapeSolver, SolverOptions, make_solver
from dlo_ros.solver.results.envelope import (Envelope, EnvelopeUnavailable, Parameter, Uncertainty,
                                             UncertaintyError, envelope)

REPO = Path(__file__).resolve().parents[2]
SAMPLES = 200
#: the sampled σ of n = 200 draws has a relative standard error 1/sqrt(2n) = 5 %: 20 % is 4 of it
AGREEMENT = 0.20
#: sampled σ against the linear map of the same draws (the empirical covariance): only the response's
#: curvature separates them
LINEARITY = 0.06


@dataclass
class Case:
    """A scene, its model, and the uncertainty the draws come from."""

    problem: Problem
    options: SolverOptions
    uncertainty: Uncertainty


def cable_case() -> Case:
    """default_cable (two clamps 0.6 m apart, sagging 0.35 m) on the 3D director model; σ per key in SI:
    10 % of Rf, 5 % of D, 20 % of Rt (which this planar sag does not feel)."""
    scene = load_scene("default_cable")
    u = Uncertainty.from_sigmas({"bend_stiffness": 0.002, "weight_per_length": 0.025, "twist_stiffness": 0.003})
    return Case(scene.problem, replace(scene.options, model="full"), u)


def torsion_case() -> Case:
    """A heavy pair clamped with the right clamp turned 1 rad about the tangent and offset out of plane
    (3D, twisted: Rf, Rt and D all move it); a correlated covariance of θ = log c, as ``dlo fit``
    reports one."""
    problem = clamped_pair(right=(0.6, 0.1, 0.2), q_right=[np.sin(0.5), 0.0, 0.0, np.cos(0.5)], weight=0.5)
    sd = np.array([0.05, 0.08, 0.04])
    corr = np.array([[1.0, 0.5, -0.3], [0.5, 1.0, 0.2], [-0.3, 0.2, 1.0]])
    u = Uncertainty.from_covariance(("Rf", "twist_stiffness", "D"), corr * np.outer(sd, sd), log=True)
    return Case(problem, SolverOptions(model="full", order=12), u)


def cantilever_case() -> Case:
    """A heavy cantilever (D L³/Rf = 3.1, tangent 0.3 rad below horizontal) on the planar model, its
    weight a three-knot table known knot by knot (a knot-by-knot fit's parameters)."""
    c, s = np.cos(-0.3), np.sin(-0.3)
    frame = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    weight = Profile.table([(0.0, 0.6), (0.25, 0.5), (0.5, 0.4)])
    string = StringProperties(0.5, Profile.constant(0.02), Profile.constant(0.015), weight)
    problem = Problem(string, (Grip("hand", 0.0, "clamp", GripPose(np.zeros(3), matrix_to_quat(frame))),))
    knots = (0.0, 0.25, 0.5)
    names = [Parameter("bend_stiffness")] + [Parameter("weight_per_length", k, knots) for k in range(3)]
    cov = np.diag([0.06, 0.05, 0.04, 0.05]) ** 2
    cov[0, 1] = cov[1, 0] = 0.3 * 0.06 * 0.05
    return Case(problem, SolverOptions(model="planar", order=12), Uncertainty.from_covariance(names, cov, log=True))


CASES = {"default_cable": cable_case, "torsion": torsion_case, "cantilever": cantilever_case}


def with_theta(problem: Problem, uncertainty: Uncertainty, theta: np.ndarray) -> Problem:
    """The problem with every parameter's θ = log c applied (a uniform scale, or one knot's factor)."""
    st = problem.string
    changes: dict[str, Profile] = {}
    for p, t in zip(uncertainty.parameters, theta):
        prof = changes.get(p.key, getattr(st, p.key))
        if p.knot is None:
            changes[p.key] = prof.scaled(float(np.exp(t)))
        else:
            assert prof.s == p.knots  # the table is the knots' own
            values = list(prof.values)
            values[p.knot] *= float(np.exp(t))
            changes[p.key] = Profile(prof.s, tuple(values))
    return replace(problem, string=replace(st, **changes))


def draws(case: Case, n: int, seed: int) -> np.ndarray:
    """θ of n Gaussian draws: of the values in SI (per-key σ), or of θ itself (a log covariance)."""
    rng = np.random.default_rng(seed)
    u = case.uncertainty
    if u.log:
        return rng.multivariate_normal(np.zeros(len(u.parameters)), u.matrix, n)
    values = np.array([p.value(case.problem.string) for p in u.parameters])
    sampled = rng.multivariate_normal(values, u.matrix, n)
    assert np.all(sampled > 0)
    return np.log(sampled / values)


def observe(result: ShapeResult) -> tuple[np.ndarray, dict, dict]:
    assert result.ok, result.message
    return (result.points, {g: w.force for g, w in result.grips.items()},
            {g: w.torque for g, w in result.grips.items()})


@pytest.fixture(scope="module", params=list(CASES))
def sampled(request):
    """(case, nominal envelope, envelope of the draws' own covariance, sampled points (n, S, 3), forces and
    torques per grip (n, 3)) — the draws solved cold and streamed, which must agree."""
    case = CASES[request.param]()
    solver = ShapeSolver(case.problem, case.options, compile="off")
    nominal = solver.solve()
    assert nominal.ok and nominal.stable, nominal.message
    spread = envelope(solver, nominal, case.uncertainty)
    assert isinstance(spread, Envelope), spread
    theta = draws(case, SAMPLES, seed=0)
    empirical = Uncertainty.from_covariance(case.uncertainty.parameters, np.cov(theta.T).reshape(len(theta[0]), -1),
                                            log=True)
    own = envelope(solver, nominal, empirical)
    assert isinstance(own, Envelope), own
    cold = ShapeSolver(case.problem, case.options, compile="off")
    streamed, solved_cold = [], []
    for t in theta:  # the stream: each draw an update warm-started from the previous answer
        problem = with_theta(case.problem, case.uncertainty, t)
        solver.set_problem(problem)
        streamed.append(observe(solver.solve()))
        cold.set_problem(problem)
        cold.reset()
        solved_cold.append(observe(cold.solve()))
    for (pw, fw, tw), (pc, fc, tc) in zip(streamed, solved_cold):  # one equilibrium, however reached
        assert np.abs(pw - pc).max() < 1e-7
        for g in fw:
            assert np.abs(fw[g] - fc[g]).max() < 1e-6 and np.abs(tw[g] - tc[g]).max() < 1e-6
    points = np.array([o[0] for o in streamed])
    forces = {g: np.array([o[1][g] for o in streamed]) for g in nominal.grips}
    torques = {g: np.array([o[2][g] for o in streamed]) for g in nominal.grips}
    return request.param, spread, own, points, forces, torques


def sampled_sigma(points: np.ndarray) -> np.ndarray:
    """Per point, sqrt of the largest eigenvalue of the sampled 3 × 3 covariance [m]."""
    dev = points - points.mean(axis=0)
    cov = np.einsum("nsi,nsj->sij", dev, dev) / (len(points) - 1)
    return np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, -1], 0.0))


def relative(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    return float(np.abs(a[where] / b[where] - 1.0).max()) if where.any() else 0.0


def test_envelope_matches_monte_carlo(sampled):
    """The linearised σ(s) and grip σ against the draws' sampled std: within 20 % wherever the spread is
    more than 5 % of its largest; against the linear map of the same draws within 6 % (near-linear)."""
    name, spread, own, points, forces, torques = sampled
    mc = sampled_sigma(points)
    moving = spread.sigma > 0.05 * spread.max_sigma
    assert moving.sum() > 10
    report = {"max sigma lin": spread.max_sigma, "max sigma mc": float(mc.max()),
              "points": relative(mc, spread.sigma, moving), "points (own)": relative(mc, own.sigma, moving)}
    for g, ge in spread.grips.items():
        for what, lin, own_sigma, values in (("force", ge.force_sigma, own.grips[g].force_sigma, forces[g]),
                                             ("torque", ge.torque_sigma, own.grips[g].torque_sigma, torques[g])):
            std = values.std(axis=0, ddof=1)
            big = lin > 0.05 * lin.max()
            report[f"{g} {what}"] = relative(std, lin, big)
            report[f"{g} {what} (own)"] = relative(std, own_sigma, big)
            small = ~big  # a component the parameters hardly move stays small in the draws too
            assert np.all(std[small] <= 0.1 * lin.max() + 1e-12), (name, g, what, std, lin)
    print(name, {k: round(v, 6) for k, v in report.items()})
    for key, value in report.items():
        if key.startswith("max"):
            continue
        assert value < (LINEARITY if key.endswith("(own)") else AGREEMENT), (name, key, report)


# ---- (b) the envelope against central differences of solves ------------------------------------------
@pytest.mark.parametrize("name", list(CASES))
def test_envelope_matches_central_differences(name):
    """C_x(s), C_F and C_T from J built by central differences of re-solves (h = 1e-5 in θ, each solve warm
    from the nominal on a solver of its own): the same to 1e-6 of their largest entry."""
    case = CASES[name]()
    solver = ShapeSolver(case.problem, case.options, compile="off")
    nominal = solver.solve()
    spread = envelope(solver, nominal, case.uncertainty)
    assert isinstance(spread, Envelope), spread
    other = ShapeSolver(case.problem, case.options, compile="off")
    assert other.solve().ok
    h, k = 1e-5, len(case.uncertainty.parameters)
    d_points = np.zeros(nominal.points.shape + (k,))
    d_force = {g: np.zeros((3, k)) for g in nominal.grips}
    d_torque = {g: np.zeros((3, k)) for g in nominal.grips}
    for i in range(k):
        sides = []
        for sign in (1.0, -1.0):
            theta = np.zeros(k)
            theta[i] = sign * h
            other.set_problem(with_theta(case.problem, case.uncertainty, theta))
            sides.append(observe(other.solve()))
        d_points[:, :, i] = (sides[0][0] - sides[1][0]) / (2 * h)
        for g in nominal.grips:
            d_force[g][:, i] = (sides[0][1][g] - sides[1][1][g]) / (2 * h)
            d_torque[g][:, i] = (sides[0][2][g] - sides[1][2][g]) / (2 * h)
    cov = case.uncertainty.log_covariance(case.problem.string)
    assert np.allclose(spread.log_covariance, cov, rtol=1e-12, atol=0)
    point_cov = np.einsum("sik,kl,sjl->sij", d_points, cov, d_points)
    assert np.abs(spread.point_covariance - point_cov).max() < 1e-6 * np.abs(point_cov).max()
    sigma = np.sqrt(np.linalg.eigvalsh(point_cov)[:, -1].clip(0.0))
    assert np.abs(spread.sigma - sigma).max() < 1e-6 * sigma.max()
    for g, ge in spread.grips.items():
        for fd, got in ((d_force[g], ge.force_covariance), (d_torque[g], ge.torque_covariance)):
            expected = fd @ cov @ fd.T
            assert np.abs(got - expected).max() < 1e-6 * np.abs(expected).max(), (name, g)


def test_auto_solver_envelope_is_the_fixed_models():
    """Through ``make_solver`` (auto: the planar model on elements for default_cable) the envelope is the 3D
    director model's to 1 %: the same physics on another discretisation."""
    case = cable_case()
    auto = make_solver(case.problem, SolverOptions(), compile="off", checks="sync")
    fixed = ShapeSolver(case.problem, case.options, compile="off")
    a = envelope(auto, auto.solve(), case.uncertainty)
    f = envelope(fixed, fixed.solve(), case.uncertainty)
    assert isinstance(a, Envelope) and isinstance(f, Envelope), (a, f)
    assert abs(a.max_sigma / f.max_sigma - 1) < 0.01
    assert np.abs(a.sigma - f.sigma).max() < 0.01 * f.max_sigma
    for g in f.grips:
        assert np.allclose(a.grips[g].force_sigma, f.grips[g].force_sigma, rtol=0, atol=0.01 * f.grips[g].force_sigma.max())
    assert a.note == ""  # Rt's σ: the planar model does not depend on it, nothing is left out


# ---- first-order relation and helpers -----------------------------------------------------------------
def test_sigma_in_si_is_relative_to_the_value():
    """σ_θ = σ / v: for a constant profile its value, for a table its mean over s (exact for a piecewise-linear
    profile); an SI covariance C gives V⁻¹ C V⁻¹."""
    table = Profile.table([(0.0, 0.2), (0.5, 0.6), (1.0, 0.6)])  # mean: (0.2 + 0.6)/4 + 0.6/2 = 0.5
    st = StringProperties(1.0, Profile.constant(0.02), Profile.constant(0.0), table)
    u = Uncertainty.from_sigmas({"bend_stiffness": 0.002, "weight_per_length": 0.05})
    assert np.allclose(u.log_covariance(st), np.diag([0.1, 0.1]) ** 2)
    assert u.sigmas == pytest.approx({"bend_stiffness": 0.002, "weight_per_length": 0.05})
    full = Uncertainty.from_covariance(["bend_stiffness", "D"], [[4e-6, 5e-5], [5e-5, 2.5e-3]])
    assert np.allclose(full.log_covariance(st), [[0.01, 0.005], [0.005, 0.01]])
    assert full.marginal_sigmas(st) == pytest.approx({"bend_stiffness": 0.002, "weight_per_length": 0.05})
    logged = Uncertainty.from_covariance(["Rf"], [[0.01]], log=True)
    assert logged.marginal_sigmas(st) == pytest.approx({"bend_stiffness": 0.002})


def test_tube_and_bounds():
    case = cable_case()
    solver = ShapeSolver(case.problem, case.options, compile="off")
    result = solver.solve()
    spread = envelope(solver, result, case.uncertainty)
    assert isinstance(spread, Envelope)
    assert np.allclose(spread.tube(2.0), 2.0 * spread.sigma) and spread.tube(3.0).max() == pytest.approx(3 * spread.max_sigma)
    lo, hi = spread.grips["left"].force_bounds(2.0)
    assert np.allclose((lo + hi) / 2, result.grips["left"].force) and np.allclose(hi - lo, 4 * spread.grips["left"].force_sigma)
    # the string's weight is shared by the two clamps: σ(F_z) = σ_D L / 2 at each
    assert spread.grips["left"].force_sigma[2] == pytest.approx(0.025 * 1.0 / 2, rel=1e-6)
    # the endpoints are held: no spread there
    assert spread.sigma[0] < 1e-12 and spread.sigma[-1] < 1e-12
    out = spread.to_dict()
    assert set(out) >= {"sigma", "grips"} and len(out["sigma"]) == len(result.s)
    assert set(out["grips"]["left"]) >= {"force_sigma", "torque_sigma"}
    json.dumps(out, allow_nan=False)


# ---- (c) validation names the field -------------------------------------------------------------------
@pytest.mark.parametrize("sigmas,field", [
    ({"bend_stiffnes": 0.1}, "uncertainty.bend_stiffnes"),
    ({"length": 0.1}, "uncertainty.length"),
    ({"bend_stiffness": -0.1}, "uncertainty.bend_stiffness"),
    ({"weight_per_length": float("nan")}, "uncertainty.weight_per_length"),
    ({"weight_per_length": float("inf")}, "uncertainty.weight_per_length"),
    ({"twist_stiffness": True}, "uncertainty.twist_stiffness"),
    ({"twist_stiffness": "0.1"}, "uncertainty.twist_stiffness"),
])
def test_bad_sigmas_name_the_field(sigmas, field):
    with pytest.raises(UncertaintyError) as info:
        Uncertainty.from_sigmas(sigmas)
    assert str(info.value).startswith(f"{field}: ") and info.value.key == field


@pytest.mark.parametrize("names,cov,field,words", [
    (["Rf", "D"], [[1.0, 2.0], [2.0, 1.0]], "uncertainty.covariance", "positive semi-definite"),
    (["Rf", "D"], [[1.0, 0.1], [0.0, 1.0]], "uncertainty.covariance", "symmetric"),
    (["Rf", "D"], [[1.0, float("nan")], [float("nan"), 1.0]], "uncertainty.covariance", "NaN"),
    (["Rf", "D"], [[1.0]], "uncertainty.covariance", "2 × 2"),
    (["Rf", "radius"], np.eye(2), "uncertainty.names[1]", "unknown parameter"),
    (["Rf", "bend_stiffness"], np.eye(2), "uncertainty.names[1]", "repeats names[0]"),
    (["Rf[2]"], np.eye(1), "uncertainty.names[0]", "knot"),
    ([Parameter("weight_per_length", 3, (0.0, 1.0))], np.eye(1), "uncertainty.names[0]", "knot 3"),
])
def test_bad_covariance_names_the_field(names, cov, field, words):
    with pytest.raises(UncertaintyError) as info:
        Uncertainty.from_covariance(names, cov)
    assert str(info.value).startswith(f"{field}: ") and words in str(info.value), str(info.value)


def scene_dict(**uncertainty) -> dict:
    d = yaml.safe_load(open(load_scene("default_cable").source))
    d["string"]["uncertainty"] = uncertainty
    return d


@pytest.mark.parametrize("uncertainty,field", [
    ({"bend_stiffness": -0.002}, "string.uncertainty.bend_stiffness"),
    ({"bend_stiffness": "much"}, "string.uncertainty.bend_stiffness"),
    ({"weight_per_length": float("nan")}, "string.uncertainty.weight_per_length"),
    ({"length": 0.01}, "string.uncertainty.length"),
    ({"stretch_stiffness": 10.0}, "string.uncertainty.stretch_stiffness"),  # inextensible: null
    ({"lateral_bend_stiffness": 0.001}, "string.uncertainty.lateral_bend_stiffness"),  # a rod
])
def test_scene_uncertainty_errors_name_the_key(uncertainty, field):
    with pytest.raises(SceneError) as info:
        scene_from_dict(scene_dict(**uncertainty))
    assert str(info.value).startswith(f"{field}: ") and info.value.key == field, str(info.value)


def test_scene_uncertainty_reads_round_trips_and_names_the_line(tmp_path):
    scene = scene_from_dict(scene_dict(bend_stiffness=0.002, weight_per_length=0.01, stretch_stiffness=0))
    assert scene.uncertainty is not None
    assert scene.uncertainty.sigmas == {"bend_stiffness": 0.002, "weight_per_length": 0.01, "stretch_stiffness": 0.0}
    again = scene_from_dict(scene_to_dict(scene))
    assert again.uncertainty == scene.uncertainty
    assert "uncertainty" not in scene_to_dict(load_scene("default_cable"))["string"]  # files stay as they were
    assert load_scene("default_cable").uncertainty is None
    path = tmp_path / "scene.yaml"
    text = yaml.safe_dump(scene_dict(bend_stiffness=-1.0), sort_keys=False)
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if "bend_stiffness: -1" in ln)
    assert str(info.value).startswith("string.uncertainty.bend_stiffness: ") and f"{path}:{line}" in str(info.value)


# ---- (d) no envelope: why ------------------------------------------------------------------------------
def test_unavailable_cases_give_the_reason():
    case = cable_case()
    solver = ShapeSolver(case.problem, case.options, compile="off")
    result = solver.solve()
    failed = envelope(solver, ShapeResult(status="failed", message="no convergence"), case.uncertainty)
    assert isinstance(failed, EnvelopeUnavailable) and "failed" in failed.reason and "no convergence" in failed.reason
    assert failed.to_dict() == {"unavailable": failed.reason}
    unverified = envelope(solver, replace(result, status="unverified"), case.uncertainty)
    assert isinstance(unverified, EnvelopeUnavailable) and "unverified" in unverified.reason
    unstable = envelope(solver, replace(result, stable=False, min_eigenvalue=-0.5), case.uncertainty)
    assert isinstance(unstable, EnvelopeUnavailable) and "unstable" in unstable.reason
    moved = {"right": (np.array([0.5, 0.0, 0.4]), np.array([0.0, 0.0, 0.0, 1.0]))}
    query = solver.solve(moved, commit=False)  # answered, but the committed equilibrium is the first one
    assert query.ok
    other = envelope(solver, query, case.uncertainty)
    assert isinstance(other, EnvelopeUnavailable) and "committed equilibrium" in other.reason
    assert isinstance(envelope(solver, result, case.uncertainty), Envelope)  # the committed one still has one
    zero_weight = replace(case.problem, string=replace(case.problem.string, weight_per_length=Profile.constant(0.0)))
    bare = ShapeSolver(zero_weight, case.options, compile="off")
    weightless = envelope(bare, bare.solve(), Uncertainty.from_sigmas({"weight_per_length": 0.01}))
    assert isinstance(weightless, EnvelopeUnavailable) and "weight_per_length" in weightless.reason
    assert isinstance(envelope(object(), result, case.uncertainty), EnvelopeUnavailable)


def test_euler_model_gives_no_torque_sigma_and_says_why():
    """The 3D Euler model does not differentiate its grip torques: the shape and forces still have their
    envelope, the torques' σ is None and the note says why."""
    case = cable_case()
    solver = ShapeSolver(case.problem, replace(case.options, rotation="euler"), compile="off")
    result = solver.solve()
    assert result.ok, result.message
    spread = envelope(solver, result, case.uncertainty)
    assert isinstance(spread, Envelope), spread
    assert spread.max_sigma > 0 and all(g.torque_sigma is None for g in spread.grips.values())
    assert "torque" in spread.note and spread.to_dict()["grips"]["left"]["torque_sigma"] is None


# ---- from dlo fit ---------------------------------------------------------------------------------------
def test_fit_result_gives_its_covariance():
    """``FitResult.uncertainty()``: the log covariance over the fitted labels, knots with the fitted table's
    arc lengths; what the data do not determine is named in the note; a misfit has none."""
    table = Profile.table([(0.0, 0.4), (0.5, 0.5), (1.0, 0.6)])
    string = StringProperties(1.0, Profile.constant(0.02), Profile.constant(0.015), table)
    cov = np.array([[0.01, 0.002, 0.0, 0.0], [0.002, 0.004, 0.0, 0.0], [0.0, 0.0, 0.004, 0.001],
                    [0.0, 0.0, 0.001, 0.004]])
    fitted = FitResult("ok", "converged", names=("Rf", "D[0]", "D[1]", "D[2]"), covariance_log=cov,
                       string=string, not_identifiable={"Rt": "no observation twists the string"})
    u = fitted.uncertainty()
    assert u.log and u.names == ("bend_stiffness", "weight_per_length[0]", "weight_per_length[1]", "weight_per_length[2]")
    assert u.parameters[2] == Parameter("weight_per_length", 1, (0.0, 0.5, 1.0))
    assert np.array_equal(u.matrix, cov) and "Rt" in u.note
    assert u.parameters[2].direction(string).change(np.array([0.25, 0.5, 0.75])) == pytest.approx([0.25, 0.5, 0.25])
    with pytest.raises(ValueError, match="misfit"):
        replace(fitted, status="misfit").uncertainty()


def test_fit_of_the_example_observation_gives_the_envelope_of_its_scene():
    """``dlo fit``'s example (default_cable's clamps, Rf and D fitted from one noisy hanging shape and the left
    grip's force measured to 0.01 N): the envelope's parameters carry the fit's relative stds, and the
    predicted grip force's σ is of the measured force's (what fixes the scale)."""
    scene = load_scene("default_cable")
    fitted = fit(scene.problem, scene.options, load_observations(REPO / "config/observations/default_cable_hanging.yaml"))
    assert fitted.ok, fitted.message
    u = fitted.uncertainty()
    for name, key in (("Rf", "bend_stiffness"), ("D", "weight_per_length")):
        est = fitted.parameters[name]
        assert u.sigmas[key] == pytest.approx(est.std / est.value, rel=1e-9)
    problem = replace(scene.problem, string=fitted.string)
    solver = make_solver(problem, scene.options, compile="off", checks="sync")
    spread = envelope(solver, solver.solve(), u)
    assert isinstance(spread, Envelope), spread
    assert 0 < spread.max_sigma < 1e-3 and spread.note == ""
    assert 0.002 < spread.grips["left"].force_sigma[0] < 0.02


# ---- dlo solve --------------------------------------------------------------------------------------------
def test_cli_solve_json_and_summary_carry_the_envelope(tmp_path, capfd):
    path = tmp_path / "uncertain.yaml"
    path.write_text(yaml.safe_dump(scene_dict(bend_stiffness=0.002, weight_per_length=0.01), sort_keys=False))
    assert cli.main(["solve", str(path), "--json", "--points", "11"]) == 0
    out = json.loads(capfd.readouterr().out)
    env = out["envelope"]
    assert len(env["sigma"]) == 11 and max(env["sigma"]) > 1e-5 and env["sigma"][0] < 1e-12
    assert set(env["grips"]) == {"left", "right"}
    assert env["grips"]["left"]["force_sigma"][2] == pytest.approx(0.005, rel=1e-6)  # σ_D L / 2
    assert len(env["grips"]["right"]["torque_sigma"]) == 3
    assert cli.main(["solve", "default_cable", "--json", "--points", "11"]) == 0
    assert "envelope" not in json.loads(capfd.readouterr().out)  # asked for by neither scene nor option
    assert cli.main(["solve", "default_cable", "--uncertainty", "bend_stiffness=0.002"]) == 0
    summary = [ln for ln in capfd.readouterr().out.splitlines() if ln.startswith("envelope")]
    assert len(summary) == 1 and "max sigma" in summary[0] and "left" in summary[0], summary
    assert cli.main(["solve", "default_cable", "--uncertainty", "bend_stiffness=-1"]) == 2
    err = capfd.readouterr().err
    assert "--uncertainty.bend_stiffness: must be >= 0" in err and "Traceback" not in err
    assert cli.main(["solve", "default_cable", "--uncertainty", "stretch_stiffness=5"]) == 2
    assert "--uncertainty.stretch_stiffness" in capfd.readouterr().err


def test_cli_solve_records_the_envelope(tmp_path, capfd):
    """`dlo solve --rrd` with an uncertainty records the 2 sigma tube beside the shape."""
    pytest.importorskip("rerun", reason="rerun-sdk needs Python >= 3.11")
    import subprocess
    import sys
    from pathlib import Path

    rrd = tmp_path / "solve.rrd"
    assert cli.main(["solve", "default_cable", "--json", "--points", "11", "--uncertainty",
                     "bend_stiffness=0.002", "--rrd", str(rrd)]) == 0
    sigma = json.loads(capfd.readouterr().out)["envelope"]["sigma"]
    rerun = str(Path(sys.executable).parent / "rerun")
    printed = subprocess.run([rerun, "rrd", "print", "--verbose", str(rrd)], capture_output=True, text=True,
                             timeout=120)
    text = printed.stdout + printed.stderr
    assert "world/envelope" in text and "events/envelope" in text, text[-2000:]
    assert max(sigma) > 1e-5
