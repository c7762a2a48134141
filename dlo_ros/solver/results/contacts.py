"""Which obstacles a result's string really presses on (what a report may call a contact).

``ShapeResult.contact_forces`` holds every obstacle's total multiplier force, including the
residue an interior-point solve leaves on rows far from their bound (IPOPT's barrier keeps
λ ≈ μ / gap > 0 on every inequality; ~1e-10 N for a cable hanging 5 cm above a table).  Such a
force is not a contact.  A report calls an obstacle *in contact* only when its force is nonzero
and the string comes within the answer's own error tolerance of it: the centreline is verified to
``solver.error_tolerance`` (default 1e-3·L), so a string farther than that from an obstacle's
surface cannot be touching it, and closer than that it cannot be told from touching.  The
numbers in ``contact_forces`` are left as they are (they feed the equilibrium residual).
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from .result import ShapeResult


def obstacle_gap(problem: Problem, index: int, points: np.ndarray) -> float:
    """Return the smallest gap [m] between the string's surface and obstacle ``index``.

    Over the centreline ``points`` (N, 3) [m], with the string's radius: −(max h(x)) − r, where h
    is the obstacle's signed distance (positive inside).  Negative when the string enters it; inf
    without points.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(points):
        return float("inf")
    h = problem.obstacles[index].h_many(points)
    return float(-np.max(h) - problem.string.radius)


def contact_tolerance(problem: Problem, error_tolerance: float = 0.0) -> float:
    """Return the gap [m] within which a string may be in contact: the answer's error tolerance.

    ``error_tolerance``: ``solver.error_tolerance`` (0 means 1e-3·L, as the solver's default).
    """
    return error_tolerance or 1e-3 * problem.string.length


def pressed_obstacles(
    result: ShapeResult, problem: Problem, error_tolerance: float = 0.0
) -> dict[int, np.ndarray]:
    """Return the obstacles in contact (scene index → total force [N]), in contact_forces order.

    In contact: a nonzero force and a gap (:func:`obstacle_gap` over ``result.points``) within
    :func:`contact_tolerance`.  ``problem`` is the scene the result answers (its obstacles are the
    indices of ``contact_forces``).
    """
    tolerance = contact_tolerance(problem, error_tolerance)
    return {
        i: f
        for i, f in result.contact_forces.items()
        if np.linalg.norm(f) > 0 and obstacle_gap(problem, i, result.points) <= tolerance
    }
