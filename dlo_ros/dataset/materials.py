"""A plan's material ranges: the string's stiffness and weight drawn per sample (``plan.string``).

::

    string:
      bend_stiffness: {min: 0.01, max: 0.04, log: true}     # [N·m²], log-uniform
      weight_per_length: {min: 0.3, max: 0.7}               # [N/m], uniform

Keys: ``bend_stiffness``, ``twist_stiffness``, ``weight_per_length`` and ``stretch_stiffness``
(this one only for a scene whose string is extensible), in the scene's SI units.  Each sample's
value is drawn from one uniform draw u of the plan's stream (``plan.py``): min + u (max − min), or
min (max/min)^u with ``log: true``.  The sample's string then has that value everywhere (a
constant profile).  A malformed entry raises PlanError naming its key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..model.problem import Problem
from ..model.profile import Profile
from .positions import PlanError

#: the string values a plan may draw, in the order of their draws
KEYS = ("bend_stiffness", "twist_stiffness", "weight_per_length", "stretch_stiffness")
#: the lowest value each may take (as the scene reader checks them: Rf > 0, Rt ≥ 0, D ≥ 0, Re > 0)
POSITIVE = ("bend_stiffness", "stretch_stiffness")


@dataclass(frozen=True)
class MaterialRange:
    """One material's values: ``low`` … ``high`` in SI units, uniform or log-uniform (``log``)."""

    low: float
    high: float
    log: bool = False

    def draw(self, u: np.ndarray) -> np.ndarray:
        """Return the values of draws ``u`` ∈ [0, 1)."""
        if self.log:
            return self.low * (self.high / self.low) ** u
        return self.low + u * (self.high - self.low)

    def as_dict(self) -> dict[str, Any]:
        """Return the plan entry this was read from."""
        return {"min": self.low, "max": self.high, "log": self.log}


def parse(spec: object) -> dict[str, MaterialRange]:
    """Return the material ranges of a plan's ``string`` entry (in KEYS order)."""
    if not isinstance(spec, dict) or not spec:
        raise PlanError(f"plan.string: must map some of {', '.join(KEYS)} to {{min, max}}")
    unknown = [str(k) for k in spec if k not in KEYS]
    if unknown:
        raise PlanError(f"plan.string.{unknown[0]}: unknown (a plan may draw {', '.join(KEYS)})")
    return {key: _range(spec[key], key) for key in KEYS if key in spec}


def _range(body: object, key: str) -> MaterialRange:
    where = f"plan.string.{key}"
    if not isinstance(body, dict) or not {"min", "max"} <= set(body) <= {"min", "max", "log"}:
        raise PlanError(f"{where}: must be {{min: …, max: …}} with an optional log: true")
    values = [body["min"], body["max"]]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise PlanError(f"{where}: min and max must be numbers")
    low, high = (float(v) for v in values)
    log = body.get("log", False)
    if not isinstance(log, bool):
        raise PlanError(f"{where}.log: must be true or false")
    if not (math.isfinite(low) and math.isfinite(high) and low <= high):
        raise PlanError(f"{where}: min and max must be finite, min ≤ max")
    if low < 0 or (key in POSITIVE or log) and low <= 0:
        bound = "> 0" if key in POSITIVE or log else "≥ 0"
        raise PlanError(f"{where}.min: must be {bound}")
    return MaterialRange(low, high, log)


def check_scene(ranges: dict[str, MaterialRange], problem: Problem) -> None:
    """Raise PlanError for a range the scene cannot take (stretch on an inextensible string)."""
    if "stretch_stiffness" in ranges and problem.string.stretch_stiffness is None:
        raise PlanError(
            "plan.string.stretch_stiffness: the scene's string is inextensible (give the scene "
            "a string.stretch_stiffness to draw it)"
        )


def with_values(problem: Problem, values: dict[str, float]) -> Problem:
    """Return ``problem`` with each of ``values`` as a constant profile of its string."""
    if not values:
        return problem
    changes: dict[str, Any] = {key: Profile.constant(value) for key, value in values.items()}
    return replace(problem, string=replace(problem.string, **changes))


def uniform_value(profile: Profile | None) -> float | None:
    """Return a constant profile's value, None for a table (or no profile)."""
    if profile is None or len(profile.values) != 1:
        return None
    return float(profile.values[0])
