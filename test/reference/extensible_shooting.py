"""Single shooting for an extensible, unshearable Kirchhoff rod clamped at both ends.

An independent reference (numpy + scipy only, nothing from ``dlo_ros``) for scenes where the
stretch matters, such as Greenhill's rod twisted past its threshold between clamps exactly the
string's length apart: the inextensible rod cannot leave the straight line there, the extensible
one buckles by stretching.  Isotropic rod, no distributed or point loads; s is the reference arc
length.  With n, m the force and moment that (s, L] exerts on [0, s] (as test/reference/kirchhoff.py)::

    ε = n·t / Re,   x' = (1 + ε) t,   R' = [R Ω]x R,   Ω = (m·t / Rt, m·d1 / Rf, m·d2 / Rf) (body),
    n' = 0,         m' = -(1 + ε) t × n

(the stationarity conditions of U = ∫ ½ Rf (Ω2² + Ω3²) + ½ Rt Ω1² + ½ Re ε² ds).  The unknowns
n(0), m(0) are found so that the far end meets the clamp's position and frame; the buckle's
orientation about the chord is a neutral direction, so the root is found by least squares
started from a guess (a solver's grip wrench) and reported with its residual.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares


@dataclass
class ExtensibleRod:
    """A shooting solution: ``s`` [m], ``x`` (len(s), 3) [m], elastic ``energy`` [J], and the
    far-end ``residual`` (position [m] and frame [rad] mismatch, max norm)."""

    s: np.ndarray
    x: np.ndarray
    energy: float
    residual: float


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _rhs(rf: float, rt: float, re: float):
    def f(_s, y):
        R = y[3:12].reshape(3, 3)
        n, m = y[12:15], y[15:18]
        t = R[:, 0]
        eps = n @ t / re
        body = R.T @ m
        omega = np.array([body[0] / rt, body[1] / rf, body[2] / rf])
        dR = _skew(R @ omega) @ R
        de = 0.5 * (rt * omega[0] ** 2 + rf * (omega[1] ** 2 + omega[2] ** 2) + re * eps**2)
        return np.concatenate(
            [(1 + eps) * t, dR.ravel(), np.zeros(3), -(1 + eps) * np.cross(t, n), [de]]
        )

    return f


def shoot_clamped(
    length: float,
    rf: float,
    rt: float,
    re: float,
    x1: np.ndarray,
    r1: np.ndarray,
    n0: np.ndarray,
    m0: np.ndarray,
    s_out: np.ndarray,
) -> ExtensibleRod:
    """Solve the rod clamped at the origin (frame I) and at ``x1`` (frame ``r1``, columns t, d1,
    d2), from the guess ``n0``, ``m0`` [N, N m] (the internal force and moment at s = 0).

    Returns the centreline at ``s_out`` [m].
    """
    rhs = _rhs(rf, rt, re)

    def run(u, s_eval=None):
        y0 = np.concatenate([np.zeros(3), np.eye(3).ravel(), u[:3], u[3:], [0.0]])
        return solve_ivp(
            rhs, (0.0, length), y0, method="DOP853", rtol=1e-12, atol=1e-13, t_eval=s_eval
        )

    def residual(u):
        y = run(u).y[:, -1]
        R = y[3:12].reshape(3, 3)
        E = r1.T @ R  # identity at the solution
        rot = 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
        return np.concatenate([y[:3] - x1, rot])

    sol = least_squares(residual, np.concatenate([n0, m0]), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    out = run(sol.x, np.asarray(s_out, dtype=float))
    return ExtensibleRod(
        out.t, out.y[:3].T.copy(), float(out.y[18, -1]), float(np.abs(residual(sol.x)).max())
    )
