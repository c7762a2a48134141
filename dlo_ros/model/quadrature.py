"""Clenshaw–Curtis quadrature and cumulative integration on Chebyshev–Lobatto nodes.

Fields are sampled at M nodes s_j = L (1 − cos(π j /(M−1))) / 2.  For samples f_j the polynomial
interpolant p of degree M−1 gives
    ∫_0^L f ds ≈ Σ_j w_j f_j                   (Clenshaw–Curtis weights w)
    ∫_0^σ f ds ≈ Σ_j W_j(σ) f_j               (cumulative integration matrix W)
Both are exact for polynomials of degree ≤ M−1 and converge spectrally for smooth f.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C


#: ``_chebvander`` evaluates at most this many points in Python floats (numpy's loop over the
#: degrees costs the same ~1 µs per degree for any number of points: 20 µs at 20 nodes, for the
#: few points a slot placement asks for at a time)
FEW_POINTS = 12


def _chebvander(x: np.ndarray, deg: int) -> np.ndarray:
    """Return ``C.chebvander(x, deg)`` for a 1-D ``x``, the same numbers in the same layout.

    Up to FEW_POINTS points: the same recurrence (T_0 = x·0 + 1, T_1 = x, T_k = T_{k−1}·2x −
    T_{k−2}) in Python floats, whose IEEE products and differences are numpy's; the array is laid
    out as numpy's (the transpose of a row per degree), so that the products that follow run
    the same BLAS call.  No point or more: numpy's.
    """
    if not 0 < x.size <= FEW_POINTS:
        return C.chebvander(x, deg)
    return _vander_floats(x.tolist(), deg)


def _vander_floats(points: list[float], deg: int) -> np.ndarray:
    """Return ``_chebvander`` of a few points given as floats (its recurrence and layout)."""
    columns = []
    for t in points:
        a, b, t2 = t * 0.0 + 1.0, t, 2.0 * t
        col = [a, b]
        for _ in range(2, deg + 1):
            a, b = b, b * t2 - a
            col.append(b)
        columns.append(col[: deg + 1])
    return np.array(list(zip(*columns)), dtype=float).reshape(deg + 1, len(points)).T


def _vander_at(s: np.ndarray, length: float, deg: int) -> np.ndarray:
    """Return ``_chebvander(τ, deg)`` at τ = 2 s / length − 1 of the flattened ``s``.

    Up to FEW_POINTS points τ too in Python floats (numpy's operations, in its order).
    """
    s = np.asarray(s, dtype=float).ravel()
    if not 0 < s.size <= FEW_POINTS:
        return _chebvander(2.0 * s / length - 1.0, deg)
    return _vander_floats([2.0 * x / length - 1.0 for x in s.tolist()], deg)


class ChebyshevQuadrature:
    """Nodes, weights and integration matrices on [0, length] with ``count`` Lobatto nodes."""

    def __init__(self, count: int, length: float) -> None:
        if count < 4:
            raise ValueError("solver.quadrature_nodes must be at least 4")
        self.count = int(count)
        self.length = float(length)
        j = np.arange(self.count)
        self.tau = -np.cos(np.pi * j / (self.count - 1))  # ascending in [-1, 1]
        self.nodes = 0.5 * self.length * (self.tau + 1.0)
        self._vinv = np.linalg.inv(C.chebvander(self.tau, self.count - 1))
        self.weights = self.integration_matrix(np.array([self.length]))[0]

    def integration_matrix(self, s: np.ndarray) -> np.ndarray:
        """W[q, j] with ∫_0^{s_q} f ds ≈ Σ_j W[q, j] f(s_j), shape (len(s), count)."""
        if not hasattr(self, "_antiderivatives"):  # column k: the Chebyshev series of ∫_{-1}^τ T_k
            self._antiderivatives = C.chebint(np.eye(self.count), lbnd=-1.0)
        return (
            0.5
            * self.length
            * (_vander_at(s, self.length, self.count) @ self._antiderivatives)
            @ self._vinv
        )

    def interpolation_matrix(self, s: np.ndarray) -> np.ndarray:
        """P[q, j] with f(s_q) ≈ Σ_j P[q, j] f(s_j) (polynomial interpolation)."""
        return _vander_at(s, self.length, self.count - 1) @ self._vinv

    def derivative_matrix(self, s: np.ndarray) -> np.ndarray:
        """P'[q, j] with f'(s_q) ≈ Σ_j P'[q, j] f(s_j): the interpolant's s-derivative."""
        if not hasattr(self, "_derivatives"):  # column k: the Chebyshev series of dT_k/dτ
            self._derivatives = C.chebder(np.eye(self.count))
        return (
            (2.0 / self.length)
            * (_vander_at(s, self.length, self.count - 2) @ self._derivatives)
            @ self._vinv
        )
