"""The outer objective of a fit at θ, from every observation's equilibrium.

The outer objective of a fit at θ: every observation's equilibrium, residuals, Jacobian and
normal matrix.

    Φ(θ) = Σ_obs Σ_j ρ(|r_j| / σ_obs) + ½ Σ ((F_meas − F(θ)) / σ_F)² + ½ Σ ((T_meas − T(θ)) / σ_T)²
           + ½ ((W_known − ∫D ds) / σ_W)² + ½ |Rθ|²

r_j: point-to-curve residuals (``curve.py``); ρ: Huber's loss; F: a measured grip force; T: a
measured grip torque (about the grip point; dT/dθ for the director and planar models only); W: the
known weight; R: the profile regulariser (``parameters.py``).  Each evaluation solves each
observation's equilibrium once (its own warm-started ``ShapeSolver``) and takes dr/dθ from the KKT
system (``solver/results/sensitivity.py``).  The Gauss–Newton normal matrix and gradient use
Huber's IRLS weights
w_j = min(1, huber / u_j), u_j = |r_j| / σ.
"""

from __future__ import annotations

import collections
import pickle
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..model.problem import Problem, StringProperties
from ..solver import ShapeResult, ShapeSolver, SolverOptions
from ..solver.build.nlp import planarity_violation
from ..solver.results.sensitivity import shape_sensitivity
from ..solver.shape_solver import structure_key
from .curve import point_to_curve
from .observations import Observation, ObservationError, ObservationSet
from .parameters import Parameterisation, profile_mean
from .results import ObservationFit


@dataclass(frozen=True)
class FitSettings:
    """How a fit iterates and what it tolerates.

    max_iterations: outer LM iterations; huber: the loss's threshold in σ; samples: centreline
    samples the points are projected on; step_tolerance: converged when the largest accepted step
    in θ is below this; max_step: the largest step in θ (log units); compile: the equilibrium
    solvers' compile mode.
    """

    max_iterations: int = 30
    huber: float = 2.5
    samples: int = 401
    step_tolerance: float = 1e-6
    max_step: float = 0.7
    compile: str = "off"


@dataclass
class Evaluation:
    """The objective and its Gauss–Newton model at one θ.

    Φ at one θ (``cost``), the normal matrix A and gradient Jᵀ W r of the Gauss–Newton step, the
    residual statistics per observation, Σ (r/σ)² (``chi2``) and the number of residual rows.
    """

    theta: np.ndarray
    cost: float
    normal: np.ndarray
    gradient: np.ndarray
    fits: list[ObservationFit]
    chi2: float
    rows: int


class SolverCache:
    """Equilibrium solvers kept from one fit to the next.

    Equilibrium solvers kept from one fit to the next, for a process that fits again and again
    (the node's fit worker): building a solver takes seconds (interpreted CasADi), a solve tens of
    ms.

    ``take`` hands out a kept solver of the same structure (``structure_key``, model and compile
    mode) with the new problem set and its warm start forgotten, so that its first solve is cold as
    a new solver's; a planar solver only when the new problem lies in its plane (the check its NLP
    makes when it is built).  ``give`` keeps a solver (the least recently given beyond ``size`` are
    dropped).  Not thread-safe: one fit at a time per cache.
    """

    def __init__(self, size: int = 4):
        self.size = size
        self._solvers: collections.OrderedDict[bytes, list[ShapeSolver]] = (
            collections.OrderedDict()
        )

    @staticmethod
    def _key(problem: Problem, options: SolverOptions, compile: str) -> bytes:
        return pickle.dumps(
            (structure_key(problem, options), compile), protocol=pickle.HIGHEST_PROTOCOL
        )

    def take(self, problem: Problem, options: SolverOptions, compile: str) -> ShapeSolver | None:
        kept = self._solvers.get(self._key(problem, options, compile))
        while kept:
            solver = kept.pop()
            if solver.nlp.planar and planarity_violation(problem, solver.nlp.r0[:, 2]):
                continue  # another plane: a planar solver of this problem is built anew
            try:
                solver.set_problem(problem)
            except ValueError:
                continue
            solver.reset()
            return solver
        return None

    def give(self, solver: ShapeSolver, compile: str) -> None:
        key = self._key(solver.problem, solver.options, compile)
        self._solvers.setdefault(key, []).append(solver)
        self._solvers.move_to_end(key)
        while sum(len(v) for v in self._solvers.values()) > self.size:
            oldest = next(iter(self._solvers))
            self._solvers[oldest].pop(0)
            if not self._solvers[oldest]:
                del self._solvers[oldest]


class ObservedShape:
    """One observation's solver and data."""

    def __init__(
        self,
        base: Problem,
        obs: Observation,
        options: SolverOptions,
        compile: str,
        cache: SolverCache | None = None,
    ):
        self.obs = obs
        self.problem = base.with_grip_poses(obs.poses)
        self.solver = _solver_for(self.problem, options, compile, cache)

    def solve(self, string: StringProperties) -> ShapeResult:
        """Solve this observation's equilibrium with ``string``, warm-started.

        The equilibrium of this observation's poses with ``string``, warm-started from the last
        one.
        """
        self.solver.set_problem(replace(self.problem, string=string))
        return self.solver.solve()


def _solver_for(
    problem: Problem, options: SolverOptions, compile: str, cache: SolverCache | None = None
) -> ShapeSolver:
    """Return a fixed-model solver for an observation's problem.

    A fixed-model solver: the scene's model, or for 'auto' the planar model where the shape is
    planar; from ``cache`` when it keeps one.
    """

    def build(opts: SolverOptions) -> ShapeSolver:
        kept = cache.take(problem, opts, compile) if cache is not None else None
        return kept if kept is not None else ShapeSolver(problem, opts, compile=compile)

    if options.model == "auto":
        try:
            return build(options.with_model("planar"))
        except ValueError:  # not a planar scene
            return build(options.with_model("full"))
    return build(options)


class Objective:
    """The objective Φ of a fit and its Gauss–Newton model at any θ.

    Φ and its Gauss–Newton model at any θ (module docstring); ``solves`` counts equilibrium
    solves.
    """

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions,
        data: ObservationSet,
        par: Parameterisation,
        settings: FitSettings,
        cache: SolverCache | None = None,
    ):
        self.data, self.par, self.settings = data, par, settings
        # the scene with the knot tables from the start: a director model splits its elements at
        # their knots
        scene = replace(problem, string=par.base)
        self.observed = [
            ObservedShape(scene, obs, options, settings.compile, cache)
            for obs in data.observations
        ]
        for i, o in enumerate(self.observed):
            if o.obs.torque is not None and not (o.solver.nlp.director or o.solver.nlp.planar):
                raise ObservationError(
                    f"observations[{i}].torque: a measured torque needs the director or planar "
                    "model (solver.rotation 'director'); the scene's 3D Euler model does not "
                    "differentiate its grip torques"
                )
        self.regulariser = par.regulariser()
        self.s = np.linspace(0.0, par.length, settings.samples)
        self.solves = 0

    def evaluate(self, theta: np.ndarray) -> Evaluation | str:
        """Φ at θ, or why an equilibrium could not be solved."""
        par, settings, data, base = self.par, self.settings, self.data, self.par.base
        names, reg, s_grid = par.labels, self.regulariser, self.s
        string = par.string(theta)
        directions = par.directions(string)
        k = len(names)
        normal, gradient, cost, chi2, rows, fits = np.zeros((k, k)), np.zeros(k), 0.0, 0.0, 0, []
        for o in self.observed:
            result = o.solve(string)
            self.solves += 1
            if result.status != "ok":
                return (
                    f"observation {o.obs.name!r}: the equilibrium is {result.status}: "
                    f"{result.message}"
                )
            sens = shape_sensitivity(o.solver, directions, s_grid)
            cr = point_to_curve(o.obs.points, sens.s, sens.points, sens.d_points)
            sigma = o.obs.sigma
            u = cr.distances / sigma
            w = np.where(u <= settings.huber, 1.0, settings.huber / np.maximum(u, 1e-300))
            cost += float(
                np.sum(
                    np.where(
                        u <= settings.huber,
                        0.5 * u * u,
                        settings.huber * u - 0.5 * settings.huber**2,
                    )
                )
            )
            chi2 += float(np.sum(u * u))
            rows += 2 * len(u)
            jw = cr.jacobian / sigma
            normal += np.einsum("n,nik,nil->kl", w, jw, jw)
            gradient += np.einsum("n,nik,ni->k", w, jw, cr.residuals / sigma)
            measured, force_res, torque_res = _measured_wrenches(o.obs, sens)
            for value, predicted, d_predicted, sigma_v in measured:
                r = (value - predicted) / sigma_v
                jv = -d_predicted / sigma_v
                cost += 0.5 * float(r @ r)
                chi2 += float(r @ r)
                rows += 3
                normal += jv.T @ jv
                gradient += jv.T @ r
            d = cr.distances
            fits.append(
                ObservationFit(
                    o.obs.name,
                    len(d),
                    float(np.sqrt(np.mean(d * d))),
                    float(np.median(d)),
                    float(d.max()),
                    int(np.sum(u > settings.huber)),
                    force_res,
                    sens.points,
                    o.obs.points - cr.residuals,
                    torque_res,
                )
            )
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
        return Evaluation(theta, cost, normal, gradient, fits, chi2, rows)


def _measured_wrenches(
    obs: Observation, sens: Any
) -> tuple[list[tuple[Any, Any, Any, float]], float | None, float | None]:
    """Return the observation's measured grip force and torque terms, and their residuals.

    The terms are (measured, predicted, d predicted/dθ, σ) for each of the grip force and grip
    torque the observation states; the residuals |measured − predicted| [N], [N·m] (None when not
    stated).  ``sens`` is the observation's ``shape_sensitivity``.
    """
    force_res = torque_res = None
    measured = []
    if obs.force is not None:
        f = obs.force
        measured.append((f.force, sens.grip_forces[f.grip], sens.d_grip_forces[f.grip], f.sigma))
        force_res = float(np.linalg.norm(f.force - sens.grip_forces[f.grip]))
    if obs.torque is not None:
        t = obs.torque
        measured.append(
            (t.torque, sens.grip_torques[t.grip], sens.d_grip_torques[t.grip], t.sigma)
        )
        torque_res = float(np.linalg.norm(t.torque - sens.grip_torques[t.grip]))
    return measured, force_res, torque_res
