"""The shape and grip-wrench envelope of an equilibrium under material uncertainty (first order).

Given the covariance C_θ of θ = log c of the material parameters (``uncertainty.py``: per scene
key σ_v [SI] gives σ_θ = σ_v / v), the equilibrium's sensitivities from its KKT system
(``sensitivity.py``: J_x(s) = dx(s)/dθ [m], J_F = dF/dθ [N], J_T = dT/dθ [N·m]; no extra solve)
propagate it linearly:

    C_x(s) = J_x(s) C_θ J_x(s)ᵀ   [m²]  (3 × 3 per output point),
    σ(s)   = sqrt(λ_max(C_x(s)))  [m]   (the largest principal standard deviation),
    C_F    = J_F C_θ J_Fᵀ  [N²],   σ_F,i = sqrt((C_F)_ii)  [N],
    C_T    = J_T C_θ J_Tᵀ  [N²·m²], σ_T,i = sqrt((C_T)_ii) [N·m],
    σ_|F|  = sqrt(uᵀ C_F u)  [N],  u = F / |F|  (the tension's, to first order).

A ball of radius k σ(s) about x(s) contains that point's k-σ ellipsoid (``Envelope.tube``).  The
forces and torques are those ``ShapeResult.grips`` holds: what each gripper exerts on the string,
world frame, torques about the grip point.

First order only: valid while the response is near-linear over the spread, i.e. for small σ, away
from a snap-through (the stability margin → 0 and J blows up) and without a change of contact
(the linearisation holds the answer's active set).  msg_docs/model_and_solver.md, "Envelope".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..shape_solver import ShapeSolver
from .result import ShapeResult
from .sensitivity import shape_sensitivity
from .uncertainty import KEYS, Parameter, Uncertainty, UncertaintyError

__all__ = [
    "KEYS",
    "Envelope",
    "EnvelopeUnavailable",
    "GripEnvelope",
    "Parameter",
    "Uncertainty",
    "UncertaintyError",
    "envelope",
]

#: the solver's committed centreline must match the result's within this times L [m] for the
#: envelope to be of that result (both come from one state: they agree to round-off)
MATCH_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class GripEnvelope:
    """One grip's wrench and its first-order spread (module docstring).

    force (3,) [N], force_sigma (3,) [N] and force_covariance (3, 3) [N²]; torque (3,) [N·m],
    torque_sigma (3,) [N·m] and torque_covariance (3, 3) [N²·m²], None where the model does not
    differentiate its torques (the 3D Euler models); tension_sigma [N]: σ of |F|.
    """

    force: np.ndarray
    force_sigma: np.ndarray
    force_covariance: np.ndarray
    tension_sigma: float
    torque: np.ndarray
    torque_sigma: np.ndarray | None = None
    torque_covariance: np.ndarray | None = None

    def force_bounds(self, k: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
        """Return (F − k σ_F, F + k σ_F) [N], component-wise."""
        return self.force - k * self.force_sigma, self.force + k * self.force_sigma

    def torque_bounds(self, k: float = 2.0) -> tuple[np.ndarray, np.ndarray] | None:
        """Return (T − k σ_T, T + k σ_T) [N·m], component-wise; None without torque σ."""
        if self.torque_sigma is None:
            return None
        return self.torque - k * self.torque_sigma, self.torque + k * self.torque_sigma

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form: ``force_sigma``, ``torque_sigma`` (or None), ``tension_sigma``."""
        return {
            "force_sigma": _list(self.force_sigma),
            "torque_sigma": None if self.torque_sigma is None else _list(self.torque_sigma),
            "tension_sigma": float(self.tension_sigma),
        }


@dataclass(frozen=True, eq=False)
class Envelope:
    """The first-order envelope of one result (module docstring).

    names: the uncertain parameters; log_covariance: C_θ (k, k) they were propagated with; s (S,)
    [m] and points (S, 3) [m]: the result's output points; sigma (S,) [m]: σ(s);
    point_covariance (S, 3, 3) [m²]: C_x(s); grips: per grip name; note: what the numbers leave
    out ("" when nothing).
    """

    available: ClassVar[bool] = True
    names: tuple[str, ...]
    log_covariance: np.ndarray
    s: np.ndarray
    points: np.ndarray
    sigma: np.ndarray
    point_covariance: np.ndarray
    grips: dict[str, GripEnvelope] = field(default_factory=dict)
    note: str = ""

    @property
    def max_sigma(self) -> float:
        """The largest σ(s) over the output points [m] (0 without points)."""
        return float(self.sigma.max(initial=0.0))

    def tube(self, k: float = 2.0) -> np.ndarray:
        """Return the radii k σ(s) [m] of the k-σ tube about the centreline, per output point."""
        return k * self.sigma

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (``dlo solve --json``'s ``envelope``, msg_docs/cli.md)."""
        return {
            "sigma": _list(self.sigma),
            "grips": {name: g.to_dict() for name, g in self.grips.items()},
            "parameters": list(self.names),
            "note": self.note,
        }


@dataclass(frozen=True)
class EnvelopeUnavailable:
    """Why there is no envelope of a result (no converged answer, a failed sensitivity, ...)."""

    available: ClassVar[bool] = False
    reason: str

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form ``{"unavailable": reason}``."""
        return {"unavailable": self.reason}


def envelope(
    solver: Any, result: ShapeResult, uncertainty: Uncertainty
) -> Envelope | EnvelopeUnavailable:
    """Return the first-order envelope of ``result`` under ``uncertainty`` (module docstring).

    ``solver``: the ShapeSolver or AutoShapeSolver (its streaming model) that answered
    ``result`` and still holds it as its committed equilibrium (a query, ``commit=False``, or a
    later solve leaves another one: the envelope is then unavailable).  The values a σ in SI
    units is relative to are those of ``solver.problem``'s string.  Never raises for a result or
    state it cannot use: an :class:`EnvelopeUnavailable` says why.
    """
    why = _why_not(result)
    if why:
        return EnvelopeUnavailable(why)
    inner = getattr(solver, "inner", solver)  # auto: the model that answered
    if not isinstance(inner, ShapeSolver):
        return EnvelopeUnavailable(f"not a shape solver: {type(solver).__name__}")
    string = solver.problem.string
    try:
        cov = uncertainty.log_covariance(string)
    except UncertaintyError as exc:
        return EnvelopeUnavailable(str(exc))
    model_string = inner.problem.string
    layout = inner.nlp.params.slices
    for p in uncertainty.parameters:
        if p.material not in layout:
            return EnvelopeUnavailable(
                f"{p.name}: the solved model has no {p.material} (the string is not a strip)"
            )
    directions = tuple(p.direction(model_string) for p in uncertainty.parameters)
    try:
        sens = shape_sensitivity(inner, directions, result.s)
    except ValueError as exc:
        return EnvelopeUnavailable(str(exc))
    length = string.length
    gap = float(np.abs(sens.points - result.points).max(initial=0.0))
    if not gap <= MATCH_TOLERANCE * length:
        return EnvelopeUnavailable(
            f"the solver's committed equilibrium is not this result's shape (they differ by "
            f"{gap:.3g} m): compute the envelope right after the solve that committed it"
        )
    notes = [uncertainty.note] if uncertainty.note else []
    notes += _left_out(uncertainty, cov, string, model_string)
    point_cov = np.einsum("sik,kl,sjl->sij", sens.d_points, cov, sens.d_points)
    sigma = np.sqrt(np.maximum(np.linalg.eigvalsh(point_cov)[:, -1], 0.0))
    grips = {
        name: _grip(result, name, (d_force, sens.d_grip_torques.get(name)), cov)
        for name, d_force in sens.d_grip_forces.items()
    }
    if not sens.d_grip_torques and sens.d_grip_forces:
        notes.append(
            "torque σ: the 3D Euler model (solver.rotation euler) does not differentiate its "
            "grip torques"
        )
    return Envelope(
        uncertainty.names,
        cov,
        sens.s,
        result.points,
        sigma,
        point_cov,
        grips,
        "; ".join(notes),
    )


def _why_not(result: ShapeResult) -> str:
    """Return why ``result`` has no envelope, or "" when it may have one."""
    if result.status != "ok":
        return (
            f"the result is {result.status}, not ok: no verified equilibrium to linearise about"
            + (f" ({result.message})" if result.message else "")
        )
    if result.stable is False:
        eig = "" if result.min_eigenvalue is None else f" ({result.min_eigenvalue:.3g})"
        return (
            f"the equilibrium is unstable (smallest reduced eigenvalue < 0{eig}): no first-order "
            "envelope about it"
        )
    if len(result.s) == 0:
        return "the result has no output points"
    return ""


def _grip(
    result: ShapeResult,
    name: str,
    derivatives: tuple[np.ndarray, np.ndarray | None],
    cov: np.ndarray,
) -> GripEnvelope:
    """Return one grip's envelope from dF/dθ (3, k) and dT/dθ (3, k) or None."""
    d_force, d_torque = derivatives
    wrench = result.grips[name]
    force_cov = d_force @ cov @ d_force.T
    norm = float(np.linalg.norm(wrench.force))
    u = wrench.force / norm if norm > 0 else np.zeros(3)
    torque_cov = None if d_torque is None else d_torque @ cov @ d_torque.T
    return GripEnvelope(
        np.array(wrench.force, dtype=float),
        _diagonal_sigma(force_cov),
        force_cov,
        float(np.sqrt(max(float(u @ force_cov @ u), 0.0))),
        np.array(wrench.torque, dtype=float),
        None if torque_cov is None else _diagonal_sigma(torque_cov),
        torque_cov,
    )


def _left_out(
    uncertainty: Uncertainty, cov: np.ndarray, string: Any, model_string: Any
) -> list[str]:
    """Name the uncertain parameters the solved model leaves out (auto: weight or stretch).

    auto drops the weight or the stretch where their effect is below its tolerance; their σ then
    adds nothing here (the solved model does not depend on them).
    """
    out = []
    for i, p in enumerate(uncertainty.parameters):
        if cov[i, i] > 0 and p.value(string) > 0 and not p.value(model_string) > 0:
            out.append(
                f"{p.name}: left out of the solved model (auto: its effect is below the "
                "tolerance), so its σ adds nothing"
            )
    return out


def _diagonal_sigma(cov: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def _list(a: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]
