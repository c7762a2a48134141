"""Rotation matrices of quaternions and back, for the director models (``model/director.py``).

Quaternions are (x, y, z, w), of any non-zero norm where a function says so; a frame's columns are
(t, d1, d2).  ``frame_columns`` serves CasADi and numpy alike; ``tangent_column`` is its first
column alone, by the same expressions (the same numbers, bit for bit); ``quat_to_frame`` of a few
quaternions works in Python floats, by the expressions of its numpy path in their order.
"""

from __future__ import annotations

import numpy as np


#: ``quat_to_frame`` of at most this many quaternions in Python floats (a stream's clamp frames:
#: numpy's per-call cost is most of the work at this size)
FEW_QUATERNIONS = 8


def quat_to_frame(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) of quaternions (…, 4) (x, y, z, w), any non-zero norm.

    The columns are ``frame_columns``' (t, d1, d2); a few quaternions in Python floats.
    """
    q = np.asarray(q, dtype=float)
    if q.ndim == 2 and q.shape[0] <= FEW_QUATERNIONS and q.shape[1] == 4:
        few = _few_quat_to_frame(q.tolist())
        if few is not None:
            return few
    columns = frame_columns(np.moveaxis(q, -1, 0), np)
    return np.stack([np.stack(column, -1) for column in columns], -1)


def _few_quat_to_frame(rows: list[list[float]]) -> np.ndarray | None:
    """``quat_to_frame`` of a few quaternions, by ``frame_columns`` on floats (the same numbers).

    None for a zero quaternion (numpy's path then gives its nan and warning).
    """
    out: list[float] = []
    for x, y, z, w in rows:
        if x * x + y * y + z * z + w * w == 0.0:
            return None
        t, d1, d2 = frame_columns((x, y, z, w), None)
        out += [t[0], d1[0], d2[0], t[1], d1[1], d2[1], t[2], d1[2], d2[2]]
    return np.array(out).reshape(len(rows), 3, 3)


def frame_to_quat(r: np.ndarray) -> np.ndarray:
    """Return the unit quaternions (…, 4) (x, y, z, w) of rotation matrices (…, 3, 3).

    Shepperd's method: each row from the largest of 1 + trace and the diagonal, so no division by
    a small number.
    """
    r = np.asarray(r, dtype=float)
    m = r.reshape(-1, 3, 3)
    d0, d1, d2 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    tr = d0 + d1 + d2
    which = np.argmax(np.stack([tr, d0, d1, d2], axis=1), axis=1)
    out = np.empty((m.shape[0], 4))
    k = which == 0
    if np.any(k):
        w = 0.5 * np.sqrt(1.0 + tr[k])
        mk = m[k]
        out[k] = np.stack(
            [
                (mk[:, 2, 1] - mk[:, 1, 2]) / (4 * w),
                (mk[:, 0, 2] - mk[:, 2, 0]) / (4 * w),
                (mk[:, 1, 0] - mk[:, 0, 1]) / (4 * w),
                w,
            ],
            axis=1,
        )
    for a in range(3):  # the largest diagonal entry is a: q_a first
        k = which == a + 1
        if not np.any(k):
            continue
        b, c = (a + 1) % 3, (a + 2) % 3
        mk = m[k]
        v = 0.5 * np.sqrt(np.maximum(1.0 + mk[:, a, a] - mk[:, b, b] - mk[:, c, c], 0.0))
        q = np.empty((mk.shape[0], 4))
        q[:, a] = v
        q[:, b] = (mk[:, a, b] + mk[:, b, a]) / (4 * v)
        q[:, c] = (mk[:, a, c] + mk[:, c, a]) / (4 * v)
        q[:, 3] = (mk[:, c, b] - mk[:, b, c]) / (4 * v)
        out[k] = q
    return out.reshape(r.shape[:-2] + (4,))


def continuous_signs(q: np.ndarray) -> np.ndarray:
    """Quaternions along s with signs flipped so that neighbours have a positive dot product."""
    q = np.array(q, dtype=float)
    for i in range(1, len(q)):
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] = -q[i]
    return q


def frame_columns(q, lib):
    """(t, d1, d2) of quaternion components (x, y, z, w) divided by |q|² (lib: casadi or numpy)."""
    x, y, z, w = q
    n2 = x * x + y * y + z * z + w * w
    t = [(w * w + x * x - y * y - z * z) / n2, 2 * (x * y + w * z) / n2, 2 * (x * z - w * y) / n2]
    d1 = [2 * (x * y - w * z) / n2, (w * w - x * x + y * y - z * z) / n2, 2 * (y * z + w * x) / n2]
    d2 = [2 * (x * z + w * y) / n2, 2 * (y * z - w * x) / n2, (w * w - x * x - y * y + z * z) / n2]
    return t, d1, d2


def tangent_column(q: np.ndarray) -> np.ndarray:
    """Return t (3, M), ``frame_columns``' first column alone, of quaternion rows q (4, M).

    (Or (3, K, M) of q (4, K, M): the same expressions elementwise.)

    The same expressions in the same order as ``frame_columns`` (so the same numbers, bit for
    bit), without the two columns a tangent does not need.
    """
    x, y, z, w = q
    n2 = x * x + y * y + z * z + w * w
    out = np.empty((3, *q.shape[1:]))  # (3, M), or (3, K, M) for stacked q
    np.divide(w * w + x * x - y * y - z * z, n2, out=out[0])
    np.divide(2 * (x * y + w * z), n2, out=out[1])
    np.divide(2 * (x * z - w * y), n2, out=out[2])
    return out
