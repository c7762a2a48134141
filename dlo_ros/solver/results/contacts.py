"""Which obstacles a result's string really presses on (what a report may call a contact).

``ShapeResult.contact_forces`` holds every obstacle's total multiplier force, including the
residue an interior-point solve leaves on rows far from their bound (IPOPT's barrier keeps
λ ≈ μ / gap > 0 on every inequality; ~1e-10 N for a cable hanging 5 cm above a table).  Such a
force is not a contact.  A report calls an obstacle *in contact* only when its force is nonzero
and the string comes within the answer's own error tolerance of it: the centreline is verified to
``solver.error_tolerance`` (default 1e-3·L), so a string farther than that from an obstacle's
surface cannot be touching it, and closer than that it cannot be told from touching.  The
numbers in ``contact_forces`` are left as they are (they feed the equilibrium residual).

``contact_loads`` splits the same multipliers into what the physics has: a distributed line load
[N/m] where consecutive rows all touch (the multipliers over the rows' quadrature weights; exact on
elements in contact along their length when the rows sit on the mesh's nodes,
``contact/obstacle_points.py``) and point forces where a contact is isolated.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from ..build.nlp import StringNLP
from ..build.slot_envelope import slot_contact_points
from ..contact.obstacle_points import index_runs
from .result import ContactLoad, ShapeResult


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


#: a row is in contact when its clearance is at most this × L (IPOPT's complementarity leaves an
#: active row ~1e-9 L off its bound; Newton's active set, exactly on it)
ROW_TOUCH = 1e-7

#: consecutive rows in contact that make a distributed load: two neighbours may share one point
#: contact that sits between them (a post between two nodes), three cannot
MIN_RUN = 3


def contact_loads(
    nlp: StringNLP, problem: Problem, z: np.ndarray, p: np.ndarray, lam_si: np.ndarray
) -> list[ContactLoad]:
    """Return the obstacles' contact forces as line loads and point forces (``ContactLoad``).

    Per obstacle, its rows on the surface (a clearance within ROW_TOUCH·L), trimmed to the first
    and last with a positive multiplier λ_j [N], that come MIN_RUN or more in a row along s are
    one 'line' load, f_j / w_j [N/m]
    at each (f_j = −λ_j ∇h(x_j), w_j the row's quadrature weight, ``nlp.obstacle_weights``:
    the mesh's LGL weights for rows on nodes); fewer are point forces, as is every touching
    contact slot.  ``lam_si``: the multipliers in SI (``λ_ipopt / (row_scale σ)``).
    """
    if not nlp.obstacle_rows or not np.any(lam_si[nlp.n_free_rows :] > 0):
        return []
    m, lay, L = nlp.model, nlp.params, nlp.length
    x = m.positions(z, nlp.obstacle_s)
    out: list[ContactLoad] = []
    for i, rows in enumerate(nlp.obstacle_rows):
        ob = problem.obstacles[i]
        lam = lam_si[rows]
        if nlp.obstacle_slots:  # a row a contact slot replaces holds no force
            lam = lam * p[lay[f"samples:{i}:on"]]
        gap = -ob.h_many(x) - problem.string.radius
        # a row on the surface belongs to its stretch even when its multiplier is zero
        touch = gap <= ROW_TOUCH * L
        forces = row_forces(nlp, ob, x, lam)
        for run in index_runs(np.flatnonzero(touch)):
            run = run[(run >= run[lam[run] > 0].min())] if np.any(lam[run] > 0) else run[:0]
            run = run[run <= run[lam[run] > 0].max()] if run.size else run
            if not run.size:
                continue
            if len(run) >= MIN_RUN:
                out.append(
                    ContactLoad(
                        i,
                        "line",
                        nlp.obstacle_s[run].copy(),
                        x[run],
                        forces[run].sum(axis=0),
                        forces[run] / nlp.obstacle_weights[run, None],
                    )
                )
            else:
                out += [
                    ContactLoad(i, "point", nlp.obstacle_s[[j]].copy(), x[[j]], forces[j])
                    for j in run
                ]
        out += _slot_loads(nlp, problem, i, z, p, lam_si)
    return out


def row_forces(nlp: StringNLP, ob, x: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Return −λ_j ∇h(x_j) (S, 3) [N] of every row (zero where λ_j ≤ 0)."""
    forces = np.zeros((len(lam), 3))
    on = np.flatnonzero(lam > 0)
    if on.size:
        grads = np.asarray(nlp.obstacle_gradient[ob.type](x[on].T, ob.params)).reshape(3, -1).T
        forces[on] = -lam[on, None] * grads
    return forces


def _slot_loads(
    nlp: StringNLP, problem: Problem, i: int, z: np.ndarray, p: np.ndarray, lam_si: np.ndarray
) -> list[ContactLoad]:
    """Return obstacle i's touching contact slots as point forces."""
    if not nlp.slot_rows:
        return []
    ob, lay, rows = problem.obstacles[i], nlp.params, np.asarray(nlp.slot_rows[i])
    touch = np.flatnonzero((lam_si[rows] > 0) & (p[lay[f"slots:{i}:on"]] > 0))
    if not touch.size:
        return []
    s, x, grads = slot_contact_points(
        nlp, ob.type, ob.params, problem.string.radius, z, p, i, touch
    )
    forces = -lam_si[rows[touch], None] * grads
    return [
        ContactLoad(i, "point", np.array([sk]), xk[None, :], f) for sk, xk, f in zip(s, x, forces)
    ]
