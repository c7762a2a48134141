"""Warm updates by Newton's method on the KKT conditions, with a primal-dual active set.

For the equality rows and the inequality rows in the active set A (at first: those at their bound
with λ > 0 at the start):

    [∇²L  J_Aᵀ] [Δz]     [∇f + J_Aᵀ λ_A]
    [J_A    0 ] [Δλ] = − [g_A − g_bound ]

repeated until ‖∇f + J_Aᵀλ_A‖∞ < 1e-9 and ‖g_A − g_bound‖∞ < 1e-11 (scaled units).  At that point
the KKT conditions of the whole problem hold when every inactive row is within its bound and every
active inequality's λ ≥ 0.  Between steps, a contact row that the last step left violated (or with
a negative multiplier) already joins (leaves) A, one row per step and at most NEWTON_STEP_SWITCHES
times (``active_set.active_steps``).  If the converged point is still wrong, the active set
changes by one row, as in an active-set method: the most violated contact row (obstacle or
self-contact, ``StringNLP.contact_row``; a violated fold guard is no equilibrium and gives up)
joins A or, if none is violated, the active inequality with the most negative λ leaves it
(``active_set.next_active_set``); Newton goes on from that point, at most
``NEWTON_ACTIVE_SET_CHANGES`` times (a grip move of 1 % of L shifts the sampled contact of a cable
lying on a table by a sample or two).  An active set seen before (a cycle) is replaced by a
contact pair moved on by one row where the multipliers of a point judged in the cycle say the
contact slid past the pair (``active_set.shifted_pairs``).  A step larger than 0.5 in any scaled
unknown, no convergence in ``max_steps`` for one active set, a cycle with no such pair or too
many changes gives up: the caller then falls back to IPOPT.  Newton lands on the stationary point
nearest the start, so the caller still checks its stability.  Every update function returns (ok,
state, steps, constraint violation [m or rad]).

The rooms: this module holds the outer loop over active sets (``newton``) and the derivatives a
start or a stability check reuses (``fill_start``, ``derivatives``); ``active_set.py`` the steps
for one active set, ``contact_free.py`` the fast path while no obstacle row is active,
``kkt.py`` the pieces they share, ``saddle.py`` leaving a saddle by shifted steps.
"""

from __future__ import annotations

import numpy as np

from ..build.functions import NlpFunctions
from ..build.nlp import StringNLP
from ..native.settings import NEWTON_ACTIVE_SET_CHANGES
from ..state import SolverState
from .active_set import newton_active, shifted_pairs
from .contact_free import newton_free
from .kkt import active_rows, all_rows, violation


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
    """Update ``start`` to the parameters ``p`` by Newton steps (see the module docstring).

    While no obstacle row is active this is ``newton_free``; ``fused``: its first steps in one
    call of ``newton_step``.  ``kkt_fn``: another system of the same form as ``fns.kkt``
    (z, p, λ) → [∇f, g, ∂g/∂z, K, energies] (``moments.ExactMomentKKT``: K need not be
    symmetric); the returned state then carries that function's derivatives, not ∇²L.  ``prof``:
    the profiles of the string solved for (``OutputFunction.profiles``), given when the answer's
    outputs are wanted: a compiled loop then evaluates them in its call
    (``native.outputs.UpdateOutputs``, ``SolverState.outputs``).
    """
    if start.g is None:  # a warm start adopted from another model
        start.g = np.asarray(nlp.g_fn(start.z, start.p)).ravel()
    active = active_rows(nlp, start.lam_g, start.g)
    if nlp.obstacle_slots:  # a row p switches off (obstacle_slots.py) holds nothing
        active &= ~nlp.disabled_rows(p)
    steps = 0
    reuse = (
        kkt_fn is None
        and start.hessian is not None
        and start.g is not None
        and start.gradient is not None
    )
    if kkt_fn is None and not active[nlp.n_free_rows :].any():
        ok, state, steps, viol, contact = newton_free(nlp, fns, start, p, max_steps, fused, prof)
        if ok or contact is None:
            return ok, state, steps, viol
        # a contact appeared: go on from the contact-free answer with its most violated row active
        violated = contact.g - nlp.ubg
        violated[: nlp.n_free_rows] = 0.0
        z, lam, reuse = contact.z, contact.lam_g, False
        active = active.copy()
        active[np.argmax(violated)] = True
    else:  # (newton_active copies z and zeroes λ off the active rows itself)
        z, lam = start.z, start.lam_g
    # the compiled loop only for the compiled KKT function it was built with
    native = fns.newton_active if kkt_fn is None and fused else None
    kkt_fn = kkt_fn or fns.kkt
    seen = {active.tobytes()}
    judged: list[np.ndarray] = []  # the multipliers of each point judged, newest last
    for _ in range(NEWTON_ACTIVE_SET_CHANGES + 1):
        ok, reached, it, changed = newton_active(
            nlp, kkt_fn, start, z, lam, p, active, max_steps, reuse, native, prof
        )
        steps += it
        if ok:
            assert reached is not None and reached.g is not None  # an answer carries its g
            return True, reached, steps, violation(nlp, reached.g)
        if changed is None:  # no convergence
            break
        assert reached is not None  # a changed active set comes with the point it was judged at
        judged.append(reached.lam_g)
        if changed.tobytes() in seen:  # a cycle: a contact pair slid past its rows?
            moved = [m for lam_j in judged[::-1] for m in shifted_pairs(nlp, lam_j, changed)]
            changed = next((m for m in moved if m.tobytes() not in seen), None)
            if changed is None:
                break
        seen.add(changed.tobytes())
        z, lam, active, reuse = reached.z, reached.lam_g, changed, False
    return False, start, steps, np.inf


def fill_start(nlp: StringNLP, fns: NlpFunctions, state: SolverState) -> None:
    """Store in ``state`` the derivatives that a warm update's first step from it reuses.

    ``newton`` then need not evaluate them: the contact-free Newton matrix and residual when no
    obstacle row is active, else ∇f, g, ∂g/∂z and ∇²L over every row (λ of the inactive rows
    taken as 0, as Newton does).  For a state mapped from another model
    (``ShapeSolver.adopt_warm_start``), from which every query that model answers starts.
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


def derivatives(
    nlp: StringNLP,
    fns: NlpFunctions,
    z: np.ndarray,
    p: np.ndarray,
    lam: np.ndarray,
    active: np.ndarray,
) -> list[np.ndarray]:
    """Return [∇f, g, ∂g/∂z, ∇²L, energies] at (z, p, λ) for the rows ``active``.

    When no obstacle row is ``active`` (so λ is zero on them) the contact-free function is used:
    the obstacle rows' Jacobian rows are returned as zeros and left out of ∇²L, which is exact
    for every use here (only active rows' Jacobians are used, and inactive rows have λ = 0).
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
