"""Stability of an equilibrium: the reduced Hessian of the Lagrangian, by inertia or eigenvalue.

    λ_min = min eig(Nᵀ ∇²L N),   N an orthonormal basis of the null space of the active rows'
    Jacobian

(the equality rows and the inequality rows at their bound or with λ > 0).  λ_min < 0 (beyond the
round-off of a neutral mode, ``is_stable``) means a direction along which the energy decreases
while every active constraint holds: the equilibrium is unstable, and its eigenvector is the way
out (``SolverState.unstable_direction``).  Units: Rf_max/L per (scaled unknown)², as the NLP's
objective.  ``stability_verdict`` (every result's) asks the inertia of [∇²L Jᵀ; J 0] first
(``inertia.py``): where it shows Nᵀ ∇²L N positive definite, stable, and λ_min is computed only
when read (``DeferredEigen``); elsewhere the eigenvalue decides, as here.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgeqp3 as _geqp3
from scipy.linalg.lapack import dorgqr as _orgqr
from scipy.linalg.lapack import dsyevr as _syevr

from ..native import settings
from ..build.functions import NlpFunctions
from ..update.newton import derivatives
from ..build.nlp import StringNLP
from ..state import Inertia, SolverState
from .inertia import stable_by_inertia
from .result import Later

#: what a result says when its active rows leave the shape no freedom (no eigenvalue, stable)
NO_FREEDOM = "stable: the constraints leave the shape no freedom (the reduced Hessian is empty)"


def min_reduced_eigenvalue(nlp: StringNLP, fns: NlpFunctions, state: SolverState) -> float | None:
    """Return λ_min of ``state`` (None when the active rows leave no freedom).

    λ_min of ``state`` (None when the active rows leave no freedom).  Fills the state's missing
    derivatives (Hessian, Jacobian, energies, gradient) and its ``unstable_direction``.  The pair
    the compiled loop computed with the state's Hessian (``SolverState.reduced_eigen``) is taken as
    it is: it reduces on the free rows, and a contact-free state's obstacle rows have zero Jacobian
    rows, which leave the null space as it is.
    """
    if isinstance(state.reduced_eigen, tuple) and state.hessian is not None:
        return _noted(state, state.reduced_eigen)
    return _noted(state, reduced_eigenpair(*held_derivatives(nlp, fns, state)))


def _noted(state: SolverState, pair: tuple[float, np.ndarray] | None) -> float | None:
    """Return λ_min of ``pair`` (None: no freedom), its eigenvector noted where it is negative."""
    if pair is None:
        return None
    value, direction = pair
    state.unstable_direction = signed(direction) if value < 0 else None
    return value


def stability_verdict(
    nlp: StringNLP, fns: NlpFunctions, state: SolverState
) -> tuple[bool, float | DeferredEigen | None]:
    """Return (stable, λ_min) of ``state``: the inertia first, the eigenvalue where it must.

    Stable by the inertia of [H Jᵀ; J 0] of the held rows (the compiled loop's verdict,
    ``Inertia.STABLE``, or ``inertia.stable_by_inertia`` here): (True, ``DeferredEigen``), λ_min
    computed only when read.  Otherwise (more negative eigenvalues, a tiny pivot, a rank-deficient
    J) λ_min as ``min_reduced_eigenvalue`` gives it, on the same H and J, and ``is_stable``'s
    verdict, or (True, None) when the held rows leave no freedom.  Both agree wherever λ_min's
    sign is clear of the neutral tolerance (test_inertia_verdict.py).  Fills the state's
    derivatives as ``min_reduced_eigenvalue``.
    """
    if isinstance(state.reduced_eigen, tuple) and state.hessian is not None:
        value = _noted(state, state.reduced_eigen)  # the compiled loop's pair
    else:
        by_loop = state.reduced_eigen is Inertia.STABLE and state.hessian is not None
        h, jac = held_derivatives(nlp, fns, state)
        if by_loop or stable_by_inertia(h, jac):
            state.unstable_direction = None
            # (jac: the held rows picked by a mask, a copy already)
            return True, DeferredEigen(np.array(h), jac)
        value = _noted(state, reduced_eigenpair(h, jac))
    if value is None:
        return True, None
    assert state.hessian is not None  # held_derivatives evaluated it
    return is_stable(value, state.hessian, state.unstable_direction), value


def held_derivatives(
    nlp: StringNLP, fns: NlpFunctions, state: SolverState
) -> tuple[np.ndarray, np.ndarray]:
    """Return (∇²L, the held rows' Jacobian) at ``state``, its missing derivatives evaluated.

    The Jacobian's rows are a new array (picked by the mask ``held_rows``); the Hessian, Jacobian,
    energies and gradient are filled in the state where it lacks them.
    """
    active = np.zeros(0, dtype=bool)
    if nlp.lbg.size:
        g = state.g if state.g is not None else np.asarray(nlp.g_fn(state.z, state.p)).ravel()
        active = held_rows(nlp.equality, nlp.ubg, state.lam_g, g)
    if state.hessian is None:
        gradient, _, state.jacobian, state.hessian, state.energies = derivatives(
            nlp, fns, state.z, state.p, state.lam_g, active
        )
        state.gradient = gradient.ravel()
    assert state.jacobian is not None  # evaluated with the Hessian
    return state.hessian, state.jacobian[active]


def reduced_eigenpair(h: np.ndarray, jac: np.ndarray) -> tuple[float, np.ndarray] | None:
    """Return λ_min of Nᵀ H N and its eigenvector N v in z (N: ``null_space(jac)``).

    None when the rows ``jac`` leave no freedom (N empty).
    """
    basis = null_space(jac) if jac.size else np.eye(h.shape[0])
    if basis.shape[1] == 0:
        return None
    value, vector = lowest_eigenpair(basis.T @ h @ basis)
    return value, basis @ vector


class DeferredEigen(Later[float]):
    """λ_min = min eig(Nᵀ H N) of a state judged stable by its inertia, worked out when first read.

    What ``ShapeResult.min_eigenvalue`` holds until read (``result.Deferred``): copies of H and
    the held rows' J (the state goes on to the next update), so that a caller who asks (the CLI's
    JSON, a dataset row, the node's diagnostics, a recording) gets the number
    ``min_reduced_eigenvalue`` gives, and a warm update that nobody asks pays only for the LDLᵀ.
    The rows leave freedom (the inertia counts m < n rows of full rank), so the value is a number,
    positive but for round-off.  Pickled as that number (``result.Later``).
    """

    def __init__(self, hessian: np.ndarray, jacobian: np.ndarray):
        super().__init__(lambda: _smallest(hessian, jacobian))


def _smallest(hessian: np.ndarray, jacobian: np.ndarray) -> float:
    """Return λ_min of Nᵀ H N (Rf_max/L per (scaled unknown)², as ``min_reduced_eigenvalue``)."""
    pair = reduced_eigenpair(hessian, jacobian)
    assert pair is not None  # m < n rows of full rank leave freedom
    return float(pair[0])


def held_rows(
    equality: np.ndarray, upper: np.ndarray, lam: np.ndarray, g: np.ndarray
) -> np.ndarray:
    """Return the rows the stability check holds, as a mask: the rows active at the answer.

    The equalities; the inequalities within STABILITY_BOUND_TOLERANCE of their bound ``upper``;
    and those with |λ| above STABILITY_MULTIPLIER_TOLERANCE and above their slack
    ``upper`` − g (scaled units).  An interior-point answer leaves λ·slack ≈ μ on every row, so a
    row far from its bound keeps a multiplier of μ/slack: 1.8e-10/slack on the random scenes,
    above 1e-9 on every row within 0.18 of its bound, which were held as if touching and left
    the shape "no freedom" (stable by accident).  An active row has λ ≫ slack, a free one
    slack ≫ λ.  The compiled loops hold the same rows (native/newton_active.c; one value,
    native/settings.py).
    """
    return (
        equality
        | (g > upper - settings.STABILITY_BOUND_TOLERANCE)
        | ((np.abs(lam) > settings.STABILITY_MULTIPLIER_TOLERANCE) & (np.abs(lam) > upper - g))
    )


def signed(direction: np.ndarray) -> np.ndarray:
    """Return the eigenvector with its sign fixed by its first large entry.

    An eigenvector with its sign fixed: LAPACK's sign is arbitrary, and rounding can flip it, so
    it is signed by its first entry above a tenth of the largest (not the largest: a mode of a
    near-symmetric shape has pairs of entries of equal size), so that two paths to the same saddle
    leave it the same way.
    """
    first = np.flatnonzero(np.abs(direction) > 0.1 * np.abs(direction).max())[0]
    return direction * np.sign(direction[first])


#: a negative λ_min counts as unstable below −NEUTRAL_TOLERANCE·|v|ᵀ|H||v| (``is_stable``)
NEUTRAL_TOLERANCE = 1e-8


def is_stable(min_eigenvalue: float, hessian: np.ndarray, direction: np.ndarray | None) -> bool:
    """Tell whether the smallest reduced eigenvalue makes the equilibrium stable.

    ``direction`` is the eigenvector of ``min_eigenvalue`` in the unknowns
    (``SolverState.unstable_direction``, set whenever it is negative).  A neutral mode (e.g.
    rotation about the chord without gravity) shows as a small eigenvalue of either sign; only
    one below −NEUTRAL_TOLERANCE·max(1, |v̂|ᵀ|H||v̂|) (v̂ = v/‖v‖) counts as unstable.  That
    scale is the componentwise bound on the rounding of v̂ᵀHv̂: the stiffness of the unknowns
    the mode itself moves, not the whole matrix's largest entry.  A strip's stiff axis sets
    max|H| (3.0e6 at Rl = 1e4·Rf) while its roll mode sees |v̂|ᵀ|H||v̂| = 476, so the old
    −1e-8·max|H| = −0.03 hid Prandtl's unstable mode at λ_min = −0.023 (test_strip.py).
    Over the stability suites (test_auto_stability, test_leave_saddle, test_greenhill_auto,
    test_self_contact, test_random_scenes, ...: 408 negative λ_min) neutral modes sit at most
    1e-3 of this threshold and unstable ones at least 2.8e3 times it.  Only the lowest pair is
    judged: a soft unstable mode above a stiff mode's larger round-off would go unseen.
    Without a direction the scale is unknown and the floor 1 is used (the strict verdict).
    """
    if min_eigenvalue >= 0.0:
        return True
    scale = 1.0
    if direction is not None:
        unit = np.abs(direction) / np.linalg.norm(direction)
        scale = max(scale, float(unit @ np.abs(hessian) @ unit))
    return bool(min_eigenvalue > -NEUTRAL_TOLERANCE * scale)


def lowest_eigenpair(a: np.ndarray) -> tuple[float, np.ndarray]:
    """Return the smallest eigenvalue of the symmetric matrix ``a`` and its unit eigenvector.

    Smallest eigenvalue of the symmetric matrix ``a`` and its unit eigenvector (LAPACK syevr for
    that one pair: a third of the time of a full eigendecomposition at the sizes here).
    """
    w, v, _, _, info = _syevr(a, compute_v=1, range="I", il=1, iu=1)
    if info != 0:
        values, vectors = np.linalg.eigh(a)
        return float(values[0]), vectors[:, 0]
    return float(w[0]), v[:, 0]


def null_space(a: np.ndarray) -> np.ndarray:
    """Return an orthonormal basis of {v : a v = 0} from a column-pivoted QR of aᵀ.

    Orthonormal basis of {v : a v = 0} from a column-pivoted QR of aᵀ (LAPACK geqp3,
    rank-revealing):
    rank = number of |R_kk| above max(a.shape)·eps·|R_00|, the tolerance scipy.linalg.null_space
    puts on singular values.  Half the time of an SVD at the sizes here.
    """
    m, n = a.shape
    qr, _, tau, _, info = _geqp3(np.array(a.T, order="F"))
    if info != 0:
        _, sv, vh = np.linalg.svd(a, full_matrices=True)
        rank = int(np.sum(sv > max(a.shape) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)))
        return vh[rank:].T.conj()
    k = min(m, n)
    d = np.abs(np.diagonal(qr)[:k])
    rank = int(np.sum(d > max(m, n) * np.finfo(float).eps * (d[0] if k else 0.0)))
    q_in = np.zeros((n, n), order="F")
    q_in[:, :k] = qr[:, :k]
    q, _, info = _orgqr(q_in, np.concatenate([tau[:k], np.zeros(n - k)]))
    return q[:, rank:]
