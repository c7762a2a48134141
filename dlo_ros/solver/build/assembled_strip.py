"""The assembled KKT functions of a strip: a director frame model with two bending stiffnesses.

``AssembledKKT`` with the per-node energy of ``director.strip_integrands``: φ_k = σ [½ w_k (Rf_k
b_1 + Rl_k b_2) + ½ w_k Rt_k τ + ½ w_k Re_k ε²] + a_k · T, so c_k carries w Rl as a seventh entry
(after ``AssembledKKT``'s six, whose order it keeps).  Everything else (rows, contact, the KKT
assembly) is the director model's, unchanged.
"""

from __future__ import annotations

import functools

import casadi as ca

from ...model.director import strip_integrands
from .assembled import AssembledKKT


class AssembledStripKKT(AssembledKKT):
    """``AssembledKKT`` for a strip (``DirectorModel.lateral``): c_k = (w Rf, w Rt, w Re, a, w Rl).

    The seventh entry w Rl weights b_2 = Ω_3², the bend about d2 (``director.strip_integrands``).
    """

    def __init__(self, nlp) -> None:
        if not getattr(nlp.model, "lateral", False):
            raise TypeError("AssembledStripKKT needs a strip's director model (lateral)")
        super().__init__(nlp)

    def _node_coefficients(self, p, a):
        """``AssembledKKT``'s c_k with w Rl appended."""
        return ca.vertcat(
            super()._node_coefficients(p, a), self.geometry.weights(p) * p[self.nlp.params["Rl"]].T
        )

    @functools.cached_property
    def node_function(self) -> ca.Function:
        """Build the per-node function (``AssembledKKT.node_function``'s outputs), strip energy.

        (u_k, c_k) → [bend_k, twist_k, stretch_k, T_k, ∇φ_k, ∇²φ_k, ∂T/∂u]; c_k = (w Rf, w Rt,
        w Re, a_k, w Rl).
        """
        w, d = self.width, self.d
        u, c = ca.SX.sym("u", d), ca.SX.sym("c", 7)
        b1, b2, tw, tangent = strip_integrands(
            [u[a] for a in range(w)], [u[w + a] for a in range(w)]
        )
        bend = 0.5 * (c[0] * b1 + c[6] * b2)
        twist = 0.5 * c[1] * tw
        return self.density_function(u, c, bend, twist, ca.vertcat(*tangent))
