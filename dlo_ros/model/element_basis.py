"""The Ritz basis 'elements': a field's nodal values on a spectral-element mesh.

A field f(s) of the Euler-angle models (φ, θ, ψ, ε) is the piecewise polynomial through its values
at the global LGL nodes of an :class:`~.elements.ElementMesh` (continuous, with a derivative that
may jump at every breakpoint: a grip, a point load, a material knot).  Its "coefficients" are those
nodal values, so ``values(s)`` and ``derivatives(s)`` are the mesh's interpolation matrices.

At a breakpoint the derivative is one-sided: ``derivatives`` takes the element on ``side``
('left' by default, as ``ElementMesh.interpolation``).  Integrals must use the mesh's composite
quadrature (:class:`CompositeQuadrature`), whose nodes list a breakpoint once per element it
ends; there B' is each element's own (``ElementMesh.dB``), which a single global rule cannot
represent (it would integrate across the derivative's jump and lose spectral accuracy).
"""

from __future__ import annotations

import numpy as np

from .elements import ElementMesh


class ElementBasis:
    """Nodal values on ``mesh``: b_k(s) is the k-th global node's cardinal function."""

    name = "elements"

    def __init__(self, mesh: ElementMesh) -> None:
        self.mesh = mesh
        self.size = int(mesh.count)
        self.length = float(mesh.length)

    def values(self, s: np.ndarray) -> np.ndarray:
        """B[i, k] = b_k(s_i), shape (len(s), size)."""
        return self.mesh.interpolation(s)[0]

    def derivatives(self, s: np.ndarray, side: str = "left") -> np.ndarray:
        """B'[i, k] = db_k/ds (s_i) [1/m]; at a breakpoint the element on ``side``'s."""
        return self.mesh.interpolation(s, side)[1]

    def values_and_derivatives(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, B') at s (the left element's B' at a breakpoint): one interpolation for both."""
        return self.mesh.interpolation(s)


class CompositeQuadrature:
    """The mesh's composite quadrature under ``ChebyshevQuadrature``'s names.

    ``nodes`` (each element's, a breakpoint once per element), ``weights``, ``count``,
    ``integration_matrix(s)`` (∫_0^s f ds ≈ W(s) f at the nodes, element by element) and the
    interpolant's ``interpolation_matrix(s)`` and ``derivative_matrix(s)``.
    """

    def __init__(self, mesh: ElementMesh) -> None:
        self.mesh = mesh
        self.length = float(mesh.length)
        self.nodes = mesh.quad_nodes
        self.weights = mesh.weights
        self.count = int(mesh.quad_count)

    def integration_matrix(self, s: np.ndarray) -> np.ndarray:
        """W[q, j] with ∫_0^{s_q} f ds ≈ Σ_j W[q, j] f(σ_j), shape (len(s), count)."""
        return self.mesh.integration_matrix(np.asarray(s, dtype=float).ravel())

    def interpolation_matrix(self, s: np.ndarray) -> np.ndarray:
        """P[q, j] with f(s_q) ≈ Σ_j P[q, j] f(σ_j): the interpolant on the element holding s_q."""
        return self.mesh.quad_interpolation(np.asarray(s, dtype=float).ravel())[0]

    def derivative_matrix(self, s: np.ndarray) -> np.ndarray:
        """P'[q, j] with f'(s_q) ≈ Σ_j P'[q, j] f(σ_j) [1/m]: the interpolant's derivative."""
        return self.mesh.quad_interpolation(np.asarray(s, dtype=float).ravel())[1]
