"""Ritz bases for the fields along the arc length s ∈ [0, L].

A field f(s) (an Euler angle or the strain) is expanded as f(s) = Σ_k c_k b_k(s).
Each basis returns the matrix B[i, k] = b_k(s_i) and its derivative dB/ds, so that
f(s_i) = (B c)_i and f'(s_i) = (B' c)_i are linear in the coefficients c.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.polynomial import chebyshev as C


class Basis(Protocol):
    """Interface of a Ritz basis of ``size`` functions on [0, length]."""

    name: str
    size: int
    length: float

    def values(self, s: np.ndarray) -> np.ndarray:
        """B[i, k] = b_k(s_i), shape (len(s), size)."""

    def derivatives(self, s: np.ndarray) -> np.ndarray:
        """B'[i, k] = db_k/ds (s_i) [1/m], shape (len(s), size)."""

    def values_and_derivatives(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, B') at s: ``values`` and ``derivatives`` (one evaluation where a basis has one)."""


class ChebyshevBasis:
    """b_k(s) = T_k(τ), τ = 2 s / L − 1, k = 0 … n−1 (Chebyshev polynomials of the first kind).

    Polynomials resolve non-periodic profiles (asymmetric clamping angles, point loads) with
    spectral accuracy, unlike the Fourier basis whose periodic part converges only algebraically
    there.
    """

    name = "chebyshev"

    def __init__(self, size: int, length: float) -> None:
        if size < 2:
            raise ValueError("solver.order must be at least 2 for the chebyshev basis")
        self.size = int(size)
        self.length = float(length)

    def _tau(self, s: np.ndarray) -> np.ndarray:
        return 2.0 * np.asarray(s, dtype=float) / self.length - 1.0

    def values(self, s: np.ndarray) -> np.ndarray:
        return C.chebvander(self._tau(s), self.size - 1)

    def derivatives(self, s: np.ndarray) -> np.ndarray:
        tau = self._tau(s)
        out = np.empty((tau.size, self.size))
        for k in range(self.size):
            coef = np.zeros(self.size)
            coef[k] = 1.0
            out[:, k] = C.chebval(tau, C.chebder(coef)) * (2.0 / self.length)
        return out

    def values_and_derivatives(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.values(s), self.derivatives(s)


class FourierBasis:
    """The paper's Fourier basis (Hirai & Wakamatsu, sec. 4).

    The paper's basis (Hirai & Wakamatsu, sec. 4): 1, s/L, sin(2nπs/L), cos(2nπs/L), n = 1, 2, …

    The first ``size`` functions of that sequence are used (the paper takes 10: n = 1 … 4).
    s is scaled by L so that every coefficient is an angle in radians.
    """

    name = "fourier"

    def __init__(self, size: int, length: float) -> None:
        if size < 2:
            raise ValueError("solver.order must be at least 2 for the fourier basis")
        self.size = int(size)
        self.length = float(length)

    def values(self, s: np.ndarray) -> np.ndarray:
        u = np.asarray(s, dtype=float) / self.length
        cols = [np.ones_like(u), u]
        n = 1
        while len(cols) < self.size:
            cols.append(np.sin(2 * n * np.pi * u))
            cols.append(np.cos(2 * n * np.pi * u))
            n += 1
        return np.stack(cols[: self.size], axis=1)

    def derivatives(self, s: np.ndarray) -> np.ndarray:
        u = np.asarray(s, dtype=float) / self.length
        inv = 1.0 / self.length
        cols = [np.zeros_like(u), np.full_like(u, inv)]
        n = 1
        while len(cols) < self.size:
            w = 2 * n * np.pi * inv
            cols.append(w * np.cos(2 * n * np.pi * u))
            cols.append(-w * np.sin(2 * n * np.pi * u))
            n += 1
        return np.stack(cols[: self.size], axis=1)

    def values_and_derivatives(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.values(s), self.derivatives(s)


BASES: dict[str, type[ChebyshevBasis] | type[FourierBasis]] = {
    "chebyshev": ChebyshevBasis,
    "fourier": FourierBasis,
}


def make_basis(name: str, size: int, length: float) -> Basis:
    """Build a basis by name ('chebyshev' or 'fourier')."""
    try:
        cls = BASES[name]
    except KeyError:
        raise ValueError(f"solver.basis must be one of {sorted(BASES)}, got {name!r}") from None
    return cls(size, length)
