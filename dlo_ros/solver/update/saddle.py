"""Leaving a saddle by shifted Newton steps, without IPOPT (``ladder.py``'s first escape).

Plain Newton from a point beside a saddle returns to it: Newton finds the stationary point nearest
its start, whatever its curvature.  ``leave_saddle`` shifts the Hessian until the reduced Hessian
is positive definite, so that its steps go downhill on the constraint surface, and hands the point
it reaches to ``newton.newton`` to polish.
"""

from __future__ import annotations

import numpy as np

from ..build.functions import NlpFunctions
from ..build.nlp import StringNLP
from ..native.settings import (
    SADDLE_DUAL_TOLERANCE,
    SADDLE_PRIMAL_TOLERANCE,
    SADDLE_SHIFT_DECAY,
    SADDLE_SHIFT_FLOOR,
    SADDLE_SHIFT_GROWTH,
    SADDLE_STEP,
    SADDLE_STEPS,
)
from ..state import SolverState
from .kkt import active_rows, kkt_step
from .newton import newton

__all__ = ["SADDLE_STEP", "SADDLE_STEPS", "leave_saddle"]


def leave_saddle(
    nlp: StringNLP,
    fns: NlpFunctions,
    saddle: SolverState,
    p: np.ndarray,
    min_eigenvalue: float,
    sign: float = 1.0,
    fused: bool = True,
    first_step: float = SADDLE_STEP,
) -> tuple[bool, SolverState, int, float]:
    """Go from the unstable stationary point ``saddle`` downhill to a stationary point nearby.

    ``saddle`` has the reduced Hessian eigenvalue ``min_eigenvalue`` < 0 along
    ``saddle.unstable_direction``.  The saddle's active rows A are held and the steps solve

        [∇²L + μ I  J_Aᵀ] [Δz]     [∇f + J_Aᵀ λ_A]
        [J_A        0   ] [Δλ] = − [g_A − g_bound ]

    with μ = 2 |λ_min| at first, so that the reduced Hessian is positive definite and the step
    goes downhill on the constraint surface (no larger than ``SADDLE_STEP``).  A step that does
    not lower the merit φ = f + ρ ‖g_A − bound‖₁ (ρ = 2 max|λ| + 1) is undone and μ grows
    fourfold; an accepted one shrinks μ eightfold, to zero below 1e-8 · max|∇²L|, after which the
    steps are Newton's.  Once the residual is small (1e-6 dual, 1e-8 primal, scaled) the point
    reached is polished by ``newton`` (which also adapts the active set).  Returns ``newton``'s
    (ok, state, steps, violation); the caller checks that the state is stable and lower than the
    saddle.  The first step goes ``sign`` × the unstable direction, ``first_step`` long (largest
    scaled unknown); ``fused`` is passed to ``newton``.
    """
    fail = (False, saddle, 0, np.inf)
    if saddle.unstable_direction is None or not min_eigenvalue < 0:
        return fail
    g0 = saddle.g if saddle.g is not None else np.asarray(nlp.g_fn(saddle.z, saddle.p)).ravel()
    active = active_rows(nlp, saddle.lam_g, g0)
    idx = np.flatnonzero(active)
    bound = nlp.ubg[idx]
    d = saddle.unstable_direction / np.max(np.abs(saddle.unstable_direction))
    z = saddle.z + sign * first_step * d
    lam = np.where(active, saddle.lam_g, 0.0)
    rho = 2.0 * float(np.abs(lam).max(initial=0.0)) + 1.0
    mu = 2.0 * abs(min_eigenvalue)
    # the compiled loop where the full KKT function is compiled (with newton's own compiled loop:
    # ``fused``), else the interpreted one; both evaluate ``fns.kkt``'s function
    escape = fns.saddle_escape if fused else None
    ok, z, lam, steps = (escape or shifted_steps)(nlp, fns, z, lam, p, idx, bound, rho, mu)
    if not ok:
        return False, saddle, steps, np.inf
    start = SolverState(z, lam, saddle.lam_x, p, g=np.asarray(nlp.g_fn(z, p)).ravel())
    ok, state, it, viol = newton(nlp, fns, start, p, fused=fused)
    return ok, state, steps + it, viol


def shifted_steps(
    nlp: StringNLP,
    fns: NlpFunctions,
    z: np.ndarray,
    lam: np.ndarray,
    p: np.ndarray,
    idx: np.ndarray,
    bound: np.ndarray,
    rho: float,
    mu: float,
) -> tuple[bool, np.ndarray, np.ndarray, int]:
    """Take ``leave_saddle``'s shifted Newton steps from (z, λ) in Python: (ok, z, λ, steps).

    The rows ``idx`` are held at ``bound``; ρ weighs the merit's ‖g_A − bound‖₁, μ is the first
    shift (the rules: ``leave_saddle``).  ``ok`` is False where a step's matrix is singular or
    its step not finite; else (z, λ) is the point to polish.  The interpreted reference of the
    compiled ``native.saddle.NativeSaddle``, which has this signature's effect.
    """
    n, kkt_fn = z.size, fns.kkt
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
                SADDLE_SHIFT_GROWTH * max(mu, SADDLE_SHIFT_FLOOR * np.abs(hess).max()),
            )
            previous = None
            continue
        if previous is not None:
            mu = mu / SADDLE_SHIFT_DECAY if mu >= SADDLE_SHIFT_FLOOR * np.abs(hess).max() else 0.0
        ja = jac[idx]
        r_dual = grad + lam[idx] @ ja
        if (
            np.abs(r_dual).max(initial=0.0) < SADDLE_DUAL_TOLERANCE
            and np.abs(r_prim).max(initial=0.0) < SADDLE_PRIMAL_TOLERANCE
        ):
            # a stationary point whatever μ was (μ only shapes the steps): newton() polishes it
            break
        previous = (merit, z.copy(), lam.copy())
        step = kkt_step(hess, ja, r_dual, r_prim, shift=mu)
        if step is None:
            return False, z, lam, steps
        scale = min(1.0, SADDLE_STEP / max(float(np.abs(step[:n]).max()), 1e-300))
        z = z + scale * step[:n]
        lam = lam.copy()
        lam[idx] += scale * step[n:]
    return True, z, lam, steps
