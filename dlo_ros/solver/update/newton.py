"""Warm updates by Newton's method on the KKT conditions, with a primal-dual active set.

For the equality rows and the inequality rows in the active set A (at first: those at their bound
with λ > 0 at the start):

    [∇²L  J_Aᵀ] [Δz]     [∇f + J_Aᵀ λ_A]
    [J_A    0 ] [Δλ] = − [g_A − g_bound ]

repeated until ‖∇f + J_Aᵀλ_A‖∞ < 1e-9 and ‖g_A − g_bound‖∞ < 1e-11 (scaled units).  At that point
the KKT conditions of the whole problem hold when every inactive row is within its bound and every
active inequality's λ ≥ 0.  Between steps, a contact row that the last step left violated (or with
a negative multiplier) already joins (leaves) A, one row per step and at most NEWTON_STEP_SWITCHES
times (``_active_steps``).  If the converged point is still wrong, the active set changes by one
row, as in an active-set method: the most violated contact row (obstacle or self-contact,
``StringNLP.contact_row``; a violated fold guard is no equilibrium and gives up) joins A or, if
none is violated, the active inequality with the most negative λ leaves it; Newton goes on from
that point, at most ``NEWTON_ACTIVE_SET_CHANGES`` times (a grip move of 1 % of L shifts the sampled
contact of a cable lying on a table by a sample or two).  A step larger than 0.5 in any scaled
unknown, no convergence in ``max_steps`` for one active set, an active set seen before (a cycle) or
too many changes gives up: the caller then falls back to IPOPT.  Newton lands on the stationary
point nearest the start, so the caller still checks its stability.  Every function returns (ok,
state, steps, constraint violation [m or rad]).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgesv as _gesv

from ..native import settings
from ..build.functions import NlpFunctions
from ..native.settings import CONVERGED
from ..build.nlp import (
    JOIN_TOLERANCE,
    LEAVE_TOLERANCE,
    NEWTON_ACTIVE_SET_CHANGES,
    NEWTON_DUAL_TOLERANCE,
    NEWTON_MAX_STEP,
    NEWTON_PRIMAL_TOLERANCE,
    NEWTON_REGULARISATION,
    NEWTON_STEP_SWITCHES,
    NEWTON_STEPS,
    StringNLP,
)
from ..state import SolverState


def regularised(kkt: np.ndarray, n: int) -> np.ndarray:
    """K + diag(δ I_n, −δ I_m), δ = NEWTON_REGULARISATION · max|K|, as a new array.

    A scene with a continuous symmetry (both end tangents along the chord and no twist held: the
    shape may turn about the chord) has an exactly singular K at every equilibrium; LU then turns
    the residual's rounding noise into an arbitrary step along the symmetry.  The shift bounds that
    step
    (≈ |r| / δ) and changes a step elsewhere by a factor 1 + O(δ / σ) for K's other singular values σ:
    convergence stays quadratic until the residual reaches its floor.
    """
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
    return float(
        np.max(
            np.maximum(np.maximum(nlp.lbg - g, 0.0), np.maximum(g - nlp.ubg, 0.0)) * nlp.row_scale
        )
    )


def newton(
    nlp: StringNLP,
    fns: NlpFunctions,
    start: SolverState,
    p: np.ndarray,
    max_steps: int = 10,
    fused: bool = True,
    kkt_fn=None,
    prof: np.ndarray | None = None,
) -> tuple[bool, SolverState, int, float]:
    """Warm update from ``start`` to the parameters ``p`` (see the module docstring).  While no
    obstacle row is active this is ``newton_free``; ``fused``: its first steps in one call of
    ``newton_step``. ``kkt_fn``: another system of the same form as ``fns.kkt`` (z, p, λ) → [∇f, g,
    ∂g/∂z, K, energies] (``moments.ExactMomentKKT``: K need not be symmetric); the returned state
    then carries that function's derivatives, not ∇²L.  ``prof``: the profiles of the string solved
    for (``OutputFunction.profiles``), given when the answer's outputs are wanted: a compiled loop
    then evaluates them in its call (``native_newton.UpdateOutputs``, ``SolverState.outputs``).
    """
    if start.g is None:  # a warm start adopted from another model
        start.g = np.asarray(nlp.g_fn(start.z, start.p)).ravel()
    active = active_rows(nlp, start.lam_g, start.g)
    if nlp.obstacle_slots:  # a row p switches off (obstacle_slots.py) holds nothing
        active &= ~nlp.disabled_rows(p)
    steps = 0
    z, lam = start.z.copy(), np.where(active, start.lam_g, 0.0)
    reuse = (
        kkt_fn is None
        and start.hessian is not None
        and start.g is not None
        and start.gradient is not None
    )
    if kkt_fn is None and not np.any(active[nlp.n_free_rows :]):
        ok, state, steps, viol, contact = _newton_free(nlp, fns, start, p, max_steps, fused, prof)
        if ok or contact is None:
            return ok, state, steps, viol
        # a contact appeared: go on from the contact-free answer with its most violated row active
        violated = contact.g - nlp.ubg
        violated[: nlp.n_free_rows] = 0.0
        z, lam, reuse = contact.z, contact.lam_g, False
        active = active.copy()
        active[np.argmax(violated)] = True
    # the compiled loop only for the compiled KKT function it was built with
    native = fns.newton_active if kkt_fn is None and fused else None
    kkt_fn = kkt_fn or fns.kkt
    seen = {active.tobytes()}
    for _ in range(NEWTON_ACTIVE_SET_CHANGES + 1):
        ok, state, it, changed = _newton_active(
            nlp, kkt_fn, start, z, lam, p, active, max_steps, reuse, native, prof
        )
        steps += it
        if ok:
            return True, state, steps, violation(nlp, state.g)
        if changed is None or changed.tobytes() in seen:  # no convergence, or a cycle
            break
        seen.add(changed.tobytes())
        z, lam, active, reuse = state.z, state.lam_g, changed, False
    return False, start, steps, np.inf


def fill_start(nlp: StringNLP, fns: NlpFunctions, state: SolverState) -> None:
    """Store in ``state`` the derivatives that a warm update's first step from it reuses instead of
    evaluating them (``newton``): the contact-free Newton matrix and residual when no obstacle row
    is active, else ∇f, g, ∂g/∂z and ∇²L over every row (λ of the inactive rows taken as 0, as
    Newton does). For a state mapped from another model (``ShapeSolver.adopt_warm_start``), from
    which every query that model answers starts.
    """
    if state.g is None:
        state.g = np.asarray(nlp.g_fn(state.z, state.p)).ravel()
    active = active_rows(nlp, state.lam_g, state.g)
    nf = nlp.n_free_rows
    if not np.any(active[nf:]):
        kkt, residual, grad, energies = fns.kkt_free(state.z, state.p, state.lam_g[:nf])
        state.kkt, state.residual = kkt, residual[:, 0]
        state.g, state.jacobian = all_rows(nlp, fns, state.z, state.p, kkt, state.residual)
        state.hessian = kkt[: state.z.size, : state.z.size]
        state.reduced_eigen = state.outputs = None
    else:
        grad, g, state.jacobian, state.hessian, energies = fns.kkt(
            state.z, state.p, np.where(active, state.lam_g, 0.0)
        )
        state.g = np.asarray(g).ravel()
        state.reduced_eigen = state.outputs = None
    state.gradient, state.energies = np.asarray(grad).ravel(), np.asarray(energies).ravel()


def active_rows(nlp: StringNLP, lam: np.ndarray, g: np.ndarray) -> np.ndarray:
    """The rows a KKT point holds: the equalities, and the inequalities at their bound with a
    positive multiplier (IPOPT leaves ~1e-10 barrier multipliers on rows far from their bound;
    those are inactive).
    """
    return nlp.equality | ((lam > 1e-8) & (g > nlp.ubg - 1e-7))


def kkt_step(
    hess: np.ndarray, ja: np.ndarray, r_dual: np.ndarray, r_prim: np.ndarray, shift: float = 0.0
) -> np.ndarray | None:
    """[Δz; Δλ_A] solving [∇²L + shift·I, J_Aᵀ; J_A, 0] [Δz; Δλ_A] = −[r_dual; r_prim], the matrix
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
    _, _, step, info = _gesv(regularised(kkt, n), -np.concatenate([r_dual, r_prim]))
    return step if info == 0 and np.isfinite(step).all() else None


def _newton_active(
    nlp: StringNLP,
    kkt_fn,
    start: SolverState,
    z: np.ndarray,
    lam: np.ndarray,
    p: np.ndarray,
    active: np.ndarray,
    max_steps: int,
    reuse: bool,
    native=None,
    prof: np.ndarray | None = None,
) -> tuple[bool, SolverState | None, int, np.ndarray | None]:
    """Newton steps from (z, λ) with the rows ``active`` held at their bound, contact rows
    switching between steps as ``_active_steps`` says.  Returns (ok, state, steps, the next active
    set): ok with the KKT point when it satisfies every row and sign; else, when Newton converged
    but the active set is wrong, that point and the corrected set (violated rows in, negative
    multipliers out); else (False, None, steps, None).  ``reuse``: (z, λ) is the start's own point
    and only grip targets changed since, so its stored derivatives give the first step.
    ``native``: the compiled loop of ``kkt_fn`` (``native_newton.ActiveNewton``), or None for the
    numpy loop; it also returns the stability eigenpair and, given ``prof``, the outputs at the
    answer (``newton``).
    """
    equality = nlp.equality
    z, lam = z.copy(), np.where(active, lam, 0.0)
    # contact rows may switch (a row p switches off holds nothing: obstacle_slots.py); fold guards
    # may not
    switchable = nlp.contact_row & ~equality
    if nlp.obstacle_slots:
        switchable &= ~nlp.disabled_rows(p)
    # Only grip targets changed → they enter g linearly (row = (x − target)/scale), so ∇f, J and H
    # stored at the start stay exact and g shifts by a known amount: the first step needs no
    # evaluation.
    keep = ~nlp.grip_parameter_mask
    reuse = reuse and np.array_equal(start.p[keep], p[keep])
    first = (
        (start.gradient, start.g + nlp.target_shift(start.p, p), start.jacobian, start.hessian)
        if reuse
        else None
    )
    eigen = outputs = None
    if (
        native is not None
    ):  # the loop of _active_steps in one compiled call (native_newton.ActiveNewton)
        out = native(
            z, lam, p, active, nlp.ubg, switchable, NEWTON_STEP_SWITCHES, max_steps, first, prof
        )
        if out.code != CONVERGED:
            return False, None, out.steps, None
        z, lam, it, active = out.z, out.lam, out.steps, out.active
        grad, g, jac, hess, energies = out.gradient, out.g, out.jacobian, out.hessian, out.energies
        eigen, outputs = out.eigen, out.outputs
    else:
        found = _active_steps(
            kkt_fn, z, lam, p, active, nlp.ubg, switchable, NEWTON_STEP_SWITCHES, max_steps, first
        )
        if found[0] is None:
            return False, None, found[-1], None
        z, lam, grad, g, jac, hess, energies, it, active = found
    state = SolverState(
        z,
        lam,
        start.lam_x,
        p,
        hessian=hess,
        jacobian=jac,
        energies=energies.ravel(),
        g=g,
        gradient=grad,
        reduced_eigen=eigen,
        outputs=outputs,
    )
    excess = np.where(~active, g - nlp.ubg, 0.0)
    negative = np.where(active & ~equality, lam, 0.0)
    changed = active.copy()
    if np.any(
        excess[~nlp.contact_row] > JOIN_TOLERANCE
    ):  # a fold guard: no equilibrium, IPOPT takes over
        return False, None, it, None
    if (
        excess.max(initial=0.0) > JOIN_TOLERANCE
    ):  # the most violated row joins (one change at a time:
        changed[np.argmax(excess)] = True  # several at once over-constrain the sampled contact)
    elif negative.min(initial=0.0) < -LEAVE_TOLERANCE:  # else the most negative multiplier leaves
        changed[np.argmin(negative)] = False
    else:
        return True, state, it, None
    return False, state, it, changed


def _active_steps(
    kkt_fn,
    z: np.ndarray,
    lam: np.ndarray,
    p: np.ndarray,
    active: np.ndarray,
    ub: np.ndarray,
    switchable: np.ndarray,
    switches: int,
    max_steps: int,
    first: tuple | None,
) -> tuple:
    """Newton steps on [∇²L J_Aᵀ; J_A 0] for the rows ``active`` held at their bound ``ub`` (both
    over every row), from (z, λ) (changed in place), until the residual converges at an evaluated
    point: (z, λ, ∇f, g, ∂g/∂z, ∇²L, energies, steps, active) there, or (None, steps) on no
    convergence, a singular matrix or too large a step.  ``first``: (∇f, g, ∂g/∂z, ∇²L) for the
    first step instead of an evaluation.

    At each evaluated iterate after the first step, while ``switches`` remain, one of the rows
    ``switchable`` changes: the most violated inactive row joins (excess over JOIN_TOLERANCE), else
    the active row with the most negative multiplier (below −LEAVE_TOLERANCE) leaves, its
    multiplier set to 0; an iterate where a row changed is not converged.  Waiting for convergence
    before each change (the outer loop in ``_newton_active``) spent 4–10 steps on an active set
    that the first step already showed to be wrong.  One row per iterate, because several at once
    over-constrain the sampled contact; the budget bounds a cycle, after which the set is held and
    the outer loop decides.
    """
    n = z.size
    active = active.copy()
    for it in range(max_steps + 1):
        if it == 0 and first is not None:
            (grad, g, jac, hess), energies = first, None
        else:
            grad, g, jac, hess, energies = kkt_fn(z, p, lam)
            grad, g = grad.ravel(), g.ravel()
        switched = False
        if it > 0 and switches > 0:
            excess = np.where(switchable & ~active, g - ub, -np.inf)
            negative = np.where(switchable & active, lam, np.inf)
            if excess.size and excess.max() > JOIN_TOLERANCE:
                active[np.argmax(excess)] = switched = True
            elif negative.size and negative.min() < -LEAVE_TOLERANCE:
                leave = np.argmin(negative)
                active[leave], lam[leave], switched = False, 0.0, True
            switches -= switched
        idx = np.flatnonzero(active)
        ja = jac[idx]
        r_dual = grad + lam[idx] @ ja
        r_prim = g[idx] - ub[idx]
        if (
            not switched
            and energies is not None
            and np.abs(r_dual).max(initial=0.0) < NEWTON_DUAL_TOLERANCE
            and np.abs(r_prim).max(initial=0.0) < NEWTON_PRIMAL_TOLERANCE
        ):
            return z, lam, grad, g, jac, hess, energies, it, active
        if it == max_steps:
            break
        step = kkt_step(hess, ja, r_dual, r_prim)
        if step is None or np.abs(step[:n]).max() > NEWTON_MAX_STEP:
            return None, it
        z += step[:n]
        lam[idx] += step[n:]
    return None, max_steps


def _newton_free(
    nlp: StringNLP,
    fns: NlpFunctions,
    start: SolverState,
    p: np.ndarray,
    max_steps: int,
    fused: bool = True,
    prof: np.ndarray | None = None,
) -> tuple[bool, SolverState, int, float, SolverState | None]:
    """``newton`` while no obstacle row is active: the active rows are the free rows (all
    equalities), and the contact-free function returns the Newton matrix K and residual r
    themselves.  Steps K [Δz; Δλ] = −r start from the start's own K with r shifted by the new
    targets, when only targets changed.  With ``fused`` the first NEWTON_STEPS steps are one call
    of ``StringNLP.newton_fn`` (around the compiled contact-free function once it is loaded); if r
    is not yet converged, each further step is one evaluation and one LAPACK solve.  The obstacle
    rows' values are evaluated once, at the end, to check that none is violated; if one is, the
    last item returned is that converged contact-free point (z, λ, g), from which ``newton`` goes
    on with the violated rows active.  The compiled loop evaluates those rows, the stability
    eigenpair and (given ``prof``) the outputs in its own call.
    """
    nf, n, rows = nlp.n_free_rows, start.z.size, nlp.lbg.size
    unknowns = np.concatenate([start.z, start.lam_g[:nf]])
    keep = ~nlp.grip_parameter_mask
    native = fns.newton_native if fused else None
    kkt = residual = energies = None
    if start.kkt is not None and np.array_equal(
        start.p[keep], p[keep]
    ):  # targets enter g linearly
        kkt, residual = start.kkt, start.residual.copy()
        residual[n:] += nlp.target_shift(start.p, p)[:nf]
    elif native is None:  # (the compiled loop evaluates them in its call)
        kkt, residual, grad, energies = fns.kkt_free(unknowns[:n], p, unknowns[n:])
        residual = residual[:, 0]
    first, eigen, rows_g, outputs = 0, None, None, None
    if (
        native is not None
    ):  # the whole loop in one compiled call (native_newton.py), the GIL released
        out = native(unknowns, p, kkt, residual, max_steps, prof)
        if out.code != CONVERGED:
            return False, start, out.steps, np.inf, None
        unknowns, kkt, residual, grad, energies = (
            out.u,
            out.kkt,
            out.residual,
            out.gradient,
            out.energies,
        )
        first, eigen, rows_g, outputs = out.steps, out.eigen, out.g, out.outputs
    elif fused:
        try:
            u, kkt, residual, grad, energies, largest = fns.newton_step(unknowns, p, kkt, residual)
        except (
            RuntimeError
        ):  # CasADi's LAPACK LU raises on a singular Newton matrix (gesv says info > 0)
            return False, start, 0, np.inf, None
        if not (np.isfinite(u).all() and largest[0, 0] <= NEWTON_MAX_STEP):
            return False, start, NEWTON_STEPS, np.inf, None
        unknowns, residual, first = u[:, 0], residual[:, 0], NEWTON_STEPS
    for it in range(
        first, max(first, max_steps) + 1
    ):  # the compiled loop's chord steps may number more
        z, lam_free = unknowns[:n], unknowns[n:]
        if (
            energies is not None
            and np.abs(residual[:n]).max() < NEWTON_DUAL_TOLERANCE
            and np.abs(residual[n:]).max(initial=0.0) < NEWTON_PRIMAL_TOLERANCE
        ):
            g, jac = all_rows(nlp, fns, z, p, kkt, residual, rows_g)
            lam = np.zeros(rows)
            lam[:nf] = lam_free
            tol = settings.CONTACT_APPEARED_TOLERANCE  # the compiled loop's too (dlo_after_run)
            # a contact appeared (or a fold guard: no equilibrium)
            if np.any(g[nf:] > nlp.ubg[nf:] + tol):
                guards = ~nlp.contact_row[nf:]
                contact = np.all(g[nf:][guards] <= nlp.ubg[nf:][guards] + tol)
                return (
                    False,
                    start,
                    it,
                    np.inf,
                    SolverState(z.copy(), lam, start.lam_x, p, g=g) if contact else None,
                )
            state = SolverState(
                z.copy(),
                lam,
                start.lam_x,
                p,
                hessian=kkt[:n, :n],
                jacobian=jac,
                energies=energies.ravel(),
                g=g,
                gradient=grad.ravel(),
                kkt=kkt,
                residual=residual,
                reduced_eigen=eigen,
                outputs=outputs,
            )
            return True, state, it, violation(nlp, g), None
        if it >= max_steps:
            break
        eigen = rows_g = outputs = None  # not this iterate's
        _, _, step, info = _gesv(regularised(kkt, n), residual)
        if info != 0 or not np.isfinite(step).all() or np.abs(step[:n]).max() > NEWTON_MAX_STEP:
            return False, start, it, np.inf, None
        unknowns = unknowns - step
        kkt, residual, grad, energies = fns.kkt_free(unknowns[:n], p, unknowns[n:])
        residual = residual[:, 0]
    return False, start, max_steps, np.inf, None


def derivatives(
    nlp: StringNLP,
    fns: NlpFunctions,
    z: np.ndarray,
    p: np.ndarray,
    lam: np.ndarray,
    active: np.ndarray,
) -> list[np.ndarray]:
    """[∇f, g, ∂g/∂z, ∇²L, energies] at (z, p, λ).  When no obstacle row is ``active`` (so λ is
    zero on them) the contact-free function is used: the obstacle rows' Jacobian rows are returned
    as zeros and left out of ∇²L, which is exact for every use here (only active rows' Jacobians
    are used, and inactive rows have λ = 0).
    """
    nf = nlp.n_free_rows
    if np.any(active[nf:]):
        return fns.kkt(z, p, lam)
    kkt, residual, grad, energies = fns.kkt_free(z, p, lam[:nf])
    g, jac = all_rows(nlp, fns, z, p, kkt, residual[:, 0])
    return [
        grad,
        g[:, None],
        jac,
        kkt[: z.size, : z.size],
        energies,
    ]  # g as a column, as kkt_fn gives it


def all_rows(
    nlp: StringNLP,
    fns: NlpFunctions,
    z: np.ndarray,
    p: np.ndarray,
    kkt: np.ndarray,
    residual: np.ndarray,
    g: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(g, ∂g/∂z) over every row from the contact-free system (K, r) at z: the free rows' values
    are r's last rows and their Jacobian K's lower-left block; the obstacle rows' values are
    evaluated (unless ``g``, every row's value, is given: the compiled loop's), their Jacobian rows
    are zeros (unused while they are inactive).
    """
    n, nf, rows = z.size, nlp.n_free_rows, nlp.lbg.size
    if g is None:
        g = np.empty(rows)
        g[:nf] = residual[n:]
        if nf < rows:
            g[nf:] = fns.obstacle_g(z, p)[0].ravel()
    jac = np.zeros((rows, n))
    jac[:nf] = kkt[n:, :n]
    return g, jac


#: Leaving a saddle by shifted Newton steps: the first step's length (largest scaled unknown, as
#: ``ipopt.escape_saddle``'s first step) and the most shifted steps taken before giving up.
SADDLE_STEP, SADDLE_STEPS = 0.2, 40


def leave_saddle(
    nlp: StringNLP,
    fns: NlpFunctions,
    saddle: SolverState,
    p: np.ndarray,
    min_eigenvalue: float,
    sign: float = 1.0,
    fused: bool = True,
) -> tuple[bool, SolverState, int, float]:
    """From an unstable stationary point ``saddle`` (reduced Hessian eigenvalue ``min_eigenvalue``
    < 0 along ``saddle.unstable_direction``) downhill to a stationary point nearby, without IPOPT.

    Plain Newton from a point beside the saddle returns to it: Newton finds the stationary point
    nearest its start, whatever its curvature.  Here the saddle's active rows A are held and the
    steps solve

        [∇²L + μ I  J_Aᵀ] [Δz]     [∇f + J_Aᵀ λ_A]
        [J_A        0   ] [Δλ] = − [g_A − g_bound ]

    with μ = 2 |λ_min| at first, so that the reduced Hessian is positive definite and the step goes
    downhill on the constraint surface (no larger than ``SADDLE_STEP``).  A step that does not
    lower the
    merit φ = f + ρ ‖g_A − bound‖₁ (ρ = 2 max|λ| + 1) is undone and μ grows fourfold; an accepted one
    shrinks μ eightfold, to zero below 1e-8 · max|∇²L|, after which the steps are Newton's.  Once the
    residual is small (1e-6 dual, 1e-8 primal, scaled) the point reached is polished by ``newton``
    (which also adapts the active set).  Returns ``newton``'s (ok, state, steps, violation); the
    caller checks that the state is stable and lower than the saddle. The first step goes ``sign``
    × the unstable direction; ``fused`` is passed to ``newton``.
    """
    fail = (False, saddle, 0, np.inf)
    if saddle.unstable_direction is None or not min_eigenvalue < 0:
        return fail
    kkt_fn = fns.kkt
    g0 = saddle.g if saddle.g is not None else np.asarray(nlp.g_fn(saddle.z, saddle.p)).ravel()
    active = active_rows(nlp, saddle.lam_g, g0)
    idx = np.flatnonzero(active)
    bound = nlp.ubg[idx]
    d = saddle.unstable_direction / np.max(np.abs(saddle.unstable_direction))
    z = saddle.z + sign * SADDLE_STEP * d
    lam = np.where(active, saddle.lam_g, 0.0)
    rho = 2.0 * float(np.abs(lam).max(initial=0.0)) + 1.0
    n = z.size
    mu = 2.0 * abs(min_eigenvalue)
    previous: tuple | None = None  # (merit, z, λ) of the last accepted point
    steps = 0
    for steps in range(1, SADDLE_STEPS + 1):
        grad, g, jac, hess, energies = kkt_fn(z, p, lam)
        grad, g, energies = grad.ravel(), g.ravel(), np.ravel(energies)
        r_prim = g[idx] - bound
        merit = nlp.sigma * float(np.sum(energies[:4]) - energies[4]) + rho * float(
            np.abs(r_prim).sum()
        )
        if previous is not None and not merit < previous[0]:  # uphill: undo, shift more
            z, lam, mu = (
                previous[1].copy(),
                previous[2].copy(),
                4.0 * max(mu, 1e-8 * np.abs(hess).max()),
            )
            previous = None
            continue
        if previous is not None:
            mu = mu / 8.0 if mu >= 1e-8 * np.abs(hess).max() else 0.0
        ja = jac[idx]
        r_dual = grad + lam[idx] @ ja
        if np.abs(r_dual).max(initial=0.0) < 1e-6 and np.abs(r_prim).max(initial=0.0) < 1e-8:
            # a stationary point whatever μ was (μ only shapes the steps): newton() polishes it
            break
        previous = (merit, z.copy(), lam.copy())
        step = kkt_step(hess, ja, r_dual, r_prim, shift=mu)
        if step is None:
            return False, saddle, steps, np.inf
        scale = min(1.0, SADDLE_STEP / max(float(np.abs(step[:n]).max()), 1e-300))
        z = z + scale * step[:n]
        lam = lam.copy()
        lam[idx] += scale * step[n:]
    start = SolverState(z, lam, saddle.lam_x, p, g=np.asarray(nlp.g_fn(z, p)).ravel())
    ok, state, it, viol = newton(nlp, fns, start, p, fused=fused)
    return ok, state, steps + it, viol
