"""An element mesh's topology and its geometry: what stays and what moves when breakpoints move.

An ``ElementMesh`` is fixed by its *topology* (the string's length, the LGL node count n_e of each
element and the quadrature's extra nodes per element) and its *geometry* (the breakpoints
0 = b_0 < … < b_E = L).  On element e, of size h_e = b_{e+1} − b_e, a point is
s = b_e + h_e (τ + 1)/2 with τ ∈ [−1, 1], and every matrix the NLP is built from splits into a
part fixed by the topology and the geometry vectors j_k = 2/h_e and w_k at the quadrature nodes
σ_k (k in element e):

    f(σ_k)      = Σ_i B_ki f_i                     B: values at reference points (no h)
    f'(σ_k)     = j_k Σ_i B̂'_ki f_i                B̂': the reference derivative (d/dτ)
    ∫_0^L f ds  ≈ Σ_k w_k f_k,                      w_k = ŵ_k / j_k
    ∫_0^s f ds  ≈ Σ_k W_k(s) f_k,  W_k(s) = A_k(s) w_k + R_k(s) / j_k

for s a mesh node or a breakpoint: A_k(s) = 1 when σ_k lies in an element that ends at or before
s (0 otherwise), and R_k(s) the reference partial integral ∫_{−1}^{τ(s)} of the element holding
s strictly inside it (0 elsewhere).  Two meshes of one topology share B, B̂', ŵ, A and R
(:class:`ReferenceGeometry`); only (j, w) differ (:func:`geometry_vectors`), so an NLP whose
functions read (j, w) from its parameters serves every breakpoint position of its topology
(``solver/build/assembled.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .elements import ElementMesh


@dataclass(frozen=True)
class MeshTopology:
    """What two meshes must share for one built NLP to serve both: L, n_e and the quadrature."""

    length: float
    counts: tuple[int, ...]
    quadrature: tuple[int, ...]  # quadrature nodes per element

    @classmethod
    def of(cls, mesh: ElementMesh) -> MeshTopology:
        """Return the topology of ``mesh``."""
        return cls(
            float(mesh.length),
            tuple(int(n) for n in mesh.counts),
            tuple(int(n) for n in np.diff(mesh.quad_first)),
        )


def quad_elements(mesh: ElementMesh) -> np.ndarray:
    """Return the element index of each quadrature node (M,)."""
    return np.repeat(np.arange(mesh.element_count), np.diff(mesh.quad_first))


def geometry_vectors(mesh: ElementMesh) -> tuple[np.ndarray, np.ndarray]:
    """Return (j, w) at the quadrature nodes: j_k = 2/h_e [1/m] and the weights w_k [m]."""
    sizes = np.diff(mesh.breakpoints)
    return 2.0 / sizes[quad_elements(mesh)], np.array(mesh.weights, dtype=float)


class ReferenceGeometry:
    """The parts of a mesh's matrices that its topology fixes (module docstring).

    Built from one mesh; :meth:`matches` tells whether another mesh has the same topology, and
    then ``value``, ``rate`` · j and :meth:`integration_rows` with that mesh's (j, w) give its
    matrices.
    """

    def __init__(self, mesh: ElementMesh) -> None:
        self.topology = MeshTopology.of(mesh)
        self._mesh = mesh
        j, w = geometry_vectors(mesh)
        #: B (M × N): nodal values → values at the quadrature nodes
        self.value = np.array(mesh.B, dtype=float)
        #: B̂' (M × N): nodal values → reference derivatives d/dτ at the quadrature nodes
        self.rate = mesh.dB / j[:, None]
        #: ŵ (M,): the reference weights (w = ŵ / j)
        self.reference_weights = w * j

    def matches(self, mesh: ElementMesh) -> bool:
        """Tell whether ``mesh`` has this topology (its matrices follow from its (j, w))."""
        return MeshTopology.of(mesh) == self.topology

    def integration_rows(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (A, R) (len(s) × M) with W(s) = A ∘ w + R ∘ (1/j) on any mesh of the topology.

        ``s`` [m] must be nodes or breakpoints of the mesh this was built from (the points that
        keep their place in the topology: node i of element e stays node i of element e); raise
        ValueError for another point.
        """
        mesh = self._mesh
        s = np.atleast_1d(np.asarray(s, dtype=float))
        tol = 1e-9 * mesh.length
        at_node = np.min(np.abs(s[:, None] - mesh.nodes[None, :]), axis=1, initial=np.inf) <= tol
        at_break = (
            np.min(np.abs(s[:, None] - mesh.breakpoints[None, :]), axis=1, initial=np.inf) <= tol
        )
        if not np.all(at_node | at_break):
            bad = s[~(at_node | at_break)]
            raise ValueError(f"mesh geometry: s = {bad.tolist()} m is no node or breakpoint")
        elements = quad_elements(mesh)
        ends = mesh.breakpoints[1:][elements]  # the end of each quadrature node's element
        starts = mesh.breakpoints[:-1][elements]
        A = (ends[None, :] <= s[:, None] + tol).astype(float)
        inside = (starts[None, :] < s[:, None] - tol) & (s[:, None] + tol < ends[None, :])
        j, _ = geometry_vectors(mesh)
        W = mesh.integration_matrix(s)
        R = np.where(inside, W * j[None, :], 0.0)
        return A, R
