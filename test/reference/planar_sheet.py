"""Shooting for a planar inextensible rod clamped at both ends under its weight (paper sheets).

An independent reference (numpy + scipy only, nothing from ``dlo_ros``) for the paper's copy-paper
sheets (sec. 5: config/scenes/paper_rect_paper.yaml, paper_trapezoid_paper.yaml): a rod in the
x–z plane, bend stiffness Rf(s) and weight w(s) per length along −z (both linear in s, as the
trapezoid's tables), clamped at s = 0 at the origin and at s = L at (x1, 0, z1), both with angle
θ0, θ1 from +x towards +z.  With θ the tangent angle, N the force (s, L] exerts on [0, s] and M
its moment (positive towards +z from +x)::

    x' = cos θ,  z' = sin θ,  θ' = M / Rf(s),  N' = (0, w(s)),  M' = −(cos θ N_z − sin θ N_x)

(the balance of [0, s]: N(s) + N_0 − ∫ w e_z = 0, M' + t × N = 0).  The unknowns N(0), M(0) are
found by Newton so that the far end meets (x1, z1, θ1); the energy is ∫ ½ Rf θ'² + w z ds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve


@dataclass
class PlanarSheet:
    """The shooting solution: ``s`` [m], ``x`` (len(s), 3) [m] (y = 0), ``energy`` [J] (bend +
    gravity) and the far-end ``residual`` (max norm, [m] and [rad])."""

    s: np.ndarray
    x: np.ndarray
    energy: float
    residual: float


def solve_sheet(
    length: float,
    rf: Callable[[float], float],
    w: Callable[[float], float],
    end: tuple[float, float],
    guess: tuple[float, float, float],
    s_out: np.ndarray,
    theta0: float = 0.0,
    theta1: float = 0.0,
) -> PlanarSheet:
    """Solve the sheet from ``guess`` = (N_x, N_z, M) at s = 0 [N, N, N m] (module docstring)."""

    def rhs(s, y):
        _, _, th, nx, nz, m, _ = y
        k = m / rf(s)
        return [
            np.cos(th),
            np.sin(th),
            k,
            0.0,
            w(s),
            -(np.cos(th) * nz - np.sin(th) * nx),
            0.5 * rf(s) * k * k + w(s) * y[1],
        ]

    def run(u, s_eval=None):
        y0 = [0.0, 0.0, theta0, u[0], u[1], u[2], 0.0]
        return solve_ivp(
            rhs, (0.0, length), y0, method="DOP853", rtol=1e-13, atol=1e-15, t_eval=s_eval
        )

    def residual(u):
        y = run(u).y[:, -1]
        return [y[0] - end[0], y[1] - end[1], y[2] - theta1]

    u = fsolve(residual, np.asarray(guess, float), xtol=1e-14)
    out = run(u, np.asarray(s_out, float))
    x = np.stack([out.y[0], 0 * out.y[0], out.y[1]], axis=1)
    return PlanarSheet(out.t, x, float(out.y[6, -1]), float(np.abs(residual(u)).max()))
