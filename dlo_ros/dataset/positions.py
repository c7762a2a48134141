"""Where a plan puts one grip: in a box, on a grid, or along a path (one class per kind).

Each kind maps sample indices ``i`` and that sample's three uniform draws ``u`` ∈ [0, 1)³ (the
plan's ``PCG64`` stream, ``plan.py``) to positions [m]:

* ``position_box: {min: [x, y, z], max: [x, y, z]}``: min + u · (max − min), uniform in the box;
* ``position_grid: {min, max, counts: [nx, ny, nz]}``: the lattice's points in C order (x slowest),
  sample i at point i mod (nx·ny·nz); a count of 1 puts that axis at min; the draws are unused;
* ``around_path: {points: [[x, y, z], ...], spread: d}``: sample i at the fraction i / (samples −
  1) of the polyline's length (in plan order: neighbours along the plan are neighbours along the
  path), moved by spread · (2u − 1) on each axis.

A malformed entry raises ``PlanError`` naming its key (``parse``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Union

import numpy as np

Vector = tuple[float, float, float]
MAX_GRID_POINTS = 10**8
MAX_PATH_POINTS = 10_000
#: the largest coordinate a plan may name [m] (a box's extent stays finite)
MAX_METRES = 1e6


class PlanError(ValueError):
    """A malformed plan: ``str(err)`` starts with the offending key path (``plan.…``)."""


@dataclass(frozen=True)
class PositionBox:
    """Positions drawn uniformly in the box ``low`` … ``high`` [m]."""

    low: Vector
    high: Vector

    def positions(self, index: np.ndarray, u: np.ndarray, samples: int) -> np.ndarray:
        """Return the (len(index), 3) positions of the samples ``index`` with draws ``u``."""
        low = np.array(self.low)
        return low + u * (np.array(self.high) - low)

    def as_dict(self) -> dict[str, Any]:
        """Return the plan entry this was read from."""
        return {"position_box": {"min": list(self.low), "max": list(self.high)}}


@dataclass(frozen=True)
class PositionGrid:
    """The lattice of ``counts`` points per axis from ``low`` to ``high`` [m], in C order."""

    low: Vector
    high: Vector
    counts: tuple[int, int, int]

    def positions(self, index: np.ndarray, u: np.ndarray, samples: int) -> np.ndarray:
        """Return the (len(index), 3) lattice points of the samples ``index``."""
        ijk = np.array(np.unravel_index(index % math.prod(self.counts), self.counts)).T
        low, high = np.array(self.low), np.array(self.high)
        steps = np.array([max(n - 1, 1) for n in self.counts], dtype=float)
        return low + ijk / steps * (high - low)

    def as_dict(self) -> dict[str, Any]:
        """Return the plan entry this was read from."""
        box = {"min": list(self.low), "max": list(self.high), "counts": list(self.counts)}
        return {"position_grid": box}


@dataclass(frozen=True)
class AroundPath:
    """Points evenly spaced along the polyline ``points`` [m], each moved by up to ``spread``."""

    points: tuple[Vector, ...]
    spread: float

    def positions(self, index: np.ndarray, u: np.ndarray, samples: int) -> np.ndarray:
        """Return the (len(index), 3) positions of the samples ``index`` with draws ``u``."""
        p = np.array(self.points)
        lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
        along = np.concatenate(([0.0], np.cumsum(lengths)))
        t = index / max(samples - 1, 1) * along[-1]
        on_path = np.column_stack([np.interp(t, along, p[:, k]) for k in range(3)])
        return on_path + self.spread * (2.0 * u - 1.0)

    def as_dict(self) -> dict[str, Any]:
        """Return the plan entry this was read from."""
        return {"around_path": {"points": [list(q) for q in self.points], "spread": self.spread}}


Sampler = Union[PositionBox, PositionGrid, AroundPath]
KINDS = ("position_box", "position_grid", "around_path")


def parse(spec: object, key: str) -> Sampler:
    """Return the sampler of one grip's plan entry ``spec`` (its key path ``key``)."""
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in KINDS:
        raise PlanError(f"{key}: must be one of {{{': …}, {'.join(KINDS)}: …}}")
    kind, body = next(iter(spec.items()))
    where = f"{key}.{kind}"
    if kind == "around_path":
        _keys(body, where, ("points", "spread"))
        points = body["points"]
        if not isinstance(points, list) or not 2 <= len(points) <= MAX_PATH_POINTS:
            raise PlanError(f"{where}.points: must be 2 to {MAX_PATH_POINTS} points [x, y, z]")
        path = tuple(vector(q, f"{where}.points[{i}]") for i, q in enumerate(points))
        spread = body["spread"]
        if isinstance(spread, bool) or not isinstance(spread, (int, float)):
            raise PlanError(f"{where}.spread: must be a number ≥ 0 [m]")
        if not 0 <= spread <= MAX_METRES:
            raise PlanError(f"{where}.spread: must be a number ≥ 0 [m], at most 1e6")
        return AroundPath(path, float(spread))
    _keys(body, where, ("min", "max", "counts") if kind == "position_grid" else ("min", "max"))
    low, high = vector(body["min"], f"{where}.min"), vector(body["max"], f"{where}.max")
    if any(a > b for a, b in zip(low, high)):
        raise PlanError(f"{where}: min must not exceed max on any axis")
    if kind == "position_box":
        return PositionBox(low, high)
    counts = body["counts"]
    valid = isinstance(counts, list) and len(counts) == 3
    if not valid or not all(isinstance(n, int) and not isinstance(n, bool) for n in counts):
        raise PlanError(f"{where}.counts: must be 3 integers [nx, ny, nz] ≥ 1")
    if min(counts) < 1 or math.prod(counts) > MAX_GRID_POINTS:
        raise PlanError(f"{where}.counts: each ≥ 1, at most {MAX_GRID_POINTS} points in all")
    return PositionGrid(low, high, (counts[0], counts[1], counts[2]))


def _keys(body: object, where: str, keys: tuple[str, ...]) -> None:
    if not isinstance(body, dict) or set(body) != set(keys):
        raise PlanError(f"{where}: must have exactly {', '.join(keys)}")


def vector(value: object, key: str) -> Vector:
    """Return ``value`` as 3 finite floats, or raise PlanError naming ``key``."""
    items = list(value) if isinstance(value, (list, tuple)) else []
    numbers = [float(v) for v in items if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if len(items) != 3 or len(numbers) != 3 or not all(abs(v) <= MAX_METRES for v in numbers):
        raise PlanError(f"{key}: must be 3 finite numbers [x, y, z] in metres, each within ±1e6")
    return (numbers[0], numbers[1], numbers[2])
