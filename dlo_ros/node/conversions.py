"""Convert ROS messages <-> numpy, and build the node's output messages from a ShapeResult.

Pure functions: they build or read message objects but need no node, context or graph, so they are
unit-tested directly.  Conventions (see msg_docs/node.md): SI units, quaternions (x, y, z, w), a
centreline pose's x-axis along the string's tangent, wrenches in the node's frame about the grip
point.
"""

from __future__ import annotations

import struct
from typing import Callable, Mapping

import numpy as np

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3, WrenchStamped
from nav_msgs.msg import Path
from std_msgs.msg import Header

from ..model.rotations import quat_to_matrix
from ..solver.results.result import GripWrench, ShapeResult
from .validation import TargetError, Vector, check_frame, normalise_frame

# ---- time ---------------------------------------------------------------------------------------


def time_to_ns(stamp: Time) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_time(ns: int) -> Time:
    ns = int(ns)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(frame_id: str, stamp_ns: int) -> Header:
    return Header(frame_id=frame_id, stamp=ns_to_time(stamp_ns))


# ---- poses --------------------------------------------------------------------------------------


def pose_to_arrays(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,) [m], quaternion (4,) x, y, z, w) of a geometry_msgs/Pose, unchecked."""
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z], dtype=float), np.array([q.x, q.y, q.z, q.w], dtype=float)


def arrays_to_pose(position: Vector, orientation: Vector) -> Pose:
    p = [float(v) for v in position]
    q = [float(v) for v in orientation]
    return Pose(
        position=Point(x=p[0], y=p[1], z=p[2]),
        orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
    )


def pose_stamped(
    position: Vector, orientation: Vector, frame_id: str, stamp_ns: int
) -> PoseStamped:
    return PoseStamped(
        header=header(frame_id, stamp_ns), pose=arrays_to_pose(position, orientation)
    )


def quat_multiply(a: Vector, b: Vector) -> np.ndarray:
    """Hamilton product a ⊗ b of quaternions (x, y, z, w)."""
    ax, ay, az, aw = (float(v) for v in a)
    bx, by, bz, bw = (float(v) for v in b)
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def transform_pose(
    position: np.ndarray,
    orientation: np.ndarray,
    translation: Vector,
    rotation: Vector,
) -> tuple[np.ndarray, np.ndarray]:
    """Apply the transform (translation, rotation quaternion) to a pose: p' = R p + t, q' = r ⊗ q.

    E.g. a tf2 TransformStamped from the pose's frame into the target frame.
    """
    r = np.asarray(rotation, dtype=float)
    r = r / np.linalg.norm(r)
    p = quat_to_matrix(r) @ np.asarray(position, dtype=float) + np.asarray(
        translation, dtype=float
    )
    return p, quat_multiply(r, orientation)


def in_frame(
    frame_id: str,
    node_frame: str,
    position: np.ndarray,
    orientation: np.ndarray,
    where: str,
    lookup: Callable[[str, str], tuple[Vector, Vector]] | None = None,
):
    """(position, orientation) of a pose given in ``frame_id``, expressed in ``node_frame``.

    Same frame (a leading '/' ignored): returned as is.  Otherwise ``lookup(node_frame, frame_id)``
    (e.g. tf2's lookup_transform) gives (translation, rotation) from frame_id into node_frame;
    without a lookup, for an empty frame_id, or when the lookup raises, TargetError('frame') names
    the problem.
    """
    if frame_id and normalise_frame(frame_id) == normalise_frame(node_frame):
        return position, orientation
    if lookup is None or not frame_id:
        check_frame(frame_id, node_frame, where)  # raises
    assert lookup is not None  # for mypy: check_frame raised otherwise
    try:
        translation, rotation = lookup(normalise_frame(node_frame), normalise_frame(frame_id))
    except Exception as exc:  # noqa: BLE001 - tf2's lookup exceptions
        raise TargetError(
            "frame", f"{where}: no transform from '{frame_id}' to '{node_frame}': {exc}"
        ) from None
    return transform_pose(position, orientation, translation, rotation)


# ---- outputs ------------------------------------------------------------------------------------


def result_to_path(result: ShapeResult, frame_id: str, stamp_ns: int) -> Path:
    """Build the centreline: one PoseStamped per output sample, x-axis along the tangent."""
    h = header(frame_id, stamp_ns)
    poses = []
    for p, q in zip(result.points.tolist(), result.orientations.tolist()):
        poses.append(
            PoseStamped(
                header=h,
                pose=Pose(
                    position=Point(x=p[0], y=p[1], z=p[2]),
                    orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
                ),
            )
        )
    return Path(header=h, poses=poses)


def _cdr_header(stamp_ns: int, frame: bytes) -> bytes:
    """Serialise a std_msgs/Header in CDR, to go at a multiple of 4 after the encapsulation.

    Stamp (int32 sec, uint32 nanosec), frame_id (uint32 length with the NUL, the bytes, the NUL).
    """
    ns = int(stamp_ns)
    return (
        struct.pack("<iII", ns // 1_000_000_000, ns % 1_000_000_000, len(frame) + 1)
        + frame
        + b"\0"
    )


def path_cdr(points: np.ndarray, orientations: np.ndarray, frame_id: str, stamp_ns: int) -> bytes:
    """Serialise a nav_msgs/Path of these poses as little-endian CDR for ``publish(bytes)``.

    Every pose carries the path's header; no per-pose Python message objects.  Alignment follows
    CDR: 4-byte integers on 4, doubles on 8, offsets counted after the 4-byte encapsulation
    header.
    """
    head = _cdr_header(stamp_ns, frame_id.encode())
    out = bytearray(b"\x00\x01\x00\x00")  # CDR, little endian
    out += head
    out += b"\0" * (-(len(out) - 4) % 4)
    out += struct.pack("<I", len(points))
    rows = np.ascontiguousarray(np.concatenate([points, orientations], axis=1), dtype="<f8")
    if not len(rows):
        return bytes(out)
    # the first pose starts where the count left off (on 4)
    out += head
    out += b"\0" * (-(len(out) - 4) % 8)
    out += rows[0].tobytes()
    # every later pose starts on 8 (its predecessor ends with doubles): one layout, filled in for
    # all at once
    lead = len(head) + (-len(head) % 8)  # the header, then padding up to its pose's doubles
    blocks = np.zeros((len(rows) - 1, lead + 56), dtype=np.uint8)
    blocks[:, : len(head)] = np.frombuffer(head, dtype=np.uint8)
    blocks[:, lead:] = rows[1:].view(np.uint8).reshape(len(rows) - 1, 56)
    out += blocks.tobytes()
    return bytes(out)


def wrench_cdr(wrench: GripWrench, frame_id: str, stamp_ns: int) -> bytes:
    """Serialise ``wrench_stamped`` as little-endian CDR for ``Publisher.publish(bytes)``.

    The header, padding to 8, then force and torque as six doubles.
    """
    head = _cdr_header(stamp_ns, frame_id.encode())
    values = np.concatenate(
        [np.asarray(wrench.force, dtype="<f8"), np.asarray(wrench.torque, dtype="<f8")]
    )
    return b"\x00\x01\x00\x00" + head + b"\0" * (-len(head) % 8) + values.tobytes()


def result_path_cdr(result: ShapeResult, frame_id: str, stamp_ns: int) -> bytes:
    """``result_to_path`` serialised directly (:func:`path_cdr`)."""
    return path_cdr(result.points, result.orientations, frame_id, stamp_ns)


class CdrError(ValueError):
    """Bytes that are not the little-endian CDR of the expected message."""


def _cdr_header_at(data: bytes, offset: int) -> tuple[int, str, int]:
    """Read a std_msgs/Header at ``offset`` (aligned to 4): (stamp [ns], frame_id, next offset)."""
    sec, nanosec, length = struct.unpack_from("<iII", data, offset)
    start = offset + 12
    if length < 1 or start + length > len(data):
        raise CdrError(f"frame_id of length {length} runs past the message")
    return (
        sec * 1_000_000_000 + nanosec,
        data[start : start + length - 1].decode(errors="replace"),
        start + length,
    )


def path_from_cdr(data: bytes) -> tuple[int, str, np.ndarray, np.ndarray]:
    """Decode a serialised Path: (stamp [ns], frame_id, points (N, 3), quaternions (N, 4)).

    What a raw subscription takes: the inverse of :func:`path_cdr` for any Path, whatever its
    poses' headers.  No per-pose Python message objects: rclpy's deserialisation of a 51-pose
    Path costs several times more (bench/results/node_latency.md).  Raises CdrError on bytes that
    are not a little-endian Path.
    """
    if len(data) < 8 or data[:2] != b"\x00\x01":
        raise CdrError("not little-endian CDR")
    try:
        stamp, frame, offset = _cdr_header_at(data, 4)

        def pad(o: int, a: int) -> int:  # alignment counts from after the 4-byte prefix
            return o + (-(o - 4) % a)

        offset = pad(offset, 4)
        (count,) = struct.unpack_from("<I", data, offset)
        offset += 4
        if (
            count > (len(data) - offset) // 64
        ):  # a pose takes at least 64 bytes: never allocate for a lie
            raise CdrError(f"{count} poses do not fit in {len(data)} bytes")
        values = np.empty((count, 7))
        for k in range(count):
            _, _, offset = _cdr_header_at(data, pad(offset, 4))
            offset = pad(offset, 8)
            values[k] = struct.unpack_from("<7d", data, offset)
            offset += 56
    except struct.error as exc:
        raise CdrError(f"truncated Path: {exc}") from None
    return stamp, frame, values[:, :3], values[:, 3:]


def path_to_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(points (N, 3), quaternions (N, 4)) of a nav_msgs/Path."""
    if not path.poses:
        return np.zeros((0, 3)), np.zeros((0, 4))
    pts, qs = zip(*(pose_to_arrays(ps.pose) for ps in path.poses))
    return np.array(pts), np.array(qs)


def wrench_stamped(wrench: GripWrench, frame_id: str, stamp_ns: int) -> WrenchStamped:
    """Build the WrenchStamped of the force [N] and torque [N m] a gripper exerts on the string.

    Frame axes, torque about the grip point.
    """
    f = [float(v) for v in wrench.force]
    t = [float(v) for v in wrench.torque]
    msg = WrenchStamped(header=header(frame_id, stamp_ns))
    msg.wrench.force = Vector3(x=f[0], y=f[1], z=f[2])
    msg.wrench.torque = Vector3(x=t[0], y=t[1], z=t[2])
    return msg


def wrench_to_arrays(msg: WrenchStamped) -> tuple[np.ndarray, np.ndarray]:
    f, t = msg.wrench.force, msg.wrench.torque
    return np.array([f.x, f.y, f.z]), np.array([t.x, t.y, t.z])


# ---- diagnostics --------------------------------------------------------------------------------

LEVELS = {
    "ok": DiagnosticStatus.OK,
    "warn": DiagnosticStatus.WARN,
    "error": DiagnosticStatus.ERROR,
    "stale": DiagnosticStatus.STALE,
}


def format_value(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def diagnostic_status(
    name: str, level: str, message: str, hardware_id: str, values: Mapping[str, object]
) -> DiagnosticStatus:
    """Build a DiagnosticStatus; ``level`` is 'ok', 'warn', 'error' or 'stale'; values as text."""
    return DiagnosticStatus(
        level=LEVELS[level],
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=format_value(v)) for k, v in values.items()],
    )


def diagnostic_values(status: DiagnosticStatus) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}
