"""Spectral elements along the arc length: breakpoints, nodal interpolation and quadrature.

The string [0, L] is split at breakpoints 0 = b_0 < b_1 < … < b_E = L.  On element e = [b_e, b_{e+1}]
a field is the polynomial of degree n − 1 through its values at n Chebyshev–Lobatto nodes; the end
nodes of neighbouring elements are the same node, so every field is continuous across a breakpoint
while its derivative may jump there (a kink at a grip, a point load or a jump of the material).
The unknowns of a field are its N = E (n − 1) + 1 nodal values.

Integrals use Clenshaw–Curtis quadrature on m Lobatto nodes per element (the breakpoints appear
once per element that ends there): for samples f_k at the quadrature nodes σ_k

    ∫_0^L f ds ≈ Σ_k w_k f_k,        ∫_0^s f ds ≈ Σ_k W_k(s) f_k,

exact for polynomials of degree ≤ m − 1 on every element and spectrally convergent for fields that are
smooth on each element.
"""
from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C

from .quadrature import ChebyshevQuadrature


def lobatto(count: int) -> np.ndarray:
    """Chebyshev–Lobatto points on [−1, 1], ascending."""
    return -np.cos(np.pi * np.arange(count) / (count - 1))


class LagrangeElement:
    """Interpolation through n Lobatto nodes of [0, h]: P(τ) f_nodes and its s-derivative."""

    def __init__(self, count: int, size: float) -> None:
        self.count, self.size = int(count), float(size)
        self._vinv = np.linalg.inv(C.chebvander(lobatto(count), count - 1))
        self._der = np.zeros((count, count))
        for k in range(count):
            coef = np.zeros(count)
            coef[k] = 1.0
            self._der[: count - 1, k] = C.chebder(coef) if count > 1 else 0.0

    def matrices(self, local_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, B') with f(s) = B f_nodes and f'(s) = B' f_nodes for local arc lengths in [0, h]."""
        tau = 2.0 * np.asarray(local_s, dtype=float) / self.size - 1.0
        v = C.chebvander(tau, self.count - 1)
        return v @ self._vinv, (v @ self._der) @ self._vinv * (2.0 / self.size)


class ElementMesh:
    """Breakpoints, global interpolation nodes and the composite quadrature of one string.

    ``order`` interpolation nodes and ``quadrature`` quadrature nodes per element.
    """

    def __init__(self, length: float, breakpoints, order: int, quadrature: int) -> None:
        self.length = float(length)
        b = np.unique(np.concatenate([[0.0, self.length], np.asarray(breakpoints, dtype=float).ravel()]))
        b = b[(b >= 0.0) & (b <= self.length)]
        # breakpoints closer than 1e-9 L merge (a grip at a load's s is one breakpoint)
        keep = np.concatenate([[True], np.diff(b) > 1e-9 * self.length])
        self.breakpoints = b[keep]
        self.breakpoints[-1] = self.length
        if order < 2:
            raise ValueError("solver.order must be at least 2")
        self.order, self.quadrature = int(order), int(quadrature)
        self.elements = [LagrangeElement(order, hi - lo) for lo, hi in zip(self.breakpoints[:-1], self.breakpoints[1:])]
        self.quads = [ChebyshevQuadrature(quadrature, hi - lo) for lo, hi in zip(self.breakpoints[:-1], self.breakpoints[1:])]
        n = order - 1
        self.count = len(self.elements) * n + 1  # global interpolation nodes
        self.nodes = np.concatenate([lo + el.size * (lobatto(order)[:-1] + 1) / 2
                                     for lo, el in zip(self.breakpoints[:-1], self.elements)] + [[self.length]])
        self.quad_nodes = np.concatenate([lo + q.nodes for lo, q in zip(self.breakpoints[:-1], self.quads)])
        self.weights = np.concatenate([q.weights for q in self.quads])
        self.quad_count = self.quad_nodes.size
        self.B, self.dB = self._quad_matrices()

    @property
    def element_count(self) -> int:
        return len(self.elements)

    def node_index(self, s: float) -> int | None:
        """The global node at arc length s, or None when s is not a node."""
        i = int(np.argmin(np.abs(self.nodes - s)))
        return i if abs(self.nodes[i] - s) <= 1e-9 * self.length else None

    def element_of(self, s: np.ndarray, side: str = "left") -> np.ndarray:
        """Element index of each s; at a breakpoint the element on ``side`` ('left' or 'right')."""
        s = np.asarray(s, dtype=float)
        inner = self.breakpoints[1:-1]
        idx = np.searchsorted(inner, s, side="left" if side == "left" else "right")
        return np.clip(idx, 0, self.element_count - 1)

    def interpolation(self, s, side: str = "left") -> tuple[np.ndarray, np.ndarray]:
        """(B, B') of shape (len(s), count): field values and s-derivatives at s from the nodal values.
        At a breakpoint the derivative is the one-sided derivative of the element on ``side``."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        B, dB = np.zeros((s.size, self.count)), np.zeros((s.size, self.count))
        n = self.order - 1
        for e in np.unique(self.element_of(s, side)):
            rows = np.flatnonzero(self.element_of(s, side) == e)
            b, db = self.elements[e].matrices(s[rows] - self.breakpoints[e])
            B[np.ix_(rows, range(e * n, e * n + self.order))] = b
            dB[np.ix_(rows, range(e * n, e * n + self.order))] = db
        return B, dB

    def _quad_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        B, dB = np.zeros((self.quad_count, self.count)), np.zeros((self.quad_count, self.count))
        n, m = self.order - 1, self.quadrature
        for e, (el, q) in enumerate(zip(self.elements, self.quads)):
            b, db = el.matrices(q.nodes)
            B[e * m:(e + 1) * m, e * n:e * n + self.order] = b
            dB[e * m:(e + 1) * m, e * n:e * n + self.order] = db
        return B, dB

    def integration_matrix(self, s) -> np.ndarray:
        """W of shape (len(s), quad_count) with ∫_0^s f ≈ W f_quad."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        W = np.zeros((s.size, self.quad_count))
        m = self.quadrature
        for e, q in enumerate(self.quads):
            lo, hi = self.breakpoints[e], self.breakpoints[e + 1]
            full = s >= hi
            W[np.ix_(full, range(e * m, (e + 1) * m))] = q.weights
            part = (s > lo) & (s < hi)
            if np.any(part):
                W[np.ix_(part, range(e * m, (e + 1) * m))] = q.integration_matrix(s[part] - lo)
        return W
