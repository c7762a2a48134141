"""The centreline from tangents at quadrature nodes, shared by every discretisation (CasADi SX).

    x(s) = x0 + Σ_j W_j(s) t_j                    (W: cumulative integration matrix of the
    quadrature) U_grav = −ĝ · Σ_j w_j D_j x(σ_j) = −ĝ · (x0 ΣwD + Σ_k m_k t_k),   m = W(σ)ᵀ (w ∘ D)

with t_j = (1 + ε_j) t̂_j the stretched tangents (3×M) and ΣwD, m assembled once per material.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def positions_sym(x0: ca.SX, t: ca.SX, w: np.ndarray) -> ca.SX:
    """Return the positions x at the arc lengths of an integration matrix, symbolically.

    x at the arc lengths whose integration matrix is ``w`` (len(s) × M): a 3×len(s)
    expression.
    """
    return ca.repmat(x0, 1, w.shape[0]) + ca.mtimes(t, ca.DM(w).T)


def weight_energy_sym(
    x0: ca.SX, t: ca.SX, weight_total: ca.SX, weight_moments: ca.SX, gravity: ca.SX
) -> ca.SX:
    """Return the gravitational energy U_grav [J] symbolically.

    U_grav [J] from the material's ΣwD and moments m (NLP parameters) and the unit gravity
    direction.
    """
    return -ca.dot(gravity, x0 * weight_total + ca.mtimes(t, weight_moments))
