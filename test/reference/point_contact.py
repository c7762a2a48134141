"""Shooting for a Kirchhoff rod that touches itself at one point: an exact self-contact reference.

An independent reference (numpy + scipy only, nothing from ``dlo_ros``) for the paper's Fig. 2
loop closed past touching (string radius r): the rod of test/reference/kirchhoff.py with two equal
and opposite point forces, F at s_a and −F at s_b, where the strands touch.  The contact is exact,
not sampled: the unknowns (F, s_a, s_b) solve

    (x_a − x_b)·t_a = 0,  (x_a − x_b)·t_b = 0   (s_a, s_b are the closest points of the strands),
    |x_a − x_b| = 2 r                          (the tubes touch),
    F ∥ x_a − x_b                              (frictionless: the force pushes the strands apart),

each residual evaluated on a ``kirchhoff.solve_clamped`` equilibrium with F, −F as dead point loads
(started from the previous one).  The answer is a contact when F·(x_a − x_b) > 0 (a push, not a
pull).  The energy to compare is the elastic energy: the contact forces do no work on an
equilibrium.  Chord Newton (a forward-difference Jacobian, renewed when a step does not halve
the residual); a start (F, s_a, s_b, and the grip wrench
for the first shooting solve) comes from the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kirchhoff import RodSolution, perp_basis, solve_clamped


@dataclass
class PointContact:
    """The rod ``rod`` (a ``RodSolution``), the contact ``s_a`` < ``s_b`` [m], the force ``force``
    [N] on s_a (−force on s_b) and the max-norm ``residual`` [m] of the contact conditions."""

    rod: RodSolution
    s_a: float
    s_b: float
    force: np.ndarray
    residual: float


def solve_point_contact(
    rod: dict,
    radius: float,
    force: np.ndarray,
    s_a: float,
    s_b: float,
    guess,
    tol: float = 1e-9,
    max_steps: int = 12,
) -> PointContact:
    """Solve the contact of a rod ``rod`` (keyword arguments of ``solve_clamped`` but ``guess``;
    its ``loads`` are added to the contact's) at distance 2 ``radius`` [m] from the start ``force`` [N], ``s_a``, ``s_b``
    [m] and the shooting ``guess`` (an (n0, m0) pair or a ``RodSolution``); ``tol``: the contact
    conditions' max-norm residual [m] to stop at, after at most ``max_steps`` Newton steps."""
    state = {"guess": guess}
    rod = dict(rod)
    rod_loads = rod.pop("loads", ())

    def equilibrium(u: np.ndarray) -> RodSolution:
        loads = ((u[3], u[:3], None), (u[4], -u[:3], None)) + tuple(rod_loads)
        return solve_clamped(**rod, loads=loads, guess=state["guess"], tol=1e-12)

    def residual(u: np.ndarray, sol: RodSolution) -> np.ndarray:
        xa, ra, _, _ = sol.state(u[3])
        xb, rb, _, _ = sol.state(u[4])
        d = xa - xb
        p, q = perp_basis(d)
        return np.array(
            [d @ ra[:, 0], d @ rb[:, 0], np.linalg.norm(d) - 2 * radius, u[:3] @ p, u[:3] @ q]
        )

    u0 = np.concatenate([np.asarray(force, float), [s_a, s_b]])
    u, sol, f = chord_newton(equilibrium, residual, u0, 1e-6 * rod["L"], state, tol, max_steps)
    return PointContact(sol, float(u[3]), float(u[4]), u[:3].copy(), float(np.abs(f).max()))


def chord_newton(equilibrium, residual, u0: np.ndarray, s_step: float, state: dict, tol: float,
                 max_steps: int):
    """Solve residual(u, equilibrium(u)) = 0 for u = (force [N] (3), arc lengths [m] …) by a chord
    method: a forward-difference Jacobian (steps 1e-7 N, ``s_step`` m) kept while Newton contracts;
    only steps that lower the max-norm residual are taken.  ``state['guess']``: the shooting guess,
    updated to each accepted solution.  Returns (u, its rod solution, its residual)."""
    u = np.asarray(u0, dtype=float)
    sol = equilibrium(u)
    state["guess"] = sol
    f = residual(u, sol)
    jac = None
    for _ in range(max_steps):
        if np.abs(f).max() < tol:
            break
        if jac is None:  # forward differences, kept while Newton contracts (a chord method)
            jac = np.empty((u.size, u.size))
            for k in range(u.size):
                step = np.zeros(u.size)
                step[k] = 1e-7 if k < 3 else s_step
                jac[:, k] = (residual(u + step, equilibrium(u + step)) - f) / step[k]
        trial = u + np.linalg.solve(jac, -f)
        sol_t = equilibrium(trial)
        f_t = residual(trial, sol_t)
        if np.abs(f_t).max() > 0.5 * np.abs(f).max():
            jac = None  # not contracting: a fresh Jacobian next step
        if np.abs(f_t).max() < np.abs(f).max():
            u, sol, f = trial, sol_t, f_t
            state["guess"] = sol
    return u, sol, f
