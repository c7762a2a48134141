"""Convert ``sensor_msgs/PointCloud2`` ↔ an (N, 3) array of observed points.

:func:`cloud_points` reads any duck-typed message with numpy alone; :func:`points_to_cloud`
builds a sensor_msgs message.

:func:`cloud_points` is what the node's ``~/observed`` subscription runs on a deserialised cloud.
It accepts ``x``, ``y``, ``z`` fields of datatype FLOAT32 or FLOAT64 (count 1) at any offsets
inside ``point_step`` (other fields are ignored), either byte order, organised (height > 1) or not,
and raises :class:`~dlo_ros.node.validation.TargetError` naming the offending field for anything
else: the frame, the size, the layout, NaN / infinity, too few or too many points.  Its cost is
bounded by ``max_points`` (the point count is checked before any point is read).
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

from .conversions import header
from .validation import TargetError, check_frame_size, normalise_frame, safe_text

#: sensor_msgs/PointField datatypes read as coordinates: FLOAT32 = 7, FLOAT64 = 8
FLOAT_TYPES = {7: "f4", 8: "f8"}
#: the datatype names, for messages (sensor_msgs/PointField constants)
TYPE_NAMES = {
    1: "INT8",
    2: "UINT8",
    3: "INT16",
    4: "UINT16",
    5: "INT32",
    6: "UINT32",
    7: "FLOAT32",
    8: "FLOAT64",
}
#: fewest points a fit can use (the observation file's minimum, dlo_ros.identify.observations)
MIN_POINTS = 3
#: bytes per point allowed for in the size limit of a serialised cloud (x, y, z, rgb, intensity,
#: normals, ...)
MAX_POINT_BYTES = 64
#: bytes of a serialised cloud beyond its points: header, field descriptions
CLOUD_OVERHEAD_BYTES = 64 * 1024


def cloud_bytes_limit(max_points: int) -> int:
    """Return the largest serialised ``~/observed`` message read for ``max_points`` points."""
    return int(max_points) * MAX_POINT_BYTES + CLOUD_OVERHEAD_BYTES


def cloud_points(msg, frame_id: str, max_points: int, where: str = "observed") -> np.ndarray:
    """Return the (N, 3) float64 points [m] of the PointCloud2 ``msg``, which is in ``frame_id``.

    Raises TargetError (kind 'frame', 'count', 'invalid' or 'non_finite') naming the field
    otherwise (module docstring).
    """
    width, height, step, row_step = _checked_layout(msg, frame_id, max_points, where)
    n = width * height
    order = ">" if msg.is_bigendian else "<"
    fields = {f.name: f for f in msg.fields}
    try:  # rclpy gives an array.array('B'): read in place
        raw = np.frombuffer(msg.data, np.uint8)
    except TypeError:  # a list of ints (a message built by hand)
        raw = np.asarray(msg.data, dtype=np.uint8)
    out = np.empty((n, 3))
    for k, axis in enumerate("xyz"):
        offset, nbytes, kind = _checked_field(fields, axis, step, where)
        # one strided view per row block: rows may be padded (row_step > width × point_step)
        view = np.lib.stride_tricks.as_strided(
            raw[offset:],
            shape=(height, width, nbytes),
            strides=(row_step, step, 1),
            writeable=False,
        )
        out[:, k] = np.ascontiguousarray(view).view(order + kind).reshape(n)
    bad = np.flatnonzero(~np.all(np.isfinite(out), axis=1))
    if bad.size:
        i = int(bad[0])
        axis = "xyz"[int(np.flatnonzero(~np.isfinite(out[i]))[0])]
        raise TargetError(
            "non_finite",
            f"{where}: point {i} (row {i // width}, column {i % width}): field '{axis}' is "
            f"{out[i, 'xyz'.index(axis)]}; {bad.size} point(s) are NaN or infinite (drop "
            "invalid points before publishing)",
        )
    return out


def _checked_layout(msg, frame_id: str, max_points: int, where: str) -> tuple[int, int, int, int]:
    """Check a cloud's frame, point count and sizes; return (width, height, point_step, row_step).

    The count is checked before any point is read, so the cost is bounded by ``max_points``.
    """
    cloud_frame = msg.header.frame_id
    check_frame_size(cloud_frame, where)
    if normalise_frame(cloud_frame) != normalise_frame(frame_id) or not cloud_frame:
        raise TargetError(
            "frame",
            f"{where}: header.frame_id is '{safe_text(cloud_frame, 80)}', not the node's frame "
            f"'{frame_id}' (clouds are not transformed: publish them in '{frame_id}')",
        )
    width, height, step, row_step = (
        int(msg.width),
        int(msg.height),
        int(msg.point_step),
        int(msg.row_step),
    )
    n = width * height
    if n < MIN_POINTS:
        raise TargetError(
            "count",
            f"{where}: width × height = {width} × {height} = {n} points; a fit needs at "
            f"least {MIN_POINTS}",
        )
    if n > max_points:
        raise TargetError(
            "count", f"{where}: width × height = {n} points, over fit.max_points = {max_points}"
        )
    if step <= 0 or row_step < width * step:
        raise TargetError(
            "invalid",
            f"{where}: point_step {step} and row_step {row_step} do not hold width {width} "
            "points per row",
        )
    size = len(msg.data)
    if size < row_step * (height - 1) + width * step:
        raise TargetError(
            "invalid",
            f"{where}: data holds {size} bytes, less than height {height} × row_step {row_step}",
        )
    return width, height, step, row_step


def _checked_field(fields: dict, axis: str, step: int, where: str) -> tuple[int, int, str]:
    """Check the field of one axis; return its (offset, bytes, numpy kind such as 'f4')."""
    f = fields.get(axis)
    if f is None:
        names = ", ".join(safe_text(name, 20) for name in list(fields)[:10]) or "none"
        raise TargetError(
            "invalid",
            f"{where}: fields: no field '{axis}' (fields: {names}); x, y, z are needed",
        )
    kind = FLOAT_TYPES.get(int(f.datatype))
    if kind is None:
        raise TargetError(
            "invalid",
            f"{where}: fields['{axis}'].datatype is "
            f"{TYPE_NAMES.get(int(f.datatype), int(f.datatype))}, not FLOAT32 or FLOAT64",
        )
    if int(f.count) != 1:
        raise TargetError("invalid", f"{where}: fields['{axis}'].count is {int(f.count)}, not 1")
    offset, nbytes = int(f.offset), int(kind[1])
    if offset < 0 or offset + nbytes > step:
        raise TargetError(
            "invalid",
            f"{where}: fields['{axis}'].offset {offset} + {nbytes} bytes is outside "
            f"point_step {step}",
        )
    return offset, nbytes, kind


def points_to_cloud(points: np.ndarray, frame_id: str, stamp_ns: int):
    """Build an unorganised PointCloud2 (height 1) of float32 x, y, z for ``points`` (N, 3) [m]."""
    pts = np.ascontiguousarray(np.asarray(points, dtype="<f4").reshape(-1, 3))
    return PointCloud2(
        header=header(frame_id, stamp_ns),
        height=1,
        width=len(pts),
        fields=[
            PointField(name=a, offset=4 * i, datatype=PointField.FLOAT32, count=1)
            for i, a in enumerate("xyz")
        ],
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(pts),
        data=pts.tobytes(),
        is_dense=True,
    )
