"""An independent reference for self-contact with twist: a discrete inextensible Cosserat rod of N rigid
edges, each carrying its own frame, with pairwise non-penetration, minimised by IPOPT (CasADi's nlpsol,
built here; nothing imports dlo_ros).

Edge j (length h = L/N) carries a unit quaternion q_j = (x, y, z, w): its frame R(q_j) = [t d1 d2] has
the tangent t = R e_x.  Vertices x_k = x_left + h Σ_{i<k} t_i and edge midpoints interleave as points
(2N+1 of them, arc lengths k h/2).  Neighbouring frames meet at a joint; the relative rotation
q_j* ⊗ q_{j+1} has the vector part v = sin(θ/2) a (θ the joint's angle, a its axis in the body frame of
edge j), and the joint of length l costs

    U_joint = (2/l) (Rt v_1² + Rf (v_2² + v_3²))  =  (1/2l)(Rt θ_1² + Rf (θ_2² + θ_3²)) (1 + O(θ²)),

the Kirchhoff energy ½∫(Rt Ω_1² + Rf(Ω_2² + Ω_3²)) ds of a uniformly bent and twisted joint (Ω = θ/l):
l = h between edges, l = h/2 between an end edge and its clamp's quaternion.  Sign-free: v² does not
change when q → −q.  Equalities: |q_j|² = 1, the right end at its clamp's position, and each pin (a
vertex held at a point, free to turn) at its position.  Inequalities, for every pair of points more than
``gap`` apart along s and within ``window`` of each other at the start: |x_a − x_b|² ≥ (2r)².
The contact force on point a of an active pair is 2μ(x_a − x_b) with μ ≥ 0 its multiplier (its
opposite acts on b).  Discretisation error O(h²) in the energy (Richardson in h²).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np


@dataclass
class TwistedContactRod:
    """The minimiser: quaternions (N, 4), point arc lengths s and points (2N+1, 3), energy [J] and its
    twist part, the pairs (a, b) within ``active_tol`` of 2r with their force on a [N], the closest far
    pair's distance [m], IPOPT's verdict."""

    quaternions: np.ndarray
    s: np.ndarray
    points: np.ndarray
    energy: float
    twist_energy: float
    active: list[tuple[int, int]]
    forces: np.ndarray
    closest: float
    success: bool
    message: str
    box_active: bool = False


def _tangent(q):
    x, y, z, w = q[0], q[1], q[2], q[3]
    return ca.vertcat(1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w))


def _relative(a, b):
    """Vector part of a* ⊗ b (the rotation from frame a to frame b, in a's body frame)."""
    av, aw, bv, bw = a[0:3], a[3], b[0:3], b[3]
    return aw * bv - bw * av - ca.cross(av, bv)


def edge_start(quaternions0, left, right):
    """Unit edge quaternions in one hemisphere along the rod (the energy does not care; IPOPT's start
    does), and the clamps' (position, quaternion) as arrays."""
    q0 = np.asarray(quaternions0, dtype=float)
    q0 = q0 / np.linalg.norm(q0, axis=1)[:, None]
    for j in range(1, len(q0)):
        if q0[j] @ q0[j - 1] < 0:
            q0[j] = -q0[j]
    return q0, tuple(np.asarray(v, dtype=float) for v in left), tuple(np.asarray(v, dtype=float) for v in right)


def solve_twisted_contact_rod(quaternions0: np.ndarray, length: float, rf: float, rt: float,
                              left: tuple[np.ndarray, np.ndarray], right: tuple[np.ndarray, np.ndarray],
                              radius: float, gap: float, window: float,
                              pins: tuple[tuple[int, np.ndarray], ...] = (), box: float = np.inf,
                              active_tol: float = 1e-6, tol: float = 1e-10) -> TwistedContactRod:
    """Minimise the energy (module docstring) from the edge quaternions ``quaternions0`` (N, 4, x y z w);
    ``left``/``right``: clamp (position, quaternion); ``pins``: (vertex index, position) pairs.

    ``box``: each quaternion component stays within ``box`` of its start (IPOPT's iterates are not a
    continuous path: from a wrapped start they may step straight through the other strand, between the
    constrained points, onto an unwrapped branch).  ``box_active`` of the answer says whether a bound
    holds it; when none does, the answer is a local minimum of the problem without the box."""
    n = len(quaternions0)
    h = length / n
    q0, (x_left, q_left), (x_right, q_right) = edge_start(quaternions0, left, right)

    Q = ca.SX.sym("q", 4, n)
    cols = [Q[:, j] for j in range(n)]
    tangents = [_tangent(c) for c in cols]
    pts = [ca.DM(x_left)]
    for j in range(n):
        pts.append(pts[-1] + h / 2 * tangents[j])  # midpoint of edge j
        pts.append(pts[-1] + h / 2 * tangents[j])  # vertex j+1
    s = np.arange(2 * n + 1) * h / 2

    def joint(a, b, l):
        v = _relative(a, b)
        return 2 / l * (rt * v[0] ** 2 + rf * (v[1] ** 2 + v[2] ** 2)), 2 / l * rt * v[0] ** 2

    terms = [joint(ca.DM(q_left), cols[0], h / 2), joint(cols[-1], ca.DM(q_right), h / 2)]
    terms += [joint(cols[j], cols[j + 1], h) for j in range(n - 1)]
    energy = sum(t[0] for t in terms)
    twist = sum(t[1] for t in terms)

    g = [ca.dot(c, c) - 1 for c in cols] + [pts[-1] - x_right]
    g += [pts[2 * k] - np.asarray(x, dtype=float) for k, x in pins]
    n_eq = n + 3 + 3 * len(pins)

    f_points = ca.Function("points", [Q], [ca.horzcat(*pts).T])
    p0 = np.array(f_points(q0.T))
    d0 = np.linalg.norm(p0[:, None] - p0[None, :], axis=2)
    ia, ib = np.nonzero((s[None, :] - s[:, None] > gap) & (d0 < window))
    c = (2 * radius) ** 2
    g += [ca.sumsqr(pts[a] - pts[b]) - c for a, b in zip(ia, ib)]
    lbg = np.concatenate([np.zeros(n_eq), np.zeros(len(ia))])
    ubg = np.concatenate([np.zeros(n_eq), np.full(len(ia), np.inf)])

    solver = ca.nlpsol("twisted_contact_rod", "ipopt", {"x": ca.vec(Q), "f": energy, "g": ca.vertcat(*g)},
                       {"print_time": False, "ipopt": {"print_level": 0, "tol": tol, "max_iter": 3000,
                                                       "sb": "yes"}})
    sol = solver(x0=q0.ravel(), lbg=lbg, ubg=ubg, lbx=q0.ravel() - box, ubx=q0.ravel() + box)  # ca.vec(Q) stacks the columns q_0, q_1, …
    stats = solver.stats()
    qv = np.array(sol["x"]).reshape(n, 4)
    points = np.array(f_points(qv.T))
    e = float(sol["f"])
    tw = float(ca.Function("tw", [Q], [twist])(qv.T))
    d = np.linalg.norm(points[:, None] - points[None, :], axis=2)
    far = s[None, :] - s[:, None] > gap
    closest = float(np.min(np.where(far, d, np.inf)))
    lam = np.array(sol["lam_g"]).ravel()[n_eq:]
    on = [k for k, (a, b) in enumerate(zip(ia, ib)) if d[a, b] ** 2 - c < active_tol * length ** 2]
    active = [(int(ia[k]), int(ib[k])) for k in on]
    # IPOPT's λ of g ≥ 0 is ≤ 0 (∇f + Jᵀλ = 0): μ = −λ ≥ 0, the force on a is μ ∂g/∂x_a = 2μ (x_a − x_b)
    forces = np.array([-2 * lam[k] * (points[ia[k]] - points[ib[k]]) for k in on]).reshape(-1, 3)
    box_active = bool(np.isfinite(box) and np.max(np.abs(qv - q0)) > box - 1e-6)
    return TwistedContactRod(qv, s, points, e, tw, active, forces, closest, bool(stats["success"]),
                             str(stats["return_status"]), box_active)
