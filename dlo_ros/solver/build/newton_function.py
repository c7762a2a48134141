"""The contact-free warm update's first Newton steps as one MX function (``StringNLP.newton_fn``).

Built on first use (a cold refinement's passes on contact never take a contact-free step), around
the interpreted contact-free KKT function or, once compiled, around its library loaded with
``casadi.external`` (``functions.NlpFunctions``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from ..native.settings import NEWTON_REGULARISATION, NEWTON_STEPS

if TYPE_CHECKING:
    from .nlp import StringNLP


def newton_function(nlp: StringNLP, kkt_free: ca.Function | None = None) -> ca.Function:
    """Build ``nlp``'s contact-free warm update as one MX function around ``kkt_free``.

    ``kkt_free``: default ``kkt_free_fn``; the compiled one loaded with ``casadi.external`` has
    the same inputs and outputs.  Inputs u = [z; λ_free], p, and the Newton system (K0, r0) at
    u for the new targets.  It takes NEWTON_STEPS steps u ← u − K⁻¹ r (the first with K0, r0:
    for new grip targets the start's own K and a shifted r, so it costs no evaluation; then one
    evaluation per step) and evaluates the system once more at the end.  Outputs: u, K, r, ∇f
    and the energies at that u, and max |Δz| over the steps (the caller rejects a step > 0.5
    and checks r for convergence).  The steps use LAPACK's LU ('lapacklu'), which CasADi cannot
    generate C for, so this function stays interpreted (a thin MX layer); CasADi's own QR,
    which it can generate, costs more per solve than the LU.
    """
    kkt_free = kkt_free or nlp.kkt_free_fn
    n, nf, n_p = nlp.z_sym.shape[0], nlp.n_free_rows, nlp.p_sym.shape[0]
    u0, pp = ca.MX.sym("u", n + nf), ca.MX.sym("p", n_p)
    k0, r0 = ca.MX.sym("K0", n + nf, n + nf), ca.MX.sym("r0", n + nf)
    u, kkt, residual, largest = u0, k0, r0, ca.MX(0)
    # kkt.regularised: K + diag(δ I, −δ_λ I) bounds the step along a symmetry of the scene
    primal = ca.DM(np.concatenate([np.ones(n), np.zeros(nf)]))
    for _ in range(NEWTON_STEPS):
        delta = NEWTON_REGULARISATION * ca.fmax(ca.mmax(ca.fabs(kkt)), 1.0)
        j_max = ca.mmax(ca.fabs(kkt[n:, :n])) if nf else ca.MX(0)
        h_max = ca.fmax(ca.mmax(ca.fabs(kkt[:n, :n])), 1.0)
        delta_rows = NEWTON_REGULARISATION * j_max * j_max / h_max
        shift = delta * primal - delta_rows * (1 - primal)
        step = ca.solve(kkt + ca.diag(shift), residual, "lapacklu")
        largest = ca.fmax(largest, ca.norm_inf(step[:n]))
        u = u - step
        kkt, residual, grad, energies = kkt_free(u[:n], pp, u[n:])
    return ca.Function("dlo_newton", [u0, pp, k0, r0], [u, kkt, residual, grad, energies, largest])
