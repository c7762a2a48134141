"""Warm updates by Newton's method on the KKT conditions, with the active set of the start.

For the equality rows and the inequality rows active at the start (at their bound with λ > 0):

    [∇²L  J_aᵀ] [Δz]     [∇f + J_aᵀ λ_a]
    [J_a    0 ] [Δλ] = − [g_a − g_bound ]

repeated until ‖∇f + J_aᵀλ_a‖∞ < 1e-9 and ‖g_a − g_bound‖∞ < 1e-11 (scaled units).  A step larger
than 0.5 in any scaled unknown, a change of the active set (an inactive obstacle row violated, or an
active inequality's λ turning negative) or no convergence in ``max_steps`` gives up: the caller then
falls back to IPOPT.  Newton lands on the stationary point nearest the start, so the caller still
checks its stability.  Every function returns (ok, state, steps, constraint violation [m or rad]).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgesv as _gesv

from .functions import NlpFunctions
from .native_newton import CONVERGED
from .nlp import (NEWTON_DUAL_TOLERANCE, NEWTON_MAX_STEP, NEWTON_PRIMAL_TOLERANCE, NEWTON_REGULARISATION,
                  NEWTON_STEPS, StringNLP)
from .state import SolverState


def regularised(kkt: np.ndarray, n: int) -> np.ndarray:
    """K + diag(δ I_n, −δ I_m), δ = NEWTON_REGULARISATION · max|K|, as a new array.

    A scene with a continuous symmetry (both end tangents along the chord and no twist held: the shape
    may turn about the chord) has an exactly singular K at every equilibrium; LU then turns the
    residual's rounding noise into an arbitrary step along the symmetry.  The shift bounds that step
    (≈ |r| / δ) and changes a step elsewhere by a factor 1 + O(δ / σ) for K's other singular values σ:
    convergence stays quadratic until the residual reaches its floor."""
    out = np.array(kkt, dtype=float, copy=True)
    delta = NEWTON_REGULARISATION * max(float(np.abs(out).max(initial=0.0)), 1.0)
    idx = np.arange(out.shape[0])
    out[idx[:n], idx[:n]] += delta
    out[idx[n:], idx[n:]] -= delta
    return out


def violation(nlp: StringNLP, g: np.ndarray) -> float:
    """The largest constraint violation of the row values g, in SI (m or rad)."""
    if g.size == 0:
        return 0.0
    return float(np.max(np.maximum(np.maximum(nlp.lbg - g, 0.0), np.maximum(g - nlp.ubg, 0.0)) * nlp.row_scale))


def newton(nlp: StringNLP, fns: NlpFunctions, start: SolverState, p: np.ndarray, max_steps: int = 10,
           fused: bool = True, kkt_fn=None) -> tuple[bool, SolverState, int, float]:
    """Warm update from ``start`` to the parameters ``p`` (see the module docstring).  While no obstacle
    row is active this is ``newton_free``; ``fused``: its first steps in one call of ``newton_step``.
    ``kkt_fn``: another system of the same form as ``fns.kkt`` (z, p, λ) → [∇f, g, ∂g/∂z, K, energies]
    (``moments.ExactMomentKKT``: K need not be symmetric); the returned state then carries that
    function's derivatives, not ∇²L."""
    z, lam = start.z.copy(), np.zeros_like(start.lam_g)
    equality = nlp.equality
    # active = at its bound with a positive multiplier (IPOPT leaves ~1e-10 barrier multipliers
    # on rows far from their bound; those are inactive)
    if start.g is None:  # a warm start adopted from another model
        start.g = np.asarray(nlp.g_fn(start.z, start.p)).ravel()
    active = equality | ((start.lam_g > 1e-8) & (start.g > nlp.ubg - 1e-7))
    if kkt_fn is None and not np.any(active[nlp.n_free_rows:]):
        return newton_free(nlp, fns, start, p, max_steps, fused)
    kkt_fn = kkt_fn or fns.kkt
    lam[active] = start.lam_g[active]
    idx = np.flatnonzero(active)
    bound = nlp.ubg[idx]
    n, m = z.size, idx.size
    kkt, rhs = np.zeros((n + m, n + m)), np.empty(n + m)
    # Only grip targets changed → they enter g linearly (row = (x − target)/scale), so ∇f, J and H
    # stored at the start stay exact and g shifts by a known amount: the first step needs no evaluation.
    keep = ~nlp.grip_parameter_mask
    reuse = (
        kkt_fn is fns.kkt and start.hessian is not None and start.g is not None and start.gradient is not None
        and np.array_equal(start.p[keep], p[keep])
    )
    for it in range(max_steps + 1):
        if it == 0 and reuse:
            grad, jac, hess, energies = start.gradient, start.jacobian, start.hessian, None
            g = start.g + nlp.target_shift(start.p, p)
        else:
            grad, g, jac, hess, energies = kkt_fn(z, p, lam)
            grad, g = grad.ravel(), g.ravel()
        ja = jac[idx]
        r_dual = grad + lam[idx] @ ja
        r_prim = g[idx] - bound
        converged = np.abs(r_dual).max(initial=0.0) < NEWTON_DUAL_TOLERANCE and \
            np.abs(r_prim).max(initial=0.0) < NEWTON_PRIMAL_TOLERANCE
        if converged and energies is not None:
            inactive_ok = np.all(g[~active] <= nlp.ubg[~active] + 1e-9)
            signs_ok = np.all(lam[active & ~equality] >= -1e-12)
            if not (inactive_ok and signs_ok):
                return False, start, it, np.inf
            state = SolverState(z, lam, start.lam_x, p, hessian=hess, jacobian=jac, energies=energies.ravel(), g=g,
                                gradient=grad)
            return True, state, it, violation(nlp, g)
        if it == max_steps:
            break
        kkt[:n, :n] = hess
        kkt[:n, n:] = ja.T
        kkt[n:, :n] = ja
        rhs[:n] = -r_dual
        rhs[n:] = -r_prim
        # LAPACK's gesv directly: numpy.linalg.solve's checks cost more than the solve at this size
        _, _, step, info = _gesv(regularised(kkt, n), rhs)
        if info != 0 or not np.isfinite(step).all() or np.abs(step[:n]).max() > NEWTON_MAX_STEP:
            return False, start, it, np.inf
        z += step[:n]
        lam[idx] += step[n:]
    return False, start, max_steps, np.inf


def newton_free(nlp: StringNLP, fns: NlpFunctions, start: SolverState, p: np.ndarray, max_steps: int,
                fused: bool = True) -> tuple[bool, SolverState, int, float]:
    """``newton`` while no obstacle row is active: the active rows are the free rows (all equalities),
    and the contact-free function returns the Newton matrix K and residual r themselves.  Steps
    K [Δz; Δλ] = −r start from the start's own K with r shifted by the new targets, when only targets
    changed.  With ``fused`` the first NEWTON_STEPS steps are one call of ``StringNLP.newton_fn`` (around
    the compiled contact-free function once it is loaded); if r is not yet converged, each further step
    is one evaluation and one LAPACK solve.  The obstacle rows' values are evaluated once, at the end,
    to check that none is violated (else the caller falls back to IPOPT)."""
    nf, n, rows = nlp.n_free_rows, start.z.size, nlp.lbg.size
    unknowns = np.concatenate([start.z, start.lam_g[:nf]])
    keep = ~nlp.grip_parameter_mask
    if start.kkt is not None and np.array_equal(start.p[keep], p[keep]):  # targets enter g linearly
        kkt, residual, energies = start.kkt, start.residual.copy(), None
        residual[n:] += nlp.target_shift(start.p, p)[:nf]
    else:
        kkt, residual, grad, energies = fns.kkt_free(unknowns[:n], p, unknowns[n:])
        residual = residual[:, 0]
    first = 0
    native = fns.newton_native if fused else None
    if native is not None:  # the whole loop in one compiled call (native_newton.py), the GIL released
        out = native(unknowns, p, kkt, residual, max_steps)
        if out.code != CONVERGED:
            return False, start, out.steps, np.inf
        unknowns, kkt, residual, grad, energies = out.u, out.kkt, out.residual, out.gradient, out.energies
        first = out.steps
    elif fused:
        try:
            u, kkt, residual, grad, energies, largest = fns.newton_step(unknowns, p, kkt, residual)
        except RuntimeError:  # CasADi's LAPACK LU raises on a singular Newton matrix (gesv says info > 0)
            return False, start, 0, np.inf
        if not (np.isfinite(u).all() and largest[0, 0] <= NEWTON_MAX_STEP):
            return False, start, NEWTON_STEPS, np.inf
        unknowns, residual, first = u[:, 0], residual[:, 0], NEWTON_STEPS
    for it in range(first, max_steps + 1):
        z, lam_free = unknowns[:n], unknowns[n:]
        if energies is not None and np.abs(residual[:n]).max() < NEWTON_DUAL_TOLERANCE and \
                np.abs(residual[n:]).max(initial=0.0) < NEWTON_PRIMAL_TOLERANCE:
            g, jac = all_rows(nlp, fns, z, p, kkt, residual)
            if np.any(g[nf:] > nlp.ubg[nf:] + 1e-9):  # a contact appeared: the active set changed
                return False, start, it, np.inf
            lam = np.zeros(rows)
            lam[:nf] = lam_free
            state = SolverState(z.copy(), lam, start.lam_x, p, hessian=kkt[:n, :n], jacobian=jac,
                                energies=energies.ravel(), g=g, gradient=grad.ravel(), kkt=kkt, residual=residual)
            return True, state, it, violation(nlp, g)
        if it == max_steps:
            break
        _, _, step, info = _gesv(regularised(kkt, n), residual)
        if info != 0 or not np.isfinite(step).all() or np.abs(step[:n]).max() > NEWTON_MAX_STEP:
            return False, start, it, np.inf
        unknowns = unknowns - step
        kkt, residual, grad, energies = fns.kkt_free(unknowns[:n], p, unknowns[n:])
        residual = residual[:, 0]
    return False, start, max_steps, np.inf


def derivatives(nlp: StringNLP, fns: NlpFunctions, z: np.ndarray, p: np.ndarray, lam: np.ndarray,
                active: np.ndarray) -> list[np.ndarray]:
    """[∇f, g, ∂g/∂z, ∇²L, energies] at (z, p, λ).  When no obstacle row is ``active`` (so λ is zero on
    them) the contact-free function is used: the obstacle rows' Jacobian rows are returned as zeros
    and left out of ∇²L, which is exact for every use here (only active rows' Jacobians are used, and
    inactive rows have λ = 0)."""
    nf = nlp.n_free_rows
    if np.any(active[nf:]):
        return fns.kkt(z, p, lam)
    kkt, residual, grad, energies = fns.kkt_free(z, p, lam[:nf])
    g, jac = all_rows(nlp, fns, z, p, kkt, residual[:, 0])
    return [grad, g[:, None], jac, kkt[: z.size, : z.size], energies]  # g as a column, as kkt_fn gives it


def all_rows(nlp: StringNLP, fns: NlpFunctions, z: np.ndarray, p: np.ndarray, kkt: np.ndarray,
             residual: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(g, ∂g/∂z) over every row from the contact-free system (K, r) at z: the free rows' values are r's
    last rows and their Jacobian K's lower-left block; the obstacle rows' values are evaluated, their
    Jacobian rows are zeros (unused while they are inactive)."""
    n, nf, rows = z.size, nlp.n_free_rows, nlp.lbg.size
    g = np.empty(rows)
    g[:nf] = residual[n:]
    if nf < rows:
        g[nf:] = fns.obstacle_g(z, p)[0].ravel()
    jac = np.zeros((rows, n))
    jac[:nf] = kkt[n:, :n]
    return g, jac
