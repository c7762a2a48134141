"""Identify Rf, Rt, D, Re from observed shapes: a bilevel Levenberg–Marquardt over log-parameters.

Unknowns θ (``parameters.py``): for each fitted material the log of a uniform scale of the scene's
profile, or (``ObservationSet.profiles``) the logs of a piecewise-linear table's knot values with a
smoothness regulariser ½|Rθ|² added to Φ.  Inner level: every observation's equilibrium, one
``ShapeSolver`` per observation, warm-started from its previous θ (Newton on the KKT conditions;
IPOPT only as its fallback). Outer level: minimise

    Φ(θ) = Σ_obs Σ_j ρ(|r_j| / σ_obs) + ½ Σ ((F_meas − F(θ)) / σ_F)² + ½ Σ ((T_meas − T(θ)) / σ_T)²
           + ½ ((W_known − ∫D ds) / σ_W)²

with r_j the point-to-curve residual of point j (``curve.py``), ρ Huber's loss (quadratic up to
``huber`` σ, linear beyond: outliers count less), the optional measured grip force, grip torque
(about the grip point) and known weight. The Jacobian comes from the implicit-function theorem on
the KKT system (``solver/results/sensitivity.py``): one linear solve per observation and iteration,
no finite differences.  Steps are Gauss–Newton steps with iteratively reweighted (Huber) normal
matrix A = Jᵀ W J / σ², Levenberg-damped, restricted to the directions the data determine
(``identifiability.py``), and clipped to ``max_step`` in log units.

Covariance of θ: A⁺ (the pseudo-inverse on the determined directions) at the solution, with the
stated σ; a parameter's standard deviation is value × sqrt(A⁺_kk) (first order).  Undetermined
parameters get no number; they are listed with the reason, and the determined ratios are reported
instead.  The fitted string reproduces the fitted shapes: along the common scale of all materials
(which shapes alone do not see) it is shifted so that the first fitted of Rf, Rt, Re, D keeps the
scene's value; otherwise an undetermined parameter stays where the steps left it (the scene's value
unless an early step, when the data still seemed to determine it, moved it).  The search is bounded
to a factor 1000 either way.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from ..model.problem import Problem
from ..solver import SolverOptions
from .gate import evaluate_gate, precheck
from .identifiability import NEITHER, ORTHOGONAL, RANK_TOLERANCE, Identifiability, analyse
from .objective import Evaluation, FitSettings, Objective, SolverCache
from .observations import ObservationError, ObservationSet
from .parameters import PROFILE, Parameterisation, profile_mean
from .results import Estimate, FitResult, ObservationFit

__all__ = ["Estimate", "FitResult", "FitSettings", "ObservationFit", "check_request", "fit"]

UNITS = {"Rf": "N·m²", "Rt": "N·m²", "D": "N/m", "Re": "N"}
#: held at the scene's value first when a direction is undetermined
ANCHOR_ORDER = ("Rf", "Rt", "Re", "D")
#: the search is bounded to a factor e^BOUND (1000) either way of the scene's values: data that do
#: not determine a parameter can otherwise drive it to 0 or ∞, where its column of J vanishes
BOUND = float(np.log(1e3))
AT_BOUND = (
    "the data drive it to the bound of the search (a factor 1000 from the scene's value): they do "
    "not "
    "determine it; the other estimates are conditional on it being there"
)
#: ratios reported (numerator, denominator, unit)
RATIOS = (("D", "Rf", "1/m³"), ("Rt", "Rf", "1"), ("Re", "Rf", "1/m²"))


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
            raise ObservationError(
                f"parameters[{i}]: Re cannot be fitted: the scene's string is inextensible "
                "(string.stretch_stiffness null); give a starting value"
            )
        if prof.minimum <= 0:
            raise ObservationError(
                f"parameters[{i}]: {name} cannot be fitted from a start of 0 (the scene's "
                f"string.{PROFILE[name]}); give a positive starting value"
            )


def fit(
    problem: Problem,
    options: SolverOptions,
    data: ObservationSet,
    settings: FitSettings = FitSettings(),
    cache: SolverCache | None = None,
) -> FitResult:
    """Fit the string parameters of a problem to observations.

    Fit ``data.parameters`` of ``problem``'s string to ``data`` (module docstring).  Raises
    ObservationError for a request the scene cannot support; solver failures give status 'failed'.
    ``cache``: equilibrium solvers to take instead of building new ones, and to keep them in
    afterwards (a process that fits repeatedly; ``objective.SolverCache``).
    """
    t0 = time.perf_counter()
    check_request(problem, data)
    fitted = tuple(data.parameters)
    par = Parameterisation(problem.string, fitted, data.profiles)
    names, base = par.labels, par.base
    fixed = {
        n: profile_mean(getattr(base, PROFILE[n]), base.length)
        for n in ("Rf", "Rt", "D", "Re")
        if n not in fitted and getattr(base, PROFILE[n]) is not None
    }
    cause = precheck(problem, data)
    if cause:  # no stiffness makes this string explain these points: no equilibrium is solved
        return FitResult(
            "misfit", f"misfit: {cause}", fixed=fixed, names=names, time_s=time.perf_counter() - t0
        )
    objective = Objective(problem, options, data, par, settings, cache)
    try:
        return gated(_fit(objective, par, fixed, settings, t0), problem, data, settings)
    finally:
        if cache is not None:
            for o in objective.observed:
                cache.give(o.solver, settings.compile)


def _fit(
    objective: Objective,
    par: Parameterisation,
    fixed: dict[str, float],
    settings: FitSettings,
    t0: float,
) -> FitResult:
    """Run the Levenberg–Marquardt iterations of :func:`fit` and build its result."""
    names = par.labels
    current = objective.evaluate(np.zeros(len(names)))
    if isinstance(current, str):
        return FitResult(
            "failed",
            f"at the scene's values: {current}",
            fixed=fixed,
            iterations=0,
            equilibrium_solves=objective.solves,
            time_s=time.perf_counter() - t0,
            names=names,
        )
    current, status, message, iterations = _levenberg_marquardt(
        objective, names, current, settings
    )
    ident = analyse(names, current.normal)
    for k in np.flatnonzero(np.abs(current.theta) >= BOUND * (1 - 1e-9)):
        ident.why[names[k]] = AT_BOUND
        message += (
            f"; {names[k]} is at the bound of the search (the other estimates are "
            f"conditional on it)"
        )
    theta = _anchored(current.theta, par, ident, current.normal)
    cov = _pseudo_inverse(current.normal, ident)
    string = par.string(theta)
    for k, comp in enumerate(par.components):
        if ident.why.get(comp.label) == NEITHER and abs(theta[k]) > 1e-6:
            message += (
                f"; {comp.label} is not determined and the fit left it at "
                f"{par.value(string, k):.4g} "
                f"{UNITS[comp.material]}: the other estimates are conditional on that value"
            )
    parameters = _parameter_estimates(par, string, ident, cov)
    ratios = _ratio_estimates(par, string, ident, cov, parameters, fixed)
    dof = max(current.rows - ident.rank, 1)
    return FitResult(
        status,
        message,
        parameters,
        ratios,
        dict(ident.why),
        fixed,
        current.fits,
        iterations,
        objective.solves,
        time.perf_counter() - t0,
        current.chi2 / dof,
        names,
        cov,
        string,
        ident,
        dof,
    )


def _levenberg_marquardt(
    objective: Objective,
    names: tuple[str, ...],
    current: Evaluation,
    settings: FitSettings,
) -> tuple[Evaluation, str, str, int]:
    """Iterate from ``current`` in the directions the data determine.

    Returns (the last accepted evaluation, status, message, iterations): "ok" when a step is below
    ``settings.step_tolerance`` or nothing is determined, else "not_converged" with why.
    """
    status, message, mu, iterations = (
        "not_converged",
        f"no convergence in {settings.max_iterations} iterations",
        0.0,
        0,
    )
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
            step = np.clip(current.theta + step, -BOUND, BOUND) - current.theta
            trial = objective.evaluate(current.theta + step)
            if not isinstance(trial, str) and trial.cost <= current.cost * (1 + 1e-12):
                accepted = trial
                mu = 0.0 if mu < 1e-6 * lam.max() else mu / 4
                break
            mu = max(4 * mu, 1e-3 * float(lam.max()))
        if accepted is None:
            status, message = (
                "not_converged",
                "no step decreased the cost (a local minimum or a kink of the loss)",
            )
            break
        current = accepted
        if float(np.abs(step).max()) < settings.step_tolerance:
            status, message = "ok", f"converged in {iterations} iterations"
            break
    return current, status, message, iterations


def _parameter_estimates(
    par: Parameterisation, string: Any, ident: Identifiability, cov: np.ndarray
) -> dict[str, Estimate]:
    """Return the estimate of each component the data determine (value ± its std)."""
    parameters = {}
    for k, comp in enumerate(par.components):
        if comp.label in ident.why:
            continue
        value = par.value(string, k)
        parameters[comp.label] = Estimate(
            comp.label,
            value,
            value * float(np.sqrt(max(cov[k, k], 0.0))),
            UNITS[comp.material],
            comp.s,
        )
    return parameters


def _ratio_estimates(
    par: Parameterisation,
    string: Any,
    ident: Identifiability,
    cov: np.ndarray,
    parameters: dict[str, Estimate],
    fixed: dict[str, float],
) -> dict[str, Estimate]:
    """Return the ratios of :data:`RATIOS` the data determine, and those to a fixed value."""
    names = par.labels
    ratios = {}
    for a_name, b_name, unit in RATIOS:
        for a in par.indices(a_name):
            for b in par.indices(b_name):
                label = f"{names[a]}/{names[b]}"
                c = np.zeros(len(names))
                c[a], c[b] = 1.0, -1.0
                if ident.determines(c) and AT_BOUND not in (
                    ident.why.get(names[a]),
                    ident.why.get(names[b]),
                ):
                    value = par.value(string, a) / par.value(string, b)
                    ratios[label] = Estimate(
                        label,
                        value,
                        value * float(np.sqrt(max(c @ cov @ c, 0.0))),
                        unit,
                        par.components[b].s
                        if par.components[b].s is not None
                        else par.components[a].s,
                    )
            if not par.indices(b_name) and names[a] in parameters and b_name in fixed:
                est = parameters[names[a]]
                ratios[f"{names[a]}/{b_name}"] = Estimate(
                    f"{names[a]}/{b_name}",
                    est.value / fixed[b_name],
                    est.std / fixed[b_name],
                    unit,
                    est.s,
                )
    return ratios


def gated(
    result: FitResult, problem: Problem, data: ObservationSet, settings: FitSettings
) -> FitResult:
    """Pass a fit result through the goodness-of-fit gate.

    ``result`` through the goodness-of-fit gate (``gate.py``): status 'misfit' with the cause
    when the fitted shapes do not explain the points (a converged fit, or one that stopped without
    descent); otherwise the standard deviations inflated by sqrt(χ²_red) when it is over 1 (σ
    stated too small or model error: the residuals say how large the noise really is; without the
    outliers the gate forgave, which the robust loss already down-weighted).
    """
    if result.status not in ("ok", "not_converged") or not result.observations:
        return result
    distances = [
        np.linalg.norm(o.points - fit.feet, axis=1)
        for o, fit in zip(data.observations, result.observations)
    ]
    gate = evaluate_gate(
        problem, data, result.chi2_reduced * result.dof, result.dof, distances, settings.huber
    )
    result = replace(result, chi2_threshold=gate.threshold)
    if not gate.passed:
        return replace(
            result, status="misfit", message=f"{gate.cause} ({result.status}: {result.message})"
        )
    if gate.note:
        result = replace(result, message=f"{result.message}; {gate.note}")
    scale = float(np.sqrt(max(gate.noise_ratio2, 1.0)))
    if scale > 1.0:

        def inflated(est: Estimate) -> Estimate:
            return replace(est, std=est.std * scale)

        result = replace(
            result,
            sigma_scale=scale,
            parameters={k: inflated(v) for k, v in result.parameters.items()},
            ratios={k: inflated(v) for k, v in result.ratios.items()},
            covariance_log=result.covariance_log * scale**2,
        )
    return result


def _anchored(
    theta: np.ndarray, par: Parameterisation, ident: Identifiability, normal: np.ndarray
) -> np.ndarray:
    """Shift θ along the common scale the data do not see, anchoring one material.

    θ shifted along the common scale u of the fitted materials that enter the solved models (u_k
    = 1, or 0 for a parameter no residual depends on, e.g. Rt of planar shapes), when the data do
    not see it (shapes alone: the energy's minimiser does not change), so that the first fitted
    material in ANCHOR_ORDER keeps the scene's value (a table: its mean log factor).  Only this
    exact symmetry is used: moving along a merely weak direction would change the fitted shapes.
    """
    diagonal = np.diag(normal)
    u = (diagonal > RANK_TOLERANCE * max(float(diagonal.max(initial=0.0)), 0.0)).astype(float)
    null = ident.null
    if not u.any():
        return theta
    if null.shape[1] == 0 or np.linalg.norm(null.T @ u) < (1.0 - ORTHOGONAL) * np.linalg.norm(u):
        return theta
    anchor = next(m for m in ANCHOR_ORDER if any(u[i] for i in par.indices(m)))
    return theta - float(np.mean(theta[par.indices(anchor)])) * u


def _pseudo_inverse(normal: np.ndarray, ident: Identifiability) -> np.ndarray:
    """Return A⁺ on the determined directions (the covariance of θ with the stated σ)."""
    vec, lam = ident.directions
    return (vec / lam) @ vec.T if lam.size else np.zeros_like(normal)
