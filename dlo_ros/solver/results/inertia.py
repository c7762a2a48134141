"""The stability verdict from the inertia of the held rows' KKT matrix, without an eigenvalue.

Sylvester's law of inertia: for J (m × n, the held rows' Jacobian) of full row rank,

    inertia([H Jᵀ; J 0]) = inertia(Nᵀ H N) + (m, m, 0),   N a basis of null(J),

so the reduced Hessian Nᵀ H N is positive definite (the equilibrium stable) exactly when the
KKT matrix K = [H Jᵀ; J 0] has n positive and m negative eigenvalues and no zero one.  The
Bunch–Kaufman factorisation K = P L D Lᵀ Pᵀ (LAPACK dsytrf, D of 1 × 1 and 2 × 2 blocks) gives
K's inertia as D's (Sylvester again: L is a congruence).  ``stable_by_inertia`` is True only for
inertia exactly (n, m, 0) with every eigenvalue of D's blocks above ``INERTIA_PIVOT_TOLERANCE``
· max(1, max|K|) in magnitude; every other case (more negative eigenvalues, a tiny pivot, a
rank-deficient J, a neutral mode) is left to the eigenvalue (``stability.min_reduced_eigenvalue``
and ``is_stable``'s neutral tolerance), so that the verdicts agree wherever λ_min's sign is clear
(test_inertia_verdict.py).  The compiled loops do the same in C (``native/dlo_inertia.h``:
the same routine, dsytrf with lwork = n + m, on the same matrix).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dsytrf as _sytrf

from ..native import settings


def kkt_matrix(hessian: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """Return K = [H Jᵀ; J 0] of the Hessian H (n × n) and the held rows' Jacobian J (m × n)."""
    n, m = hessian.shape[0], jacobian.shape[0]
    k = np.zeros((n + m, n + m))
    k[:n, :n] = hessian
    k[n:, :n] = jacobian
    k[:n, n:] = jacobian.T
    return k


def inertia(k: np.ndarray) -> tuple[int, int, int]:
    """Return (positive, negative, tiny) eigenvalue counts of the symmetric ``k`` from its LDLᵀ.

    Tiny: an eigenvalue of one of D's pivot blocks within ``INERTIA_PIVOT_TOLERANCE`` ·
    max(1, max|k|) of zero (its sign is round-off's); (0, 0, size) if LAPACK fails or D is
    singular.  A 2 × 2 block [a b; b c] has the eigenvalues (a + c)/2 ± hypot((a − c)/2, b), the
    smaller in magnitude taken as det / larger (no cancellation), as in C.
    """
    size = k.shape[0]
    tol = settings.INERTIA_PIVOT_TOLERANCE * max(1.0, float(np.abs(k).max(initial=0.0)))
    ldu, ipiv, info = _sytrf(k, lower=1)
    if info != 0:
        return 0, 0, size
    d = np.diagonal(ldu).copy()  # D's diagonal; each 2 × 2 block's two: its eigenvalues (below)
    # LAPACK marks both rows k, k + 1 of a 2 × 2 block with the same negative ipiv: the sorted
    # negative entries are those pairs, the last row never starts one
    first = np.flatnonzero(ipiv < 0)[0::2]
    first = first[first + 1 < size]
    a, b, c = ldu[first, first], ldu[first + 1, first], ldu[first + 1, first + 1]
    mean, radius = 0.5 * (a + c), np.hypot(0.5 * (a - c), b)
    large = np.where(mean >= 0.0, mean + radius, mean - radius)
    safe = np.where(large != 0.0, large, 1.0)
    d[first], d[first + 1] = large, np.where(large != 0.0, (a * c - b * b) / safe, 0.0)
    tiny = ~(np.abs(d) > tol)
    return int(np.sum(~tiny & (d > 0))), int(np.sum(~tiny & (d < 0))), int(np.sum(tiny))


def stable_by_inertia(hessian: np.ndarray, jacobian: np.ndarray) -> bool:
    """Tell whether the inertia alone shows Nᵀ H N positive definite (stable; see the module).

    False says nothing (the eigenvalue decides): also when the held rows leave no freedom
    (m ≥ n), which the eigenvalue path's rank-revealing QR judges.
    """
    n, m = hessian.shape[0], jacobian.shape[0]
    if m >= n:
        return False
    return inertia(kkt_matrix(hessian, jacobian)) == (n, m, 0)
