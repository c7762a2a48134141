"""Ritz discretisation of the string energy (Hirai & Wakamatsu, secs. 2–3) as CasADi expressions.

Unknowns z = [x0/L (3), c_φ (n), c_θ (n), c_ψ (n, only if twist is held), c_ε (n, only if
extensible)]: the position of s = 0 scaled by L, and the coefficients of the Euler angles φ(s),
θ(s), ψ(s) and of the strain ε(s) in a basis of n functions.  On M Chebyshev–Lobatto nodes s_j:

    ζ_j   = R0 [−sinθ cosφ, sinθ sinφ, cosθ]_j                       unit tangent (eq. 1)
    x(σ)  = x0 + Σ_j W_j(σ) (1 + ε_j) ζ_j                            centreline (eq. 2)
    U_bend    = Σ_j w_j ½ Rf_j (θ'_j² + sin²θ_j φ'_j²)                 ½ Rf κ²
    U_twist   = Σ_j w_j ½ Rt_j (φ'_j cosθ_j + ψ'_j)²                   ½ Rt ω²
    U_stretch = Σ_j w_j ½ Re_j ε_j²
    U_grav    = Σ_j w_j D_j (−ĝ · x(s_j))                              D × height
(the terms quadratic in the coefficients are assembled once per material as matrices:
``material_terms``)
    W         = Σ_k F_k · x(s_k) − m_k φ(s_k)                          eq. 5, m_k = M_k · n

with Clenshaw–Curtis weights w and the cumulative integration matrix W (see quadrature.py).  With
basis 'elements' (element_basis.py) the coefficients are nodal values on a spectral-element mesh
split at grips, loads and material knots, and s_j, w_j, W are the mesh's composite quadrature (per
element, so B' at a breakpoint is each element's own one-sided derivative).  The
point-moment work −m φ is exact for moments about the reference normal n = R0 e_z (a rotation of
the frame about n by α changes φ by −α).  Material profiles (Rf, Rt, Re, D at the nodes) and the
gravity direction are NLP parameters, so changing them never rebuilds the problem.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .basis import Basis, make_basis
from .centreline import positions_sym, weight_energy_sym
from .element_basis import CompositeQuadrature, ElementBasis
from .elements import ElementMesh
from .memo import ArrayMemo
from .quadrature import ChebyshevQuadrature


@dataclass(frozen=True)
class FieldLayout:
    """Which fields are unknowns, and where their coefficients sit in z."""

    order: int
    twist: bool
    stretch: bool
    planar: bool = False  # θ ≡ π/2: the string stays in the plane normal to n = R0 e_z

    @property
    def size(self) -> int:
        return 3 + self.order * (1 + int(not self.planar) + int(self.twist) + int(self.stretch))

    def slice(self, name: str) -> slice:
        n = self.order
        start = {"phi": 3}
        offset = 3 + n
        if not self.planar:
            start["theta"] = offset
            offset += n
        if self.twist:
            start["psi"] = offset
            offset += n
        if self.stretch:
            start["eps"] = offset
        if name not in start:
            raise KeyError(name)
        return slice(start[name], start[name] + n)


class RitzModel:
    """Maps the unknowns z to fields, positions and energy terms, numerically and symbolically."""

    def __init__(
        self,
        length: float,
        basis: str,
        order: int,
        nodes: int,
        r0: np.ndarray,
        twist: bool,
        stretch: bool,
        planar: bool = False,
        mesh: ElementMesh | None = None,
    ):
        """Build the model; basis 'elements' needs ``mesh`` (and ignores order and nodes)."""
        self.length = float(length)
        self.r0 = np.asarray(r0, dtype=float)
        if planar and twist:
            raise ValueError("a planar model has no twist field")
        self._memo: ArrayMemo[tuple[np.ndarray, np.ndarray, np.ndarray]] = ArrayMemo()
        #: the element mesh of basis 'elements' (None for a single-interval basis)
        self.mesh = mesh if basis == "elements" else None
        self.basis: Basis
        self.quad: ChebyshevQuadrature | CompositeQuadrature
        if basis == "elements":
            if mesh is None:
                raise ValueError("solver.basis: 'elements' needs the element mesh")
            self.basis, self.quad = ElementBasis(mesh), CompositeQuadrature(mesh)
            # each element's own rows: a breakpoint's two quadrature nodes take one-sided B'
            self.B, self.dB = mesh.B, mesh.dB  # (M, n)
        else:
            self.basis = make_basis(basis, order, length)
            self.quad = ChebyshevQuadrature(nodes, length)
            self.B = self.basis.values(self.quad.nodes)  # (M, n)
            self.dB = self.basis.derivatives(self.quad.nodes)  # (M, n)
        self.layout = FieldLayout(self.basis.size, twist, stretch, planar)

    # ---- fields ---------------------------------------------------------------------------------
    def coefficients(self, z, name: str):
        """Coefficient vector of field ``name``, or None when the field is not an unknown."""
        try:
            return z[self.layout.slice(name)]
        except KeyError:
            return None

    def tangents(self, phi, theta, eps=None, lib=ca):
        """(1 + ε) ζ at the nodes: a 3×M expression (lib = casadi) or array (lib = numpy).

        A planar model has θ ≡ π/2 exactly: ζ = R0 [−cos φ, sin φ, 0], two columns of R0, so the
        tangent has no out-of-plane part (cos(π/2) in floating point is 6e-17).  It saves little
        work: CasADi already simplifies sin θ = 1 in the general formula (0.3 % of the planar KKT
        instructions).
        """
        if self.layout.planar:
            local, r0 = [-lib.cos(phi), lib.sin(phi)], self.r0[:, :2]
        else:
            st = lib.sin(theta)
            local, r0 = [-st * lib.cos(phi), st * lib.sin(phi), lib.cos(theta)], self.r0
        if lib is ca:
            t = ca.mtimes(ca.DM(r0), ca.vertcat(*[ca.reshape(c, 1, -1) for c in local]))
            if eps is not None:
                t = t * ca.repmat(ca.reshape(1 + eps, 1, -1), 3, 1)
            return t
        t = r0 @ np.stack(local)
        return t if eps is None else t * (1 + eps)[None, :]

    def matrices(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (B(s), B'(s), W(s)) for arc lengths s, memoised (``memo.ArrayMemo``)."""
        return self._memo.get(
            "matrices",
            s,
            lambda s: (*self.basis.values_and_derivatives(s), self.quad.integration_matrix(s)),
        )

    def position_matrix(self, s: np.ndarray) -> np.ndarray:
        """W(s) with x(s) = x0 + tangents · W(s)ᵀ."""
        return self.matrices(s)[2]

    # ---- symbolic energy ------------------------------------------------------------------------
    @functools.cached_property
    def stiffness_pattern(self) -> sp.csc_matrix:
        """The structural pattern (n × n, CSC) of every K_* = B'ᵀ diag(w R) B' or Bᵀ diag(w R) B.

        Dense for a single-interval basis; block-banded for elements (B, B' are local to each
        element), so p holds O(n) stiffness entries instead of n² (a 640-node mesh: 0.4 M).
        """
        b, db = sp.csc_matrix(np.abs(self.B)), sp.csc_matrix(np.abs(self.dB))
        pattern = sp.csc_matrix(b.T @ b + db.T @ db)
        pattern.sort_indices()
        return pattern

    def stiffness_sym(self, values: ca.SX) -> ca.SX:
        """K_* from its nonzeros in p (column-major on ``stiffness_pattern``)."""
        k = self.stiffness_pattern
        n = k.shape[0]
        return ca.SX(ca.Sparsity(n, n, k.indptr.tolist(), k.indices.tolist()), values)

    def material_sizes(self) -> dict[str, int]:
        """Sizes of the parameter-only parts of the energy (``material_terms``), by name."""
        nnz, M = self.stiffness_pattern.nnz, self.quad.count
        sizes = {"K_bend": nnz}
        if self.layout.twist:
            sizes["K_twist"] = nnz
        if self.layout.stretch:
            sizes["K_stretch"] = nnz
        sizes["weight_moments"] = M
        sizes["weight_total"] = 1
        return sizes

    def material_terms(self, profiles: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Return the parts of the energy that depend on the material alone.

        Assembled once per string (numpy); each K_* as its nonzeros on ``stiffness_pattern``::

            K_bend    = B'ᵀ diag(w Rf) B'     ½ ∫ Rf θ'² ds = ½ c_θᵀ K_bend c_θ  (planar: c_φ)
            K_twist   = B'ᵀ diag(w Rt) B'     the ψ'² part of ½ ∫ Rt ω² ds
            K_stretch = Bᵀ diag(w Re) B       ½ ∫ Re ε² ds
            m         = W(s_nodes)ᵀ (w ∘ D)   Σ_j w_j D_j x(s_j) = x0 ΣwD + Σ_k m_k t_k
            ΣwD                               the weight [N]

        Each is the same quadrature as the symbolic sum it replaces (so the energy is unchanged to
        rounding), but its Hessian costs nothing per evaluation instead of M·n² operations.
        """
        w, pattern = self.quad.weights, self.stiffness_pattern
        rows, cols = (
            pattern.indices,
            np.repeat(np.arange(pattern.shape[1]), np.diff(pattern.indptr)),
        )

        def packed(basis: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
            # the nonzeros of Bᵀ diag(w R) B on the pattern, column-major (stiffness_sym's order)
            return (basis.T @ ((w * stiffness)[:, None] * basis))[rows, cols]

        out = {"K_bend": packed(self.dB, profiles["Rf"])}
        if self.layout.twist:
            out["K_twist"] = packed(self.dB, profiles["Rt"])
        if self.layout.stretch:
            out["K_stretch"] = packed(self.B, profiles["Re"])
        wd = w * profiles["D"]
        out["weight_moments"] = self.position_matrix(self.quad.nodes).T @ wd
        out["weight_total"] = np.array([wd.sum()])
        return out

    def energy_terms(self, z: ca.SX, profiles: dict[str, ca.SX], gravity: ca.SX):
        """Return (bend, twist, stretch, gravity) energies [J] and the node tangents, as CasADi SX.

        ``profiles``: Rf, Rt (3D) at the nodes and the ``material_terms`` (K_* as their nonzeros
        on ``stiffness_pattern``), all NLP parameters.
        """
        dB, w = ca.DM(self.dB), ca.DM(self.quad.weights)
        cphi, cth = self.coefficients(z, "phi"), self.coefficients(z, "theta")
        cpsi, ceps = self.coefficients(z, "psi"), self.coefficients(z, "eps")

        def quadratic(name: str, c: ca.SX) -> ca.SX:
            return 0.5 * ca.dot(c, ca.mtimes(self.stiffness_sym(profiles[name]), c))

        phi, dphi = ca.mtimes(ca.DM(self.B), cphi), ca.mtimes(dB, cphi)
        if cth is None:  # planar: θ ≡ π/2, so κ² = φ'²
            th = ca.DM.ones(self.quad.count) * (np.pi / 2)
            bend = quadratic("K_bend", cphi)
        else:
            th = ca.mtimes(ca.DM(self.B), cth)
            st = ca.sin(th)
            bend = quadratic("K_bend", cth) + 0.5 * ca.dot(w, profiles["Rf"] * st**2 * dphi**2)
        if cpsi is not None:  # ½ Rt (φ' cosθ + ψ')² = ½ Rt (φ' cosθ)² + Rt φ' cosθ ψ' + ½ Rt ψ'²
            a = dphi * ca.cos(th)
            twist = ca.dot(w, profiles["Rt"] * a * (0.5 * a + ca.mtimes(dB, cpsi))) + quadratic(
                "K_twist", cpsi
            )
        else:
            twist = ca.SX(0)
        eps = ca.mtimes(ca.DM(self.B), ceps) if ceps is not None else None
        stretch = quadratic("K_stretch", ceps) if ceps is not None else ca.SX(0)
        t = self.tangents(phi, th, eps)
        grav = weight_energy_sym(
            z[0:3] * self.length, t, profiles["weight_total"], profiles["weight_moments"], gravity
        )
        return bend, twist, stretch, grav, t

    def positions_sym(self, z: ca.SX, t: ca.SX, s: np.ndarray) -> ca.SX:
        """Centreline positions at arc lengths s as a 3×len(s) SX expression."""
        return positions_sym(z[0:3] * self.length, t, self.position_matrix(s))

    def angle_sym(self, z: ca.SX, name: str, s: float) -> ca.SX:
        c = self.coefficients(z, name)
        if c is None:
            raise KeyError(f"{name} is not an unknown of this model")
        return ca.mtimes(ca.DM(self.basis.values(np.array([s]))), c)

    # ---- numerical evaluation of a solution -----------------------------------------------------
    def fields(
        self, z: np.ndarray, s: np.ndarray, names: tuple[str, ...] = ("phi", "theta", "psi", "eps")
    ) -> dict[str, np.ndarray]:
        """φ, θ, ψ, ε (or only ``names``) and their s-derivatives at arc lengths s.

        Fields that are not unknowns are constants: θ = π/2 in a planar model, ψ = ε = 0.  With
        basis 'elements' the derivative at a breakpoint is the left element's (one-sided).
        """
        B, dB, _ = self.matrices(s)
        out = {}
        for name in names:
            c = self.coefficients(z, name)
            constant = np.pi / 2 if name == "theta" else 0.0
            out[name] = B @ c if c is not None else np.full(len(s), constant)
            out["d" + name] = dB @ c if c is not None else np.zeros(len(s))
        return out

    def node_fields(
        self, z: np.ndarray, names: tuple[str, ...] = ("phi", "theta", "psi", "eps")
    ) -> dict[str, np.ndarray]:
        """Return ``fields`` at the quadrature nodes, with each element's own B' there.

        ``fields(z, quad.nodes)`` would take one side's derivative at both copies of a
        breakpoint (basis 'elements').
        """
        out = {}
        for name in names:
            c = self.coefficients(z, name)
            constant = np.pi / 2 if name == "theta" else 0.0
            out[name] = self.B @ c if c is not None else np.full(self.quad.count, constant)
            out["d" + name] = self.dB @ c if c is not None else np.zeros(self.quad.count)
        return out

    def node_tangents(self, z: np.ndarray) -> np.ndarray:
        """(1 + ε) ζ at the quadrature nodes, (3, M)."""
        f = self.node_fields(z, ("phi", "theta", "eps"))
        eps = f["eps"] if self.layout.stretch else None
        return self.tangents(f["phi"], f["theta"], eps, lib=np)

    def positions(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(len(s), 3) centreline positions [m]."""
        return self.positions_at_rows(z, self.position_matrix(s))

    def position_rows(self, s: np.ndarray) -> np.ndarray:
        """Return W(s) as ``position_matrix`` does, not remembered (s changes every solve)."""
        return self.quad.integration_matrix(np.asarray(s, dtype=float))

    def tangent_rows(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (P, P') with x'(s) = T Pᵀ and x''(s) = T P'ᵀ (T: ``node_tangents``)."""
        s = np.asarray(s, dtype=float)
        return self.quad.interpolation_matrix(s), self.quad.derivative_matrix(s)

    def positions_at_rows(self, z: np.ndarray, w: np.ndarray) -> np.ndarray:
        """(len(w), 3) centreline positions [m] at the arc lengths whose rows of W are ``w``."""
        return (np.asarray(z[0:3]) * self.length)[None, :] + w @ self.node_tangents(z).T

    def zero_twist_psi(
        self, z: np.ndarray, s: np.ndarray, s_anchor: float, psi_anchor: float
    ) -> np.ndarray:
        """Return ψ(s) with no twist rate: the twist a free string settles to.

        ψ(s) with ω ≡ 0 (ψ' = −φ' cosθ), ψ(s_anchor) = ψ_anchor: the twist a free string settles
        to.
        """
        f = self.node_fields(z, ("phi", "theta"))
        g = -f["dphi"] * np.cos(f["theta"])
        W = self.position_matrix(np.append(np.asarray(s, dtype=float), s_anchor))
        integral = W @ g
        return psi_anchor + integral[:-1] - integral[-1]
