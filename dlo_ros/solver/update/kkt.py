"""The KKT system at one point: its active rows, its regularised Newton step, its violation.

The pieces every Newton loop of a warm update shares (``newton.py``, ``active_set.py``,
``contact_free.py``, ``saddle.py``), in the NLP's scaled units:

* ``active_rows``: the rows a KKT point holds (equalities, inequalities at their bound with λ > 0);
* ``kkt_step``: one Newton step on [∇²L J_Aᵀ; J_A 0] for those rows, through ``regularised``;
* ``all_rows``: g and ∂g/∂z over every row from the contact-free system (K, r);
* ``violation``: the largest constraint violation in SI units (m or rad).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgesv

from ..build.functions import NlpFunctions
from ..build.nlp import StringNLP
from ..native.settings import NEWTON_REGULARISATION


def regularised(kkt: np.ndarray, n: int) -> np.ndarray:
    """Return K + diag(δ I_n, −δ_λ I_m) for K = [H Jᵀ; J 0], as a new array.

    δ = ε · max(max|K|, 1) and δ_λ = ε · max|J|² / max(max|H|, 1), ε = NEWTON_REGULARISATION.

    A scene with a continuous symmetry (both end tangents along the chord and no twist held: the
    shape may turn about the chord) has an exactly singular K at every equilibrium; LU then turns
    the residual's rounding noise into an arbitrary step along the symmetry.  The shift δ bounds
    that step (≈ |r| / δ) and changes a step elsewhere by a factor 1 + O(δ / σ) for K's other
    singular values σ: convergence stays quadratic until the residual reaches its floor.  The rows'
    shift δ_λ is scaled as the Schur complement J H⁻¹ Jᵀ it perturbs: it bounds the multipliers of
    two identical rows, and leaves the primal residual δ_λ·Δλ after a step.  (With δ there too,
    two contact rows 0.3 mm apart at the end of a short element, J_A's singular value 3.5e-3,
    converged linearly at a rate of 0.6 per step and every such update fell back to IPOPT.)
    """
    out = np.array(kkt, dtype=float, copy=True)
    delta = NEWTON_REGULARISATION * max(float(np.abs(out).max(initial=0.0)), 1.0)
    h_max = max(float(np.abs(out[:n, :n]).max(initial=0.0)), 1.0)
    j_max = float(np.abs(out[n:, :n]).max(initial=0.0))
    delta_rows = NEWTON_REGULARISATION * j_max * j_max / h_max
    idx = np.arange(out.shape[0])
    out[idx[:n], idx[:n]] += delta
    out[idx[n:], idx[n:]] -= delta_rows
    return out


def same_scene(nlp: StringNLP, p_old: np.ndarray, p_new: np.ndarray) -> bool:
    """Whether two parameter vectors differ in grip targets at most (``np.array_equal`` there)."""
    rows = nlp.scene_parameter_rows
    a, b = p_old[rows], p_new[rows]
    return a.shape == b.shape and bool((a == b).all())


def violation(nlp: StringNLP, g: np.ndarray) -> float:
    """Return the largest constraint violation of the row values g, in SI (m or rad)."""
    if g.size == 0:
        return 0.0
    # max_i max(l_i − g_i, g_i − u_i, 0) s_i with s_i > 0: the zero taken once, after the scaling
    # (the same numbers; nan stays nan)
    over = np.maximum(nlp.lbg - g, g - nlp.ubg)
    over *= nlp.row_scale
    worst = float(over.max())
    return worst if not worst < 0.0 else 0.0


def active_rows(nlp: StringNLP, lam: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Return the rows a KKT point holds, as a boolean mask over every row.

    The equalities, and the inequalities at their bound with a positive multiplier (IPOPT leaves
    ~1e-10 barrier multipliers on rows far from their bound; those are inactive).
    """
    return nlp.equality | ((lam > 1e-8) & (g > nlp.ubg - 1e-7))


def kkt_step(
    hess: np.ndarray, ja: np.ndarray, r_dual: np.ndarray, r_prim: np.ndarray, shift: float = 0.0
) -> np.ndarray | None:
    """Return the Newton step [Δz; Δλ_A] of the active rows, or None.

    It solves [∇²L + shift·I, J_Aᵀ; J_A, 0] [Δz; Δλ_A] = −[r_dual; r_prim], the matrix
    ``regularised``; None when LAPACK finds it singular or the step is not finite.
    """
    n, m = hess.shape[0], ja.shape[0]
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n] = hess
    if shift:
        kkt[np.arange(n), np.arange(n)] += shift
    kkt[:n, n:] = ja.T
    kkt[n:, :n] = ja
    # LAPACK's gesv directly: numpy.linalg.solve's checks cost more than the solve at this size
    _, _, step, info = dgesv(regularised(kkt, n), -np.concatenate([r_dual, r_prim]))
    return step if info == 0 and np.isfinite(step).all() else None


def all_rows(
    nlp: StringNLP,
    fns: NlpFunctions,
    z: np.ndarray,
    p: np.ndarray,
    kkt: np.ndarray,
    residual: np.ndarray,
    g: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Return (g, ∂g/∂z) over every row from the contact-free system (K, r) at z.

    The free rows' values are r's last rows and their Jacobian K's lower-left block; the obstacle
    rows' values are evaluated (unless ``g``, every row's value, is given: the compiled loop's),
    their Jacobian rows are zeros (unused while they are inactive).
    """
    n, nf, rows = z.size, nlp.n_free_rows, nlp.lbg.size
    if g is None:
        g = np.empty(rows)
        g[:nf] = residual[n:]
        if nf < rows:
            assert fns.obstacle_g is not None  # an NLP with obstacle rows has their function
            g[nf:] = fns.obstacle_g(z, p)[0].ravel()
    jac = np.zeros((rows, n))
    jac[:nf] = kkt[n:, :n]
    return g, jac
