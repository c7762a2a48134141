"""Spectral elements along the arc length: breakpoints, nodal interpolation and quadrature.

The string [0, L] is split at breakpoints 0 = b_0 < b_1 < … < b_E = L.  On element e = [b_e,
b_{e+1}] a field is the polynomial of degree n_e − 1 through its values at the n_e
Legendre–Gauss–Lobatto (LGL) nodes of the element; the end nodes of neighbouring elements are the
same node, so every field is continuous across a breakpoint while its derivative may jump there (a
kink at a grip, a point load or a jump of the material).  ``order`` nodes are shared out by length,
n_e = max(MIN_NODES, ⌈order · h_e / L⌉ + 1), so the unknowns of a field, N = Σ (n_e − 1) + 1, stay
close to ``order`` however many elements there are (each element's field is smooth, so it needs
fewer).

Integrals are taken by the LGL rule on the same nodes (the spectral element method's collocated
quadrature, exact for polynomials of degree ≤ 2n − 3 on every element): for samples f_k at the
quadrature nodes σ_k (each element's n nodes, so a breakpoint appears once per element it ends)

    ∫_0^L f ds ≈ Σ_k w_k f_k,        ∫_0^s f ds ≈ Σ_k W_k(s) f_k,

W integrating each element's interpolant exactly.  Collocation makes a field's value at σ_k a nodal
unknown itself and its derivative one row of the element's differentiation matrix, so the energy's
Hessian costs O(E n³) instead of O(E n² m) for m separate quadrature nodes.
"""

from __future__ import annotations

import bisect
import functools

import numpy as np
from numpy.polynomial import chebyshev as C
from numpy.polynomial import legendre as Leg

from .quadrature import FEW_POINTS, ChebyshevQuadrature


def lgl_nodes(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Legendre–Gauss–Lobatto nodes on [−1, 1] (ascending) and their quadrature weights."""
    if count < 2:
        raise ValueError("at least 2 nodes per element")
    p = Leg.Legendre.basis(count - 1)
    x = (
        np.concatenate([[-1.0], np.sort(p.deriv().roots().real), [1.0]])
        if count > 2
        else np.array([-1.0, 1.0])
    )
    w = 2.0 / (count * (count - 1) * p(x) ** 2)
    return x, w


class NodalElement:
    """The polynomial through n LGL nodes of [0, h].

    The polynomial through n LGL nodes of [0, h]: values, s-derivatives and integrals at any
    s.
    """

    def __init__(self, count: int, size: float) -> None:
        self.count, self.size = int(count), float(size)
        # what depends on the count alone: every element of n nodes shares it (a mesh's
        # elements mostly have the same count, and each refinement pass builds a new mesh)
        self.tau, weights, self._vinv, self._der, self._int = _reference(self.count)
        self.nodes = 0.5 * self.size * (self.tau + 1.0)
        self.weights = 0.5 * self.size * weights
        self.D = self.matrices(self.nodes)[1]  # differentiation matrix at the element's own nodes

    def matrices(self, local_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, B') with f(s) = B f_nodes and f'(s) = B' f_nodes for local arc lengths in [0, h]."""
        tau = 2.0 * np.asarray(local_s, dtype=float) / self.size - 1.0
        v = C.chebvander(tau, self.count - 1)
        return v @ self._vinv, (v @ self._der) @ self._vinv * (2.0 / self.size)

    def integral(self, local_s: np.ndarray) -> np.ndarray:
        """Return the matrix I with ∫_0^s f = I f_nodes.

        I with ∫_0^s f = I f_nodes for local arc lengths in [0, h] (the interpolant,
        exactly).
        """
        tau = 2.0 * np.asarray(local_s, dtype=float) / self.size - 1.0
        return 0.5 * self.size * (C.chebvander(tau, self.count) @ self._int) @ self._vinv


@functools.lru_cache(maxsize=128)
def _reference(count: int) -> tuple[np.ndarray, ...]:
    """Return the reference element's arrays for ``count`` LGL nodes (read-only).

    (τ, weights on [−1, 1], the inverse Chebyshev–Vandermonde matrix (nodal values → Chebyshev
    coefficients), and the coefficient maps of the derivative and of the integral from −1, the
    latter (count + 1) × count).
    """
    tau, weights = lgl_nodes(count)
    vinv = np.linalg.inv(C.chebvander(tau, count - 1))
    eye = np.eye(count)
    der = np.stack([np.concatenate([C.chebder(eye[k]), [0.0]]) for k in range(count)], axis=1)
    integral = np.stack([C.chebint(eye[k], lbnd=-1.0) for k in range(count)], axis=1)
    out = (tau, weights, vinv, der, integral)
    for a in out:
        a.flags.writeable = False
    return out


#: fewest LGL nodes of one element (a cubic-and-more polynomial per piece)
MIN_NODES = 6


class ElementMesh:
    """Breakpoints, global nodes and the composite quadrature of one string.

    Breakpoints, global nodes and the composite quadrature of one string: ``order`` LGL nodes
    shared out by element length, or ``counts`` (n_e per element, each at least 3) when a
    refinement chose them; ``extra`` > 0: n_e + ``extra`` Clenshaw–Curtis quadrature nodes per
    element instead of the collocated LGL rule.
    """

    def __init__(
        self, length: float, breakpoints, order: int, extra: int = 0, counts=None
    ) -> None:
        self.length = float(length)
        b = np.unique(
            np.concatenate([[0.0, self.length], np.asarray(breakpoints, dtype=float).ravel()])
        )
        b = b[(b >= 0.0) & (b <= self.length)]
        # breakpoints closer than 1e-9 L merge (a grip at a load's s is one breakpoint)
        keep = np.concatenate([[True], np.diff(b) > 1e-9 * self.length])
        self.breakpoints = b[keep]
        self.breakpoints[-1] = self.length
        if order < 3:
            raise ValueError("solver.order must be at least 3")
        self.order = int(order)
        sizes = np.diff(self.breakpoints)
        if counts is not None:
            if len(counts) != len(sizes) or min(counts) < 3:
                raise ValueError(
                    f"mesh: {len(sizes)} elements need as many node counts of at least 3, "
                    f"got {list(counts)}"
                )
            self.counts = [int(n) for n in counts]
        else:
            self.counts = (
                [order]
                if len(sizes) == 1
                else [max(MIN_NODES, int(np.ceil(order * h / self.length)) + 1) for h in sizes]
            )
        self.elements = [NodalElement(n, h) for n, h in zip(self.counts, sizes)]
        # first global node of each element (its last node is the next element's first)
        self.first = np.concatenate([[0], np.cumsum([n - 1 for n in self.counts])]).astype(int)
        self.count = int(self.first[-1]) + 1  # global nodes
        starts = self.breakpoints[:-1]
        self.nodes = np.concatenate(
            [lo + el.nodes[:-1] for lo, el in zip(starts, self.elements)] + [[self.length]]
        )
        self.quads = (
            [ChebyshevQuadrature(el.count + extra, el.size) for el in self.elements]
            if extra
            else None
        )
        per = [el.count + extra for el in self.elements]
        self.quad_first = np.concatenate([[0], np.cumsum(per)]).astype(int)
        if self.quads is None:
            self.quad_nodes = np.concatenate(
                [lo + el.nodes for lo, el in zip(starts, self.elements)]
            )
            self.weights = np.concatenate([el.weights for el in self.elements])
        else:
            self.quad_nodes = np.concatenate([lo + q.nodes for lo, q in zip(starts, self.quads)])
            self.weights = np.concatenate([q.weights for q in self.quads])
        self.quad_count = self.quad_nodes.size
        self._bounds: list[float] = self.breakpoints.tolist()  # (inside_one)
        # B: global nodal values → values at the quadrature nodes (a selection when collocated);
        # dB: derivatives
        self.B = np.zeros((self.quad_count, self.count))
        self.dB = np.zeros((self.quad_count, self.count))
        for e, el in enumerate(self.elements):
            rows = slice(self.quad_first[e], self.quad_first[e + 1])
            cols = slice(self.first[e], self.first[e] + el.count)
            if self.quads is None:
                self.B[rows, cols], self.dB[rows, cols] = np.eye(el.count), el.D
            else:
                self.B[rows, cols], self.dB[rows, cols] = el.matrices(self.quads[e].nodes)

    @property
    def element_count(self) -> int:
        return len(self.elements)

    def node_index(self, s: float) -> int | None:
        """Return the global node at arc length s, or None when s is not a node."""
        i = int(np.argmin(np.abs(self.nodes - s)))
        return i if abs(self.nodes[i] - s) <= 1e-9 * self.length else None

    def element_of(self, s: np.ndarray, side: str = "left") -> np.ndarray:
        """Element index of each s; at a breakpoint the element on ``side`` ('left' or 'right')."""
        inner = self.breakpoints[1:-1]
        idx = np.searchsorted(
            inner, np.asarray(s, dtype=float), side="left" if side == "left" else "right"
        )
        return np.clip(idx, 0, self.element_count - 1)

    def interpolation(self, s, side: str = "left") -> tuple[np.ndarray, np.ndarray]:
        """Return the interpolation matrices (B, B') at s from the nodal values.

        (B, B') of shape (len(s), count): field values and s-derivatives at s from the nodal
        values. At a breakpoint the derivative is the one-sided derivative of the element on
        ``side``.
        """
        s = np.atleast_1d(np.asarray(s, dtype=float))
        B, dB = np.zeros((s.size, self.count)), np.zeros((s.size, self.count))
        which = self.element_of(s, side)
        for e in np.unique(which):
            rows = np.flatnonzero(which == e)
            b, db = self.elements[e].matrices(s[rows] - self.breakpoints[e])
            # the element's columns as a slice (np.ix_ built index arrays: the same entries)
            cols = slice(self.first[e], self.first[e] + self.elements[e].count)
            B[rows, cols] = b
            dB[rows, cols] = db
        return B, dB

    def quad_interpolation(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Return (P, P') of shape (len(s), quad_count): f(s) ≈ P f_quad and f'(s) ≈ P' f_quad.

        The interpolant of values at the quadrature nodes on the element holding s (at a
        breakpoint: the one before it), and its s-derivative.
        """
        s = np.atleast_1d(np.asarray(s, dtype=float))
        inside = self.inside_one(s)
        if inside is not None and self.quads is not None and len(self.elements) == 1:
            return self._quad_matrices(0, s)  # (new arrays: all of P and P')
        P, dP = np.zeros((s.size, self.quad_count)), np.zeros((s.size, self.quad_count))
        if inside is not None:  # every point in one element: its rows are all the rows
            P[:, inside[1]], dP[:, inside[1]] = self._quad_matrices(inside[0], s)
            return P, dP
        which = self.element_of(s, "left")
        for e in np.unique(which):
            rows = np.flatnonzero(which == e)
            cols = slice(self.quad_first[e], self.quad_first[e + 1])
            P[rows, cols], dP[rows, cols] = self._quad_matrices(e, s[rows])
        return P, dP

    def _quad_matrices(self, e: int, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return element e's (P, P') at the arc lengths ``s`` on it (``quad_interpolation``)."""
        local = s - self.breakpoints[e]
        if self.quads is None:
            return self.elements[e].matrices(local)
        return self.quads[e].interpolation_matrix(local), self.quads[e].derivative_matrix(local)

    def inside_one(self, s: np.ndarray) -> tuple[int, slice] | None:
        """Return (e, its quadrature columns) when a few ``s`` lie strictly inside element e.

        Up to FEW_POINTS points, checked in Python floats; None otherwise (more points, a point
        on a breakpoint or outside, NaN).  The matrices then hold one block per row.
        """
        if not 0 < s.size <= FEW_POINTS:
            return None
        points = s.tolist()
        bounds = self._bounds
        e = bisect.bisect_right(bounds, points[0]) - 1
        if not 0 <= e < len(self.elements):
            return None
        lo, hi = bounds[e], bounds[e + 1]
        if not all(lo < x < hi for x in points):
            return None
        return e, slice(int(self.quad_first[e]), int(self.quad_first[e + 1]))

    def integration_matrix(self, s) -> np.ndarray:
        """W of shape (len(s), quad_count) with ∫_0^s f ≈ W f_quad."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        inside = self.inside_one(s)
        if inside is not None and self.quads is not None and len(self.elements) == 1:
            return self._integral(0, s - self.breakpoints[0])  # (a new array: all of W)
        W = np.zeros((s.size, self.quad_count))
        if inside is not None:  # the elements before in full, element e's part: every row alike
            e = inside[0]
            for k in range(e):
                W[:, self.quad_first[k] : self.quad_first[k + 1]] = self._quad_weights(k)
            W[:, inside[1]] = self._integral(e, s - self.breakpoints[e])
            return W
        for e in range(len(self.elements)):
            lo, hi = self.breakpoints[e], self.breakpoints[e + 1]
            cols = slice(self.quad_first[e], self.quad_first[e + 1])
            full = s >= hi
            W[full, cols] = self._quad_weights(e)
            part = (s > lo) & (s < hi)
            if np.any(part):
                W[part, cols] = self._integral(e, s[part] - lo)
        return W

    def _quad_weights(self, e: int) -> np.ndarray:
        """Return element e's quadrature weights (its row of W at its end)."""
        return self.elements[e].weights if self.quads is None else self.quads[e].weights

    def _integral(self, e: int, local: np.ndarray) -> np.ndarray:
        """Return element e's rows of W at the local arc lengths ``local`` inside it."""
        if self.quads is None:
            return self.elements[e].integral(local)
        return self.quads[e].integration_matrix(local)


def element_mesh_of(model) -> ElementMesh | None:
    """Return the model's element mesh (``model.mesh``), or None for a model without one."""
    mesh = getattr(model, "mesh", None)
    return mesh if isinstance(mesh, ElementMesh) else None
