"""The numbers the Python paths and the compiled Newton drivers (``native/*.c``) share: each once.

The drivers get them as ``-D`` flags (``defines``), and the compiled libraries' cache keys hash
those flags (``native.build``), so a change here reaches both paths and rebuilds the libraries.
The Python side reads them from this module at call time (``stability.min_reduced_eigenvalue``,
``newton``'s contact check).  Newton's step settings (``NEWTON_*``, ``JOIN_TOLERANCE``,
``LEAVE_TOLERANCE``) reach the drivers as call arguments instead; they live here too, beside the
others, and the Python Newton (``update/newton.py``) and ``build/newton_function.py`` read them
from here.
"""

from __future__ import annotations

#: Newton steps a contact-free warm update takes in one call (``StringNLP.newton_fn``): with the
#: start's own system as the first, a grip move of 1 % of L converges to |r| ~ 1e-14 in three.
NEWTON_STEPS = 3

#: A Newton step larger than this in any scaled unknown leaves the start's basin: IPOPT takes over.
NEWTON_MAX_STEP = 0.5
#: Active-set changes a warm Newton update may make before IPOPT takes over (``update/newton.py``).
NEWTON_ACTIVE_SET_CHANGES = 6
#: Contact rows that may join or leave between Newton steps, per active set, before it is held
#: (``update/active_set.py``).
NEWTON_STEP_SWITCHES = 4
#: A contact row joins the active set above this excess g − bound; an active one leaves below
#: −LEAVE_TOLERANCE multiplier (scaled units).
JOIN_TOLERANCE, LEAVE_TOLERANCE = 1e-9, 1e-12
#: A warm update has converged when ‖∇f + Jᵀλ‖∞ and ‖g − bound‖∞ (scaled units) are below these.
NEWTON_DUAL_TOLERANCE, NEWTON_PRIMAL_TOLERANCE = 1e-9, 1e-11
#: The compiled loops (``native/newton.py``, ``native/active.py``) take Newton's own steps while a
#: step exceeds NEWTON_CHORD_START in a scaled unknown (and, with an active set, until a check of
#: the rows changes none), then chord steps on the last factored matrix.  They have converged when,
#: besides the tolerances above, the last step is below NEWTON_CHORD_TOLERANCE (or no longer
#: shrinks: round-off); a step that shrinks by less than NEWTON_CHORD_CONTRACTION against the one
#: before has the matrix evaluated and factored anew; at most NEWTON_CHORD_STEPS steps.
NEWTON_CHORD_START, NEWTON_CHORD_TOLERANCE, NEWTON_CHORD_CONTRACTION, NEWTON_CHORD_STEPS = (
    0.05,
    1e-11,
    0.25,
    40,
)

#: Leaving a saddle by shifted Newton steps (``update/saddle.py``, ``native/saddle_escape.c``): the
#: first step's length (largest scaled unknown, as ``ipopt.escape_saddle``'s first step), which
#: also bounds every step, and the most shifted steps taken before the point reached is polished.
SADDLE_STEP, SADDLE_STEPS = 0.2, 40
#: The first step of a second try, both ways, where neither way of the first (SADDLE_STEP) reached
#: a stable point below the saddle: a weakly unstable saddle (λ_min ≈ −0.1) can rise over a step of
#: 0.2 before it falls, and the descent from there ends on another branch above the saddle (the
#: main job's cable lowered onto its post, update 409: IPOPT took the update instead, 60-100 ms).
SADDLE_RETRY_STEP = SADDLE_STEP / 8
#: The shifted steps stop once ‖∇f + J_Aᵀλ_A‖∞ and ‖g_A − bound‖∞ (scaled) are below these: Newton
#: polishes the point from there.
SADDLE_DUAL_TOLERANCE, SADDLE_PRIMAL_TOLERANCE = 1e-6, 1e-8
#: The shift μ: an uphill step is undone and μ ← SADDLE_SHIFT_GROWTH · max(μ, SADDLE_SHIFT_FLOOR ·
#: max|∇²L|); after an accepted step μ ← μ / SADDLE_SHIFT_DECAY, or 0 once below that floor.
SADDLE_SHIFT_GROWTH, SADDLE_SHIFT_DECAY, SADDLE_SHIFT_FLOOR = 4.0, 8.0, 1e-8

#: δ / max|K| of the regularised Newton matrix K + diag(δ I, −δ_λ I) of every warm update, and
#: δ_λ / (max|J|² / max|H|) (``update/kkt.py``, ``regularised``).
NEWTON_REGULARISATION = 1e-10

#: The stability check holds a row (reduces the Hessian on its null space) when g is within
#: STABILITY_BOUND_TOLERANCE of its bound, or |λ| exceeds STABILITY_MULTIPLIER_TOLERANCE and the
#: row's slack, besides every equality row (scaled units; ``results/stability.py``, held_rows).
STABILITY_MULTIPLIER_TOLERANCE = 1e-9
STABILITY_BOUND_TOLERANCE = 1e-9

#: After the contact-free loop converges, an obstacle row above its bound by more than this (scaled
#: units) means a contact appeared: the answer is no equilibrium of the whole problem, and Newton
#: goes on with that row active.
CONTACT_APPEARED_TOLERANCE = 1e-9

#: Return codes of the drivers' ``dlo_newton_run`` and ``dlo_newton_active_run``.
CONVERGED, NOT_CONVERGED, SINGULAR, STEP_TOO_LARGE, EVALUATION_FAILED = 0, 1, 2, 3, 4

#: Codes of the drivers' stability eigenpair: found, no freedom (the held rows fix every
#: unknown), LAPACK failed (the numpy path decides), stable by the inertia of the held rows' KKT
#: matrix (no eigenpair computed: ``native/dlo_inertia.h``, ``results/inertia.py``).
EIGEN_FOUND, EIGEN_NO_FREEDOM, EIGEN_FAILED, EIGEN_INERTIA_STABLE = 0, 1, -1, 2

#: The inertia of [∇²L Jᵀ; J 0] (``results/inertia.py``) counts only when every eigenvalue of its
#: LDLᵀ factor's pivot blocks D exceeds this times max(1, max|K|) in magnitude: a smaller one is
#: round-off's to sign, and the eigenvalue path (``stability.is_stable``) decides instead.
INERTIA_PIVOT_TOLERANCE = 1e-8

_NAMES = (
    "STABILITY_MULTIPLIER_TOLERANCE",
    "STABILITY_BOUND_TOLERANCE",
    "CONTACT_APPEARED_TOLERANCE",
    "CONVERGED",
    "NOT_CONVERGED",
    "SINGULAR",
    "STEP_TOO_LARGE",
    "EVALUATION_FAILED",
    "EIGEN_FOUND",
    "EIGEN_NO_FREEDOM",
    "EIGEN_FAILED",
    "EIGEN_INERTIA_STABLE",
    "INERTIA_PIVOT_TOLERANCE",
)


def _literal(value: float | int) -> str:
    """Return a C literal of ``value`` that parses back to the same double or int.

    A C literal of ``value`` that parses back to the same double or int: ``repr`` of a float is
    the shortest string that round-trips, and C's strtod rounds correctly.
    """
    text = repr(float(value)) if isinstance(value, float) else str(int(value))
    return f"({text})" if text.startswith("-") else text


def defines() -> tuple[str, ...]:
    """Return the settings as the compiler's ``-DDLO_<NAME>=<value>`` flags.

    The settings as the compiler's ``-DDLO_<NAME>=<value>`` flags, read now (so a changed value
    gives other flags, and another library).
    """
    module = globals()
    return tuple(f"-DDLO_{name}={_literal(module[name])}" for name in _NAMES)
