"""Shooting for a heavy, twisted Kirchhoff rod resting on a sphere at one point: an exact reference.

An independent reference (numpy + scipy only, nothing from ``dlo_ros``) for a rod clamped at both
ends that touches a sphere (centre c, radius R; the rod's own radius r) at one point: the rod of
test/reference/kirchhoff.py (gravity, twist, clamps) with one dead point force F at s*.  The contact
is exact, not sampled: the unknowns (F, s*) solve

    |x(s*) − c| = R + r            (the tube touches the sphere),
    t(s*)·(x(s*) − c) = 0          (tangentially: s* is the closest point to the centre),
    F ∥ x(s*) − c                  (frictionless: the force is normal to the sphere),

each residual evaluated on a ``kirchhoff.solve_clamped`` equilibrium with F at s* (started from the
previous one).  The answer is a contact when F·(x(s*) − c) > 0 (a push); the caller checks that no
other point of the rod comes closer than R + r to c (``clearance``) and that the rod keeps off any
other obstacle.  Chord Newton as test/reference/point_contact.py (a forward-difference Jacobian,
renewed when a step does not halve the residual); the start (F, s*, and the grip wrench for the
first shooting solve) comes from the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kirchhoff import RodSolution, perp_basis, solve_clamped
from .point_contact import chord_newton


@dataclass
class SphereContact:
    """The rod ``rod`` (a ``RodSolution``), the contact ``s_contact`` [m], the force ``force`` [N] the
    sphere exerts there, the max-norm ``residual`` [m] of the contact conditions and the smallest
    |x(s) − c| − (R + r) [m] over a dense grid (``clearance``: ≈ 0 at the contact, never below)."""

    rod: RodSolution
    s_contact: float
    force: np.ndarray
    residual: float
    clearance: float


def solve_sphere_contact(
    rod: dict,
    centre,
    reach: float,
    force,
    s_contact: float,
    guess,
    tol: float = 1e-10,
    max_steps: int = 16,
) -> SphereContact:
    """Solve the contact of a rod ``rod`` (keyword arguments of ``solve_clamped`` but ``guess``) with
    the sphere of centre ``centre`` at distance ``reach`` = R + r [m] from the start ``force`` [N],
    ``s_contact`` [m] and the shooting ``guess`` (an (n0, m0) pair or a ``RodSolution``); ``tol``:
    the contact conditions' max-norm residual [m] to stop at, after at most ``max_steps`` steps."""
    state = {"guess": guess}
    c = np.asarray(centre, dtype=float)
    length = rod["L"]

    def equilibrium(u: np.ndarray) -> RodSolution:
        return solve_clamped(**rod, loads=((u[3], u[:3], None),), guess=state["guess"], tol=1e-12)

    def residual(u: np.ndarray, sol: RodSolution) -> np.ndarray:
        x, frame, _, _ = sol.state(u[3])
        d = x - c
        p, q = perp_basis(d)
        return np.array([np.linalg.norm(d) - reach, d @ frame[:, 0], u[:3] @ p, u[:3] @ q])

    u0 = np.concatenate([np.asarray(force, float), [s_contact]])
    u, sol, f = chord_newton(equilibrium, residual, u0, 1e-6 * length, state, tol, max_steps)
    dense = np.linspace(0.0, length, 4001)
    clearance = float(np.min(np.linalg.norm(sol.position(dense) - c, axis=1)) - reach)
    clearance = min(clearance, float(np.linalg.norm(sol.state(u[3])[0] - c) - reach))
    return SphereContact(sol, float(u[3]), u[:3].copy(), float(np.abs(f).max()), clearance)
