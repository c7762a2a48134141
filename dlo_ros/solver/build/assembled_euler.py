"""The KKT functions of the Euler-angle models, assembled from per-node derivatives.

The KKT functions of the Euler-angle models (planar and 3D), assembled from per-quadrature-node
derivatives.

The same construction as ``assembled.py`` (read its docstring first) for a ``RitzModel``, whose
unknowns are x0/L and the basis coefficients of φ, θ, ψ, ε.  At Chebyshev node s_k the per-node
unknowns are

    u_k = E_k z = (φ_k)                                   planar model (θ ≡ π/2)
                = (φ_k, θ_k, φ'_k [, ψ'_k])               3D model [ψ' only when twist is held]
    followed by ε_k when the string stretches,

each a row of B = B(s_k) or B' = B'(s_k) times that field's coefficients (one row block of the
constant sparse E).  The Lagrangian splits as

    L(z, λ) = Σ_k φ_k(u_k) + ℓ(z, λ) + Λ(z, λ)

* φ_k = σ [½ w_k Rf_k sin²θ_k φ'_k² + w_k Rt_k a_k (½ a_k + ψ'_k)] + a_k · T(u_k),  a_k = φ'_k cos
  θ_k,
  T = (1 + ε) R0 [−sinθ cosφ, sinθ sinφ, cosθ]  (planar: T = (1 + ε) R0 [−cosφ, sinφ, 0], no
  curvature term per node), with a_k ∈ R³ the terms linear in the positions as in ``assembled.py``
  (gravity, point forces, position rows);
* ℓ: those terms' part in x0 (linear in z);
* Λ = λ·g_local − σ W_M + σ (½ c_bᵀ K_bend c_b + ½ c_ψᵀ K_twist c_ψ + ½ c_εᵀ K_stretch c_ε): the
  angle
  rows of the grips (linear in z), the point moments' work W_M = −Σ m_i φ(s_i) (linear), and the
  energy parts quadratic in the coefficients with the material matrices K of the NLP's parameters
  (c_b = c_θ, or c_φ in the planar model), differentiated directly as a small SX expression.

Obstacle rows are handled by ``assembled_contact.nonlinear_rows`` unchanged
(X_j = x0 + Σ_k W_jk T_k); an Euler-angle model has no self-contact slots, unit-norm or fold rows.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from ...model.ritz import RitzModel
from .assembled import AssembledKKT
from .mesh_parameters import KktGeometry


class AssembledEulerKKT(AssembledKKT):
    """``AssembledKKT`` for a ``StringNLP`` whose model is a ``RitzModel``.

    ``AssembledKKT`` for a ``StringNLP`` whose model is a ``RitzModel`` (see the module
    docstring).
    """

    def __init__(self, nlp) -> None:  # noqa: D107 (the parent's constructor is director-only)
        model = nlp.model
        if not isinstance(model, RitzModel):
            raise TypeError("the assembled Euler-angle KKT function needs a RitzModel")
        self.nlp, self.model = nlp, model
        self._local_functions: dict[bytes, ca.Function] = {}  # local_function's, by rows
        lay = model.layout
        self.planar, self.twist, self.stretch = lay.planar, lay.twist, lay.stretch
        # (field, derivative?) of each component of u_k
        parts = [("phi", False)]
        if not lay.planar:
            parts += [("theta", False), ("phi", True)] + ([("psi", True)] if lay.twist else [])
        if lay.stretch:
            parts.append(("eps", False))
        self.parts = parts
        self.d = len(parts)
        self.M = model.quad.count
        self.n = lay.size
        self.E = self._node_map()
        self.geometry = KktGeometry(self)  # the built model's constants (no mesh in p)
        self._rows()

    def _node_map(self) -> np.ndarray:
        """Return E (d·M × n): row j + d k of E z is component j of u_k.

        E (d·M × n): row j + d k of E z is component j of u_k (B or B' times a field's
        coefficients).
        """
        model, d = self.model, self.d
        E = np.zeros((d * self.M, self.n))
        for j, (name, derivative) in enumerate(self.parts):
            E[j::d, model.layout.slice(name)] = model.dB if derivative else model.B
        return E

    def _node_coefficients(self, p, a):
        """c_k: a_k (planar), or (w Rf, w Rt, a_k) (3D)."""
        if self.planar:
            return a
        lay, weights = self.nlp.params, ca.DM(self.model.quad.weights).T
        return ca.vertcat(weights * p[lay["Rf"]].T, weights * p[lay["Rt"]].T, a)

    def _tangent(self, u: ca.SX) -> ca.SX:
        """T(u_k) = (1 + ε_k) ζ_k, as ``RitzModel.tangents``."""
        phi = u[0]
        if self.planar:
            t = ca.mtimes(ca.DM(self.model.r0[:, :2]), ca.vertcat(-ca.cos(phi), ca.sin(phi)))
        else:
            st = ca.sin(u[1])
            t = ca.mtimes(
                ca.DM(self.model.r0), ca.vertcat(-st * ca.cos(phi), st * ca.sin(phi), ca.cos(u[1]))
            )
        return (1 + u[self.d - 1]) * t if self.stretch else t

    @functools.cached_property
    def node_function(self) -> ca.Function:
        """Build the per-node function of an Euler-angle model.

        (u_k, c_k) → [bend_k, twist_k, 0, T_k, ∇φ_k, ∇²φ_k, ∂T/∂u]: the per-node parts of the
        energies (none in the planar model: its bend energy is quadratic) and φ_k's derivatives.
        """
        u = ca.SX.sym("u", self.d)
        t = self._tangent(u)
        if self.planar:
            c = ca.SX.sym("c", 3)
            bend = twist = ca.SX.zeros(1, 1)
            phi = ca.dot(c, t)
        else:
            c = ca.SX.sym("c", 5)
            theta, dphi = u[1], u[2]
            bend = 0.5 * c[0] * ca.sin(theta) ** 2 * dphi**2
            if self.twist:
                a = dphi * ca.cos(theta)
                twist = c[1] * a * (0.5 * a + u[3])
            else:
                twist = ca.SX.zeros(1, 1)
            phi = self.nlp.sigma * (bend + twist) + ca.dot(c[2:5], t)
        hess, grad = ca.hessian(phi, u)
        return ca.Function(
            "dlo_node_density",
            [u, c],
            [
                bend,
                twist,
                ca.SX.zeros(1, 1),
                t,
                grad,
                ca.densify(hess),
                ca.densify(ca.jacobian(t, u)),
            ],
        )

    @functools.cached_property
    def tangent_function(self) -> ca.Function:
        """u_k → T_k (the first pass, for rows nonlinear in the positions)."""
        u = ca.SX.sym("u", self.d)
        return ca.Function("dlo_node_tangent", [u], [self._tangent(u)])

    def direct_terms(self, z: ca.SX, p: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Return the point moments' work and the energy parts quadratic in the coefficients.

        (W_M, (½ c_bᵀ K_bend c_b, ½ c_ψᵀ K_twist c_ψ, ½ c_εᵀ K_stretch c_ε)): the point moments'
        work W_M = −Σ m_i φ(s_i) and the energy parts quadratic in the coefficients
        (``RitzModel.energy_terms``).
        """
        nlp, model, lay = self.nlp, self.model, self.nlp.params
        moments = ca.SX(0)
        for i, ld in enumerate(nlp.problem.loads):
            moments -= p[lay[f"load:{i}:moment"]][0] * model.angle_sym(z, "phi", ld.s)
        parts = dict(self._quadratic_parts(p))
        energies = []
        for name in ("K_bend", "K_twist", "K_stretch"):
            if name in parts:
                part, stiffness = parts[name]
                energies.append(0.5 * ca.dot(z[part], ca.mtimes(stiffness, z[part])))
            else:
                energies.append(ca.SX(0))
        return moments, ca.vertcat(*energies)

    def _quadratic_parts(self, p: ca.SX) -> list[tuple[str, tuple[slice, ca.SX]]]:
        """Return (name, (s, K)) of the bend, twist and stretch parts present (K from p)."""
        lay = self.nlp.params
        fields = (("K_bend", "phi" if self.planar else "theta"), ("K_twist", "psi"))
        found = []
        for name, field in fields + (("K_stretch", "eps"),):
            try:
                part = self.model.layout.slice(field)
            except KeyError:
                continue
            found.append((name, (part, self.model.stiffness_sym(p[lay[name]]))))
        return found

    def quadratic_terms(self, p: ca.SX) -> list[tuple[slice, ca.SX]]:
        """Return (s, K) of the bend, twist and stretch parts: all of U_direct here.

        Differentiated by hand in ``assembled_local.local_rows_function``.
        """
        return [term for _, term in self._quadratic_parts(p)]
