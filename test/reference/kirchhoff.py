"""Independent reference solver for static Kirchhoff rods (numpy + scipy only).

This module deliberately imports nothing from ``dlo_ros``: it is a second, independent
implementation used to check the package against.

Model
=====
Inextensible, unshearable, isotropic Kirchhoff rod of length ``L``, arc length ``s in [0, L]``,
bend stiffness ``Rf`` [N m^2], twist stiffness ``Rt`` [N m^2], weight per length ``D`` [N/m]
acting along the unit vector ``g`` (distributed force ``f = D g`` per length), optional dead point
forces ``F_k`` [N] and point moments ``M_k`` [N m] (world frame) at ``s_k``.

State along ``s`` (all vectors in the world frame):

* ``x(s)``  centre line position,
* ``R(s) = [t d1 d2]`` material frame (columns; ``t = x'`` is the unit tangent), stored as a unit
  quaternion ``q = (w, x, y, z)``,
* ``n(s)``  internal force, ``m(s)`` internal moment.

Sign convention: **n(s), m(s) are the force and the moment (about x(s)) that the part (s, L] exerts
on the part [0, s].**  Balance of a slice then gives the equations integrated here::

    x' = t
    R' = [w]x R,  w = R Omega  (world Darboux vector),
    Omega = (m.t / Rt, m.d1 / Rf, m.d2 / Rf)   (body curvature/twist in (t, d1, d2) components)
    n' = -f
    m' = -t x n   ( = n x t )

and at a point load ``(s_k, F_k, M_k)``::

    n(s_k+) = n(s_k-) - F_k,     m(s_k+) = m(s_k-) - M_k.

Loads at ``s_k = 0`` go straight into the clamp (they only change the reaction at s = 0 and the
energy); loads at ``s_k = L`` are applied before the end conditions (a free end with a tip force F
has ``n(L-) = F``, ``n(L+) = 0``).

Reactions (force/moment the gripper applies ON the rod, moments about the rod end point)::

    at s = 0:  F_0 = -n(0-) = -(n(0+) + sum_{s_k=0} F_k),   M_0 = -(m(0+) + sum_{s_k=0} M_k)
    at s = L:  F_L = +n(L+),                                M_L = +m(L+)

Energy (the quantity whose stationary points are the equilibria, up to the omitted moment work)::

    U = int_0^L [ 1/2 Rf (Omega_2^2 + Omega_3^2) + 1/2 Rt Omega_1^2 ] ds
        - int_0^L D g.x ds - sum_k F_k . x(s_k)

The work of point *moments* is not included (it is not a function of the frame alone without
choosing a rotation parametrisation); document/avoid point moments when comparing energies.

Numerics
========
Everything is made dimensionless internally: ``s~ = s/L``, ``x~ = x/L``, ``n~ = n L^2/Rf``,
``m~ = m L/Rf``, ``f~ = f L^3/Rf``, energy in units of ``Rf/L``.  Shooting (single or multiple): the
unknowns are ``n(0+), m(0+)`` and, for every interior node of the multiple-shooting grid, the full
state (position, a rotation vector relative to a reference quaternion, n, m).  Each segment is
integrated with ``scipy.integrate.solve_ivp`` (DOP853, rtol = atol = 1e-12).  The Jacobian of the
shooting map is computed by forward differences, integrating the base state and all perturbed
states of one segment *as one batched ODE system* (one shared step sequence, hence smooth
differences and the cost of roughly one integration).  Roots are found with a Gauss-Newton
iteration on the SVD of that Jacobian (minimum-norm steps, so rank-deficient Jacobians of genuine
solution families are fine), globalised by step halving / Levenberg-Marquardt damping, with
``scipy.optimize.root`` ('hybr', then 'lm') as fallbacks.

``residual`` in :class:`RodSolution` is the max-norm of the dimensionless shooting residual
(positions / L, rotation-vector components [rad], n L^2/Rf, m L/Rf).  ``solve_clamped`` raises
``RuntimeError`` when it cannot bring it below ``tol``.

Other tools
===========
* :func:`continuation` marches a parameter (previous solution as guess, optional secant predictor,
  step halving on failure).  Natural-parameter continuation stops at folds (limit points).
* :func:`boundary_jacobian`: the single-shooting Jacobian at given (n0, m0) (bifurcation points).
* :func:`discrete_stability`: second variation of a discrete rod built around a solution (shooting
  finds equilibria, stable or not).  :func:`relaxed_guess`: energy descent of that discrete rod from an
  unstable equilibrium, turned into a shooting guess (branch switching to a lower-energy state).
* :func:`frame_curvature_energy`: elastic energy from the sampled frames alone.
* :class:`blas_threads`: run with single-threaded OpenBLAS (much faster on a busy machine).

Caveats: no self-contact (loops may pass through themselves); isotropic cross-section only; when
both end tangents lie on the chord line and the rod is isotropic, every solution belongs to a
one-parameter family (rotation about the chord combined with a uniform material rotation): the
Jacobian is then singular and the solver returns one member of the family.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import numpy as np
from scipy.integrate import simpson, solve_ivp
from scipy.optimize import root

__all__ = [
    "RodSolution",
    "solve_clamped",
    "continuation",
    "secant_guess",
    "boundary_jacobian",
    "rot_x",
    "rot_y",
    "rot_z",
    "frame_curvature_energy",
    "discrete_stability",
    "relaxed_guess",
    "StabilityReport",
    "blas_threads",
]

RTOL = 1e-12
ATOL = 1e-12
_NSTATE = 14  # x(3), q(4), n(3), m(3), accumulated energy(1)


# --------------------------------------------------------------------------------------------
# small rotation helpers (quaternions are (w, x, y, z))
# --------------------------------------------------------------------------------------------
def rot_x(a: float) -> np.ndarray:
    """Rotation matrix about the world x axis by angle ``a``."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation matrix about the world y axis by angle ``a``."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation matrix about the world z axis by angle ``a``."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.array([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ])


def _qconj(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def _qexp(phi: np.ndarray) -> np.ndarray:
    """Unit quaternion of the rotation vector ``phi``."""
    a = float(np.linalg.norm(phi))
    if a < 1e-8:
        return np.array([1.0 - a * a / 8.0, *(0.5 * (1.0 - a * a / 24.0) * np.asarray(phi))])
    return np.array([np.cos(a / 2), *(np.sin(a / 2) / a * np.asarray(phi))])


def _qrotvec(q: np.ndarray) -> np.ndarray:
    """A rotation-vector-like residual of unit quaternion q: 2 sign(w) vec(q) (= rotation vector to
    first order; zero exactly for the identity rotation q = +-1)."""
    sgn = 1.0 if q[0] >= 0.0 else -1.0
    return 2.0 * sgn * np.asarray(q[1:4])


def _quat_to_rot(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a (not necessarily unit) quaternion."""
    w, x, y, z = q
    nq = w * w + x * x + y * y + z * z
    return np.array([
        [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ]) / nq


def _rot_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    cands = [tr, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                      (R[1, 0] - R[0, 1]) / (4 * w)])
    elif k == 1:
        x = 0.5 * np.sqrt(1.0 + 2 * R[0, 0] - tr)
        q = np.array([(R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x),
                      (R[0, 2] + R[2, 0]) / (4 * x)])
    elif k == 2:
        y = 0.5 * np.sqrt(1.0 + 2 * R[1, 1] - tr)
        q = np.array([(R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), y,
                      (R[1, 2] + R[2, 1]) / (4 * y)])
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * R[2, 2] - tr)
        q = np.array([(R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z),
                      (R[1, 2] + R[2, 1]) / (4 * z), z])
    return q / np.linalg.norm(q)


def _check_rotation(R, name: str) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 rotation matrix")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0:
        raise ValueError(f"{name} is not a rotation matrix")
    return R


def perp_basis(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = t / np.linalg.norm(t)
    a = np.eye(3)[int(np.argmin(np.abs(t)))]
    e1 = np.cross(t, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(t, e1)


def _rotvec_of_matrix(R: np.ndarray) -> np.ndarray:
    """Rotation vector (log map) of a rotation matrix near the identity."""
    return _qrotvec_exact(_rot_to_quat(R))


def _qrotvec_exact(q: np.ndarray) -> np.ndarray:
    q = q if q[0] >= 0 else -q
    v = q[1:4]
    sv = np.linalg.norm(v)
    if sv < 1e-12:
        return 2.0 * v
    return 2.0 * np.arctan2(sv, q[0]) * v / sv


# --------------------------------------------------------------------------------------------
# the solution object
# --------------------------------------------------------------------------------------------
@dataclass
class RodSolution:
    """A converged equilibrium (SI units, world frame; conventions in the module docstring).

    Arrays are sampled at ``s`` (which includes 0 and L).  At an interior point load the sampled
    n, m are the left limits n(s_k-), m(s_k-); at s = 0 they are n(0+), m(0+); at s = L they are
    n(L-), m(L-).  ``energy`` = elastic + gravity - point-force work (point-moment work omitted);
    ``elastic_energy`` is the first term alone.  ``force0/moment0`` and ``forceL/momentL`` are the
    gripper reactions on the rod (moments about the rod end points).  ``residual`` is the
    dimensionless max-norm shooting residual.
    """

    s: np.ndarray
    x: np.ndarray
    frames: np.ndarray
    n: np.ndarray
    m: np.ndarray
    energy: float
    residual: float
    elastic_energy: float = float("nan")
    force0: np.ndarray = field(default_factory=lambda: np.zeros(3))
    moment0: np.ndarray = field(default_factory=lambda: np.zeros(3))
    forceL: np.ndarray = field(default_factory=lambda: np.zeros(3))
    momentL: np.ndarray = field(default_factory=lambda: np.zeros(3))
    L: float = float("nan")
    Rf: float = float("nan")
    Rt: float = float("nan")
    info: dict = field(default_factory=dict, repr=False)
    _pieces: list = field(default_factory=list, repr=False)  # (s_a, s_b, OdeSolution) SI s

    # ---- dense evaluation ------------------------------------------------------------------
    def _raw(self, s: float, side: str = "left") -> np.ndarray:
        """Dimensionless 14-state at arc length s (SI), from the dense output of the pieces."""
        pieces = self._pieces
        if not pieces:
            raise RuntimeError("solution has no dense output")
        s = float(np.clip(s, 0.0, self.L))
        idx = None
        if side == "right":
            for i, (a, b, _) in enumerate(pieces):
                if a <= s < b:
                    idx = i
                    break
            if idx is None:
                idx = len(pieces) - 1
        else:
            for i, (a, b, _) in enumerate(pieces):
                if a < s <= b:
                    idx = i
                    break
            if idx is None:
                idx = 0
        a, b, sol = pieces[idx]
        return np.asarray(sol(s / self.L)).reshape(_NSTATE)

    def state(self, s: float, side: str = "left") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x, R, n, m) at arc length s in SI units (``side`` picks the limit at a piece boundary)."""
        y = self._raw(s, side)
        L, Rf = self.L, self.Rf
        return y[0:3] * L, _quat_to_rot(y[3:7]), y[7:10] * Rf / L**2, y[10:13] * Rf / L

    def position(self, s) -> np.ndarray:
        """Positions at arbitrary arc lengths (dense output of DOP853, 7th order): (3,) or (K, 3)."""
        s_arr = np.atleast_1d(np.asarray(s, dtype=float))
        out = np.array([self._raw(si)[0:3] * self.L for si in s_arr])
        return out[0] if np.ndim(s) == 0 else out

    @property
    def n0(self) -> np.ndarray:
        return self.n[0]

    @property
    def m0(self) -> np.ndarray:
        return self.m[0]

    @property
    def tangents(self) -> np.ndarray:
        return self.frames[:, :, 0]


class blas_threads:
    """Context manager limiting the bundled OpenBLAS libraries of numpy/scipy to ``n`` threads (and
    restoring the previous count).  On a busy machine, threaded BLAS makes the small dense linear
    algebra used here up to 100x slower.  Best effort: does nothing if no OpenBLAS is found."""

    _SET = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
            "openblas_set_num_threads64_", "openblas_set_num_threads")
    _GET = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
            "openblas_get_num_threads64_", "openblas_get_num_threads")

    def __init__(self, n: int = 1):
        self.n = int(n)
        self._saved: list = []

    @staticmethod
    def _libs():
        import ctypes
        try:
            with open("/proc/self/maps") as fh:
                paths = sorted({ln.split()[-1] for ln in fh
                                if "openblas" in ln.lower() and ln.split()[-1].startswith("/")})
        except OSError:
            return []
        out = []
        for pth in paths:
            try:
                out.append(ctypes.CDLL(pth))
            except OSError:
                pass
        return out

    def __enter__(self):
        import ctypes
        for lib in self._libs():
            setf = next((getattr(lib, s) for s in self._SET if hasattr(lib, s)), None)
            getf = next((getattr(lib, s) for s in self._GET if hasattr(lib, s)), None)
            if setf is None:
                continue
            prev = int(getf()) if getf is not None else None
            setf(ctypes.c_int(self.n))
            self._saved.append((setf, prev))
        return self

    def __exit__(self, *exc):
        import ctypes
        for setf, prev in self._saved:
            if prev is not None:
                setf(ctypes.c_int(prev))
        self._saved.clear()
        return False


class _BudgetExceeded(FloatingPointError):
    """A trial point with absurd curvature would take millions of ODE steps: treat as a failure."""


# --------------------------------------------------------------------------------------------
# the shooting problem
# --------------------------------------------------------------------------------------------
class _Problem:
    """Dimensionless (multiple-)shooting formulation; see the module docstring."""

    def __init__(self, L, Rf, Rt, x0, R0, x1, R1_or_tangent, mode_end, D, g, loads, segments):
        if mode_end not in ("clamp", "tangent", "pin", "free"):
            raise ValueError(f"unknown mode_end {mode_end!r}")
        if L <= 0 or Rf <= 0 or Rt <= 0:
            raise ValueError("L, Rf and Rt must be positive")
        self.L, self.Rf, self.Rt = float(L), float(Rf), float(Rt)
        self.rho = self.Rt / self.Rf
        g = np.asarray(g, dtype=float)
        gn = np.linalg.norm(g)
        self.ghat = g / gn if gn > 0 else np.zeros(3)
        self.D = float(D)
        self.f = self.D * self.L**3 / self.Rf * self.ghat  # dimensionless distributed force
        self._f = tuple(float(v) for v in self.f)
        self.mode_end = mode_end
        self.x0 = np.asarray(x0, dtype=float) / self.L
        self.q0 = _rot_to_quat(_check_rotation(R0, "R0"))
        self.x1 = None if x1 is None else np.asarray(x1, dtype=float) / self.L
        if mode_end in ("clamp", "tangent", "pin") and self.x1 is None:
            raise ValueError(f"mode_end={mode_end!r} needs x1")
        if mode_end == "clamp":
            self.q1 = _rot_to_quat(_check_rotation(R1_or_tangent, "R1"))
        elif mode_end == "tangent":
            t1 = np.asarray(R1_or_tangent, dtype=float)
            if t1.shape == (3, 3):
                t1 = t1[:, 0]
            self.t1 = t1 / np.linalg.norm(t1)
            self.e1, self.e2 = perp_basis(self.t1)
        # loads (dimensionless), sorted
        self.loads_si = []
        for ld in loads:
            sk, Fk, Mk = ld
            sk = float(sk)
            if not (0.0 <= sk <= self.L):
                raise ValueError(f"load position {sk} outside [0, L]")
            Fk = np.zeros(3) if Fk is None else np.asarray(Fk, dtype=float)
            Mk = np.zeros(3) if Mk is None else np.asarray(Mk, dtype=float)
            self.loads_si.append((sk, Fk, Mk))
        self.loads = [(sk / self.L, Fk * self.L**2 / self.Rf, Mk * self.L / self.Rf)
                      for sk, Fk, Mk in sorted(self.loads_si, key=lambda t: t[0])]
        self.N = int(segments)
        if self.N < 1:
            raise ValueError("segments must be >= 1")
        self.nodes = np.linspace(0.0, 1.0, self.N + 1)
        # pieces of every segment: (a, b, jump_n, jump_m) with the jump applied at b
        self.seg_pieces = []
        for i in range(self.N):
            a, b = self.nodes[i], self.nodes[i + 1]
            inner = sorted({sk for sk, _, _ in self.loads if a < sk < b})
            pts = [a, *inner, b]
            pcs = []
            for j in range(len(pts) - 1):
                pa, pb = pts[j], pts[j + 1]
                jn = np.zeros(3)
                jm = np.zeros(3)
                for sk, Fk, Mk in self.loads:
                    if sk == pb and sk > 0.0:
                        jn -= Fk
                        jm -= Mk
                pcs.append((pa, pb, jn, jm))
            self.seg_pieces.append(pcs)
        self.qref = [self.q0.copy() for _ in range(self.N)]
        self.nu = 6 + 12 * (self.N - 1)
        self.nfev = 0
        self._calls = 0
        self.max_rhs_calls = 40000  # per segment integration; normal ones need a few hundred

    # ---- ODE ---------------------------------------------------------------------------------
    def rhs(self, s, y):
        self._calls += 1
        if self._calls > self.max_rhs_calls:
            raise _BudgetExceeded("too many ODE steps (absurd curvature at a trial point)")
        if y.size == _NSTATE:
            return self._rhs1(y)
        Y = y.reshape(_NSTATE, -1)
        a, b, c, d = Y[3], Y[4], Y[5], Y[6]
        n0, n1, n2 = Y[7], Y[8], Y[9]
        m0, m1, m2 = Y[10], Y[11], Y[12]
        inv = 1.0 / (a * a + b * b + c * c + d * d)
        aa, bb, cc, dd = a * a, b * b, c * c, d * d
        bc, ad, bd, ac, cd, ab = b * c, a * d, b * d, a * c, c * d, a * b
        t0 = (aa + bb - cc - dd) * inv
        t1 = 2.0 * (bc + ad) * inv
        t2 = 2.0 * (bd - ac) * inv
        u0 = 2.0 * (bc - ad) * inv
        u1 = (aa - bb + cc - dd) * inv
        u2 = 2.0 * (cd + ab) * inv
        v0 = 2.0 * (bd + ac) * inv
        v1 = 2.0 * (cd - ab) * inv
        v2 = (aa - bb - cc + dd) * inv
        O1 = (m0 * t0 + m1 * t1 + m2 * t2) / self.rho
        O2 = m0 * u0 + m1 * u1 + m2 * u2
        O3 = m0 * v0 + m1 * v1 + m2 * v2
        dY = np.empty_like(Y)
        dY[0], dY[1], dY[2] = t0, t1, t2
        dY[3] = 0.5 * (-b * O1 - c * O2 - d * O3)
        dY[4] = 0.5 * (a * O1 + c * O3 - d * O2)
        dY[5] = 0.5 * (a * O2 + d * O1 - b * O3)
        dY[6] = 0.5 * (a * O3 + b * O2 - c * O1)
        f = self.f
        dY[7] = -f[0]
        dY[8] = -f[1]
        dY[9] = -f[2]
        dY[10] = n1 * t2 - n2 * t1
        dY[11] = n2 * t0 - n0 * t2
        dY[12] = n0 * t1 - n1 * t0
        dY[13] = 0.5 * (self.rho * O1 * O1 + O2 * O2 + O3 * O3) - (f[0] * Y[0] + f[1] * Y[1] + f[2] * Y[2])
        return dY.reshape(-1)

    def _rhs1(self, y):
        """Same as :meth:`rhs` for a single state, in plain float arithmetic (much faster than
        numpy on 14-element arrays)."""
        x0, x1, x2, a, b, c, d, n0, n1, n2, m0, m1, m2, _ = y.tolist()
        inv = 1.0 / (a * a + b * b + c * c + d * d)
        aa, bb, cc, dd = a * a, b * b, c * c, d * d
        bc, ad, bd, ac, cd, ab = b * c, a * d, b * d, a * c, c * d, a * b
        t0 = (aa + bb - cc - dd) * inv
        t1 = 2.0 * (bc + ad) * inv
        t2 = 2.0 * (bd - ac) * inv
        O1 = (m0 * t0 + m1 * t1 + m2 * t2) / self.rho
        O2 = (m0 * 2.0 * (bc - ad) + m1 * (aa - bb + cc - dd) + m2 * 2.0 * (cd + ab)) * inv
        O3 = (m0 * 2.0 * (bd + ac) + m1 * 2.0 * (cd - ab) + m2 * (aa - bb - cc + dd)) * inv
        f0, f1, f2 = self._f
        return np.array([
            t0, t1, t2,
            0.5 * (-b * O1 - c * O2 - d * O3),
            0.5 * (a * O1 + c * O3 - d * O2),
            0.5 * (a * O2 + d * O1 - b * O3),
            0.5 * (a * O3 + b * O2 - c * O1),
            -f0, -f1, -f2,
            n1 * t2 - n2 * t1,
            n2 * t0 - n0 * t2,
            n0 * t1 - n1 * t0,
            0.5 * (self.rho * O1 * O1 + O2 * O2 + O3 * O3) - (f0 * x0 + f1 * x1 + f2 * x2),
        ])

    def integrate_segment(self, i: int, Y0: np.ndarray, dense: bool = False):
        """Integrate segment i from the (14, B) start states Y0 (jumps at load points applied).

        Returns the (14, B) end states, and with ``dense`` the list of (a, b, OdeSolution)."""
        Y = np.array(Y0, dtype=float, copy=True)
        B = Y.shape[1]
        self._calls = 0
        dense_list = []
        for pa, pb, jn, jm in self.seg_pieces[i]:
            sol = solve_ivp(self.rhs, (pa, pb), Y.reshape(-1), method="DOP853", rtol=RTOL, atol=ATOL,
                            dense_output=dense)
            self.nfev += sol.nfev
            if sol.status != 0 or not np.all(np.isfinite(sol.y[:, -1])):
                raise FloatingPointError(f"integration failed on segment {i}: {sol.message}")
            Y = sol.y[:, -1].reshape(_NSTATE, B).copy()
            if dense:
                dense_list.append((pa, pb, sol.sol))
            Y[7:10] += jn[:, None]
            Y[10:13] += jm[:, None]
        return (Y, dense_list) if dense else Y

    # ---- unknowns ----------------------------------------------------------------------------
    def block(self, i: int) -> slice:
        return slice(0, 6) if i == 0 else slice(6 + 12 * (i - 1), 6 + 12 * i)

    def start_state(self, i: int, ub: np.ndarray) -> np.ndarray:
        y = np.zeros(_NSTATE)
        if i == 0:
            y[0:3] = self.x0
            y[3:7] = self.q0
            y[7:13] = ub
        else:
            y[0:3] = ub[0:3]
            y[3:7] = _qmul(self.qref[i], _qexp(ub[3:6]))
            y[7:13] = ub[6:12]
        return y

    def unknowns_from_states(self, n0m0: np.ndarray, node_states: Sequence[np.ndarray]) -> np.ndarray:
        """Build u from (n~0, m~0) and the dimensionless states at nodes 1..N-1 (resets qref)."""
        u = np.zeros(self.nu)
        u[0:6] = n0m0
        for i in range(1, self.N):
            y = node_states[i - 1]
            q = np.asarray(y[3:7], dtype=float)
            self.qref[i] = q / np.linalg.norm(q)
            blk = self.block(i)
            u[blk] = np.concatenate([y[0:3], np.zeros(3), y[7:10], y[10:13]])
        return u

    def unknowns_from_single_shot(self, n0m0: np.ndarray) -> np.ndarray:
        y = self.start_state(0, n0m0)
        nodes = []
        for i in range(self.N - 1):
            y = self.integrate_segment(i, y[:, None])[:, 0]
            nodes.append(y.copy())
            y = y.copy()
            y[13] = 0.0
        return self.unknowns_from_states(n0m0, nodes)

    # ---- residual ----------------------------------------------------------------------------
    def end_residual(self, E: np.ndarray) -> np.ndarray:
        x, q, n, m = E[0:3], E[3:7] / np.linalg.norm(E[3:7]), E[7:10], E[10:13]
        if self.mode_end == "clamp":
            return np.concatenate([x - self.x1, _qrotvec(_qmul(_qconj(self.q1), q))])
        if self.mode_end == "tangent":
            t = _quat_to_rot(q)[:, 0]
            return np.concatenate([x - self.x1, [t @ self.e1, t @ self.e2, m @ t]])
        if self.mode_end == "pin":
            return np.concatenate([x - self.x1, m])
        return np.concatenate([n, m])  # free

    def assemble(self, ends: Sequence[np.ndarray], u: np.ndarray) -> np.ndarray:
        res = []
        for i in range(self.N - 1):
            E = ends[i]
            ys = self.start_state(i + 1, u[self.block(i + 1)])
            qe = E[3:7] / np.linalg.norm(E[3:7])
            res.append(E[0:3] - ys[0:3])
            res.append(_qrotvec(_qmul(_qconj(ys[3:7]), qe)))
            res.append(E[7:13] - ys[7:13])
        res.append(self.end_residual(ends[self.N - 1]))
        return np.concatenate(res)

    def ends(self, u: np.ndarray) -> list[np.ndarray]:
        return [self.integrate_segment(i, self.start_state(i, u[self.block(i)])[:, None])[:, 0]
                for i in range(self.N)]

    def fun(self, u: np.ndarray) -> np.ndarray:
        try:
            return self.assemble(self.ends(u), u)
        except FloatingPointError:
            return np.full(self.nu, 1e6)

    def fun_jac(self, u: np.ndarray, h_rel: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
        """Residual and forward-difference Jacobian (one batched integration per segment)."""
        u = np.asarray(u, dtype=float)
        base_ends, pert = [], []
        steps = h_rel * np.maximum(1.0, np.abs(u))
        for i in range(self.N):
            blk = self.block(i)
            ub = u[blk]
            cols = [self.start_state(i, ub)]
            for j in range(ub.size):
                ubj = ub.copy()
                ubj[j] += steps[blk][j]
                cols.append(self.start_state(i, ubj))
            Yend = self.integrate_segment(i, np.array(cols).T)
            base_ends.append(Yend[:, 0].copy())
            pert.append(Yend)
        F = self.assemble(base_ends, u)
        J = np.empty((self.nu, self.nu))
        for i in range(self.N):
            blk = self.block(i)
            for j in range(blk.stop - blk.start):
                k = blk.start + j
                ends_j = list(base_ends)
                ends_j[i] = pert[i][:, 1 + j]
                uj = u.copy()
                uj[k] += steps[k]
                J[:, k] = (self.assemble(ends_j, uj) - F) / steps[k]
        return F, J

    # ---- solution ----------------------------------------------------------------------------
    def build_solution(self, u: np.ndarray, residual: float, s_eval, info: dict) -> RodSolution:
        L, Rf = self.L, self.Rf
        pieces = []
        e_total = 0.0
        ends = []
        for i in range(self.N):
            y0 = self.start_state(i, u[self.block(i)])
            Y, dl = self.integrate_segment(i, y0[:, None], dense=True)
            ends.append(Y[:, 0])
            e_total += Y[13, 0]
            pieces.extend((pa * L, pb * L, sol) for pa, pb, sol in dl)
        if s_eval is None:
            s_eval = np.linspace(0.0, L, 401)
        s_eval = np.asarray(s_eval, dtype=float)
        s_all = np.unique(np.concatenate([s_eval, [0.0, L], [sk for sk, _, _ in self.loads_si]]))
        sol = RodSolution(s=s_all, x=np.empty((s_all.size, 3)), frames=np.empty((s_all.size, 3, 3)),
                          n=np.empty((s_all.size, 3)), m=np.empty((s_all.size, 3)), energy=0.0,
                          residual=float(residual), L=L, Rf=Rf, Rt=self.Rt, info=info, _pieces=pieces)
        for k, sk in enumerate(s_all):
            x, R, n, m = sol.state(sk)
            sol.x[k], sol.frames[k], sol.n[k], sol.m[k] = x, R, n, m
        # reactions
        n0p = u[0:3] * Rf / L**2
        m0p = u[3:6] * Rf / L
        F0 = sum((Fk for sk, Fk, _ in self.loads_si if sk == 0.0), np.zeros(3))
        M0 = sum((Mk for sk, _, Mk in self.loads_si if sk == 0.0), np.zeros(3))
        sol.force0 = -(n0p + F0)
        sol.moment0 = -(m0p + M0)
        E = ends[-1]
        if self.mode_end == "free":
            sol.forceL, sol.momentL = np.zeros(3), np.zeros(3)
        else:
            sol.forceL = E[7:10] * Rf / L**2
            sol.momentL = E[10:13] * Rf / L
        # energy: integrated (elastic + gravity) minus point-force work
        U = e_total * Rf / L
        work = 0.0
        for sk, Fk, _ in self.loads_si:
            xk = sol.state(sk)[0]
            work += float(Fk @ xk)
        sol.energy = U - work
        # elastic part alone (from the gravity part computed by quadrature of the dense output)
        if self.D != 0.0 and np.any(self.ghat):
            sq = np.linspace(0.0, L, 2001)
            gx = np.array([self.ghat @ sol.state(si)[0] for si in sq])
            grav = -self.D * simpson(gx, x=sq)
        else:
            grav = 0.0
        sol.elastic_energy = U - grav
        return sol


# --------------------------------------------------------------------------------------------
# root finding
# --------------------------------------------------------------------------------------------
def _find_root(prob: _Problem, u0: np.ndarray, tol: float, max_newton: int = 30,
               fallback: bool = True) -> tuple[np.ndarray, float, dict]:
    """Root of the shooting map.

    1. Gauss-Newton / Levenberg-Marquardt on the SVD of the batched forward-difference Jacobian
       (minimum-norm steps, adaptive damping, acceptance on |F|_2).  Least squares keeps it working
       when J is rank deficient, which happens for genuine solution families (e.g. an isotropic rod
       with a free-twist end: the whole shape may rotate about the chord; a straight rod at chord
       exactly L: the axial tension is indeterminate).
       It gives up early when stagnating (4 successive heavily damped steps).
    2. if that stalls and ``fallback``: ``scipy.optimize.root`` 'hybr' (with the same Jacobian), then
       'lm', each followed by a Gauss-Newton polish.  (Inside a continuation it is usually cheaper to
       switch the fallback off and let the continuation halve the step.)
    """
    cache: dict = {}
    info: dict = {"methods": [], "newton_iterations": 0}

    def fun(u):
        return prob.fun(u)

    def jac(u):
        key = u.tobytes()
        if key not in cache:
            cache.clear()
            try:
                cache[key] = prob.fun_jac(u)
            except FloatingPointError:
                cache[key] = (np.full(prob.nu, 1e6), np.eye(prob.nu))
        return cache[key][1]

    best_u, best_r = u0.copy(), float(np.max(np.abs(fun(u0))))
    if best_r <= tol:
        info["methods"].append("guess")
        return best_u, best_r, info

    def consider(u):
        nonlocal best_u, best_r
        r = float(np.max(np.abs(fun(u))))
        if np.isfinite(r) and r < best_r:
            best_u, best_r = u.copy(), r
        return r

    def newton(u, iters):
        """Gauss-Newton through the SVD of J (singular values below 1e-9 s_max count as zero: exact
        symmetries), globalised without new Jacobians: the full step first, then per trial both a
        halved Gauss-Newton step and a Levenberg-Marquardt step -sum_i s_i/(s_i^2 + mu^2) v_i (u_i.F)
        with mu growing x10 (the LM step damps near-null directions that are not exactly null, e.g.
        a symmetry orbit away from the solution set); the best candidate that lowers |F|_2 wins."""
        u = u.copy()
        F = fun(u)
        prev = np.inf
        mu_rel = 0.0
        stalls = 0
        for _ in range(iters):
            r = np.max(np.abs(F))
            # done: well below tol, or below tol and no longer improving (integration-noise floor)
            if r <= 0.01 * tol or (r <= tol and r > 0.25 * prev):
                break
            prev = r
            try:
                F, J = prob.fun_jac(u)
            except FloatingPointError:
                break
            info["newton_iterations"] += 1
            Uj, S, Vt = np.linalg.svd(J)
            smax = S[0]
            keep = S > 1e-9 * smax
            UF = Uj.T @ F
            nF = np.linalg.norm(F)
            accepted = False
            coef_gn = np.where(keep, 1.0 / np.where(keep, S, 1.0), 0.0)
            du_gn = -Vt.T @ (coef_gn * UF)
            cap = max(20.0, np.max(np.abs(u)))  # crude trust region (dimensionless unknowns)
            if np.max(np.abs(du_gn)) > cap:
                du_gn *= cap / np.max(np.abs(du_gn))
            t, mu_try = 1.0, max(mu_rel, 1e-7)
            for trial in range(12):
                cands = [(t * du_gn, 0.0, t)]
                if trial > 0:  # alternatives: a shorter Gauss-Newton step and a damped (LM) step
                    mu = mu_try * smax
                    du_lm = -Vt.T @ (np.where(keep, S / (S * S + mu * mu), 0.0) * UF)
                    if np.max(np.abs(du_lm)) > cap:
                        du_lm *= cap / np.max(np.abs(du_lm))
                    cands.append((du_lm, mu_try, 1.0))
                    mu_try *= 10.0
                best = None
                for du_c, mu_c, t_c in cands:
                    F_c = fun(u + du_c)
                    n_c = np.linalg.norm(F_c)
                    if np.all(np.isfinite(F_c)) and n_c < nF and (best is None or n_c < best[0]):
                        best = (n_c, du_c, F_c, mu_c, t_c)
                if best is not None:
                    accepted = True
                    _, du, F2, mu_acc, t_acc = best
                    break
                t *= 0.5
            if not accepted:
                break
            u = u + du
            F = F2
            heavy = mu_acc > 1e-2 or t_acc < 0.1
            stalls = stalls + 1 if heavy else 0
            mu_rel = mu_acc / 10.0
            if stalls >= 4:
                break
        return u

    info["methods"].append("newton")
    consider(newton(u0, max_newton))
    if best_r > tol and fallback:
        sol = root(fun, best_u, jac=jac, method="hybr", options={"xtol": 1e-14, "maxfev": 5 * (prob.nu + 1)})
        info["methods"].append("hybr")
        consider(sol.x)
        consider(newton(best_u, 8))
    if best_r > tol and fallback:
        # MINPACK counts maxiter in function evaluations here (the Jacobian is ours)
        sol = root(fun, best_u, jac=jac, method="lm",
                   options={"xtol": 1e-15, "ftol": 1e-15, "maxiter": 5 * (prob.nu + 1)})
        info["methods"].append("lm")
        consider(sol.x)
        consider(newton(best_u, 8))
    return best_u, best_r, info


def _n0m0_nd(prob: _Problem, n0, m0) -> np.ndarray:
    return np.concatenate([np.asarray(n0, dtype=float) * prob.L**2 / prob.Rf,
                           np.asarray(m0, dtype=float) * prob.L / prob.Rf])


def _initial_unknowns(prob: _Problem, guess) -> np.ndarray:
    if guess is None:
        return prob.unknowns_from_single_shot(np.zeros(6))
    if isinstance(guess, RodSolution):
        scale = guess.L / prob.L
        _, _, n0, m0 = guess.state(0.0, side="right")
        nodes = []
        for i in range(1, prob.N):
            x, R, n, m = guess.state(prob.nodes[i] * prob.L * scale, side="right")
            nodes.append(np.concatenate([x / prob.L, _rot_to_quat(R), n * prob.L**2 / prob.Rf,
                                         m * prob.L / prob.Rf, [0.0]]))
        return prob.unknowns_from_states(_n0m0_nd(prob, n0, m0), nodes)
    if callable(guess):
        _, _, n0, m0 = guess(0.0)
        nodes = []
        for i in range(1, prob.N):
            x, R, n, m = guess(prob.nodes[i] * prob.L)
            nodes.append(np.concatenate([np.asarray(x, float) / prob.L, _rot_to_quat(R),
                                         np.asarray(n, float) * prob.L**2 / prob.Rf,
                                         np.asarray(m, float) * prob.L / prob.Rf, [0.0]]))
        return prob.unknowns_from_states(_n0m0_nd(prob, n0, m0), nodes)
    n0, m0 = guess
    return prob.unknowns_from_single_shot(_n0m0_nd(prob, n0, m0))


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
def solve_clamped(L, Rf, Rt, x0, R0, x1=None, R1_or_tangent=None, *, mode_end="clamp", D=0.0,
                  g=(0.0, 0.0, -1.0), loads=(), guess=None, s_eval=None, tol=1e-10,
                  segments: int = 4, max_newton: int = 30, fallback: bool = True) -> RodSolution:
    """Static equilibrium of a rod clamped at s = 0 (pose x0, R0 = [t d1 d2]).

    End s = L (``mode_end``):

    * ``'clamp'``   position x1 and frame R1 (3x3) held: x(L) = x1, vec(q1* q(L)) = 0 (6 conditions);
      R1 fixes the end orientation modulo full turns: the number of turns of twist comes from the guess
    * ``'tangent'`` position x1 and tangent t1 (3-vector, or the first column of a 3x3) held, twist
      about the tangent free: x(L) = x1, t(L).e1 = t(L).e2 = 0 (e_i _|_ t1), m(L).t(L) = 0
    * ``'pin'``     position x1 held: x(L) = x1, m(L) = 0
    * ``'free'``    n(L+) = 0, m(L+) = 0 (x1, R1 ignored)

    ``D`` weight per length along unit ``g``; ``loads`` = sequence of (s_k, F_k, M_k) (dead, world
    frame, F_k/M_k may be None).  ``guess`` = None (straight rod: n0 = m0 = 0), an (n0, m0) pair in
    SI (single-shot from it), a previous :class:`RodSolution` (its states at the shooting nodes,
    arc length scaled by L_new/L_old; use this for continuation), or a callable
    ``s -> (x, R, n, m)`` (SI, e.g. built from a discrete rod) sampled at the shooting nodes.
    ``segments`` = number of multiple-shooting segments (1 = single shooting).  ``s_eval`` = sample
    points (default 401 uniform; 0, L and the load points are always added).  Root finding:
    Gauss-Newton/LM on the SVD (at most ``max_newton`` Jacobians), then, if ``fallback``, scipy
    'hybr' and 'lm' (use ``fallback=False`` inside a continuation: halving the step is cheaper).
    Raises ``RuntimeError`` if the dimensionless residual does not drop below ``tol``.
    ``sol.info`` records the methods used, the iteration count and the problem data.
    """
    prob = _Problem(L, Rf, Rt, x0, R0, x1, R1_or_tangent, mode_end, D, g, loads, segments)
    try:
        u0 = _initial_unknowns(prob, guess)
    except FloatingPointError as exc:
        raise RuntimeError(f"integration of the initial guess failed: {exc}") from exc
    u, r, info = _find_root(prob, u0, tol, max_newton=max_newton, fallback=fallback)
    if not (r <= tol):
        raise RuntimeError(f"shooting did not converge: residual {r:.3e} > tol {tol:.1e} "
                           f"(methods tried: {info['methods']})")
    if mode_end == "tangent":
        E = prob.ends(u)[-1]
        if _quat_to_rot(E[3:7])[:, 0] @ prob.t1 < 0:
            raise RuntimeError("converged to the reversed end tangent (t(L) = -t1); give a better guess")
    info["nfev"] = prob.nfev
    info["problem"] = {"mode_end": mode_end, "x0": np.asarray(x0, float), "R0": np.asarray(R0, float),
                       "x1": None if x1 is None else np.asarray(x1, float), "D": float(D),
                       "g": prob.ghat.copy(), "loads": list(prob.loads_si)}
    return prob.build_solution(u, r, s_eval, info)


def boundary_jacobian(L, Rf, Rt, x0, R0, x1, R1_or_tangent, n0, m0, *, mode_end="clamp", D=0.0,
                      g=(0.0, 0.0, -1.0), loads=()) -> tuple[np.ndarray, np.ndarray]:
    """Single-shooting residual and 6x6 Jacobian w.r.t. the dimensionless (n~(0), m~(0)) at the
    given SI (n0, m0).  Rows: the 6 end conditions of ``mode_end`` (as in :func:`solve_clamped`).
    Useful for locating bifurcations (singular Jacobian) of a known solution branch."""
    prob = _Problem(L, Rf, Rt, x0, R0, x1, R1_or_tangent, mode_end, D, g, loads, 1)
    return prob.fun_jac(_n0m0_nd(prob, n0, m0))


def secant_guess(p_prev, sol_prev: RodSolution, p_cur, sol_cur: RodSolution, p_next) -> Callable:
    """Secant predictor: a guess ``s -> (x, R, n, m)`` extrapolated linearly in the parameter from
    two converged solutions (rotations extrapolated on the group: R_cur exp(a log(R_prev^T R_cur)))."""
    dp = np.atleast_1d(np.asarray(p_cur, float) - np.asarray(p_prev, float))
    step = np.atleast_1d(np.asarray(p_next, float) - np.asarray(p_cur, float))
    a = float(np.dot(step, dp) / np.dot(dp, dp))
    Lc, Lp = sol_cur.L, sol_prev.L

    def fn(s):
        x1, R1, n1, m1 = sol_cur.state(s, side="right")
        x0, R0, n0, m0 = sol_prev.state(s * Lp / Lc, side="right")
        dR = _rotvec_of_matrix(R0.T @ R1)
        q = _qmul(_rot_to_quat(R1), _qexp(a * dR))
        return x1 + a * (x1 - x0), _quat_to_rot(q), n1 + a * (n1 - n0), m1 + a * (m1 - m0)

    return fn


def continuation(solve_fn: Callable, params_list: Iterable, guess=None, *, max_halvings: int = 4,
                 callback: Callable | None = None,
                 predictor: bool = False) -> list[tuple[object, RodSolution]]:
    """March a parameter: ``solve_fn(param, guess) -> RodSolution`` for every param in turn, each
    step using the previous solution as guess (with ``predictor``, from the second step on, a secant
    extrapolation of the last two solutions, :func:`secant_guess`, falling back to the plain previous
    solution if that fails).  If a step fails (RuntimeError), the interval from the last converged
    parameter is halved (parameters must support ``a + 0.5 * (b - a)`` — floats or numpy arrays) up
    to ``max_halvings`` times.  Returns [(param, solution), ...] for the requested params
    (intermediate half-steps are not returned).  ``callback(param, sol)`` is called after every
    requested step."""
    out = []
    prev_p, prev = None, guess
    hist: list = []  # (param, solution) of converged steps, including half-steps

    def attempt(q, cur):
        if predictor and len(hist) >= 2 and isinstance(hist[-1][1], RodSolution):
            (pa, sa), (pb, sb) = hist[-2], hist[-1]
            try:
                return solve_fn(q, secant_guess(pa, sa, pb, sb, q))
            except (RuntimeError, ZeroDivisionError, FloatingPointError):
                pass
        return solve_fn(q, cur)

    for p in params_list:
        if prev_p is None:
            sol = solve_fn(p, prev)
            hist.append((p, sol))
        else:
            target, a, sol, halvings = p, prev_p, None, 0
            pending = [target]
            cur, cur_p = prev, a
            while pending:
                q = pending[-1]
                try:
                    s_new = attempt(q, cur)
                except RuntimeError:
                    halvings += 1
                    if halvings > max_halvings:
                        raise
                    pa = np.asarray(cur_p, dtype=float)
                    mid = pa + 0.5 * (np.asarray(q, dtype=float) - pa)
                    pending.append(mid if np.ndim(mid) else float(mid))
                    continue
                pending.pop()
                cur, cur_p = s_new, q
                hist.append((q, s_new))
            sol = cur
        out.append((p, sol))
        if callback is not None:
            callback(p, sol)
        prev_p, prev = p, sol
    return out


def frame_curvature_energy(sol: RodSolution) -> float:
    """Elastic energy recomputed from the sampled frames only (discrete Darboux vector
    log(R_k^T R_{k+1}) / ds at the interval midpoints, midpoint rule) — independent of the
    internal moment m and of the integrated energy; second-order accurate in the sample spacing."""
    U = 0.0
    for k in range(len(sol.s) - 1):
        ds = sol.s[k + 1] - sol.s[k]
        if ds <= 0:
            continue
        Om = _rotvec_of_matrix(sol.frames[k].T @ sol.frames[k + 1]) / ds
        U += 0.5 * (sol.Rt * Om[0] ** 2 + sol.Rf * (Om[1] ** 2 + Om[2] ** 2)) * ds
    return U


# --------------------------------------------------------------------------------------------
# optional: stability by a discrete rod
# --------------------------------------------------------------------------------------------
def _qmul_v(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], axis=-1)


def _qexp_v(phi: np.ndarray) -> np.ndarray:
    a = np.linalg.norm(phi, axis=-1)
    small = a < 1e-8
    s = np.where(small, 0.5 - a * a / 48.0, np.sin(a / 2) / np.where(small, 1.0, a))
    return np.concatenate([np.cos(a / 2)[..., None], s[..., None] * phi], axis=-1)


def _qlog_v(q: np.ndarray) -> np.ndarray:
    sgn = np.where(q[..., 0] < 0, -1.0, 1.0)
    w = q[..., 0] * sgn
    v = q[..., 1:] * sgn[..., None]
    sv = np.linalg.norm(v, axis=-1)
    small = sv < 1e-12
    fac = np.where(small, 2.0, 2.0 * np.arctan2(sv, w) / np.where(small, 1.0, sv))
    return fac[..., None] * v


@dataclass
class StabilityReport:
    """Result of :func:`discrete_stability`.

    ``eigenvalues``: sorted eigenvalues of the constrained second variation of the discrete rod at its
    own equilibrium next to the shooting solution, made dimensionless as lambda L^2 / (Rf h) (smooth
    low modes are then O(1..100)); ``n_negative``: how many are below ``-zero_tol``; ``n_zero``: how
    many are within +-zero_tol (neutral directions, e.g. the rotation of the whole shape about the
    chord in an aligned isotropic problem); ``shift``: max rotation [rad] between the sampled shooting
    frames and the discrete equilibrium (O(h^2): a consistency check of the two models);
    ``gradient``: remaining first variation (same scaling as the eigenvalues)."""

    eigenvalues: np.ndarray
    n_negative: int
    n_zero: int
    shift: float
    gradient: float
    n_edges: int

    @property
    def stable(self) -> bool:
        return self.n_negative == 0


class _DiscreteRod:
    """Discrete Kirchhoff rod built around a shooting solution (see :func:`discrete_stability`).

    Unknowns: body rotation vectors phi_j of the N edge frames (R_j <- R_j exp([phi_j]x)) and, for a
    'tangent' end, the twist of the end frame about its tangent; multiplier lam of the end-position
    constraint h sum_j t_j = x1 - x0."""

    def __init__(self, sol: RodSolution, n_edges: int, fd_step: float):
        prm = sol.info.get("problem")
        if prm is None:
            raise ValueError("solution has no problem record (not from solve_clamped)")
        if any(np.any(Mk != 0) for _, _, Mk in prm["loads"]):
            raise NotImplementedError("point moments have no potential here")
        self.prm = prm
        self.mode = mode = prm["mode_end"]
        self.L, self.Rf, self.Rt = L, Rf, Rt = sol.L, sol.Rf, sol.Rt
        self.N = N = int(n_edges)
        self.h = h = L / N
        s_mid = (np.arange(N) + 0.5) * h
        self.qfree = np.array([_rot_to_quat(sol.state(si)[1]) for si in s_mid])
        self.q_start = self.qfree.copy()
        self.q0 = _rot_to_quat(prm["R0"])[None, :]
        self.has_end = mode in ("clamp", "tangent")
        self.q_end = _rot_to_quat(sol.frames[-1])[None, :]
        self.ell = np.array([h / 2] + [h] * (N - 1) + ([h / 2] if self.has_end else []))
        self.nf = N + 1 + (1 if self.has_end else 0)
        self.Kd = np.array([Rt, Rf, Rf])
        self.constrained = mode in ("clamp", "tangent", "pin")
        self.lam = np.array(sol.forceL if self.constrained else np.zeros(3), dtype=float)
        self.dx = (prm["x1"] - prm["x0"]) if self.constrained else None
        avec = np.zeros((N, 3))  # dead loads as -sum_j a_j . t_j (x piecewise linear in the t_j)
        if prm["D"] != 0.0:
            avec += (prm["D"] * h * h * (N - np.arange(N) - 0.5))[:, None] * prm["g"][None, :]
        for sk, Fk, _ in prm["loads"]:
            kk = min(int(np.floor(sk / h)), N - 1)
            avec[:kk] += h * Fk
            avec[kk] += (sk - kk * h) * Fk
        self.avec = avec
        self.free = np.array(list(range(3, 3 * (N + 1))) + ([3 * (N + 1)] if mode == "tangent" else []))
        self.nfree = self.free.size
        self.d = fd_step
        self.scale = L**2 / (Rf * h)

    # ---- geometry / energy ----
    def ext(self, qfree=None, q_end=None) -> np.ndarray:
        qfree = self.qfree if qfree is None else qfree
        q_end = self.q_end if q_end is None else q_end
        return np.concatenate([self.q0, qfree] + ([q_end] if self.has_end else []))

    def _W(self, Q, dL=None, dR=None) -> np.ndarray:
        qa, qb = Q[:-1], Q[1:]
        if dL is not None:
            qa = _qmul_v(qa, _qexp_v(np.broadcast_to(dL, (self.nf - 1, 3))))
            qb = _qmul_v(qb, _qexp_v(np.broadcast_to(dR, (self.nf - 1, 3))))
        return _qlog_v(_qmul_v(qa * np.array([1, -1, -1, -1]), qb)) / self.ell[:, None]

    def tangents(self, qfree=None) -> np.ndarray:
        q = self.qfree if qfree is None else qfree
        w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        return np.stack([w * w + x * x - y * y - z * z, 2 * (x * y + w * z), 2 * (x * z - w * y)], axis=-1)

    def energy(self, qfree=None, q_end=None) -> float:
        W = self._W(self.ext(qfree, q_end))
        return float(np.sum(0.5 * (W * W) @ self.Kd * self.ell) - np.sum(self.avec * self.tangents(qfree)))

    def constraint(self, qfree=None):
        return self.h * self.tangents(qfree).sum(axis=0) - self.dx

    def apply(self, dphi: np.ndarray, qfree=None, q_end=None):
        qfree = self.qfree if qfree is None else qfree
        q_end = self.q_end if q_end is None else q_end
        qf = _qmul_v(qfree, _qexp_v(dphi[:3 * self.N].reshape(self.N, 3)))
        qe = q_end
        if self.mode == "tangent":
            qe = _qmul_v(q_end, _qexp_v(np.array([[dphi[3 * self.N], 0.0, 0.0]])))
        return qf, qe

    def cjac(self, qfree=None) -> np.ndarray:
        q = self.qfree if qfree is None else qfree
        C = np.zeros((3, self.nfree))
        skew_e1 = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
        for j in range(self.N):
            C[:, 3 * j:3 * j + 3] = -self.h * _quat_to_rot(q[j]) @ skew_e1
        return C

    # ---- derivatives ----
    def assemble(self):
        """Gradient and Hessian of the Lagrangian w.r.t. the free dofs, constraint Jacobian, residual."""
        Q = self.ext()
        nf, d = self.nf, self.d
        unit = np.eye(6) * d

        def ev(v):
            W = self._W(Q, v[:3], v[3:])
            return 0.5 * (W * W) @ self.Kd * self.ell

        loc_g = np.zeros((nf - 1, 6))
        loc_H = np.zeros((nf - 1, 6, 6))
        for a in range(6):
            loc_g[:, a] = (ev(unit[a]) - ev(-unit[a])) / (2 * d)
            for b in range(a, 6):
                val = (ev(unit[a] + unit[b]) - ev(unit[a] - unit[b]) - ev(unit[b] - unit[a])
                       + ev(-unit[a] - unit[b])) / (4 * d * d)
                loc_H[:, a, b] = val
                loc_H[:, b, a] = val
        nd = 3 * nf
        H = np.zeros((nd, nd))
        g = np.zeros(nd)
        for k in range(nf - 1):
            H[3 * k:3 * k + 6, 3 * k:3 * k + 6] += loc_H[k]
            g[3 * k:3 * k + 6] += loc_g[k]
        Rq = np.array([_quat_to_rot(q) for q in self.qfree])
        b = self.avec + (self.h * self.lam if self.constrained else 0.0)
        bt = np.einsum("jik,ji->jk", Rq, b)                   # R_j^T b_j
        e1 = np.array([1.0, 0.0, 0.0])
        for j in range(self.N):
            i3 = 3 * (j + 1)
            g[i3:i3 + 3] -= np.cross(e1, bt[j])
            H[i3:i3 + 3, i3:i3 + 3] += (-0.5 * (np.outer(bt[j], e1) + np.outer(e1, bt[j]))
                                        + bt[j][0] * np.eye(3))
        Hf = H[np.ix_(self.free, self.free)]
        Hf = 0.5 * (Hf + Hf.T)
        gf = g[self.free]
        if self.constrained:
            return gf, Hf, self.cjac(), self.constraint()
        return gf, Hf, np.zeros((0, self.nfree)), np.zeros(0)

    def reduced(self):
        gf, Hf, C, c = self.assemble()
        if self.constrained:
            from scipy.linalg import null_space
            Z = null_space(C)
        else:
            Z = np.eye(self.nfree)
        return Z, Z.T @ gf, Z.T @ Hf @ Z, gf, C

    # ---- solvers ----
    def kkt_newton(self, steps: int):
        for _ in range(steps):
            gf, Hf, C, c = self.assemble()
            nc = C.shape[0]
            KKT = np.block([[Hf, -C.T], [C, np.zeros((nc, nc))]])
            step = np.linalg.lstsq(KKT, -np.concatenate([gf, c]), rcond=1e-10)[0]
            self.qfree, self.q_end = self.apply(step[:self.nfree])
            if self.constrained:
                self.lam = self.lam + step[self.nfree:]

    def restore(self, qf, qe, iters: int = 6):
        """Gauss-Newton (minimum-norm) projection back onto the end-position constraint."""
        if not self.constrained:
            return qf, qe
        for _ in range(iters):
            c = self.constraint(qf)
            if np.max(np.abs(c)) < 1e-14 * self.L:
                break
            C = self.cjac(qf)
            qf, qe = self.apply(-np.linalg.lstsq(C, c, rcond=None)[0], qf, qe)
        return qf, qe

    def relax(self, max_iter: int = 60, kick: float = 0.3, gtol: float = 1e-8) -> int:
        """Descend to a local energy minimum (saddle-free Newton on the constraint manifold: the
        reduced Hessian with |eigenvalues|; from a saddle, a step of max rotation ``kick`` [rad]
        along the most negative mode).  Returns the iterations used."""
        for it in range(max_iter):
            Z, gr, Hr, gf, C = self.reduced()
            if self.constrained:  # multiplier update so that the Lagrangian gradient is tangent
                self.lam = self.lam + np.linalg.lstsq(C.T, gf, rcond=None)[0]
            w, V = np.linalg.eigh(Hr)
            floor = 1e-6 * np.max(np.abs(w))
            gnorm = np.max(np.abs(gr)) * self.scale
            if gnorm < gtol and w[0] > -floor:
                return it
            p = -V @ ((V.T @ gr) / np.maximum(np.abs(w), floor))
            if w[0] < -floor and gnorm < 1e-3:                # (near) saddle: go down the negative mode
                v = Z @ V[:, 0]
                p_full = kick * v / np.max(np.abs(v))
            else:
                p_full = Z @ p
            big = np.max(np.abs(p_full))
            if big > 0.5:
                p_full *= 0.5 / big
            E0 = self.energy()
            t = 1.0
            while t > 1e-6:
                qf, qe = self.restore(*self.apply(t * p_full))
                if self.energy(qf, qe) <= E0 + 1e-15 * abs(E0):
                    self.qfree, self.q_end = qf, qe
                    break
                t *= 0.5
            else:
                return it
        return max_iter

    def report(self, zero_tol: float) -> StabilityReport:
        Z, gr, Hr, _, _ = self.reduced()
        ev_ = np.sort(np.linalg.eigvalsh(Hr)) * self.scale
        shift = float(np.max(np.linalg.norm(
            _qlog_v(_qmul_v(self.q_start * np.array([1, -1, -1, -1]), self.qfree)), axis=-1)))
        return StabilityReport(eigenvalues=ev_, n_negative=int(np.sum(ev_ < -zero_tol)),
                               n_zero=int(np.sum(np.abs(ev_) <= zero_tol)), shift=shift,
                               gradient=float(np.max(np.abs(gr)) * self.scale), n_edges=self.N)

    def state_fn(self) -> Callable:
        """s -> (x, R, n, m) of the discrete rod (SI), usable as a shooting guess."""
        N, h, L = self.N, self.h, self.L
        Rs = np.array([_quat_to_rot(q) for q in self.qfree])
        xv = np.vstack([np.zeros(3), np.cumsum(self.tangents() * h, axis=0)]) + self.prm["x0"]
        sv = np.arange(N + 1) * h
        Q = self.ext()
        W = self._W(Q)
        qmid = _qmul_v(Q[:-1], _qexp_v(0.5 * W * self.ell[:, None]))
        mj = np.array([_quat_to_rot(qm) @ (self.Kd * w) for qm, w in zip(qmid, W)])
        sj = np.r_[h / 4, np.arange(1, N) * h, [L - h / 4] if self.has_end else []]
        lam = self.lam if self.constrained else np.zeros(3)
        prm = self.prm

        def fn(s):
            x = np.array([np.interp(s, sv, xv[:, i]) for i in range(3)])
            R = Rs[int(np.clip(np.floor(s / h), 0, N - 1))]
            m = np.array([np.interp(s, sj, mj[:, i]) for i in range(3)])
            n = lam + prm["D"] * (L - s) * prm["g"]
            for sk, Fk, _ in prm["loads"]:
                if sk > s:
                    n = n + Fk
            return x, R, n, m

        return fn


def discrete_stability(sol: RodSolution, n_edges: int = 100, zero_tol: float = 1e-2,
                       fd_step: float = 1e-4, newton_steps: int = 4) -> StabilityReport:
    """Stability of a shooting solution, judged on a discrete Kirchhoff rod built around it.

    Discrete rod: ``n_edges`` edges of length h = L/N with frames R_j (started from the shooting
    frames at the edge midpoints), tangent t_j = R_j e1, vertices x_k = x0 + h sum_{j<k} t_j
    (inextensible by construction).  Energy = sum over joints of 1/2 (Rt W1^2 + Rf (W2^2 + W3^2)) l,
    W = log(R_a^T R_b) / l for consecutive frames (the clamp frame R0 at s = 0 and, for 'clamp' /
    'tangent', the end frame at s = L are joined to the end edges with l = h/2; for 'tangent' the end
    frame may turn about its tangent: one extra dof), minus the work of the dead loads (weight, point
    forces; point moments are not supported); end-position constraint h sum t_j = x1 - x0 ('clamp',
    'tangent', 'pin') with multiplier lambda (started from the shooting end reaction).
    Perturbations are body rotation vectors, R_j exp([phi_j]x).  Gradient and Hessian of the
    Lagrangian: joint terms by vectorised central differences, load/constraint terms exactly.
    ``newton_steps`` KKT-Newton steps move the discrete rod onto its own equilibrium (the shooting
    solution is one only up to O(h): the half-length clamp joint), then the Hessian is projected on
    the null space of the linearised constraint and its eigenvalues are reported.

    Caveats: stability of the discrete model (eigenvalues carry O(h^2) discretisation error), so
    eigenvalues near zero are inconclusive; exact symmetries give (near-)zero eigenvalues."""
    rod = _DiscreteRod(sol, n_edges, fd_step)
    rod.kkt_newton(newton_steps)
    return rod.report(zero_tol)


def relaxed_guess(sol: RodSolution, n_edges: int = 40, kick: float = 0.3, max_iter: int = 60,
                  fd_step: float = 1e-4) -> tuple[Callable, dict]:
    """Branch switching by energy: build the discrete rod around ``sol``, let it descend to a local
    energy minimum (leaving a saddle along its most negative mode), and return a shooting guess
    ``s -> (x, R, n, m)`` built from the relaxed discrete rod, plus a dict with its energy and
    iteration count.  Polish with ``solve_clamped(..., guess=fn)``; compare energies."""
    rod = _DiscreteRod(sol, n_edges, fd_step)
    rod.kkt_newton(2)
    E_start = rod.energy()
    it = rod.relax(max_iter=max_iter, kick=kick)
    return rod.state_fn(), {"iterations": it, "discrete_energy_start": E_start,
                            "discrete_energy": rod.energy()}
