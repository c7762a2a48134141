"""How ``~/query_shape`` (nav_msgs/srv/GetPlan) says what its answer is; how a client reads it.

GetPlan's response is one nav_msgs/Path, so the status travels in ``plan.header.frame_id``
(msg_docs/node.md, ``~/query_shape``):

* a verified, stable equilibrium: ``frame_id`` is the node's frame, exactly, and ``poses`` the
  shape;
* anything else: ``frame_id`` is ``<node frame>#<kind>``, where ``<kind>`` is one of :data:`KINDS`;
  only ``unverified`` carries poses (the shape found, whose check did not pass or did not finish).

A suffix, not a zero stamp: a planner that transforms the plan with tf2 fails on an unknown frame
instead of silently using a shape that was not verified, and ``frame_id.partition('#')`` reads it.
Pure module: no rclpy (test/unit tests it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..solver.results.result import ShapeResult

SEPARATOR = "#"
VERIFIED = "verified"
#: the statuses a reply can have, besides VERIFIED
KINDS = (
    "unverified",  # a shape (poses given) that is not a verified equilibrium
    # none exists: grips beyond the string's reach, or infeasible (e.g. a grip in an obstacle)
    "no_equilibrium",
    "unstable",  # the equilibrium found is unstable and no stable one was found near it
    "failed",  # the solver did not converge: unknown whether an equilibrium exists
    "invalid",  # a bad request (pose, frame): nothing was solved
    "busy",  # too many queries pending: try again
    "not_ready",  # the solver is still being built: try again
    "inactive",  # a managed node that is not active: activate it first
)
#: ShapeResult.status -> reply kind (an 'ok' result is VERIFIED, or 'unstable' when stable is
#: False)
STATUS_KINDS = {
    "unverified": "unverified",
    "unreachable": "no_equilibrium",
    "infeasible": "no_equilibrium",
    "failed": "failed",
    "invalid": "invalid",
}


def result_kind(result: ShapeResult) -> str:
    """Return the reply kind of a solver's answer."""
    if result.status == "ok":
        return "unstable" if result.stable is False else VERIFIED
    return STATUS_KINDS.get(result.status, "failed")


def carries_shape(kind: str) -> bool:
    """Whether a reply of this kind has poses."""
    return kind in (VERIFIED, "unverified")


def reply_frame(frame_id: str, kind: str) -> str:
    """``plan.header.frame_id`` of a reply of this kind from a node in ``frame_id``."""
    if kind != VERIFIED and kind not in KINDS:
        raise ValueError(f"query reply kind: {kind!r} is not one of {(VERIFIED,) + KINDS}")
    return frame_id if kind == VERIFIED else f"{frame_id}{SEPARATOR}{kind}"


@dataclass(frozen=True)
class QueryAnswer:
    """A decoded ``~/query_shape`` reply: its status, the node's frame and the shape.

    ``status``: VERIFIED or one of KINDS; the shape: points (N, 3) [m], orientations (N, 4) x, y,
    z, w, empty unless carries_shape.
    """

    status: str
    frame_id: str
    points: np.ndarray
    orientations: np.ndarray

    @property
    def verified(self) -> bool:
        return self.status == VERIFIED


def decode(frame_id: str, points: np.ndarray, orientations: np.ndarray) -> QueryAnswer:
    """Decode a reply whose ``plan.header.frame_id`` and poses are these.

    Only a suffix in KINDS is a status (a frame id may itself contain '#'); an empty plan without
    one (a node from before this convention) reads as 'failed': never as verified.
    """
    frame, sep, kind = frame_id.rpartition(SEPARATOR)
    if not sep or kind not in KINDS:
        frame, kind = frame_id, VERIFIED
    if kind == VERIFIED and len(points) == 0:
        kind = "failed"
    return QueryAnswer(kind, frame, points, orientations)
