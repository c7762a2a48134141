"""What a fit returns, as dataclasses with their JSON.

What a fit returns: determined values with standard deviations, ratios, what is not determined,
and the residuals per observation (``FitResult.to_dict()`` is the JSON of ``dlo fit --json``,
msg_docs/fitting.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.problem import StringProperties
from ..solver.results.uncertainty import KEYS, Parameter, Uncertainty
from .identifiability import Identifiability

#: the scene key of each fitted material's symbol
_KEY_OF = {symbol: key for key, symbol in KEYS.items()}


@dataclass
class Estimate:
    """A determined quantity: value, standard deviation and unit.

    A determined quantity: value, standard deviation (same unit) and unit.  For a table profile
    the value is its mean over s (the fit scales the table).
    """

    name: str
    value: float
    std: float
    unit: str
    s: float | None = None  # the knot's arc length [m] of a piecewise-linear profile's value

    def as_dict(self) -> dict:
        out = {
            "value": self.value,
            "std": self.std,
            "relative_std": self.std / abs(self.value) if self.value else None,
            "unit": self.unit,
        }
        if self.s is not None:
            out["s"] = self.s
        return out


@dataclass
class ObservationFit:
    """Residuals of one observation at the fit.

    |r| statistics over its points [m], how many points the robust loss down-weighted
    (|r| > huber σ), the grip-force residual |F_meas − F| [N] and the grip-torque
    residual |T_meas − T| [N·m] where measured.
    """

    name: str
    points: int
    rms_m: float
    median_m: float
    max_m: float
    downweighted: int
    force_residual_n: float | None = None
    #: the fitted centreline (S, 3) [m] and each observed point's nearest point on it (N, 3) [m],
    #: for drawing
    shape: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    feet: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    torque_residual_nm: float | None = None

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "points": self.points,
            "rms_m": self.rms_m,
            "median_m": self.median_m,
            "max_m": self.max_m,
            "downweighted": self.downweighted,
            "force_residual_n": self.force_residual_n,
            "torque_residual_nm": self.torque_residual_nm,
        }


@dataclass
class FitResult:
    """The result of a fit: status, estimates, what is not determined, residuals.

    status: 'ok' (converged and the fitted shapes explain the points), 'misfit' (they do not:
    the reduced χ² is over ``chi2_threshold``, ``gate.py``; the message says why), 'not_converged'
    (iteration limit or no descent) or 'failed' (an equilibrium could not be solved: message).
    parameters: the determined ones; ratios: the determined ratios (D/Rf, Rt/Rf, Re/Rf);
    not_identifiable[name]: why the data cannot determine it; fixed: the scene's values of
    parameters not fitted (the estimates are conditional on them); string: the scene's string with
    the fitted values; chi2_reduced: Σ(r/σ)² / dof, dof = 2 N_points + force, torque and mass rows
    − rank; sigma_scale: the factor the stds were inflated by (sqrt(chi2_reduced) when it is over
    1).
    """

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
    dof: int = 0
    chi2_threshold: float = float("nan")
    sigma_scale: float = 1.0

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def uncertainty(self) -> Uncertainty:
        """Return the fitted parameters' covariance as an envelope's input (``envelope.py``).

        The covariance of θ = log c (``covariance_log``, inflated by ``sigma_scale`` like the
        reported stds) over every fitted parameter: ``Rf`` as ``bend_stiffness`` (a uniform
        scale), ``Rf[k]`` as knot k of the fitted table.  It is zero along the directions the
        data do not determine, so its ``note`` names those parameters: the envelope holds them
        where the fit left them.  Raises ValueError for a fit without a usable covariance (status
        'failed' or 'misfit', or nothing fitted).
        """
        if self.status not in ("ok", "not_converged") or self.string is None or not self.names:
            raise ValueError(
                f"fit status {self.status!r}: no covariance that describes the string"
                + (f" ({self.message})" if self.message else "")
            )
        parameters = []
        for label in self.names:
            symbol, _, rest = label.partition("[")
            key = _KEY_OF[symbol]
            if rest:
                knots = tuple(float(s) for s in getattr(self.string, key).s)
                parameters.append(Parameter(key, int(rest.rstrip("]")), knots))
            else:
                parameters.append(Parameter(key))
        notes = []
        if self.status != "ok":
            notes.append(f"the fit is {self.status}: {self.message}")
        if self.not_identifiable:  # the pseudo-inverse is zero along what the data do not see
            notes.append(
                f"the fit does not determine {', '.join(sorted(self.not_identifiable))} alone: "
                "the covariance is zero along the undetermined directions, which the envelope "
                "holds where the fit left them"
            )
        return Uncertainty.from_covariance(
            parameters, self.covariance_log, log=True, where="fit", note="; ".join(notes)
        )

    def to_dict(self) -> dict:
        """JSON-ready (``dlo fit --json``, msg_docs/fitting.md)."""
        ident = self.identifiability
        return {
            "status": self.status,
            "message": self.message,
            "parameters": {k: v.as_dict() for k, v in self.parameters.items()},
            "ratios": {k: v.as_dict() for k, v in self.ratios.items()},
            "not_identifiable": dict(self.not_identifiable),
            "fixed": dict(self.fixed),
            "observations": [o.as_dict() for o in self.observations],
            "chi2_reduced": self.chi2_reduced,
            "chi2_threshold": self.chi2_threshold,
            "dof": self.dof,
            "sigma_scale": self.sigma_scale,
            "iterations": self.iterations,
            "equilibrium_solves": self.equilibrium_solves,
            "time_s": self.time_s,
            "fitted": list(self.names),
            "covariance_log": self.covariance_log.tolist(),
            "rank": None if ident is None else ident.rank,
            "condition": None if ident is None else ident.condition,
        }
