"""The element mesh's geometry read from p by the assembled KKT functions (director models).

A director model's p carries "mesh:j" and "mesh:w": j_k = 2/h_e and the weight w_k at every
quadrature node (``model/mesh_geometry.py``; filled with the material terms,
``DirectorModel.material_terms``).  The assembled KKT functions (``assembled.py``,
``assembled_contact.py``) take every geometric factor from them:

* the node map E = E_value + diag(J) E_rate (J: j_k on each of node k's d rows), u_k = E_k z;
* the weights of the per-node energies, w_k;
* the integration rows at the grips, the loads, the relative positions' ends and the obstacles'
  node rows, W = A ∘ w + R ∘ (1/j) (A, R fixed by the topology).

So one built function serves every mesh of its topology (the same node counts per element):
evaluated with another mesh's p, it is that mesh's function (``test_mesh_parameters.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from ...model.mesh_geometry import ReferenceGeometry
from .assembled_contact import sparse

#: p's slices of the geometry vectors
J_NAME, W_NAME = "mesh:j", "mesh:w"


def node_map_of(layout, d: int, values: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Return a director model's node map (d·M × n) from per-quadrature-node rows (M × N).

    Row d k + a of E z is component a of u_k = (v(σ_k), v'(σ_k), ε(σ_k)): ``values`` places the
    rotation field's and ε's values, ``rates`` its derivatives (the mesh's B and B' give
    ``AssembledKKT``'s E; the reference geometry's B and B̂' its two parts here).
    """
    M, width = values.shape[0], layout.width
    E = np.zeros((d * M, layout.size))
    cols = 3 + width * np.arange(layout.nodes)
    for k in range(M):
        for a in range(width):
            E[d * k + a, cols + a] = values[k]
            E[d * k + width + a, cols + a] = rates[k]
        if layout.stretch:
            E[d * k + 2 * width, layout.eps] = values[k]
    return E


class MeshParameters:
    """The geometric factors of one assembled KKT builder as expressions of p (module doc)."""

    def __init__(self, kkt) -> None:
        """Split ``kkt``'s node map by its model's mesh (``kkt``: an ``AssembledKKT``)."""
        model, lay = kkt.model, kkt.nlp.params
        self.reference = ReferenceGeometry(model.mesh)
        self.d, self.M = kkt.d, kkt.M
        self._j, self._w = lay[J_NAME], lay[W_NAME]
        ref, zero = self.reference, np.zeros_like(self.reference.value)
        self._value = sparse(node_map_of(model.layout, kkt.d, ref.value, zero))
        self._rate = sparse(node_map_of(model.layout, kkt.d, zero, ref.rate))

    def j(self, p) -> ca.MX:
        """Return the vector j = 2/h of the quadrature nodes (M × 1) from p."""
        return p[self._j]

    def w(self, p) -> ca.MX:
        """Return the quadrature weights (M × 1) from p."""
        return p[self._w]

    def node_map(self, p) -> ca.MX:
        """Return E (d·M × n) at p's geometry: E_value + diag(J) E_rate."""
        return self._value + scaled(self._rate, self.j(p), rows=True, width=self.d)

    def _rows_j(self, p) -> ca.MX:
        """Return J (d·M × 1): j_k on each of node k's d rows."""
        return ca.vec(ca.repmat(self.j(p).T, self.d, 1))

    def apply(self, p, z) -> ca.MX:
        """Return E z at p's geometry without forming E: E_value z + J ∘ (E_rate z)."""
        return ca.mtimes(self._value, z) + self._rows_j(p) * ca.mtimes(self._rate, z)

    def apply_transpose(self, p, v) -> ca.MX:
        """Return Eᵀ v at p's geometry without forming E: E_valueᵀ v + E_rateᵀ (J ∘ v)."""
        return ca.mtimes(self._value.T, v) + ca.mtimes(self._rate.T, self._rows_j(p) * v)

    def integration_rows(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (A, R) of W at ``s`` [m] (``ReferenceGeometry.integration_rows``)."""
        return self.reference.integration_rows(s)

    def rows(self, p, A: np.ndarray, R: np.ndarray) -> ca.MX:
        """Return W = A ∘ w + R ∘ (1/j) (rows × M) at p's geometry."""
        out = ca.MX(A.shape[0], self.M)
        if np.any(A):
            out += scaled(A, self.w(p))
        if np.any(R):
            out += scaled(R, 1 / self.j(p))
        return out


def scaled(matrix, factors: ca.MX, rows: bool = False, width: int = 1) -> ca.MX:
    """Return ``matrix`` (numpy, or a CasADi DM) with its columns scaled by ``factors``.

    ``rows``: its rows instead, factor k on rows width·k … width·k + width − 1.  Written on the
    matrix's non-zeros (one product each: a product with diag(factors) or a repeated row was a
    general sparse product or a dense matrix per call).
    """
    dm = matrix if isinstance(matrix, ca.DM) else sparse(matrix)
    sp = dm.sparsity()
    cols, rows_of = sp.get_col(), sp.row()
    index = [r // width for r in rows_of] if rows else cols
    values = ca.DM(dm.nonzeros()) * factors[index]
    return ca.sparsity_cast(values, sp)


class KktGeometry:
    """The geometric factors an assembled KKT builder writes its functions with.

    Read from p (:class:`MeshParameters`) when p holds the mesh's geometry, else the built
    model's constants (the Euler-angle models).  ``kkt``: an ``AssembledKKT`` (its node map
    ``E``, model and NLP).
    """

    def __init__(self, kkt) -> None:
        """Return the factors of ``kkt``'s model (from p when its layout has "mesh:j")."""
        self.kkt = kkt
        self.params = MeshParameters(kkt) if J_NAME in kkt.nlp.params.slices else None
        self._rows: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def node_map(self, p) -> ca.DM | ca.MX:
        """Return the node map E (d·M × n)."""
        return sparse(self.kkt.E) if self.params is None else self.params.node_map(p)

    def apply(self, p, z, E: ca.DM | ca.MX | None = None) -> ca.MX:
        """Return E z (the per-node values u); ``E``: the node map already at hand, if any.

        From p's geometry without forming E (a residual needs E z and Eᵀ v alone).
        """
        if self.params is None:
            return ca.mtimes(sparse(self.kkt.E) if E is None else E, z)
        return self.params.apply(p, z)

    def apply_transpose(self, p, v, E: ca.DM | ca.MX | None = None) -> ca.MX:
        """Return Eᵀ v (a per-node gradient's part of ∇L), as :meth:`apply`."""
        if self.params is None:
            return ca.mtimes((sparse(self.kkt.E) if E is None else E).T, v)
        return self.params.apply_transpose(p, v)

    def weights(self, p) -> ca.DM | ca.MX:
        """Return the quadrature weights w (1 × M)."""
        if self.params is None:
            return ca.DM(self.kkt.model.quad.weights).T
        return self.params.w(p).T

    def rows(self, p, points: Sequence[tuple[float, ...]]) -> ca.DM | ca.MX:
        """Return a row of W per entry of ``points`` (len × M).

        W(s) for an entry (s,), W(s_b) − W(s_a) for (s_a, s_b) (a relative position's ends).
        """
        key = tuple(points)
        if key not in self._rows:  # (W, 0) of the built model, or (A, R) of the topology
            A, R = np.zeros((len(points), self.kkt.M)), np.zeros((len(points), self.kkt.M))
            for r, s in enumerate(points):
                at = np.array(s, dtype=float)
                if self.params is None:
                    a, rr = self.kkt.model.position_matrix(at), np.zeros((len(s), self.kkt.M))
                else:
                    a, rr = self.params.integration_rows(at)
                A[r], R[r] = (a[0], rr[0]) if len(s) == 1 else (a[1] - a[0], rr[1] - rr[0])
            self._rows[key] = (A, R)
        if self.params is None:
            return ca.DM(self._rows[key][0])
        return self.params.rows(p, *self._rows[key])

    def obstacle_rows(self, p) -> ca.DM | ca.MX:
        """Return W at the obstacle rows' arc lengths (S × M).

        Rows on the mesh's nodes follow p's geometry; rows on uniform samples (other points of
        other elements on another mesh) are the built mesh's constants.
        """
        nlp = self.kkt.nlp
        if self.params is not None and nlp.options.obstacle_points == "nodes":
            return self.params.rows(p, *self.params.integration_rows(nlp.obstacle_s))
        return ca.DM(self.kkt.model.position_matrix(nlp.obstacle_s))
