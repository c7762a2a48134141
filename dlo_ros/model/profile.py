"""Material properties that are constant or vary along the arc length."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Profile:
    """A property p(s): a constant, or a piecewise-linear table of (s [m], value) rows.

    Outside the table's range the end values are held.  The paper's trapezoid sheet
    (width b = 50 + s/4 mm, Rf = 330 b gw·mm²) is a two-row table, exactly.
    """

    s: tuple[float, ...]
    values: tuple[float, ...]

    @staticmethod
    def constant(value: float) -> "Profile":
        return Profile((0.0,), (float(value),))

    @staticmethod
    def table(rows: list[tuple[float, float]] | np.ndarray) -> "Profile":
        arr = np.asarray(rows, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 1:
            raise ValueError("a table needs rows of [s, value]")
        if np.any(np.diff(arr[:, 0]) <= 0):
            raise ValueError("table s values must be strictly increasing")
        return Profile(tuple(arr[:, 0]), tuple(arr[:, 1]))

    def __call__(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        if len(self.s) == 1:
            return np.full(s.shape, self.values[0])
        return np.interp(s, self.s, self.values)

    @property
    def minimum(self) -> float:
        return float(min(self.values))

    @property
    def maximum(self) -> float:
        return float(max(self.values))

    @property
    def is_zero(self) -> bool:
        return all(v == 0.0 for v in self.values)

    def scaled(self, factor: float) -> "Profile":
        return Profile(self.s, tuple(v * factor for v in self.values))
