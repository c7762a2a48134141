"""The closest points of two strands of a smooth centreline, where a self-contact is held exactly.

A self-contact slot (``self_contact.py``) holds a pair of samples at least D = √((2r)² + h²/2)
apart: the sampling's price is a separation up to D − 2r ≈ h²/(8r) too wide (1.2e-3 L at
h = r = 0.01 L), which no refinement of the elements removes.  Where two strands touch while
crossing at an angle, the exact contact is one pair of points (σ_a, σ_b): the closest points of
the two strands, |x(σ_a) − x(σ_b)| = 2r, x_a − x_b normal to both tangents.  A slot held at the
closest points of the shape it is solved on, with the bound 2r, has the exact contact's
optimality conditions at a fixed point (the closest points' derivative is zero there, so the
distance's gradient is the one of the frozen pair).

``closest_points`` finds them by Newton on f(a, b) = |x(a) − x(b)|² from a sample pair, with
the curvature terms of the Hessian by central differences of the tangents.  It refuses (None)
where the strands are near parallel (|t_a × t_b| below ``MIN_SINE``): there the closest points
are ill-defined (a line contact) and the sampled rows stay.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: below this |t_a × t_b| the strands are too close to parallel for one pair of closest points
MIN_SINE = 0.3

#: Newton steps at most; the step tolerance is ``STEP`` · L
ITERATIONS, STEP = 30, 1e-13


@dataclass(frozen=True)
class ClosestPoints:
    """The closest points σ_a < σ_b [m] of two strands and their distance [m]."""

    s_a: float
    s_b: float
    distance: float


def closest_points(
    positions: Callable[[np.ndarray], np.ndarray],
    tangents: Callable[[np.ndarray], np.ndarray],
    a: float,
    b: float,
    window: float,
    length: float,
) -> ClosestPoints | None:
    """Return the closest points of the strands through s = ``a`` and ``b`` [m], or None.

    ``positions(s)`` / ``tangents(s)``: the centreline's points and unit tangents at the arc
    lengths s (len(s), 3).  Newton from (a, b), each step at most ``window`` / 4 [m]; None when
    the strands are near parallel, the answer leaves ``window`` of the start or [0, L], or
    Newton does not converge.
    """
    u = np.array([a, b], dtype=float)
    e = 1e-6 * length
    for _ in range(ITERATIONS):
        x = positions(u)
        t = tangents(np.array([u[0] - e, u[0], u[0] + e, u[1] - e, u[1], u[1] + e]))
        ta, tb = t[1], t[4]
        if np.linalg.norm(np.cross(ta, tb)) < MIN_SINE:
            return None
        ka, kb = (t[2] - t[0]) / (2 * e), (t[5] - t[3]) / (2 * e)
        d = x[0] - x[1]
        grad = np.array([d @ ta, -(d @ tb)])
        hess = np.array([[ta @ ta + d @ ka, -(ta @ tb)], [-(ta @ tb), tb @ tb - d @ kb]])
        step = np.linalg.solve(hess, -grad)
        step *= min(1.0, 0.25 * window / max(np.abs(step).max(), 1e-300))
        u = u + step
        if np.abs(u - [a, b]).max() > window or u.min() < 0 or u.max() > length:
            return None
        if np.abs(step).max() < STEP * length:
            x = positions(u)
            return ClosestPoints(float(u[0]), float(u[1]), float(np.linalg.norm(x[0] - x[1])))
    return None
