"""The wire format between a Recorder and its writer: snapshots of what was logged, as flat tuples.

A result or a target set is copied into a tuple of primitives and bytes (a few µs to build and to
pickle); :func:`decode` turns any queued message back into an :class:`QueueItem` for the writer.
Copies, never references into the caller's objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np


@dataclass
class QueueItem:
    """One queued message, decoded: its ``kind`` (the writer's ``_handle_<kind>``), when, what.

    ``update`` is the update number (None: static), ``ros_time_ns`` the ROS time [ns].
    """

    kind: str
    update: int | None
    ros_time_ns: int
    payload: Any = None


@dataclass
class ResultSnap:
    """What the writer draws of one ShapeResult, as plain data (the writer never imports it)."""

    status: str
    message: str
    stable: bool | None
    min_eigenvalue: float | None
    iterations: int
    solve_time_ms: float
    warm_started: bool
    warm_call: bool | None
    s: np.ndarray
    points: np.ndarray
    orientations: np.ndarray
    energy: dict
    forces: dict
    bend_stiffness: Any
    targets: dict | None = None
    model: dict = field(default_factory=dict)
    # one row per self-contact: s_a, s_b [m], point_a, point_b [m], force on s_a [N] (its opposite
    # acts on s_b)
    self_contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 11)))


@dataclass
class FitSnap:
    """A fit as the node recorded it: points, fitted centreline, residual feet, summary.

    A fit as the node recorded it: observed points, fitted centreline and each point's nearest
    point on it (m), the stated σ [m] and the robust loss's threshold [σ], the summary text,
    whether it was ok.
    """

    points: np.ndarray
    shape: np.ndarray
    feet: np.ndarray
    sigma: float
    huber: float
    text: str
    ok: bool


@dataclass
class EnvelopeSnap:
    """An envelope as the node recorded it: output points [m], tube radii k σ [m], summary."""

    points: np.ndarray
    radii: np.ndarray
    text: str


def _pose_bytes(pose: Any) -> bytes:
    pos, quat = (pose.position, pose.orientation) if hasattr(pose, "position") else pose
    return np.asarray(pos, dtype=float).tobytes() + np.asarray(quat, dtype=float).tobytes()


def encode_targets(poses: Mapping[str, Any], update: int, ros_time_ns: int) -> tuple:
    """Encode log_targets' message as a flat tuple of primitives and bytes.

    log_targets' message: a flat tuple of primitives and bytes (a few µs to build and to
    pickle).
    """
    return (
        "T",
        update,
        ros_time_ns,
        tuple(str(n) for n in poses),
        b"".join(_pose_bytes(p) for p in poses.values()),
    )


def _decode_poses(names: tuple, data: bytes) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    arr = np.frombuffer(data, dtype=float).reshape(len(names), 7)
    return {n: (arr[i, 0:3], arr[i, 3:7]) for i, n in enumerate(names)}


def encode_result(
    result: Any,
    update: int,
    ros_time_ns: int,
    bend_stiffness: Any,
    targets: Any,
    warm: bool | None,
    eigenvalue: bool = True,
) -> tuple:
    """log_result's message: the result copied into a flat tuple of primitives and bytes.

    ``eigenvalue``: record ``min_eigenvalue`` even where the solve left it to be worked out on
    first read (the inertia showed the shape stable); False records it only where it is known.
    """
    energy, grips = result.energy, result.grips
    if eigenvalue:
        eig = result.min_eigenvalue
    else:  # here, not at the top: the writer's child process imports this module, not the model
        from ..solver.results.result import known

        eig = known(result, "min_eigenvalue")
    return (
        "R",
        update,
        ros_time_ns,
        str(result.status),
        str(result.message),
        result.stable,
        None if eig is None else float(eig),
        int(result.iterations),
        float(result.solve_time_ms),
        (bool(result.warm_started), warm),
        tuple(energy),
        # a term that is None (a dead moment without a potential) travels as NaN
        np.array([np.nan if v is None else v for v in energy.values()], dtype=float).tobytes(),
        tuple(grips),
        b"".join(np.asarray(w.force, dtype=float).tobytes() for w in grips.values()),
        np.asarray(result.s, dtype=float).tobytes(),
        np.asarray(result.points, dtype=float).tobytes(),
        np.asarray(result.orientations, dtype=float).tobytes(),
        None if bend_stiffness is None else np.asarray(bend_stiffness, dtype=float).tobytes(),
        None
        if targets is None
        else (tuple(str(n) for n in targets), b"".join(_pose_bytes(p) for p in targets.values())),
        result.model_dict(),
        b"".join(
            np.concatenate([[c.s_a, c.s_b], c.point_a, c.point_b, c.force]).astype(float).tobytes()
            for c in getattr(result, "self_contacts", ())
        ),
    )


def decode(message: Any) -> QueueItem:
    """Decode a queued message (a QueueItem, or an encoded result or targets tuple)."""
    if isinstance(message, QueueItem):
        return message
    if message[0] == "T":
        _, update, t, names, data = message
        return QueueItem("targets", update, t, _decode_poses(names, data))
    (
        _,
        update,
        t,
        status,
        text,
        stable,
        eig,
        iterations,
        ms,
        warm,
        e_names,
        e_data,
        g_names,
        g_data,
        s,
        points,
        orientations,
        rf,
        targets,
        model,
        contacts,
    ) = message
    f = np.frombuffer(g_data, dtype=float).reshape(len(g_names), 3)
    bend = None if rf is None else np.frombuffer(rf, dtype=float)
    snap = ResultSnap(
        status=status,
        message=text,
        stable=stable,
        min_eigenvalue=eig,
        iterations=iterations,
        solve_time_ms=ms,
        warm_started=warm[0],
        warm_call=warm[1],
        s=np.frombuffer(s, dtype=float),
        points=np.frombuffer(points, dtype=float).reshape(-1, 3),
        orientations=np.frombuffer(orientations, dtype=float).reshape(-1, 4),
        energy=dict(zip(e_names, np.frombuffer(e_data, dtype=float).tolist())),
        forces={n: f[i] for i, n in enumerate(g_names)},
        bend_stiffness=None if bend is None else (float(bend[0]) if bend.size == 1 else bend),
        targets=None if targets is None else _decode_poses(*targets),
        model=model,
        self_contacts=np.frombuffer(contacts, dtype=float).reshape(-1, 11),
    )
    return QueueItem("result", update, t, snap)
