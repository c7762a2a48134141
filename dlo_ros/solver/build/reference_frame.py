"""The Euler angles' reference frame R0 of a scene, and whether the scene is planar in it.

``choose_reference_frame`` picks R0 so that the working plane's normal is the angles' singular
axis; ``planarity_violation`` says why a scene does not fit the planar model in a given plane.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from ...model.rotations import (
    farthest_pole,
    frame_with_pole,
    pole_angle_deg,
    quat_to_matrix,
    reference_frame,
)
from .structure import has_point_moments


#: a held grip tangent closer than this to the pole of the chord-and-gravity frame turns the pole
#: [deg]
GRIP_POLE_MIN_DEG = 30.0


def choose_reference_frame(problem: Problem, frame: str) -> np.ndarray:
    """R0 for the Euler angles: identity for 'paper'; for 'auto' the working plane's frame.

    The working plane holds the chord between the first two grips (or the first grip's tangent) and
    gravity; its normal becomes the singular axis n = R0 e_z, which planar and near-planar shapes
    avoid. When a held grip tangent lies within GRIP_POLE_MIN_DEG of that normal (grippers holding
    the string across the chord), n is instead the direction farthest from the held tangents and
    the chord — unless point moments are applied (they are modelled about the working-plane
    normal).
    """
    if frame == "paper":
        return np.eye(3)
    grips = sorted(problem.grips, key=lambda g: g.s)
    if (
        len(grips) >= 2
        and np.linalg.norm(grips[-1].pose.position - grips[0].pose.position)
        > 1e-9 * problem.string.length
    ):
        chord = grips[-1].pose.position - grips[0].pose.position
    else:
        chord = quat_to_matrix(grips[0].pose.orientation)[:, 0]
    up = -problem.gravity_unit
    if abs(np.dot(chord / np.linalg.norm(chord), up)) > 0.999:
        # chord along gravity: take the plane of the chord and the first grip's tangent or normal
        r = quat_to_matrix(grips[0].pose.orientation)
        up = r[:, 0] if abs(np.dot(r[:, 0], up)) < 0.999 else r[:, 1]
    r0 = reference_frame(chord, up)
    # a held tangent on (or near) the pole makes the grip's Euler angles singular: then turn the
    # pole to the direction farthest from the held tangents and the chord (planar scenes never need
    # this)
    held = [quat_to_matrix(g.pose.orientation)[:, 0] for g in grips if g.mode != "pin"]
    if (
        held
        and not has_point_moments(problem)
        and pole_angle_deg(np.array(held), r0[:, 2]) < GRIP_POLE_MIN_DEG
    ):
        normal, _ = farthest_pole(np.array(held + [chord / np.linalg.norm(chord)]))
        r0 = frame_with_pole(normal, -chord)
    return r0


def planarity_violation(problem: Problem, normal: np.ndarray, tolerance: float = 1e-9) -> str:
    """Say why the scene is not planar in a plane ('' if it is).

    Why the scene is not planar in the plane through the first grip with ``normal`` ('' if it
    is).

    Planar means: every grip position lies in the plane and every held tangent lies in it; gravity,
    forces and relative offsets lie in it; moments are along the normal; obstacles are half-spaces
    whose normals lie in the plane, or spheres/capsules/boxes centred on it (symmetric about it);
    a strip's (``string.lateral_bend_stiffness``) clamps hold its width (their y-axis, d1: the soft
    bending axis) along the normal, so that the planar model's one bending stiffness is its Rf.
    """
    n = normal / np.linalg.norm(normal)
    L = problem.string.length
    origin = problem.grips[0].pose.position
    for i, g in enumerate(problem.grips):
        off = abs(np.dot(g.pose.position - origin, n))
        if off > tolerance * L:
            return f"grips[{i}].position is {off:.3g} m out of the plane"
        if (
            g.mode != "pin"
            and abs(np.dot(quat_to_matrix(g.pose.orientation)[:, 0], n)) > tolerance
        ):
            return f"grips[{i}].orientation: the tangent leaves the plane"
        if (
            g.mode == "clamp"
            and problem.string.lateral_bend_stiffness is not None
            and abs(np.dot(quat_to_matrix(g.pose.orientation)[:, 1], n)) < 1 - tolerance
        ):
            return (
                f"grips[{i}].orientation: the strip's width (the grip's y-axis) is not normal to "
                "the plane (it would bend about its lateral axis)"
            )
    return _scene_planarity(problem, origin, n, tolerance)


#: ``_scene_planarity``'s verdicts by their inputs' bytes (cleared when full)
_SCENE_VERDICTS: dict[tuple, str] = {}


def _scene_planarity(problem: Problem, origin: np.ndarray, n: np.ndarray, tolerance: float) -> str:
    """Say why gravity, the loads, the offsets or the obstacles leave the plane ('' if none does).

    ``planarity_violation``'s tests of what does not move with the grips, in the plane through
    ``origin`` with unit normal ``n``.  A stream asks them of every planar target with the same
    scene: computed once per plane.
    """
    key = (
        np.asarray(origin, dtype=float).tobytes(),
        n.tobytes(),
        tolerance,
        problem.string.length,
        np.asarray(problem.gravity, dtype=float).tobytes(),
        tuple(
            np.concatenate([np.asarray(ld.force, float), np.asarray(ld.moment, float)]).tobytes()
            for ld in problem.loads
        ),
        tuple(np.asarray(rel.offset, dtype=float).tobytes() for rel in problem.relative_positions),
        tuple((ob.type, np.asarray(ob.params, dtype=float).tobytes()) for ob in problem.obstacles),
    )
    why = _SCENE_VERDICTS.get(key)
    if why is None:
        why = _scene_planarity_of(problem, origin, n, tolerance)
        if len(_SCENE_VERDICTS) >= 256:
            _SCENE_VERDICTS.clear()
        _SCENE_VERDICTS[key] = why
    return why


def _scene_planarity_of(
    problem: Problem, origin: np.ndarray, n: np.ndarray, tolerance: float
) -> str:
    """``_scene_planarity``, computed."""
    L = problem.string.length
    if abs(np.dot(problem.gravity_unit, n)) > tolerance:
        return "gravity.direction is not in the plane"
    for i, ld in enumerate(problem.loads):
        if abs(np.dot(ld.force, n)) > tolerance * (1 + np.linalg.norm(ld.force)):
            return f"loads[{i}].force is not in the plane"
        moment = np.asarray(ld.moment, dtype=float)
        across = moment - np.dot(moment, n) * n
        if np.linalg.norm(across) > tolerance * (1 + np.linalg.norm(moment)):
            return f"loads[{i}].moment is not along the plane's normal"
    for i, rel in enumerate(problem.relative_positions):
        if abs(np.dot(rel.offset, n)) > tolerance * L:
            return f"relative_positions[{i}].offset is not in the plane"
    for i, ob in enumerate(problem.obstacles):
        p = np.asarray(ob.params, dtype=float)
        why = ob.obstacle_type.planarity_violation(p, origin, n, tolerance, L)
        if why:
            return f"obstacles[{i}]: {why}"
    return ""
