"""Checks of incoming grip targets (pure: numpy and the model only, no ROS).

Every check raises :class:`TargetError`, whose ``kind`` says which class of bad input it is (the
node counts and throttles warnings per kind, and reports them in the diagnostics) and whose message
names the offending input (``grips/left/target: quaternion norm is 1.2, not 1 (tolerance 0.001)``).
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from ..model.problem import GripPose, PoseError
from ..text import TEXT_LIMIT as TEXT_LIMIT  # the node's modules import it from here
from ..text import safe_text

#: a vector given as numbers: a sequence or a numpy array
Vector = Sequence[float] | np.ndarray

#: Longest ``header.frame_id`` of a target (or ``frame_id`` parameter) the node accepts; tf2 frame
#: ids are short.
FRAME_ID_LIMIT = 256

#: Largest serialised target message (PoseStamped or PoseArray, CDR bytes) the node deserialises:
#: room for a 256-character frame_id and 64 poses (a scene has at most 16 grips), so a miscounted
#: array is still named by its count, and a huge one is refused by its size before any work.
TARGET_BYTES_LIMIT = 4096

#: |‖q‖ − 1| up to this is normalised silently; beyond it the target is rejected.
QUATERNION_TOLERANCE = 1e-3

#: The kinds of bad input and failures the node reports (diagnostics keys ``errors.<kind>``).
KINDS = (
    "size",  # a serialised target message over TARGET_BYTES_LIMIT bytes
    "non_finite",  # NaN or infinity in a position or quaternion
    "quaternion",  # zero or not unit within QUATERNION_TOLERANCE
    "frame",  # header.frame_id is not the node's frame (and no transform is available)
    "count",  # a PoseArray whose length is not the number of grips
    "unreachable",  # grips farther apart than the string between them reaches
    "invalid",  # anything else the solver refused as input
    "infeasible",  # IPOPT: no point satisfies the constraints (e.g. obstacles)
    "failed",  # the solver found no equilibrium
    "internal",  # an unexpected exception (a bug): reported, never fatal
    "inactive",  # a managed node that is not active refuses targets and queries
)


class TargetError(ValueError):
    """A rejected target; ``kind`` is one of :data:`KINDS`."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


def normalise_frame(frame_id: str) -> str:
    """tf2 frame ids carry no leading slash; ``/world`` and ``world`` are the same frame."""
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def check_message_size(n_bytes: int, where: str) -> None:
    """Raise TargetError('size') for a serialised message over :data:`TARGET_BYTES_LIMIT` bytes.

    Checked before it is deserialised.
    """
    if n_bytes > TARGET_BYTES_LIMIT:
        raise TargetError(
            "size",
            f"{where}: message of {n_bytes} bytes is over the limit of {TARGET_BYTES_LIMIT} "
            "bytes; it was not read",
        )


def check_frame_size(frame_id: str, where: str) -> None:
    """Raise TargetError('frame') for a ``header.frame_id`` over :data:`FRAME_ID_LIMIT` characters.

    Checked before anything compares, transforms, logs or records it.
    """
    if len(frame_id) > FRAME_ID_LIMIT:
        raise TargetError(
            "frame",
            f"{where}: header.frame_id has {len(frame_id)} characters (at most "
            f"{FRAME_ID_LIMIT}): '{safe_text(frame_id, 40)}'",
        )


def check_frame(frame_id: str, expected: str, where: str) -> None:
    """Raise TargetError('frame') unless ``frame_id`` names ``expected`` (empty is refused too)."""
    if not frame_id:
        raise TargetError(
            "frame", f"{where}: header.frame_id is empty; targets must be given in '{expected}'"
        )
    check_frame_size(frame_id, where)
    if normalise_frame(frame_id) != normalise_frame(expected):
        raise TargetError(
            "frame",
            f"{where}: header.frame_id is '{safe_text(frame_id, 80)}', not '{expected}' (no "
            "transform available: "
            "send targets in the node's frame_id or make tf2 available)",
        )


def check_pose(
    position: Vector,
    orientation: Vector,
    where: str,
    tolerance: float = QUATERNION_TOLERANCE,
) -> GripPose:
    """Return the checked GripPose, its quaternion normalised (``GripPose.checked``).

    GripPose.checked is the one pose validation; its PoseError becomes a TargetError of the same
    kind naming the problem.  position: (x, y, z) [m]; orientation: (x, y, z, w).
    """
    try:
        return GripPose.checked(position, orientation, where, tolerance)
    except PoseError as exc:
        raise TargetError(exc.kind, str(exc)) from None


def check_count(count: int, grip_names: Sequence[str], where: str) -> None:
    """TargetError('count') unless a PoseArray has one pose per configured grip."""
    if count != len(grip_names):
        raise TargetError(
            "count",
            f"{where}: {count} poses for {len(grip_names)} grips; send one pose per grip in the "
            f"order {list(grip_names)}",
        )


def grip_miss(
    points: np.ndarray,
    s: np.ndarray,
    grips: Iterable[tuple[str, float, np.ndarray]],
    tolerance: float,
) -> str:
    """Return why a converged shape misses its grip targets ('' if it does not).

    Also '' if no grip sits on an output sample.  A sanity check of the solver's result, never
    expected to fire.  points (N, 3), s (N,): the centreline; grips: (name, s, target position).
    """
    if len(s) == 0:
        return ""
    span = max(float(s[-1] - s[0]), 1.0)
    for name, sg, target in grips:
        k = int(np.argmin(np.abs(s - sg)))
        if abs(s[k] - sg) > 1e-9 * span:
            continue  # the grip is between output samples
        miss = float(np.linalg.norm(points[k] - np.asarray(target, dtype=float)))
        if not miss <= tolerance:
            return (
                f"the solver reported an equilibrium that misses grip '{name}' by {miss:.3g} m "
                f"(at {_fmt(points[k])}, target {_fmt(np.asarray(target, dtype=float))})"
            )
    return ""


def _fmt(a: np.ndarray) -> str:
    return "[" + ", ".join("nan" if math.isnan(v) else f"{v:.6g}" for v in a) + "]"
