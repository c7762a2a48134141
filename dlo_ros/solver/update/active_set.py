"""Newton steps with an active set: the rows held at their bound, and how that set changes.

``newton.newton`` calls ``newton_active`` once per active set.  It runs the steps (``active_steps``
in numpy, or the compiled loop ``native.active.ActiveNewton`` doing the same in one call), then
judges the point reached (``next_active_set``): a KKT point of the whole problem is the answer;
otherwise the most violated contact row joins the set or the most negative multiplier leaves it,
and ``newton`` goes on from there with the changed set.
"""

from __future__ import annotations

import numpy as np

from ..build.nlp import StringNLP
from ..native.settings import (
    CONVERGED,
    JOIN_TOLERANCE,
    LEAVE_TOLERANCE,
    NEWTON_DUAL_TOLERANCE,
    NEWTON_MAX_STEP,
    NEWTON_PRIMAL_TOLERANCE,
    NEWTON_STEP_SWITCHES,
)
from ..state import SolverState
from .kkt import kkt_step, same_scene


def newton_active(
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
    """Take Newton steps from (z, λ) with the rows ``active`` held at their bound.

    Contact rows switch between steps as ``active_steps`` says.  Returns (ok, state, steps, the
    next active set): ok with the KKT point when it satisfies every row and sign; else, when
    Newton converged but the active set is wrong, that point and the corrected set (violated rows
    in, negative multipliers out); else (False, None, steps, None).  ``reuse``: (z, λ) is the
    start's own point and only grip targets changed since, so its stored derivatives give the
    first step.  ``native``: the compiled loop of ``kkt_fn`` (``native.active.ActiveNewton``), or
    None for the numpy loop; it also returns the stability eigenpair and, given ``prof``, the
    outputs at the answer (``newton``).
    """
    z, lam = z.copy(), np.where(active, lam, 0.0)
    switchable = switchable_rows(nlp, p)
    first = first_derivatives(nlp, start, p, reuse)
    eigen = outputs = None
    if native is not None:  # the loop of active_steps in one compiled call (ActiveNewton)
        out = native(
            z, lam, p, active, nlp.ubg, switchable, NEWTON_STEP_SWITCHES, max_steps, first, prof
        )
        if out.code != CONVERGED:
            return False, None, out.steps, None
        z, lam, it, active = out.z, out.lam, out.steps, out.active
        grad, g, jac, hess, energies = out.gradient, out.g, out.jacobian, out.hessian, out.energies
        eigen, outputs = out.eigen, out.outputs
    else:
        found = active_steps(
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
    done, changed = next_active_set(nlp, g, lam, active)
    if done:
        return True, state, it, None
    if changed is None:  # a fold guard: no equilibrium, IPOPT takes over
        return False, None, it, None
    return False, state, it, changed


def shifted_pairs(nlp: StringNLP, lam: np.ndarray, proposed: np.ndarray) -> list[np.ndarray]:
    """Return the active sets to try when one-row changes went round in a cycle.

    ``lam``: the multipliers at a point judged in the cycle; ``proposed``: the set the cycle came
    back to.  Where two neighbouring rows i, j of one obstacle carry λ_i < 0 < λ_j (adjacent
    along s), their resultant (λ_i s_i + λ_j s_j)/(λ_i + λ_j) lies beyond j: the contact has
    slid past the pair, so the pair moves by one row, {j, j + (j − i)} instead of {i, j}.  One
    candidate per such pair, ``proposed`` changed so.  The cycle it breaks: the main job's cable
    sliding over the post on node rows, {i, j} giving λ_i < 0 and {j} leaving row i just inside
    the post (Newton fell back to IPOPT at every update there, 0.1–0.3 s interpreted).
    """
    found = []
    for obstacle in nlp.obstacle_rows:
        rows = np.asarray(obstacle)
        for a in np.flatnonzero(lam[rows] < -LEAVE_TOLERANCE):
            for step in (1, -1):
                b, c = a + step, a + 2 * step
                if 0 <= c < rows.size and lam[rows[b]] > LEAVE_TOLERANCE:
                    moved = proposed.copy()
                    moved[rows[a]], moved[rows[b]], moved[rows[c]] = False, True, True
                    found.append(moved)
    return found


def switchable_rows(nlp: StringNLP, p: np.ndarray) -> np.ndarray:
    """Return the rows that may join or leave the active set between steps.

    The contact rows (a row p switches off holds nothing: ``obstacle_slots.py``); fold guards may
    not switch.
    """
    switchable = nlp.switchable_rows  # read-only: a new array where slots switch rows off
    if nlp.obstacle_slots:
        switchable = switchable & ~nlp.disabled_rows(p)
    return switchable


def first_derivatives(
    nlp: StringNLP, start: SolverState, p: np.ndarray, reuse: bool
) -> tuple | None:
    """Return (∇f, g, ∂g/∂z, ∇²L) for the first step from ``start``, or None to evaluate them.

    Only grip targets changed → they enter g linearly (row = (x − target)/scale), so ∇f, J and H
    stored at the start stay exact and g shifts by a known amount: the first step needs no
    evaluation.
    """
    if not (reuse and same_scene(nlp, start.p, p)):
        return None
    return start.gradient, start.g + nlp.target_shift(start.p, p), start.jacobian, start.hessian


def next_active_set(
    nlp: StringNLP, g: np.ndarray, lam: np.ndarray, active: np.ndarray
) -> tuple[bool, np.ndarray | None]:
    """Judge a converged point of the rows ``active``: (done, the next active set).

    (True, None) when every inactive row is within its bound and every active inequality's λ is
    not below −LEAVE_TOLERANCE; (False, None) when a row that is no contact (a fold guard) is
    violated: no equilibrium; else (False, the set with one row changed): the most violated row
    joins (one change at a time: several at once over-constrain the sampled contact), or, if none
    is violated, the active inequality with the most negative multiplier leaves.
    """
    excess = np.where(~active, g - nlp.ubg, 0.0)
    negative = np.where(active & ~nlp.equality, lam, 0.0)
    changed = active.copy()
    if np.any(excess[~nlp.contact_row] > JOIN_TOLERANCE):
        return False, None
    if excess.max(initial=0.0) > JOIN_TOLERANCE:
        changed[np.argmax(excess)] = True
    elif negative.min(initial=0.0) < -LEAVE_TOLERANCE:
        changed[np.argmin(negative)] = False
    else:
        return True, None
    return False, changed


def active_steps(
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
    """Take Newton steps on [∇²L J_Aᵀ; J_A 0] for the rows ``active`` held at their bound ``ub``.

    Both are over every row.  From (z, λ) (changed in place), until the residual converges at an
    evaluated point: (z, λ, ∇f, g, ∂g/∂z, ∇²L, energies, steps, active) there, or (None, steps)
    on no convergence, a singular matrix or too large a step.  ``first``: (∇f, g, ∂g/∂z, ∇²L)
    for the first step instead of an evaluation.

    At each evaluated iterate after the first step, while ``switches`` remain, one of the rows
    ``switchable`` changes: the most violated inactive row joins (excess over JOIN_TOLERANCE),
    else the active row with the most negative multiplier (below −LEAVE_TOLERANCE) leaves, its
    multiplier set to 0; an iterate where a row changed is not converged.  Waiting for
    convergence before each change (the outer loop in ``newton.newton``) spent 4–10 steps on an
    active set that the first step already showed to be wrong.  One row per iterate, because
    several at once over-constrain the sampled contact; the budget bounds a cycle, after which
    the set is held and the outer loop decides.
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
            switched = switch_one_row(g, lam, active, ub, switchable)
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


def switch_one_row(
    g: np.ndarray, lam: np.ndarray, active: np.ndarray, ub: np.ndarray, switchable: np.ndarray
) -> bool:
    """Change one of the rows ``switchable`` in ``active`` (in place); True if one changed.

    The most violated inactive row joins (excess over JOIN_TOLERANCE), else the active row with
    the most negative multiplier (below −LEAVE_TOLERANCE) leaves, its multiplier in ``lam`` set
    to 0.
    """
    excess = np.where(switchable & ~active, g - ub, -np.inf)
    negative = np.where(switchable & active, lam, np.inf)
    if excess.size and excess.max() > JOIN_TOLERANCE:
        active[np.argmax(excess)] = True
        return True
    if negative.size and negative.min() < -LEAVE_TOLERANCE:
        leave = np.argmin(negative)
        active[leave], lam[leave] = False, 0.0
        return True
    return False
