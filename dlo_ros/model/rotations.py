"""Rotations, quaternions (x, y, z, w) and the Euler-angle convention of the string model.

Convention (Hirai & Wakamatsu, eq. 1, generalised by a constant reference rotation R0):
    Q(s) = R0 · Rz(−φ) · Ry(−θ) · Rz(−ψ)
is the material frame with columns (ξ, η, ζ); ζ is the unit tangent
    ζ = R0 · [−sinθ cosφ, sinθ sinφ, cosθ]ᵀ.
With R0 = I this is the paper's frame, whose singular direction (θ = 0) is the natural straight
state. The curvature and twist are frame-independent:  κ² = θ'² + sin²θ φ'²,  ω = φ' cosθ + ψ'.

Published poses use the ROS convention "x along the tangent": Q_out = Q · P with P e_x = e_z,
P e_y = e_x, P e_z = e_y, i.e. (x_out, y_out, z_out) = (ζ, ξ, η).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

#: Q_out = Q @ TANGENT_X, maps material axes (ξ, η, ζ) to ROS pose axes (x = ζ, y = ξ, z = η).
TANGENT_X = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return a × b over the last axis, with broadcasting.

    a × b over the last axis (3) with broadcasting: ``np.cross`` without its axis bookkeeping,
    which costs more than the arithmetic at the sizes here.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def rot_z(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about z by angles a (…) → (…, 3, 3)."""
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def rot_y(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about y by angles a (…) → (…, 3, 3)."""
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2
    )


def material_frames(
    r0: np.ndarray, phi: np.ndarray, theta: np.ndarray, psi: np.ndarray
) -> np.ndarray:
    """Q = R0 Rz(−φ) Ry(−θ) Rz(−ψ) for arrays of angles → (N, 3, 3), columns (ξ, η, ζ)."""
    return r0 @ rot_z(-np.asarray(phi)) @ rot_y(-np.asarray(theta)) @ rot_z(-np.asarray(psi))


def quat_multiply_matrices(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the matrices (L, R) of left and right quaternion multiplication.

    (L, R) with a ⊗ q = L q and q ⊗ b = R q for quaternions (x, y, z, w): a = ``left``, b =
    ``right``.
    """
    x, y, z, w = left
    lm = np.array([[w, -z, y, x], [z, w, -x, y], [-y, x, w, z], [-x, -y, -z, w]])
    x, y, z, w = right
    rm = np.array([[w, z, -y, x], [-z, w, x, y], [y, -x, w, z], [-x, -y, -z, w]])
    return lm, rm


def pose_quaternions(
    r0: np.ndarray, phi: np.ndarray, theta: np.ndarray, psi: np.ndarray
) -> np.ndarray:
    """Return the quaternions of the pose frames from the Euler angles.

    Quaternions (N, 4), (x, y, z, w) with w ≥ 0, of the pose frames Q·TANGENT_X, Q = R0 Rz(−φ)
    Ry(−θ) Rz(−ψ).

    The same rotations as ``matrix_to_quat(material_frames(r0, φ, θ, ψ) @ TANGENT_X)`` without
    building matrices: with a = −φ, b = −θ, c = −ψ the z-y-z product is
        q_zyz = (−sin(b/2) sin((a−c)/2), sin(b/2) cos((a−c)/2), cos(b/2) sin((a+c)/2), cos(b/2)
        cos((a+c)/2)),
    and the constant rotations R0 (left) and TANGENT_X (right) are one 4×4 matrix on it.
    """
    half_b = -0.5 * np.asarray(theta, dtype=float)
    diff = 0.5 * (np.asarray(psi, dtype=float) - np.asarray(phi, dtype=float))  # (a − c)/2
    summ = -0.5 * (np.asarray(phi, dtype=float) + np.asarray(psi, dtype=float))  # (a + c)/2
    sb, cb = np.sin(half_b), np.cos(half_b)
    q = np.stack(
        [-sb * np.sin(diff), sb * np.cos(diff), cb * np.sin(summ), cb * np.cos(summ)], axis=-1
    )
    q = q @ _frame_map(np.asarray(r0, dtype=float).tobytes())
    q[q[:, 3] < 0] *= -1.0
    return q


@lru_cache(maxsize=64)
def _frame_map(r0_bytes: bytes) -> np.ndarray:
    """Return the matrix that maps a row quaternion to its pose frame's.

    (L(q_R0) R(q_TANGENT_X))ᵀ: right-multiplying row quaternions by it applies R0 · (…) ·
    TANGENT_X.
    """
    lm, rm = quat_multiply_matrices(
        matrix_to_quat(np.frombuffer(r0_bytes).reshape(3, 3)), matrix_to_quat(TANGENT_X)
    )
    return (lm @ rm).T


def euler_from_frame(r0: np.ndarray, q: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`material_frames` for one frame, θ ∈ [0, π]; φ, ψ ∈ (−π, π].

    A = R0ᵀ Q = Rz(−φ) Ry(−θ) Rz(−ψ) gives cosθ = A33, (−cosφ, sinφ) sinθ = (A13, A23),
    (cosψ, sinψ) sinθ = (A31, A32).  At sinθ = 0 (the singular direction) ψ is set to 0.
    """
    a = r0.T @ q
    theta = float(np.arccos(np.clip(a[2, 2], -1.0, 1.0)))
    if np.hypot(a[0, 2], a[1, 2]) < 1e-12:
        # A = Rz(−φ) Ry(0 or −π) Rz(−ψ): only φ ± ψ is defined; put it all in φ.
        return float(np.arctan2(a[0, 1], a[1, 1])), theta, 0.0
    phi = float(np.arctan2(a[1, 2], -a[0, 2]))
    psi = float(np.arctan2(a[2, 1], a[2, 0]))
    return phi, theta, psi


def unwrap_to(angle: float, reference: float) -> float:
    """Return the angle + 2πk closest to ``reference`` (keeps multi-turn rotations continuous)."""
    return float(angle + 2.0 * np.pi * np.round((reference - angle) / (2.0 * np.pi)))


def slerp(q0: np.ndarray, q1: np.ndarray, t: float) -> np.ndarray:
    """Return the quaternion a fraction t of the shortest rotation from q0 to q1.

    The unit quaternion (x, y, z, w) a fraction t ∈ [0, 1] of the shortest rotation from q0 to
    q1.
    """
    q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
    q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:  # q and −q are one rotation: take the shorter arc
        q1, dot = -q1, -dot
    angle = np.arccos(min(dot, 1.0))
    if angle < 1e-9:
        q = q0 + t * (q1 - q0)
    else:
        q = (np.sin((1.0 - t) * angle) * q0 + np.sin(t * angle) * q1) / np.sin(angle)
    return q / np.linalg.norm(q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Return the rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=float)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) → quaternions (…, 4) as (x, y, z, w) with w ≥ 0."""
    # start-up: scipy.spatial.transform costs 0.30 s (python -X importtime, 3 runs) and nothing
    # else in dlo_ros.model needs scipy
    from scipy.spatial.transform import Rotation

    m = np.asarray(m, dtype=float)
    q = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    q[q[:, 3] < 0] *= -1.0
    return q.reshape(m.shape[:-2] + (4,))


class PoseError(ValueError):
    """A position or quaternion that cannot be used, and why (``kind``).

    A position or quaternion that cannot be used; ``kind``: 'invalid' (not numbers, wrong
    count), 'non_finite' (NaN or infinity) or 'quaternion' (zero, or not unit within the
    tolerance).
    """

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


def _numbers(value: object, n: int, field: str, what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise PoseError("invalid", f"{field}: expected {n} numbers{what}, got {value!r}") from None
    if arr.size != n:
        raise PoseError("invalid", f"{field}: needs {n} numbers{what}, got {arr.size}")
    # (math.isfinite on the few floats: np.isfinite's answer without its dispatch)
    if not all(map(math.isfinite, arr.tolist())):
        shown = ", ".join("nan" if np.isnan(v) else f"{v:.6g}" for v in arr)
        raise PoseError("non_finite", f"{field}: [{shown}] contains NaN or infinity")
    return arr


def check_position(p: object, field: str) -> np.ndarray:
    """Validate a position (x, y, z) [m].

    Validate a position (x, y, z) [m]: three finite numbers; PoseError naming ``field``
    otherwise.
    """
    return _numbers(p, 3, field, "")


def check_quaternion(q: object, field: str, tolerance: float = 1e-3) -> np.ndarray:
    """Validate a quaternion (x, y, z, w) and return it normalised.

    Validate a quaternion (x, y, z, w): finite, non-zero, unit within ``tolerance``; return it
    normalised.

    The one check of an orientation (scene files, grip targets, observations): PoseError (a
    ValueError) naming ``field`` otherwise.
    """
    arr = _numbers(q, 4, field, " (x, y, z, w)")
    norm = math.sqrt(float(arr.dot(arr)))  # np.linalg.norm's own sum, without its dispatch
    if norm < 1e-9:
        raise PoseError("quaternion", f"{field}: zero quaternion (no rotation)")
    if abs(norm - 1.0) > tolerance:
        raise PoseError(
            "quaternion",
            f"{field}: quaternion norm is {norm:.6g}, not 1 (tolerance {tolerance:g})",
        )
    return arr / norm


def reference_frame(chord: np.ndarray, up_hint: np.ndarray) -> np.ndarray:
    """Return R0 whose singular axis is normal to the chord and the up hint.

    R0 whose singular axis n = R0 e_z is normal to the plane spanned by ``chord`` and
    ``up_hint``.

    Columns (e1, e2, n) with e1 = −d (d the unit chord), n = d × up / |d × up|, e2 = n × e1 (= the
    part of ``up_hint`` normal to d).  The straight string along d is then φ = 0, θ = π/2: as far
    from the singularity θ ∈ {0, π} as possible, and a planar shape in that plane keeps θ ≡ π/2.
    """
    d = np.asarray(chord, dtype=float)
    dn = np.linalg.norm(d)
    d = d / dn if dn > 1e-12 else np.array([1.0, 0.0, 0.0])
    up = np.asarray(up_hint, dtype=float)
    n = np.cross(d, up)
    if np.linalg.norm(n) < 1e-9:
        for trial in (
            np.array([0.0, 0.0, 1.0]),
            np.array([0.0, 1.0, 0.0]),
            np.array([1.0, 0.0, 0.0]),
        ):
            n = np.cross(d, trial)
            if np.linalg.norm(n) > 1e-6:
                break
    n = n / np.linalg.norm(n)
    e1 = -d
    e2 = np.cross(n, e1)
    return np.stack([e1, e2, n], axis=1)


def pole_angle_deg(tangents: np.ndarray, normal: np.ndarray) -> float:
    """Return the smallest angle [deg] between the Euler angles' singular axis and the tangents.

    Smallest angle [deg] between the Euler angles' singular axis ``normal`` (n = R0 e_z) and the
    unit ``tangents`` (N, 3), either sign: 90° for a shape in the plane normal to n, 0° at the
    pole, where φ and ψ turn about the same axis and the fields get steep (slow convergence in the
    basis order).
    """
    t = np.asarray(tangents, dtype=float)
    t = t / np.linalg.norm(t, axis=1, keepdims=True)
    return float(
        np.degrees(
            np.arccos(np.clip(np.max(np.abs(t @ np.asarray(normal, dtype=float))), 0.0, 1.0))
        )
    )


def _hemisphere(count: int = 4000) -> np.ndarray:
    """Fibonacci points on the unit upper hemisphere (z ≥ 0), (count, 3)."""
    k = np.arange(count) + 0.5
    z = k / count
    r = np.sqrt(1.0 - z * z)
    a = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


def farthest_pole(tangents: np.ndarray) -> tuple[np.ndarray, float]:
    """Return the axis farthest from every tangent, and that angle [deg].

    (n, angle [deg]): the axis farthest from every tangent (maximises ``pole_angle_deg``),
    searched over 4000 directions (about 2° apart).
    """
    t = np.asarray(tangents, dtype=float)
    t = t / np.linalg.norm(t, axis=1, keepdims=True)
    candidates = _hemisphere()
    closest = np.max(np.abs(candidates @ t.T), axis=1)
    best = int(np.argmin(closest))
    return candidates[best], float(np.degrees(np.arccos(np.clip(closest[best], 0.0, 1.0))))


def frame_with_pole(normal: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """Return R0 = [e1, e2, n] with R0 e_z = ``normal``.

    R0 = [e1, e2, n] (right-handed) with R0 e_z = ``normal``; e1 is ``hint`` made normal to
    n.
    """
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    for h in (np.asarray(hint, dtype=float), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        e1 = h - np.dot(h, n) * n
        if np.linalg.norm(e1) > 1e-6:
            break
    e1 = e1 / np.linalg.norm(e1)
    return np.stack([e1, np.cross(n, e1), n], axis=1)


def quat_z_to(direction: np.ndarray) -> np.ndarray:
    """Return the quaternion of the shortest rotation taking +z to ``direction``.

    Quaternion (x, y, z, w) of the shortest rotation taking +z to ``direction`` (for
    markers/arrows).
    """
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, d))
    if c < -1 + 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    axis = np.cross(z, d)
    q = np.array([axis[0], axis[1], axis[2], 1.0 + c])
    return q / np.linalg.norm(q)
