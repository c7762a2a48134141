"""What a scene lets auto leave out: obstacles out of reach or clear of the plane, and the plane.

Pure tests on a :class:`~dlo_ros.model.problem.Problem` (no solver): which obstacles the string
can reach from its grips, which a string lying in a plane could touch, whether the scene is planar
in a reference frame, whether the clamps impose twist, and whether the grips stretch an extensible
string from the start.  :mod:`.choice` and :class:`.auto_solver.AutoShapeSolver` decide with them.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from typing import Iterable

import numpy as np

from ...model.obstacles import Obstacle
from ...model.problem import Problem
from ...model.rotations import TANGENT_X, euler_from_frame, quat_to_matrix
from ..build.nlp import planarity_violation
from ..results.result import ShapeResult


def obstacle_distance(ob: Obstacle, x: np.ndarray) -> float:
    """Return a lower bound of the distance [m] from x to the obstacle (≤ 0 inside)."""
    p = np.asarray(ob.params, dtype=float)
    return ob.obstacle_type.distance_bound(np.asarray(x, dtype=float), p)


#: a shape's contacts are another's (``same_contacts``) while each obstacle's total contact force
#: stays within this factor of the other's
CONTACT_FORCE_FACTOR = 2.0


def touches_obstacle(result: ShapeResult) -> bool:
    """Tell whether the result presses on an obstacle (``pressed_obstacles``)."""
    return bool(pressed_obstacles(result))


def pressed_obstacles(result: ShapeResult) -> dict[int, float]:
    """Return the obstacles the result presses on: their total contact force [N], by key.

    A contact force above 1e-6 of the largest grip force counts (an interior-point answer leaves
    ~1e-10 N of barrier multipliers on samples that do not touch).
    """
    scale = max((float(np.linalg.norm(w.force)) for w in result.grips.values()), default=0.0)
    forces = {k: float(np.linalg.norm(f)) for k, f in result.contact_forces.items()}
    return {k: f for k, f in forces.items() if f > 1e-6 * max(scale, 1e-3)}


def same_contacts(a: dict[int, float], b: dict[int, float]) -> bool:
    """Tell whether two shapes press on the same obstacles with forces within CONTACT_FORCE_FACTOR.

    ``a``, ``b``: ``pressed_obstacles`` of each.
    """
    return a.keys() == b.keys() and all(
        b[k] <= CONTACT_FORCE_FACTOR * f and f <= CONTACT_FORCE_FACTOR * b[k] for k, f in a.items()
    )


def reachable_obstacles(problem: Problem, margin: float) -> tuple[int, ...]:
    """Return the indices of the obstacles the string can reach from every grip.

    An obstacle is reachable when, from each grip g, it lies within max(s_g, L − s_g) + ``margin``
    [m] (the string's radius included): the string cannot touch it otherwise.
    """
    L, r = problem.string.length, problem.string.radius
    keep = []
    for i, ob in enumerate(problem.obstacles):
        if all(
            obstacle_distance(ob, g.pose.position) - r <= max(g.s, L - g.s) + margin
            for g in problem.grips
        ):
            keep.append(i)
    return tuple(keep)


def clear_of_plane(ob: Obstacle, origin: np.ndarray, normal: np.ndarray, margin: float) -> bool:
    """Tell whether the obstacle is more than ``margin`` from the plane through ``origin``.

    ``normal``: the plane's unit normal.  A string lying in the plane cannot touch the obstacle, so
    the planar equilibrium is an equilibrium of the 3D problem with that obstacle inactive (the
    planar model leaves it out; its 3D stability is checked with it).
    """
    p = np.asarray(ob.params, dtype=float)
    return bool(ob.obstacle_type.clear_of_plane(p, origin, normal, margin))


def in_plane_obstacles(
    problem: Problem, obstacles: Iterable[int], r0: np.ndarray
) -> tuple[int, ...]:
    """Return the ``obstacles`` (indices) a string in the plane of ``r0`` could touch.

    The plane goes through the first grip with normal r0[:, 2]; an obstacle within the string's
    radius plus 1e-3·L of it counts as touchable.
    """
    origin, margin = (
        problem.grips[0].pose.position,
        problem.string.radius + 1e-3 * problem.string.length,
    )
    return tuple(
        i for i in obstacles if not clear_of_plane(problem.obstacles[i], origin, r0[:, 2], margin)
    )


def imposes_twist(problem: Problem, r0: np.ndarray) -> bool:
    """Tell whether the clamps' orientations differ by a rotation about the tangent.

    True when the ψ targets of the clamps are not all equal (and the string resists twist).
    """
    if problem.string.twist_stiffness.is_zero:
        return False
    clamps = tuple(
        np.asarray(g.pose.orientation, dtype=float).tobytes()
        for g in problem.grips
        if g.mode == "clamp"
    )
    return _clamps_twisted(np.asarray(r0, dtype=float).tobytes(), clamps)


@lru_cache(maxsize=64)
def _clamps_twisted(r0: bytes, clamps: tuple[bytes, ...]) -> bool:
    """``imposes_twist`` of the clamp orientations (quaternions) in the frame R0, as bytes.

    A stream asks it of every planar target, mostly with the clamps turned as before: computed
    once per orientation (the Euler angles' numpy calls took a planar stream's update 0.17 ms).
    """
    frame = np.frombuffer(r0).reshape(3, 3)
    psis = [
        euler_from_frame(frame, quat_to_matrix(np.frombuffer(q)) @ TANGENT_X.T)[2] for q in clamps
    ]
    return any(abs(np.angle(np.exp(1j * (p - psis[0])))) > 1e-9 for p in psis[1:])


def not_planar(
    problem: Problem, obstacles: Iterable[int], r0: np.ndarray, tolerance: float | None = None
) -> str:
    """Say why the scene is not planar in the plane of ``r0`` (normal r0[:, 2]); '' if it is.

    Only the ``obstacles`` (indices) are part of the scene tested.  ``tolerance``: that of
    ``planarity_violation`` (its default when None).
    """
    chosen = tuple(sorted(obstacles))
    everything = chosen == tuple(range(len(problem.obstacles)))
    scene = (
        problem
        if everything
        else replace(problem, obstacles=tuple(problem.obstacles[i] for i in chosen))
    )
    kw = {} if tolerance is None else {"tolerance": tolerance}
    return planarity_violation(scene, r0[:, 2], **kw) or (
        "the clamps impose twist" if imposes_twist(scene, r0) else ""
    )


def stretch_needed(problem: Problem, slack: float = 0.0) -> str:
    """Say why an extensible scene needs its stretch field from the start ('' if it does not).

    It does when two grips are farther apart than the inextensible string between them reaches,
    or taut: within ``slack``·span/L [m] of it ('' when none are, or when the string is
    inextensible).
    Taut matters because the inextensible model then leaves the string only the straight line
    between the two grips: a clamped pair twisted past Greenhill's threshold, or pushed by a
    sideways load, cannot buckle out of it, while the extensible string does by stretching a
    little.  The elongation bound (checks.py) cannot see that: the straight shape pulls on no
    grip.  (IPOPT also fails on that degenerate feasible set: Error_In_Step_Computation.)
    """
    if problem.string.stretch_stiffness is None:
        return ""
    L = problem.string.length
    pair = problem.farthest_apart(max(0.0, 1.0 - slack / L))
    if pair is None:
        return ""
    a, b, dist, _ = pair
    span = abs(a.s - b.s)
    if dist > span + 1e-12:
        return (
            f"extensible: grips {a.name!r} and {b.name!r} are {dist:.4g} m apart, "
            f"beyond the {span:.4g} m the inextensible string reaches"
        )
    return (
        f"extensible: grips {a.name!r} and {b.name!r} are {dist:.4g} m apart, within "
        f"{slack:.3g} m of the {span:.4g} m of string between them (taut: the inextensible "
        "model leaves only the straight line)"
    )
