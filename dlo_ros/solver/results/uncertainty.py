"""What is not known of the string's material: a covariance over named material parameters.

A parameter is one of the scene's ``string`` keys that scale a material profile (``KEYS``:
bend_stiffness Rf, twist_stiffness Rt, stretch_stiffness Re, weight_per_length D,
lateral_bend_stiffness Rl), taken as θ = log c of a uniform scale P(s) → c P(s) of that profile
(``sensitivity.MaterialDirection`` with no ``change``), or, from a knot-by-knot fit
(``identify/parameters.py``), θ_k = log of the factor at one knot s_k of a piecewise-linear table
(dP/dθ_k = P(s_k) h_k(s), h_k the hat function of knot k on the table's knots).

An :class:`Uncertainty` holds the covariance C of these parameters, either in SI units of the keys
(``log`` False: C_ij = ρ_ij σ_i σ_j, σ_i in N·m², N or N/m as the key's unit) or of θ itself
(``log`` True, dimensionless: what ``dlo fit`` reports as ``covariance_log``).  To first order
δθ_i = δv_i / v_i, v_i the parameter's value (a uniform scale: the profile's mean over s; a knot:
the profile's value there), so

    C_θ = V⁻¹ C V⁻¹,   V = diag(v).

Every error is an :class:`UncertaintyError` (a ValueError) whose message starts with the field it
is about (``uncertainty.bend_stiffness: must be >= 0, got -1``).  No ROS, no solve here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ...model.problem import StringProperties
from ...model.profile import Profile
from .sensitivity import MaterialDirection

#: the scene's ``string`` key of each material parameter and its symbol (sensitivity.MATERIALS)
KEYS: dict[str, str] = {
    "bend_stiffness": "Rf",
    "twist_stiffness": "Rt",
    "stretch_stiffness": "Re",
    "weight_per_length": "D",
    "lateral_bend_stiffness": "Rl",
}
#: the SI unit of each key (msg_docs/scene_format.md)
UNITS: dict[str, str] = {
    "bend_stiffness": "N·m²",
    "twist_stiffness": "N·m²",
    "stretch_stiffness": "N",
    "weight_per_length": "N/m",
    "lateral_bend_stiffness": "N·m²",
}
_SYMBOL_KEY = {symbol: key for key, symbol in KEYS.items()}
#: relative tolerance of the covariance's symmetry and of its smallest eigenvalue below zero (the
#: round-off of a pseudo-inverse such as the fit's)
PSD_TOLERANCE = 1e-9


class UncertaintyError(ValueError):
    """A malformed uncertainty; ``str(err)`` starts with the field path ``key``."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


@dataclass(frozen=True)
class Parameter:
    """One uncertain material parameter θ (module docstring).

    key: a ``KEYS`` entry; knot: None for a uniform scale of the profile, else the index into
    ``knots`` [m], the arc lengths of a knot-by-knot fit's table.
    """

    key: str
    knot: int | None = None
    knots: tuple[float, ...] = ()

    @property
    def name(self) -> str:
        """The scene key, with ``[k]`` for a knot (``bend_stiffness[2]``)."""
        return self.key if self.knot is None else f"{self.key}[{self.knot}]"

    @property
    def material(self) -> str:
        """The material's symbol (Rf, Rt, Re, D, Rl)."""
        return KEYS[self.key]

    def value(self, string: StringProperties) -> float:
        """Return v [the key's unit]: the profile's mean over s, or its value at the knot."""
        profile = getattr(string, self.key)
        if profile is None:
            return 0.0
        if self.knot is None:
            return profile_mean(profile, string.length)
        return float(profile(np.array([self.knots[self.knot]]))[0])

    def direction(self, string: StringProperties) -> MaterialDirection:
        """Return dP/dθ for the sensitivity: the profile itself, or P(s_k) h_k(s) for a knot."""
        if self.knot is None:
            return MaterialDirection(self.name, self.material)
        hat = np.zeros(len(self.knots))
        hat[self.knot] = self.value(string)
        return MaterialDirection(
            self.name, self.material, Profile(self.knots, tuple(float(v) for v in hat))
        )


def profile_mean(profile: Profile, length: float) -> float:
    """Return (1/L) ∫₀ᴸ P ds [unit of P], exact for a piecewise-linear table."""
    s = np.unique(np.clip(np.concatenate(([0.0, length], profile.s)), 0.0, length))
    return float(np.trapezoid(profile(s), s) / length)


@dataclass(frozen=True)
class Uncertainty:
    """A covariance of material parameters (module docstring).

    parameters: the θ; covariance: C as nested tuples (k × k; hashable, so that a Scene holding
    one compares and pickles); log: C is of θ = log c (dimensionless) rather than in the keys' SI
    units; note: what the numbers leave out (e.g. a fit's undetermined directions), carried into
    the envelope.  Build one with :meth:`from_sigmas` or :meth:`from_covariance`, which validate.
    """

    parameters: tuple[Parameter, ...]
    covariance: tuple[tuple[float, ...], ...]
    log: bool = False
    note: str = field(default="", compare=False)

    @classmethod
    def from_sigmas(cls, sigmas: Mapping[str, float], where: str = "uncertainty") -> Uncertainty:
        """Build independent standard deviations σ [the key's SI unit] per key (C = diag σ²).

        Raises UncertaintyError naming ``<where>.<key>`` for an unknown key, or a σ that is not a
        finite number >= 0.
        """
        if not isinstance(sigmas, Mapping):
            raise UncertaintyError(
                where, f"expected a mapping of keys to σ, got {type(sigmas).__name__}"
            )
        parameters, values = [], []
        for key, sigma in sigmas.items():
            if key not in KEYS:
                raise UncertaintyError(
                    f"{where}.{key}", f"unknown key (allowed: {', '.join(KEYS)})"
                )
            values.append(_sigma(sigma, f"{where}.{key}"))
            parameters.append(Parameter(key))
        cov = np.diag(np.square(values)) if values else np.zeros((0, 0))
        return cls(tuple(parameters), _tuples(cov))

    @classmethod
    def from_covariance(
        cls,
        names: Sequence[str | Parameter],
        covariance: np.ndarray | Sequence[Sequence[float]],
        log: bool = False,
        where: str = "uncertainty",
        note: str = "",
    ) -> Uncertainty:
        """Build a full covariance over named parameters (keys, Rf/Rt/Re/D/Rl, or Parameters).

        ``log``: the covariance is of θ = log c (as ``dlo fit``'s ``covariance_log``), else in
        the keys' SI units.  Raises UncertaintyError naming ``<where>.names[i]`` (unknown or
        repeated) or ``<where>.covariance`` (shape, NaN, asymmetric, not positive semi-definite).
        """
        parameters = tuple(_parameter(n, f"{where}.names[{i}]") for i, n in enumerate(names))
        seen: dict[str, int] = {}
        for i, p in enumerate(parameters):
            if p.name in seen:
                raise UncertaintyError(
                    f"{where}.names[{i}]", f"{p.name!r} repeats names[{seen[p.name]}]"
                )
            seen[p.name] = i
        cov = _checked_covariance(covariance, len(parameters), f"{where}.covariance")
        return cls(parameters, _tuples(cov), bool(log), note)

    @property
    def names(self) -> tuple[str, ...]:
        """Return each parameter's name: its key, with ``[k]`` for a knot."""
        return tuple(p.name for p in self.parameters)

    @property
    def matrix(self) -> np.ndarray:
        """C as a (k, k) array [SI units of the keys, squared; or dimensionless when ``log``]."""
        k = len(self.parameters)
        return np.array(self.covariance, dtype=float).reshape(k, k)

    @property
    def sigmas(self) -> dict[str, float]:
        """σ_i = sqrt(C_ii) per parameter name (SI, or log units when ``log``)."""
        variances = np.maximum(np.diag(self.matrix), 0.0)  # a PSD matrix's round-off below 0
        return {p.name: math.sqrt(v) for p, v in zip(self.parameters, variances)}

    def check_string(self, string: StringProperties, where: str = "uncertainty") -> None:
        """Refuse a σ in SI units on a parameter whose value is 0 or absent (C_θ is undefined).

        Raises UncertaintyError naming ``<where>.<name>``.
        """
        if self.log:
            return
        for p, var in zip(self.parameters, np.diag(self.matrix)):
            if var > 0 and not p.value(string) > 0:
                what = "null" if getattr(string, p.key) is None else "0"
                raise UncertaintyError(
                    f"{where}.{p.name}",
                    f"the string's {p.key} is {what}: a standard deviation relative to it is "
                    "undefined (the envelope scales the profile, θ = log c); give the string a "
                    "value or drop the key",
                )

    def log_covariance(self, string: StringProperties) -> np.ndarray:
        """Return C_θ (k, k) of θ = log c at ``string``: C itself, or V⁻¹ C V⁻¹ (module docs).

        Raises UncertaintyError as :meth:`check_string`.
        """
        cov = self.matrix
        if self.log:
            return cov
        self.check_string(string)
        values = np.array([p.value(string) for p in self.parameters])
        inverse = np.divide(1.0, values, out=np.zeros_like(values), where=values > 0)
        return cov * np.outer(inverse, inverse)

    def marginal_sigmas(self, string: StringProperties) -> dict[str, float]:
        """Return {key: σ [the key's SI unit]} of the uniform scales (``string.uncertainty``'s).

        The marginals: a log σ is multiplied by the key's value in ``string``; correlations and
        knots are left out (the scene format has one σ per key).
        """
        out = {}
        for p, var in zip(self.parameters, np.maximum(np.diag(self.matrix), 0.0)):
            if p.knot is None:
                out[p.key] = math.sqrt(var) * (p.value(string) if self.log else 1.0)
        return out


def _sigma(value: object, where: str) -> float:
    """Return a standard deviation: a finite number >= 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UncertaintyError(where, f"expected a number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise UncertaintyError(where, f"must be a finite number >= 0, got {v}")
    if v < 0:
        raise UncertaintyError(where, f"must be >= 0, got {v:g}")
    return v


def _parameter(name: str | Parameter, where: str) -> Parameter:
    """Return the Parameter a name stands for: a scene key, a symbol (Rf, ...) or a Parameter."""
    if isinstance(name, Parameter):
        if name.key not in KEYS:
            raise UncertaintyError(where, f"unknown key {name.key!r} (allowed: {', '.join(KEYS)})")
        if name.knot is not None and not 0 <= name.knot < len(name.knots):
            raise UncertaintyError(
                where, f"knot {name.knot} of a table of {len(name.knots)} knots"
            )
        return name
    key = _SYMBOL_KEY.get(name, name) if isinstance(name, str) else None
    if key not in KEYS:
        raise UncertaintyError(
            where,
            f"unknown parameter {name!r} (allowed: {', '.join(KEYS)} or {', '.join(_SYMBOL_KEY)}; "
            "a knot of a table: a Parameter with its knots, as FitResult.uncertainty gives)",
        )
    return Parameter(key)


def _checked_covariance(
    covariance: np.ndarray | Sequence[Sequence[float]], k: int, where: str
) -> np.ndarray:
    """Return the covariance as a (k, k) float array: finite, symmetric, positive semi-definite."""
    try:
        cov = np.array(covariance, dtype=float)
    except (TypeError, ValueError):
        raise UncertaintyError(where, "expected a k × k matrix of numbers") from None
    if cov.size == 0 and k == 0:
        return np.zeros((0, 0))
    if cov.shape != (k, k):
        raise UncertaintyError(where, f"expected {k} × {k} (one row per name), got {cov.shape}")
    if not np.all(np.isfinite(cov)):
        raise UncertaintyError(where, "contains NaN or infinity")
    scale = float(np.abs(cov).max(initial=0.0))
    if np.abs(cov - cov.T).max(initial=0.0) > PSD_TOLERANCE * scale:
        raise UncertaintyError(where, "not symmetric")
    cov = 0.5 * (cov + cov.T)
    smallest = float(np.linalg.eigvalsh(cov).min(initial=0.0)) if k else 0.0
    if smallest < -PSD_TOLERANCE * scale:
        raise UncertaintyError(
            where, f"not positive semi-definite (smallest eigenvalue {smallest:.3g})"
        )
    return cov


def _tuples(cov: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in cov)
