"""An independent discrete reference for a heavy, twisted rod against obstacles: the discrete rod of
test/reference/twisted_contact_rod.py (N rigid edges with their own quaternion frames, bend and twist
joints, clamps at both ends) with gravity, spheres and half-spaces, minimised by IPOPT (CasADi's
nlpsol, built here; nothing imports dlo_ros).

Points: the vertices x_k = x_left + h Σ_{i<k} t_i and the edge midpoints m_j (2N+1 points, arc
lengths k h/2, h = L/N).  Energy: the joints' Kirchhoff energy (twisted_contact_rod) plus the weight
D [N/m] along the unit ``gravity``,

    U_gravity = − D h Σ_j gravity·m_j,

exact for the straight edges (the midpoint rule: O(h²) against the smooth rod).  Constraints, at
every point p (vertices and midpoints): a sphere (centre c, radius R) keeps |p − c|² ≥ (R + r)²,
a half-space (a point p0 on its surface, unit outward normal n; the solid is n·(x − p0) ≤ 0, as
dlo_ros/model/obstacles.py) keeps n·(p − p0) ≥ r, r the string's radius.  The clamps fix the end
positions and frames (the right end's position an equality; its frame enters through the last joint).

Accuracy: the elastic and gravity terms are O(h²) (Richardson in h² removes them: solve at N and 2N
edges, x ≈ (4 x_2N − x_N)/3 at the common points).  A contact held at points only lets the piecewise
linear curve cut into a sphere between two points, by at most (h/2)² κ/8 (κ the sphere's curvature
relative to the rod's), and the contact point lands on the grid: an O(h²) error whose coefficient
jumps with the contact's place between points, so Richardson does not cancel it; at N = 400 for the
post (R + r = 0.085 m, h/2 = 1.25 mm) it is below 2.5e-6 m.  ``richardson`` returns both answers and
the extrapolation; the change between them measures the accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .twisted_contact_rod import _relative, _tangent, edge_start


@dataclass
class HeavyContactRod:
    """The minimiser: quaternions (N, 4), point arc lengths s and points (2N+1, 3), energy [J], for
    every obstacle the indices of the points within ``active_tol`` of it and their forces [N]
    (``contacts``: obstacle index -> (indices, forces (K, 3))), IPOPT's verdict."""

    quaternions: np.ndarray
    s: np.ndarray
    points: np.ndarray
    energy: float
    contacts: dict
    clearance: np.ndarray
    success: bool
    message: str

    def at(self, s: np.ndarray) -> np.ndarray:
        """Points at arc lengths s, linear between the points (the discrete rod's own centreline)."""
        return np.stack([np.interp(s, self.s, self.points[:, k]) for k in range(3)], axis=1)


def sphere(centre, radius: float) -> tuple:
    """A sphere obstacle for ``solve_heavy_contact_rod``."""
    return ("sphere", np.asarray(centre, dtype=float), float(radius))


def halfspace(point, normal) -> tuple:
    """A half-space obstacle (the solid behind the outward ``normal``)."""
    n = np.asarray(normal, dtype=float)
    return ("halfspace", np.asarray(point, dtype=float), n / np.linalg.norm(n))


def solve_heavy_contact_rod(quaternions0: np.ndarray, length: float, rf: float, rt: float,
                            weight: float, gravity, left, right, radius: float,
                            obstacles=(), active_tol: float = 1e-9,
                            tol: float = 1e-11) -> HeavyContactRod:
    """Minimise the energy (module docstring) from the edge quaternions ``quaternions0`` (N, 4,
    x y z w); ``left``/``right``: clamp (position, quaternion); ``weight`` D [N/m] along the unit
    ``gravity``; ``obstacles``: ``sphere(...)`` and ``halfspace(...)``, kept off every point."""
    n = len(quaternions0)
    h = length / n
    q0, (x_left, q_left), (x_right, q_right) = edge_start(quaternions0, left, right)
    g_dir = np.asarray(gravity, dtype=float)
    g_dir = g_dir / np.linalg.norm(g_dir)

    # unknowns: the quaternions and the inner vertices (sparse: each edge ties two vertices)
    Q = ca.SX.sym("q", 4, n)
    X = ca.SX.sym("x", 3, n - 1)
    cols = [Q[:, j] for j in range(n)]
    tangents = [_tangent(c) for c in cols]
    vertices = [ca.DM(x_left)] + [X[:, k] for k in range(n - 1)] + [ca.DM(x_right)]
    pts = []
    for j in range(n):
        pts += [vertices[j], vertices[j] + h / 2 * tangents[j]]
    pts.append(vertices[-1])
    s = np.arange(2 * n + 1) * h / 2

    def joint(a, b, l):
        v = _relative(a, b)
        return 2 / l * (rt * v[0] ** 2 + rf * (v[1] ** 2 + v[2] ** 2))

    energy = joint(ca.DM(q_left), cols[0], h / 2) + joint(cols[-1], ca.DM(q_right), h / 2)
    energy += sum(joint(cols[j], cols[j + 1], h) for j in range(n - 1))
    energy -= weight * h * sum(ca.dot(ca.DM(g_dir), pts[2 * j + 1]) for j in range(n))

    g = [ca.dot(c, c) - 1 for c in cols]
    g += [vertices[j + 1] - vertices[j] - h * tangents[j] for j in range(n)]  # the right clamp at j = n − 1
    n_eq = n + 3 * n
    rows = []  # (obstacle, point) of every inequality row
    for i, ob in enumerate(obstacles):
        for k, p in enumerate(pts):
            if ob[0] == "sphere":
                g.append(ca.sumsqr(p - ob[1]) - (ob[2] + radius) ** 2)
            else:
                g.append(ca.dot(ca.DM(ob[2]), p - ob[1]) - radius)
            rows.append((i, k))
    lbg = np.zeros(n_eq + len(rows))
    ubg = np.concatenate([np.zeros(n_eq), np.full(len(rows), np.inf)])

    t0 = np.stack([np.array(_tangent(ca.DM(q))).ravel() for q in q0])
    x0 = x_left + h * np.cumsum(t0, axis=0)[:-1]  # the start's inner vertices
    z = ca.vertcat(ca.vec(Q), ca.vec(X))
    solver = ca.nlpsol("heavy_contact_rod", "ipopt", {"x": z, "f": energy, "g": ca.vertcat(*g)},
                       {"print_time": False, "ipopt": {"print_level": 0, "tol": tol, "max_iter": 3000,
                                                       "sb": "yes"}})
    sol = solver(x0=np.concatenate([q0.ravel(), x0.ravel()]), lbg=lbg, ubg=ubg)  # vec: column-major
    stats = solver.stats()
    zv = np.array(sol["x"]).ravel()
    qv = zv[: 4 * n].reshape(n, 4)
    points = np.array(ca.Function("points", [z], [ca.horzcat(*pts).T])(zv))
    value = np.array(ca.Function("g", [z], [ca.vertcat(*g)[n_eq:]])(zv)).ravel()
    lam = np.array(sol["lam_g"]).ravel()[n_eq:]
    contacts, clearance = {}, np.full(len(obstacles), np.inf)
    for i, ob in enumerate(obstacles):
        on, forces = [], []
        for row, (j, k) in enumerate(rows):
            if j != i:
                continue
            p = points[k]
            if ob[0] == "sphere":
                gap = np.linalg.norm(p - ob[1]) - ob[2] - radius
                grad = 2 * (p - ob[1])
            else:
                gap = value[row]
                grad = ob[2]
            clearance[i] = min(clearance[i], gap)
            if gap < active_tol:  # IPOPT's λ of g ≥ 0 is ≤ 0: the force on the point is −λ ∇g
                on.append(k)
                forces.append(-lam[row] * grad)
        contacts[i] = (np.array(on, dtype=int), np.array(forces).reshape(-1, 3))
    return HeavyContactRod(qv, s, points, float(sol["f"]), contacts, clearance,
                           bool(stats["success"]), str(stats["return_status"]))


def refine(quaternions: np.ndarray) -> np.ndarray:
    """Edge quaternions of the rod with twice the edges (each edge's frame on both its halves)."""
    return np.repeat(np.asarray(quaternions, dtype=float), 2, axis=0)


def richardson(quaternions0: np.ndarray, s_eval: np.ndarray, **problem):
    """Solve at N = len(quaternions0) and 2N edges (the second from the first's answer) and return
    (coarse, fine, extrapolated points at ``s_eval``): (4 x_2N − x_N)/3, both interpolated linearly
    at ``s_eval`` (chosen on the coarse grid's points, where linear interpolation is exact)."""
    coarse = solve_heavy_contact_rod(quaternions0, **problem)
    fine = solve_heavy_contact_rod(refine(coarse.quaternions), **problem)
    return coarse, fine, (4 * fine.at(s_eval) - coarse.at(s_eval)) / 3
