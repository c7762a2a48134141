"""The numbers the Python paths and the compiled Newton drivers (``native/*.c``) share: each once.

The drivers get them as ``-D`` flags (``defines``), and the compiled libraries' cache keys hash
those flags (``native_build``), so a change here reaches both paths and rebuilds the libraries.
The Python side reads them from this module at call time (``stability.min_reduced_eigenvalue``,
``newton``'s contact check).  Newton's step tolerances (``nlp.NEWTON_*``) reach the drivers as
call arguments instead, so they are single already.
"""

from __future__ import annotations

#: The stability check holds a row (reduces the Hessian on its null space) when |λ| exceeds
#: STABILITY_MULTIPLIER_TOLERANCE or g is within STABILITY_BOUND_TOLERANCE of its bound, besides
#: every equality row (scaled units).
STABILITY_MULTIPLIER_TOLERANCE = 1e-9
STABILITY_BOUND_TOLERANCE = 1e-9

#: After the contact-free loop converges, an obstacle row above its bound by more than this (scaled
#: units) means a contact appeared: the answer is no equilibrium of the whole problem, and Newton
#: goes on with that row active.
CONTACT_APPEARED_TOLERANCE = 1e-9

#: Return codes of the drivers' ``dlo_newton_run`` and ``dlo_newton_active_run``.
CONVERGED, NOT_CONVERGED, SINGULAR, STEP_TOO_LARGE, EVALUATION_FAILED = 0, 1, 2, 3, 4

#: Codes of the drivers' stability eigenpair: found, no freedom (the held rows fix every
#: unknown), LAPACK failed (the numpy path decides).
EIGEN_FOUND, EIGEN_NO_FREEDOM, EIGEN_FAILED = 0, 1, -1

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
)


def _literal(value: float | int) -> str:
    """A C literal of ``value`` that parses back to the same double or int: ``repr`` of a float is
    the shortest string that round-trips, and C's strtod rounds correctly.
    """
    text = repr(float(value)) if isinstance(value, float) else str(int(value))
    return f"({text})" if text.startswith("-") else text


def defines() -> tuple[str, ...]:
    """The settings as the compiler's ``-DDLO_<NAME>=<value>`` flags, read now (so a changed value
    gives other flags, and another library).
    """
    module = globals()
    return tuple(f"-DDLO_{name}={_literal(module[name])}" for name in _NAMES)
