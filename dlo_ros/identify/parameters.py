"""The fitted parameters θ and the string they stand for.

Each fitted material P ∈ {Rf, Rt, D, Re} (SI: N·m², N·m², N/m, N) is either

* scaled uniformly from the scene's profile: P(s) = e^θ P_scene(s), one θ labelled ``Rf`` (a table
  keeps
  its shape); or
* a piecewise-linear table with n knots s_k evenly spaced over [0, L] (``ProfileFit``): P(s_k) =
  e^{θ_k} P_scene(s_k), linear in between, n values labelled ``Rf[k]``, with the smoothness
  regulariser ½ λ Σ_k (θ_{k−1} − 2 θ_k + θ_{k+1})² (λ = ``smoothing``; dimensionless, θ in log
  units).  It penalises curvature of log P along the knots, not its mean or slope, so it does not
  bias a constant or log-linear profile and does not fix the overall scale.

dP/dθ is P itself (uniform) or the table with every value but knot k set to zero
(``MaterialDirection``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..model.profile import Profile
from ..model.problem import StringProperties
from ..solver.results.sensitivity import MaterialDirection
from .observations import ProfileFit

#: the StringProperties field of each material
PROFILE = {
    "Rf": "bend_stiffness",
    "Rt": "twist_stiffness",
    "D": "weight_per_length",
    "Re": "stretch_stiffness",
}


@dataclass(frozen=True)
class Component:
    """One θ: its label, material, and knot index and arc length [m] (None: a uniform scale)."""

    label: str
    material: str
    knot: int | None = None
    s: float | None = None


def profile_mean(profile: Profile, length: float) -> float:
    """(1/L) ∫ P ds [unit of P] (the value of a constant profile)."""
    if len(profile.s) == 1:
        return float(profile.values[0])
    s = np.linspace(0.0, length, 2001)
    return float(np.trapezoid(profile(s), s) / length)


class Parameterisation:
    """The map between θ and the string's fitted materials.

    θ ↔ string for the materials ``names`` of ``string``; ``profiles[name]`` fits that one knot
    by knot.
    """

    def __init__(
        self, string: StringProperties, names: tuple[str, ...], profiles: dict[str, ProfileFit]
    ):
        self.length = string.length
        self.profiles = dict(profiles)
        changes: dict[str, Any] = {}
        comps = []
        for name in names:
            spec = profiles.get(name)
            if spec is None:
                comps.append(Component(name, name))
                continue
            knots = np.linspace(0.0, string.length, spec.knots)
            scene = getattr(string, PROFILE[name])
            changes[PROFILE[name]] = Profile(
                tuple(float(s) for s in knots), tuple(float(v) for v in scene(knots))
            )
            comps += [Component(f"{name}[{k}]", name, k, float(s)) for k, s in enumerate(knots)]
        self.base = replace(string, **changes)
        self.components = tuple(comps)
        self.labels = tuple(c.label for c in comps)

    def indices(self, material: str) -> list[int]:
        return [i for i, c in enumerate(self.components) if c.material == material]

    def string(self, theta: np.ndarray) -> StringProperties:
        """Return the string at θ."""
        changes = {}
        for material in dict.fromkeys(c.material for c in self.components):
            idx = self.indices(material)
            prof = getattr(self.base, PROFILE[material])
            if self.components[idx[0]].knot is None:
                changes[PROFILE[material]] = prof.scaled(float(np.exp(theta[idx[0]])))
            else:
                changes[PROFILE[material]] = Profile(
                    prof.s, tuple(float(v) for v in np.asarray(prof.values) * np.exp(theta[idx]))
                )
        return replace(self.base, **changes)

    def directions(self, string: StringProperties) -> tuple[MaterialDirection, ...]:
        """dP/dθ for every θ at ``string`` (= self.string(θ))."""
        out = []
        for c in self.components:
            if c.knot is None:
                out.append(MaterialDirection(c.label, c.material))
                continue
            prof = getattr(string, PROFILE[c.material])
            values = np.zeros(len(prof.values))
            values[c.knot] = prof.values[c.knot]
            out.append(MaterialDirection(c.label, c.material, Profile(prof.s, tuple(values))))
        return tuple(out)

    def value(self, string: StringProperties, k: int) -> float:
        """θ_k's quantity in SI: the profile's mean over s (uniform) or its value at the knot."""
        c = self.components[k]
        prof = getattr(string, PROFILE[c.material])
        return profile_mean(prof, self.length) if c.knot is None else float(prof.values[c.knot])

    def weight_gradient(self, string: StringProperties) -> np.ndarray:
        """d(∫ D ds)/dθ [N]."""
        out = np.zeros(len(self.components))
        for k, d in enumerate(self.directions(string)):
            if d.material == "D":
                change = getattr(string, PROFILE["D"]) if d.change is None else d.change
                out[k] = profile_mean(change, self.length) * self.length
        return out

    def regulariser(self) -> np.ndarray:
        """Return R, with ½ |R θ|² the smoothness penalty; (0, n) if there is none.

        Its rows are √λ (θ_{k−1} − 2θ_k + θ_{k+1}).
        """
        rows = []
        for material, spec in self.profiles.items():
            idx = self.indices(material)
            for k in range(1, len(idx) - 1):
                row = np.zeros(len(self.components))
                row[[idx[k - 1], idx[k], idx[k + 1]]] = np.sqrt(spec.smoothing) * np.array(
                    [1.0, -2.0, 1.0]
                )
                rows.append(row)
        return np.array(rows).reshape(len(rows), len(self.components))
