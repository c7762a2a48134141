"""What an update accepts: the grip poses checked, the reach of the string, the scene's structure.

Contract: pure functions of a ``Problem`` (and the options); nothing is solved.

* ``with_checked_poses``: a problem with new, validated grip poses (ValueError names the grip);
* ``admit``: the scene a solve is asked for, or the status and message that refuse it;
* ``unreachable_reason``: why the position constraints cannot all hold ('' when they can);
* ``structure_key`` / ``only_poses_differ``: whether two scenes share one NLP, and whether they
  differ in their grips' poses at most (then the warm start and the validation carry over).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...model.problem import GripPose, Problem
from ..build.nlp import StringNLP, planarity_violation
from ..options import SolverOptions


def structure_key(problem: Problem, options: SolverOptions) -> tuple:
    """Return what fixes the NLP's structure; problems with equal keys share one NLP."""
    return (
        problem.string.length,
        tuple((g.name, g.s, g.mode) for g in problem.grips),
        tuple(ld.s for ld in problem.loads),
        tuple((r.s_a, r.s_b) for r in problem.relative_positions),
        tuple(o.type for o in problem.obstacles),
        problem.string.stretch_stiffness is not None,
        problem.string.twist_stiffness.is_zero,
        problem.string.lateral_bend_stiffness is not None,  # a strip: p carries Rl (its layout)
        options,
    )


def only_poses_differ(problem: Problem, other: Problem) -> bool:
    """Whether ``problem`` is ``other`` but for its grips' poses.

    The same string, gravity, loads, obstacles and relative positions (the same objects), and grips
    of the same names, arc lengths and modes.  Then both validate alike (a pose is checked where it
    is made: ``GripPose.checked``) and share their NLP's structure (``structure_key``).
    """
    return (
        problem.string is other.string
        and problem.gravity is other.gravity
        and problem.loads is other.loads
        and problem.obstacles is other.obstacles
        and problem.relative_positions is other.relative_positions
        and len(problem.grips) == len(other.grips)
        and all(
            a.name == b.name and a.s == b.s and a.mode == b.mode
            for a, b in zip(problem.grips, other.grips)
        )
    )


def with_checked_poses(problem: Problem, poses: Mapping | None) -> Problem:
    """Return ``problem`` with new grip poses (GripPose or (position, quaternion) per grip name).

    Validated: unknown names, NaN and bad quaternions raise ValueError naming the grip.
    """
    if not poses:
        return problem
    names = {g.name for g in problem.grips}
    checked = {}
    for name, pose in poses.items():
        if name not in names:
            raise ValueError(f"grip {name!r}: unknown (configured grips: {sorted(names)})")
        pos, quat = (pose.position, pose.orientation) if isinstance(pose, GripPose) else pose
        checked[name] = GripPose.checked(pos, quat, f"grips.{name}")
    return problem.with_grip_poses(checked)


def unreachable_reason(problem: Problem, options: SolverOptions) -> str:
    """Return why the position constraints cannot all hold (empty string if they can)."""
    reach = 1.0 + (options.max_strain if problem.string.stretch_stiffness is not None else 0.0)
    pair = problem.farthest_apart(reach)
    if pair is not None:
        a, b, dist, span = pair
        return (
            f"grips {a.name!r} and {b.name!r} are {dist:.4g} m apart but the string between "
            f"them reaches at most {span:.4g} m"
        )
    for k, rel in enumerate(problem.relative_positions):
        dist = float(np.linalg.norm(rel.offset))
        if dist > abs(rel.s_b - rel.s_a) * reach + 1e-12:
            return (
                f"relative_positions[{k}].offset: {dist:.4g} m is longer than the string "
                f"between s_a and s_b"
            )
    return ""


def admit(
    problem: Problem,
    nlp: StringNLP,
    options: SolverOptions,
    poses: Mapping[str, GripPose | tuple] | None,
    checked: bool,
) -> Problem | tuple[str, str]:
    """Return ``problem`` with ``poses`` (``ShapeSolver.solve``'s), or (status, message).

    'invalid' for a pose that fails its checks or, for a planar model, leaves its plane;
    'unreachable' for grips farther apart than the string reaches (``unreachable_reason``).
    ``checked``: the poses are GripPose objects already validated and, for a planar model,
    already found in its plane.
    """
    try:
        admitted = (
            problem.with_grip_poses(poses)  # type: ignore[arg-type]  # checked: GripPose
            if checked and poses
            else with_checked_poses(problem, poses)
        )
    except (ValueError, KeyError) as exc:
        return "invalid", str(exc).strip("'\"")
    if nlp.planar and not checked:
        why = planarity_violation(admitted, nlp.r0[:, 2], tolerance=1e-7)
        if why:
            return "invalid", f"solver.model planar: {why}"
    reason = unreachable_reason(admitted, options)
    if reason:
        return "unreachable", reason
    return admitted
