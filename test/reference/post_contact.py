"""An independent reference for obstacle contact: a heavy planar elastica clamped at both ends, resting on
a round post at one point, by shooting (numpy + scipy only; nothing here uses dlo_ros).

The rod lies in the x–z plane, gravity along −z.  State along s: position (x, z), tangent angle θ
(t = (cos θ, sin θ)), the internal force n = (n_x, n_z) and moment m that the part (s, L] exerts on
[0, s] (the sign convention of ``kirchhoff.py``), with a×b = a_x b_z − a_z b_x:

    x' = cos θ,  z' = sin θ,  θ' = m / Rf,  n' = −f = (0, w),  m' = −t × n,

w the weight per length [N/m].  The post is a circle (centre c, radius R) in the plane, the rod's
centreline keeps R + r from it; the contact is one point s* with

    |x(s*) − c| = R + r,   t(s*)·(x(s*) − c) = 0   (the rod touches tangentially),

and the post pushes with F = P (x(s*) − c)/(R + r), P ≥ 0: n jumps by n(s*+) = n(s*−) − F.  Clamps:
x(0), θ(0) and x(L), θ(L) given.  Unknowns n(0), m(0), s*, P: five equations (the far clamp's three,
the contact's two), solved by Levenberg–Marquardt on solve_ivp (DOP853, rtol = atol = 1e-12) from a
guess (the caller's), then checked: every point of the rod keeps R + r from the centre, P ≥ 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares


@dataclass
class PostContact:
    """The solution: arc lengths s and points (x, z) on a dense grid, the contact s* [m], the post's push
    P [N], the reaction at s = 0 (force n(0) [N] and moment m(0) [N·m]), the closest distance of the rod
    to the post's centre minus R + r [m] away from the contact, and the final residual."""

    s: np.ndarray
    points: np.ndarray
    s_contact: float
    push: float
    n0: np.ndarray
    m0: float
    clearance: float
    residual: float

    def at(self, s: np.ndarray) -> np.ndarray:
        """(x, z) at arc lengths s, interpolated (cubic) from the dense grid."""
        from scipy.interpolate import CubicSpline

        return np.stack([CubicSpline(self.s, self.points[:, k])(s) for k in range(2)], axis=1)


def _rhs(_s, y, rf: float, w: float):
    x, z, th, nx, nz, m = y
    c, sn = np.cos(th), np.sin(th)
    return [c, sn, m / rf, 0.0, w, -(c * nz - sn * nx)]


def _shoot(u, length, rf, w, start, theta0, centre, reach, dense: bool = False):
    nx, nz, m0, s_star, push = u
    s_star = float(np.clip(s_star, 1e-6 * length, length * (1 - 1e-6)))
    y0 = [start[0], start[1], theta0, nx, nz, m0]
    kw = dict(method="DOP853", rtol=1e-12, atol=1e-12, args=(rf, w))
    grid_a = np.linspace(0.0, s_star, 400) if dense else None
    a = solve_ivp(_rhs, (0.0, s_star), y0, t_eval=grid_a, **kw)
    ya = a.y[:, -1].copy()
    radial = ya[0:2] - centre
    ya[3:5] -= push * radial / reach
    grid_b = np.linspace(s_star, length, 400) if dense else None
    b = solve_ivp(_rhs, (s_star, length), ya, t_eval=grid_b, **kw)
    return a, b, radial


def solve(length: float, rf: float, w: float, start, theta0: float, end, theta1: float, centre, post_radius: float,
          rod_radius: float, guess) -> PostContact:
    """Shoot from ``guess`` = (n_x(0), n_z(0), m(0), s*, P); see the module docstring."""
    centre, start, end = (np.asarray(v, dtype=float) for v in (centre, start, end))
    reach = post_radius + rod_radius

    def residual(u):
        a, b, radial = _shoot(u, length, rf, w, start, theta0, centre, reach)
        ya, yb = a.y[:, -1], b.y[:, -1]
        tangent = np.array([np.cos(ya[2]), np.sin(ya[2])])
        return np.array([(yb[0] - end[0]) / length, (yb[1] - end[1]) / length, yb[2] - theta1,
                         (np.linalg.norm(radial) - reach) / length, tangent @ radial / reach])

    fit = least_squares(residual, np.asarray(guess, dtype=float), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=2000)
    a, b, _ = _shoot(fit.x, length, rf, w, start, theta0, centre, reach, dense=True)
    s = np.concatenate([a.t, b.t[1:]])
    points = np.concatenate([a.y[0:2].T, b.y[0:2, 1:].T])
    distance = np.linalg.norm(points - centre, axis=1) - reach
    return PostContact(s, points, float(fit.x[3]), float(fit.x[4]), fit.x[0:2].copy(), float(fit.x[2]),
                       float(distance.min()), float(np.max(np.abs(fit.fun))))
