"""Twist-free frames along a curve: the tangent director model's frames (no roll of its own)."""

from __future__ import annotations

import numpy as np

from .rotations import cross3

#: consecutive tangents closer than this to opposite (cos) carry d1 unrotated: their smallest
#: rotation has no defined axis
_OPPOSITE_COS = -0.999999


def transported_frames(t: np.ndarray, k0: int, hint: np.ndarray) -> np.ndarray:
    """Return twist-free frames transported along unit tangents.

    Frames (K, 3, 3) (columns t, d1, d2) along unit tangents t (K, 3) without twist: d1 at k0 is
    ``hint`` made perpendicular to t[k0], and is carried to its neighbours, both ways, by the
    smallest rotation between consecutive tangents (a discrete d1' = −(t'·d1) t).  The rotation
    from t[k0] to t[k] is the ordered product of those steps' quaternions, formed for every k at
    once by a prefix product (log2 K vectorised rounds) instead of a loop over k.
    """
    t = np.asarray(t, dtype=float)
    d1 = hint - np.dot(hint, t[k0]) * t[k0]
    d1 = d1 / np.linalg.norm(d1)
    steps = _smallest_rotations(t[:-1], t[1:])  # step k: t[k] -> t[k + 1]
    ahead = _prefix_products(steps[k0:])  # t[k0] -> t[k0 + 1 + j]
    behind = _prefix_products(_conjugate(steps[:k0][::-1]))  # t[k0] -> t[k0 - 1 - j]
    turns = np.concatenate([behind[::-1], [[1.0, 0.0, 0.0, 0.0]], ahead])
    d1s = _rotate(turns, d1)
    d1s /= np.linalg.norm(d1s, axis=1)[:, None]
    return np.stack([t, d1s, cross3(t, d1s)], axis=-1)


def _smallest_rotations(t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Return unit quaternions (w, x, y, z), (K, 4): the smallest rotations taking t0[k] to t1[k].

    (1 + c, t0 × t1) normalised, c = t0·t1: half the angle between them; the identity where they
    are (nearly) opposite.
    """
    c = np.sum(t0 * t1, axis=1)
    q = np.concatenate([(1.0 + c)[:, None], cross3(t0, t1)], axis=1)
    q[c < _OPPOSITE_COS] = (1.0, 0.0, 0.0, 0.0)
    return q / np.linalg.norm(q, axis=1)[:, None]


def _conjugate(q: np.ndarray) -> np.ndarray:
    """Return the inverse rotations of unit quaternions (K, 4)."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the quaternion products a b (rotation b first, then a), row by row, (K, 4)."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=1,
    )


def _prefix_products(q: np.ndarray) -> np.ndarray:
    """Return the running products p[j] = q[j] ⋯ q[1] q[0] (rotations in order), normalised.

    Hillis–Steele scan: after the round with offset h, p[j] is the product of q[max(0, j−2h+1)..j].
    """
    p = np.array(q, dtype=float, copy=True).reshape(-1, 4)
    h = 1
    while h < len(p):
        p[h:] = _multiply(p[h:], p[:-h])
        h *= 2
    return p / np.linalg.norm(p, axis=1)[:, None] if len(p) else p


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Return v (3,) rotated by each unit quaternion q (K, 4): v + 2w (u × v) + 2 u × (u × v)."""
    w, u = q[:, :1], q[:, 1:]
    uv = cross3(u, v[None, :])
    return v[None, :] + 2.0 * w * uv + 2.0 * cross3(u, uv)
