"""Newton steps while no obstacle row is active: the contact-free system K [Δz; Δλ] = −r.

The active rows are then the free rows (all equalities), and the contact-free function returns
the Newton matrix K and residual r themselves.  ``newton_free`` is ``newton.newton``'s fast path:
its first steps (``first_steps``: reused, compiled or fused), further steps one evaluation and
one LAPACK solve each, and the converged point's check of the obstacle rows (``converged``).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgesv

from ..build.functions import NlpFunctions
from ..build.nlp import StringNLP
from ..native import settings
from ..native.settings import (
    CONVERGED,
    NEWTON_DUAL_TOLERANCE,
    NEWTON_MAX_STEP,
    NEWTON_PRIMAL_TOLERANCE,
    NEWTON_STEPS,
)
from ..state import SolverState
from .kkt import all_rows, regularised, same_scene, violation

#: (ok, state, steps, constraint violation [m or rad], the converged contact-free point when a
# contact appeared there, else None) of ``newton_free``
FreeAnswer = tuple[bool, SolverState, int, float, SolverState | None]

#: (u = [z; λ_free], K, r, ∇f, energies, steps taken, eigenpair, every row's g, outputs) after
# ``first_steps``: the last four from the compiled loop, else None
FreeIterate = tuple


def newton_free(
    nlp: StringNLP,
    fns: NlpFunctions,
    start: SolverState,
    p: np.ndarray,
    max_steps: int,
    fused: bool = True,
    prof: np.ndarray | None = None,
) -> FreeAnswer:
    """Run ``newton`` while no obstacle row is active (see the module docstring).

    Steps K [Δz; Δλ] = −r start from the start's own K with r shifted by the new targets, when
    only targets changed.  With ``fused`` the first NEWTON_STEPS steps are one call of
    ``StringNLP.newton_fn`` (around the compiled contact-free function once it is loaded); if r
    is not yet converged, each further step is one evaluation and one LAPACK solve.  The obstacle
    rows' values are evaluated once, at the end, to check that none is violated; if one is, the
    last item returned is that converged contact-free point (z, λ, g), from which ``newton`` goes
    on with the violated rows active.  The compiled loop evaluates those rows, the stability
    eigenpair and (given ``prof``) the outputs in its own call.
    """
    n = start.z.size
    begun = first_steps(nlp, fns, start, p, max_steps, fused, prof)
    if isinstance(begun, int):
        return False, start, begun, np.inf, None
    unknowns, kkt, residual, grad, energies, first, eigen, rows_g, outputs = begun
    # the compiled loop's chord steps may number more
    for it in range(first, max(first, max_steps) + 1):
        if (
            energies is not None
            and np.abs(residual[:n]).max() < NEWTON_DUAL_TOLERANCE
            and np.abs(residual[n:]).max(initial=0.0) < NEWTON_PRIMAL_TOLERANCE
        ):
            reached = (unknowns, kkt, residual, grad, energies, it, eigen, rows_g, outputs)
            return converged(nlp, fns, start, p, reached)
        if it >= max_steps:
            break
        eigen = rows_g = outputs = None  # not this iterate's
        _, _, step, info = dgesv(regularised(kkt, n), residual)
        if info != 0 or not np.isfinite(step).all() or np.abs(step[:n]).max() > NEWTON_MAX_STEP:
            return False, start, it, np.inf, None
        unknowns = unknowns - step
        kkt, residual, grad, energies = fns.kkt_free(unknowns[:n], p, unknowns[n:])
        residual = residual[:, 0]
    return False, start, max_steps, np.inf, None


def first_steps(
    nlp: StringNLP,
    fns: NlpFunctions,
    start: SolverState,
    p: np.ndarray,
    max_steps: int,
    fused: bool,
    prof: np.ndarray | None,
) -> FreeIterate | int:
    """Return the iterate after ``newton_free``'s first steps, or the steps taken when they fail.

    K and r at the start are the start's own (r shifted by the new targets) when only targets
    changed, else evaluated (unless the compiled loop evaluates them in its call).  The compiled
    loop (``native/newton.py``, the GIL released) then takes every step; ``fused`` without it, the
    first NEWTON_STEPS steps in one call of ``newton_step``; otherwise none is taken here.
    """
    nf, n = nlp.n_free_rows, start.z.size
    unknowns = np.concatenate([start.z, start.lam_g[:nf]])
    native = fns.newton_native if fused else None
    kkt = residual = grad = energies = None
    if (
        start.kkt is not None and start.residual is not None and same_scene(nlp, start.p, p)
    ):  # targets enter g linearly
        kkt, residual = start.kkt, start.residual.copy()
        residual[n:] += nlp.target_shift(start.p, p)[:nf]
    elif native is None:  # (the compiled loop evaluates them in its call)
        kkt, residual, grad, energies = fns.kkt_free(unknowns[:n], p, unknowns[n:])
        residual = residual[:, 0]
    if native is not None:  # the whole loop in one compiled call
        out = native(unknowns, p, kkt, residual, max_steps, prof)
        if out.code != CONVERGED:
            return int(out.steps)
        return (
            out.u,
            out.kkt,
            out.residual,
            out.gradient,
            out.energies,
            out.steps,
            out.eigen,
            out.g,
            out.outputs,
        )
    if fused:
        try:
            u, kkt, residual, grad, energies, largest = fns.newton_step(unknowns, p, kkt, residual)
        except (
            RuntimeError
        ):  # CasADi's LAPACK LU raises on a singular Newton matrix (gesv: info > 0)
            return 0
        if not (np.isfinite(u).all() and largest[0, 0] <= NEWTON_MAX_STEP):
            return NEWTON_STEPS
        return u[:, 0], kkt, residual[:, 0], grad, energies, NEWTON_STEPS, None, None, None
    return unknowns, kkt, residual, grad, energies, 0, None, None, None


def converged(
    nlp: StringNLP, fns: NlpFunctions, start: SolverState, p: np.ndarray, reached: FreeIterate
) -> FreeAnswer:
    """Return ``newton_free``'s answer at the converged contact-free point ``reached``.

    The obstacle rows' values (the compiled loop's, else evaluated) decide it: a verified state
    when none exceeds its bound by more than CONTACT_APPEARED_TOLERANCE; the point itself (z, λ,
    g) as the last item when a contact row does (a contact appeared: ``newton`` goes on from it);
    a plain failure when a fold guard does (no equilibrium).
    """
    unknowns, kkt, residual, grad, energies, it, eigen, rows_g, outputs = reached
    nf, n, rows = nlp.n_free_rows, start.z.size, nlp.lbg.size
    z, lam_free = unknowns[:n], unknowns[n:]
    g, jac = all_rows(nlp, fns, z, p, kkt, residual, rows_g)
    lam = np.zeros(rows)
    lam[:nf] = lam_free
    tol = settings.CONTACT_APPEARED_TOLERANCE  # the compiled loop's too (dlo_after_run)
    # a contact appeared (or a fold guard: no equilibrium)
    if (g[nf:] > nlp.ubg[nf:] + tol).any():
        guards = ~nlp.contact_row[nf:]
        contact = np.all(g[nf:][guards] <= nlp.ubg[nf:][guards] + tol)
        point = SolverState(z.copy(), lam, start.lam_x, p, g=g) if contact else None
        return False, start, it, np.inf, point
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
