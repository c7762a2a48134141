"""Identify Rf, Rt, D, Re from observed shapes: a bilevel Levenberg–Marquardt over log-parameters.

Unknowns θ (``parameters.py``): for each fitted material the log of a uniform scale of the scene's
profile, or (``ObservationSet.profiles``) the logs of a piecewise-linear table's knot values with a
smoothness regulariser ½|Rθ|² added to Φ.  Inner level: every observation's equilibrium, one ``ShapeSolver`` per
observation, warm-started from its previous θ (Newton on the KKT conditions; IPOPT only as its fallback).
Outer level: minimise

    Φ(θ) = Σ_obs Σ_j ρ(|r_j| / σ_obs) + ½ Σ ((F_meas − F(θ)) / σ_F)² + ½ ((W_known − ∫D ds) / σ_W)²

with r_j the point-to-curve residual of point j (``curve.py``), ρ Huber's loss (quadratic up to
``huber`` σ, linear beyond: outliers count less), the optional measured grip force and known weight.
The Jacobian comes from the implicit-function theorem on the KKT system (``solver/sensitivity.py``):
one linear solve per observation and iteration, no finite differences.  Steps are Gauss–Newton steps
with iteratively reweighted (Huber) normal matrix A = Jᵀ W J / σ², Levenberg-damped, restricted to the
directions the data determine (``identifiability.py``), and clipped to ``max_step`` in log units.

Covariance of θ: A⁺ (the pseudo-inverse on the determined directions) at the solution, with the stated
σ; a parameter's standard deviation is value × sqrt(A⁺_kk) (first order).  Undetermined parameters get
no number: they stay at the scene's value (or move only as a determined ratio forces, with Rf, then
Rt, Re, D held first), are listed with the reason, and the determined ratios are reported instead.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..model.problem import Problem, StringProperties
from ..model.profile import Profile
from ..solver import ShapeSolver, SolverOptions
from ..solver.sensitivity import shape_sensitivity
from .curve import point_to_curve
from .identifiability import Identifiability, analyse
from .observations import Observation, ObservationError, ObservationSet
from .parameters import PROFILE, Parameterisation, profile_mean

UNITS = {"Rf": "N·m²", "Rt": "N·m²", "D": "N/m", "Re": "N"}
#: held at the scene's value first when a direction is undetermined
ANCHOR_ORDER = ("Rf", "Rt", "Re", "D")
#: ratios reported (numerator, denominator, unit)
RATIOS = (("D", "Rf", "1/m³"), ("Rt", "Rf", "1"), ("Re", "Rf", "1/m²"))


@dataclass(frozen=True)
class FitSettings:
    """max_iterations: outer LM iterations; huber: the loss's threshold in σ; samples: centreline samples
    the points are projected on; step_tolerance: converged when the largest accepted step in θ is below
    this; max_step: the largest step in θ (log units); compile: the equilibrium solvers' compile mode."""

    max_iterations: int = 30
    huber: float = 2.5
    samples: int = 401
    step_tolerance: float = 1e-6
    max_step: float = 0.7
    compile: str = "off"


@dataclass
class Estimate:
    """A determined quantity: value, standard deviation (same unit) and unit.  For a table profile the
    value is its mean over s (the fit scales the table)."""

    name: str
    value: float
    std: float
    unit: str
    s: float | None = None  # the knot's arc length [m] of a piecewise-linear profile's value

    def as_dict(self) -> dict:
        out = {"value": self.value, "std": self.std, "relative_std": self.std / abs(self.value) if self.value else None,
               "unit": self.unit}
        if self.s is not None:
            out["s"] = self.s
        return out


@dataclass
class ObservationFit:
    """Residuals of one observation at the fit: |r| statistics over its points [m], how many points the
    robust loss down-weighted (|r| > huber σ), and the grip-force residual |F_meas − F| [N] if measured."""

    name: str
    points: int
    rms_m: float
    median_m: float
    max_m: float
    downweighted: int
    force_residual_n: float | None = None
    #: the fitted centreline (S, 3) [m] and each observed point's nearest point on it (N, 3) [m], for drawing
    shape: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    feet: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)

    def as_dict(self) -> dict:
        return {"name": self.name, "points": self.points, "rms_m": self.rms_m, "median_m": self.median_m,
                "max_m": self.max_m, "downweighted": self.downweighted, "force_residual_n": self.force_residual_n}


@dataclass
class FitResult:
    """status: 'ok' (converged), 'not_converged' (iteration limit or no descent) or 'failed' (an
    equilibrium could not be solved: message).  parameters: the determined ones; ratios: the determined
    ratios (D/Rf, Rt/Rf, Re/Rf); not_identifiable[name]: why the data cannot determine it; fixed: the
    scene's values of parameters not fitted (the estimates are conditional on them); string: the scene's
    string with the fitted values; chi2_reduced: Σ(r/σ)² / (2 N_points + force rows − rank)."""

    status: str
    message: str
    parameters: dict[str, Estimate] = field(default_factory=dict)
    ratios: dict[str, Estimate] = field(default_factory=dict)
    not_identifiable: dict[str, str] = field(default_factory=dict)
    fixed: dict[str, float] = field(default_factory=dict)
    observations: list[ObservationFit] = field(default_factory=list)
    iterations: int = 0
    equilibrium_solves: int = 0
    time_s: float = 0.0
    chi2_reduced: float = float("nan")
    names: tuple[str, ...] = ()
    covariance_log: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    string: StringProperties | None = None
    identifiability: Identifiability | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict:
        """JSON-ready (``dlo fit --json``, msg_docs/fitting.md)."""
        ident = self.identifiability
        return {
            "status": self.status, "message": self.message,
            "parameters": {k: v.as_dict() for k, v in self.parameters.items()},
            "ratios": {k: v.as_dict() for k, v in self.ratios.items()},
            "not_identifiable": dict(self.not_identifiable),
            "fixed": dict(self.fixed),
            "observations": [o.as_dict() for o in self.observations],
            "chi2_reduced": self.chi2_reduced,
            "iterations": self.iterations, "equilibrium_solves": self.equilibrium_solves, "time_s": self.time_s,
            "fitted": list(self.names),
            "covariance_log": self.covariance_log.tolist(),
            "rank": None if ident is None else ident.rank,
            "condition": None if ident is None else ident.condition,
        }


@dataclass
class _Evaluation:
    """Everything the outer step needs at one θ."""

    theta: np.ndarray
    cost: float
    normal: np.ndarray
    gradient: np.ndarray
    fits: list[ObservationFit]
    chi2: float
    rows: int


def check_request(problem: Problem, data: ObservationSet) -> None:
    """Raise ObservationError for a request that cannot be fitted from this scene."""
    data.check(problem)
    st = problem.string
    for name in data.profiles:
        if name not in data.parameters:
            raise ObservationError(f"profiles.{name}: {name!r} is not in parameters")
    for i, name in enumerate(data.parameters):
        prof = getattr(st, PROFILE[name])
        if prof is None:
            raise ObservationError(f"parameters[{i}]: Re cannot be fitted: the scene's string is inextensible "
                                   "(string.stretch_stiffness null); give a starting value")
        if prof.minimum <= 0:
            raise ObservationError(f"parameters[{i}]: {name} cannot be fitted from a start of 0 (the scene's "
                                   f"string.{PROFILE[name]}); give a positive starting value")


class _Observed:
    """One observation's solver and data."""

    def __init__(self, base: Problem, obs: Observation, options: SolverOptions, compile: str):
        self.obs = obs
        self.problem = base.with_grip_poses(obs.poses)
        self.solver = _solver_for(self.problem, options, compile)

    def solve(self, string: StringProperties):
        self.solver.set_problem(replace(self.problem, string=string))
        return self.solver.solve()


def _solver_for(problem: Problem, options: SolverOptions, compile: str) -> ShapeSolver:
    """A fixed-model solver: the scene's model, or for 'auto' the planar model where the shape is planar."""
    if options.model == "auto":
        try:
            return ShapeSolver(problem, replace(options, model="planar"), compile=compile)
        except ValueError:  # not a planar scene
            return ShapeSolver(problem, replace(options, model="full"), compile=compile)
    return ShapeSolver(problem, options, compile=compile)


def fit(problem: Problem, options: SolverOptions, data: ObservationSet,
        settings: FitSettings = FitSettings()) -> FitResult:
    """Fit ``data.parameters`` of ``problem``'s string to ``data`` (module docstring).  Raises
    ObservationError for a request the scene cannot support; solver failures give status 'failed'."""
    t0 = time.perf_counter()
    check_request(problem, data)
    fitted = tuple(data.parameters)
    par = Parameterisation(problem.string, fitted, data.profiles)
    names, base = par.labels, par.base
    fixed = {n: profile_mean(getattr(base, PROFILE[n]), base.length) for n in ("Rf", "Rt", "D", "Re")
             if n not in fitted and getattr(base, PROFILE[n]) is not None}
    # the scene with the knot tables from the start: a director model splits its elements at their knots
    observed = [_Observed(replace(problem, string=base), obs, options, settings.compile) for obs in data.observations]
    reg = par.regulariser()
    s_grid = np.linspace(0.0, base.length, settings.samples)
    solves = 0

    def evaluate(theta: np.ndarray) -> _Evaluation | str:
        nonlocal solves
        string = par.string(theta)
        directions = par.directions(string)
        k = len(names)
        normal, gradient, cost, chi2, rows, fits = np.zeros((k, k)), np.zeros(k), 0.0, 0.0, 0, []
        for o in observed:
            result = o.solve(string)
            solves += 1
            if result.status != "ok":
                return f"observation {o.obs.name!r}: the equilibrium is {result.status}: {result.message}"
            sens = shape_sensitivity(o.solver, directions, s_grid)
            cr = point_to_curve(o.obs.points, sens.s, sens.points, sens.d_points)
            sigma = o.obs.sigma
            u = cr.distances / sigma
            w = np.where(u <= settings.huber, 1.0, settings.huber / np.maximum(u, 1e-300))
            cost += float(np.sum(np.where(u <= settings.huber, 0.5 * u * u, settings.huber * u - 0.5 * settings.huber ** 2)))
            chi2 += float(np.sum(u * u))
            rows += 2 * len(u)
            jw = cr.jacobian / sigma
            normal += np.einsum("n,nik,nil->kl", w, jw, jw)
            gradient += np.einsum("n,nik,ni->k", w, jw, cr.residuals / sigma)
            force_res = None
            if o.obs.force is not None:
                f = o.obs.force
                r = (f.force - sens.grip_forces[f.grip]) / f.sigma
                jf = -sens.d_grip_forces[f.grip] / f.sigma
                cost += 0.5 * float(r @ r)
                chi2 += float(r @ r)
                rows += 3
                normal += jf.T @ jf
                gradient += jf.T @ r
                force_res = float(np.linalg.norm(f.force - sens.grip_forces[f.grip]))
            d = cr.distances
            fits.append(ObservationFit(o.obs.name, len(d), float(np.sqrt(np.mean(d * d))), float(np.median(d)),
                                       float(d.max()), int(np.sum(u > settings.huber)), force_res,
                                       sens.points, o.obs.points - cr.residuals))
        if data.total_mass is not None:
            weight, sigma_w = data.total_mass.weight
            predicted = profile_mean(string.weight_per_length, base.length) * base.length
            r = (weight - predicted) / sigma_w
            j = -par.weight_gradient(string) / sigma_w
            cost += 0.5 * r * r
            chi2 += r * r
            rows += 1
            normal += np.outer(j, j)
            gradient += j * r
        if reg.size:
            cost += 0.5 * float(np.sum((reg @ theta) ** 2))
            normal += reg.T @ reg
            gradient += reg.T @ (reg @ theta)
        return _Evaluation(theta, cost, normal, gradient, fits, chi2, rows)

    def failed(message: str, iterations: int) -> FitResult:
        return FitResult("failed", message, fixed=fixed, iterations=iterations, equilibrium_solves=solves,
                         time_s=time.perf_counter() - t0, names=names)

    current = evaluate(np.zeros(len(names)))
    if isinstance(current, str):
        return failed(f"at the scene's values: {current}", 0)
    status, message, mu, iterations = "not_converged", f"no convergence in {settings.max_iterations} iterations", 0.0, 0
    for iterations in range(1, settings.max_iterations + 1):
        ident = analyse(names, current.normal)
        vec, lam = ident.directions
        if vec.shape[1] == 0:
            status, message = "ok", "nothing the data determine"
            break
        g1 = vec.T @ current.gradient
        accepted = None
        for _ in range(10):
            step = -vec @ (g1 / (lam + mu))
            largest = float(np.abs(step).max())
            if largest > settings.max_step:
                step *= settings.max_step / largest
            trial = evaluate(current.theta + step)
            if not isinstance(trial, str) and trial.cost <= current.cost * (1 + 1e-12):
                accepted = trial
                mu = 0.0 if mu < 1e-6 * lam.max() else mu / 4
                break
            mu = max(4 * mu, 1e-3 * float(lam.max()))
        if accepted is None:
            status, message = "not_converged", "no step decreased the cost (a local minimum or a kink of the loss)"
            break
        current = accepted
        if float(np.abs(step).max()) < settings.step_tolerance:
            status, message = "ok", f"converged in {iterations} iterations"
            break
    ident = analyse(names, current.normal)
    theta = _anchored(current.theta, par, ident)
    cov = _pseudo_inverse(current.normal, ident)
    string = par.string(theta)
    parameters, ratios = {}, {}
    for k, comp in enumerate(par.components):
        if comp.label in ident.why:
            continue
        value = par.value(string, k)
        parameters[comp.label] = Estimate(comp.label, value, value * float(np.sqrt(max(cov[k, k], 0.0))),
                                          UNITS[comp.material], comp.s)
    for a_name, b_name, unit in RATIOS:
        for a in par.indices(a_name):
            for b in par.indices(b_name):
                label = f"{names[a]}/{names[b]}"
                c = np.zeros(len(names))
                c[a], c[b] = 1.0, -1.0
                if ident.determines(c):
                    value = par.value(string, a) / par.value(string, b)
                    ratios[label] = Estimate(label, value, value * float(np.sqrt(max(c @ cov @ c, 0.0))), unit,
                                             par.components[b].s if par.components[b].s is not None else par.components[a].s)
            if not par.indices(b_name) and names[a] in parameters and b_name in fixed:
                est = parameters[names[a]]
                ratios[f"{names[a]}/{b_name}"] = Estimate(f"{names[a]}/{b_name}", est.value / fixed[b_name],
                                                          est.std / fixed[b_name], unit, est.s)
    dof = max(current.rows - ident.rank, 1)
    return FitResult(status, message, parameters, ratios, dict(ident.why), fixed, current.fits, iterations, solves,
                     time.perf_counter() - t0, current.chi2 / dof, names, cov, string, ident)


def _anchored(theta: np.ndarray, par: Parameterisation, ident: Identifiability) -> np.ndarray:
    """θ moved along the undetermined directions (which leave every residual unchanged) so that the
    undetermined materials first in ANCHOR_ORDER keep the scene's values (a table: its mean log factor)."""
    null = ident.null
    if null.shape[1] == 0:
        return theta
    rows = []
    for material in ANCHOR_ORDER:
        idx = [i for i in par.indices(material) if par.components[i].label in ident.why]
        if idx:
            row = np.zeros(len(theta))
            row[idx] = 1.0 / len(idx)
            rows.append(row)
    g = np.array(rows[: null.shape[1]])
    if g.size == 0:
        return theta
    a = np.linalg.lstsq(g @ null, -g @ theta, rcond=None)[0]
    return theta + null @ a


def _pseudo_inverse(normal: np.ndarray, ident: Identifiability) -> np.ndarray:
    """A⁺ on the determined directions (the covariance of θ with the stated σ)."""
    vec, lam = ident.directions
    return (vec / lam) @ vec.T if lam.size else np.zeros_like(normal)
