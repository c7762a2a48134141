"""The assembled KKT functions' node-local rows and the energy terms computed directly from z.

``local_rows_function(kkt, rows)`` builds (z, p, λ_local) → [g_local, ∂g_local/∂z, ∇Λ, ∇²Λ, W_M,
U_direct] for ``AssembledKKT.local_function`` (``kkt``: the AssembledKKT or AssembledEulerKKT,
its NLP, ``direct_terms`` and ``quadratic_terms``), with

    Λ = λ·g_local − σ W_M + σ Σ U_direct.

The rows are the node-local ones (unit norm, grip orientation, folds; an Euler-angle model's angle
rows).  U_direct's parts quadratic in the unknowns, ½ z_sᵀ K z_s, are differentiated by hand:
∇ = K̄ z_s and ∇² = K̄ on the block s × s, K̄ = (K + Kᵀ)/2.  Left to ``ca.hessian``, those n²
products were most of a planar element model's build (the paper's Fig. 3 cold, 1.07 → 0.72 s).
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def local_rows_function(kkt, rows: np.ndarray) -> ca.Function:
    """Build the function of the node-local ``rows`` of ``kkt``'s NLP (module docstring)."""
    nlp = kkt.nlp
    z, p = nlp.z_sym, nlp.p_sym
    g_local = nlp.g_sym[rows.tolist()] if rows.size else ca.SX(0, 1)
    moments, direct = kkt.direct_terms(z, p)
    lam = ca.SX.sym("lam_local", g_local.shape[0])
    quadratic = kkt.quadratic_terms(p)
    lagrangian = ca.dot(lam, g_local) - nlp.sigma * moments
    if not quadratic:
        lagrangian += nlp.sigma * ca.sum1(direct)
    hess, grad = ca.hessian(lagrangian, z)
    for part, stiffness in quadratic:
        idx = list(range(z.shape[0]))[part]
        sym = 0.5 * (stiffness + stiffness.T)
        hess[idx, idx] += nlp.sigma * sym
        grad[idx] += nlp.sigma * ca.mtimes(sym, z[idx])
    return ca.Function(
        "dlo_local_rows",
        [z, p, lam],
        [g_local, ca.jacobian(g_local, z), grad, hess, moments, direct],
    )
