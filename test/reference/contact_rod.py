"""An independent reference for self-contact: a discrete inextensible elastic rod, bending only, with
pairwise non-penetration constraints, minimised by scipy's SLSQP.

N edges of length h = L/N with unit tangents t_j (unknowns, |t_j|² = 1 as equality constraints); points
x = A T at the vertices and edge midpoints (A accumulates h t_j from the clamp at the origin).  Energy

    E = Σ_{j=0}^{N−2} (Rf/h)(1 − t_j·t_{j+1}) + (Rf/h)|t_0 − e_0|² + (Rf/h)|t_{N−1} − e_L|²

(a joint of length h between edges, of length h/2 at each held end: Rf θ²/(2 l) per joint with
|Δt|² = θ² to leading order), the end position h Σ t_j = c as an equality, and for every pair of points
more than ``gap`` apart along s and within ``window`` of each other at the start, |x_a − x_b|² ≥ (2r)².
Dead point forces F_k at points k add −Σ F_k·x_k to E.  The contact forces are the multipliers μ of the
active pairs, from the KKT conditions ∇E = J_eqᵀν + J_activeᵀμ at the minimiser (linear least squares):
the force on point a is 2μ(x_a − x_b), its opposite acts on b.
Twist is not modelled: with the roll free at one end and no point moments the twisting moment of an
isotropic rod is zero everywhere (m·t is constant along the rod and vanishes at the free roll).
Nothing here uses dlo_ros.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize


@dataclass
class ContactRod:
    """The minimiser: tangents (N, 3), point arc lengths s and points (2N+1, 3), energy [J], the pairs
    (a, b) at their bound (within ``active_tol`` of 2r), the closest far pair's distance [m], and the
    contact force on the first point of each active pair [N]."""

    tangents: np.ndarray
    s: np.ndarray
    points: np.ndarray
    energy: float
    active: list[tuple[int, int]]
    closest: float
    success: bool
    message: str
    forces: np.ndarray  # (len(active), 3) [N]: the contact force on the first point of each active pair


def accumulation(n: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """A (2n+1, n) with points = A @ T (vertices and midpoints interleaved) and their arc lengths."""
    a = np.zeros((2 * n + 1, n))
    for k in range(2 * n + 1):
        full = k // 2
        a[k, :full] = h
        if k % 2 == 1:
            a[k, full] = h / 2
    return a, np.arange(2 * n + 1) * h / 2


def solve_contact_rod(tangents0: np.ndarray, length: float, rf: float, end: np.ndarray, e0: np.ndarray,
                      el: np.ndarray, radius: float, gap: float, window: float, active_tol: float = 1e-6,
                      maxiter: int = 500, loads: tuple[tuple[int, np.ndarray], ...] = ()) -> ContactRod:
    """Minimise E from the tangents ``tangents0`` (N, 3), clamp at the origin with tangent e0, the end at
    ``end`` with tangent el, dead forces ``loads`` ((point index into ``s``, force [N]), …) (module
    docstring)."""
    n = len(tangents0)
    h = length / n
    a, s = accumulation(n, h)
    t0 = tangents0 / np.linalg.norm(tangents0, axis=1)[:, None]
    p0 = a @ t0
    d0 = np.linalg.norm(p0[:, None] - p0[None, :], axis=2)
    ia, ib = np.nonzero((s[None, :] - s[:, None] > gap) & (d0 < window))
    diff = a[ia] - a[ib]  # (P, n): x_a − x_b = diff @ T
    c = (2 * radius) ** 2
    # −Σ F_k·x_k = −Σ_j (Σ_k a[k, j] F_k)·t_j: each tangent's share of the loads' work
    work = sum((np.outer(a[k], f) for k, f in loads), np.zeros((n, 3)))

    def energy(v):
        t = v.reshape(n, 3)
        return rf / h * (np.sum(1 - np.sum(t[:-1] * t[1:], axis=1)) + np.sum((t[0] - e0) ** 2)
                         + np.sum((t[-1] - el) ** 2)) - np.sum(work * t)

    def grad(v):
        t = v.reshape(n, 3)
        g = np.zeros_like(t)
        g[:-1] -= t[1:]
        g[1:] -= t[:-1]
        g[0] += 2 * (t[0] - e0)
        g[-1] += 2 * (t[-1] - el)
        return (rf / h * g - work).ravel()

    def eq(v):
        t = v.reshape(n, 3)
        return np.concatenate([np.sum(t * t, axis=1) - 1, h * t.sum(axis=0) - end])

    def eq_jac(v):
        t = v.reshape(n, 3)
        j = np.zeros((n + 3, 3 * n))
        for k in range(n):
            j[k, 3 * k: 3 * k + 3] = 2 * t[k]
        for d in range(3):
            j[n + d, d::3] = h
        return j

    def ineq(v):
        dx = diff @ v.reshape(n, 3)
        return np.sum(dx * dx, axis=1) - c

    def ineq_jac(v):
        dx = diff @ v.reshape(n, 3)
        return 2 * (diff[:, :, None] * dx[:, None, :]).reshape(len(dx), 3 * n)

    cons = [{"type": "eq", "fun": eq, "jac": eq_jac}]
    if len(ia):
        cons.append({"type": "ineq", "fun": ineq, "jac": ineq_jac})
    res = minimize(energy, t0.ravel(), jac=grad, constraints=cons, method="SLSQP",
                   options={"maxiter": maxiter, "ftol": 1e-12})
    t = res.x.reshape(n, 3)
    pts = a @ t
    d = np.linalg.norm(pts[:, None] - pts[None, :], axis=2)
    far = s[None, :] - s[:, None] > gap
    closest = float(np.min(np.where(far, d, np.inf)))
    on = np.array([d[i, j] ** 2 - c < active_tol * length ** 2 for i, j in zip(ia, ib)], dtype=bool)
    active = [(int(i), int(j)) for i, j, k in zip(ia, ib, on) if k]
    # KKT: ∇E = J_eqᵀ ν + J_activeᵀ μ (SLSQP's sign: g ≥ 0 rows); least squares for (ν, μ)
    rows = np.vstack([eq_jac(res.x), ineq_jac(res.x)[on]]) if len(ia) else eq_jac(res.x)
    mult = np.linalg.lstsq(rows.T, grad(res.x), rcond=None)[0][n + 3:]
    forces = np.array([2 * m * (pts[i] - pts[j]) for m, (i, j) in zip(mult, active)]).reshape(-1, 3)
    return ContactRod(t, s, pts, float(energy(res.x)), active, closest, bool(res.success), str(res.message),
                      forces)
