"""A discretised 3D rod of the bench's own (method 4 in 3D): N straight segments, one unit quaternion each.

Segment j (j = 1 … N, length h = L/N) carries a material frame Q_j = R(q_j) whose x-axis is the tangent
(the ROS pose convention, so a grip's quaternion is directly a frame).  Joints between neighbouring
frames a, b at distance ℓ (h inside, h/2 to a clamp's frame) store

    E_joint = ½ ℓ (Rt κ_x² + Rf (κ_y² + κ_z²)),   κ = 2 vec(q_a* ⊗ q_b) / ℓ,

the discrete Darboux vector (2 sin(α/2) for a relative rotation α: consistent to O(α³), and unchanged
when either quaternion changes sign, so q and −q are the same frame).  Positions x_i = x_0 + h Σ_{j≤i} t_j,
weight at segment centres, unit-norm constraints |q_j|² = 1 (IPOPT; the stability check works on their
null space, which removes the sign gauge).  A 'tangent' grip adds a free frame whose tangent is held
(twist free).  The turn count of a twisted end lives in the continuous chain of frames: a cold start is
told the total turn τ (the guess spreads it linearly); sweeps warm-start from the previous frames.
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

from dlo_ros.model.problem import Problem
from dlo_ros.model.rotations import quat_to_matrix

from bench.common import S_OUT, Outcome, interp_points, quat_twisted
from bench.methods.nlp_tools import CasadiNLP, NLPSolution
from bench.methods.planar import guess_angles, tangent_angle


def qmul(a, b):
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return ca.vertcat(aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                      aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def qconj(a):
    return ca.vertcat(-a[0], -a[1], -a[2], a[3])


def qtangent(q):
    x, y, z, w = q[0], q[1], q[2], q[3]
    return ca.vertcat(w * w + x * x - y * y - z * z, 2 * (x * y + w * z), 2 * (x * z - w * y))


class Rod3D:
    P_SIZE = 15  # left pos, right pos, left quat, right quat, weight scale

    def __init__(self, problem: Problem, segments: int = 40):
        t0 = time.perf_counter()
        self.problem = problem
        L, N = problem.string.length, segments
        self.L, self.N, self.h = L, N, L / N
        h = self.h
        self.modes = {g.name: g.mode for g in problem.grips}
        assert problem.grip("left").s == 0.0 and problem.grip("right").s == L
        if self.modes["left"] not in ("clamp", "pin"):
            raise ValueError("Rod3D: the left grip must be a clamp or a pin")
        if any(np.linalg.norm(ld.moment) > 0 for ld in problem.loads):
            raise ValueError("Rod3D: point moments are not modelled (use the planar rod)")
        st = problem.string
        s_nodes = np.arange(N + 1) * h
        self.s_nodes = s_nodes
        s_mid = (np.arange(N) + 0.5) * h
        extra = 1 if self.modes["right"] == "tangent" else 0
        self.nq = N + extra
        z = ca.SX.sym("q", 4 * self.nq)
        p = ca.SX.sym("p", self.P_SIZE)
        q = [z[4 * j: 4 * j + 4] for j in range(self.nq)]
        Rf, Rt = st.bend_stiffness(s_nodes), st.twist_stiffness(s_nodes)

        def joint(qa, qb, ell, k):
            r = qmul(qconj(qa), qb)
            return (2.0 / ell) * (Rt[k] * r[0] ** 2 + Rf[k] * (r[1] ** 2 + r[2] ** 2))

        energy = 0
        for j in range(N - 1):
            energy += joint(q[j], q[j + 1], h, j + 1)
        if self.modes["left"] == "clamp":
            energy += joint(p[6:10], q[0], h / 2, 0)
        if self.modes["right"] == "clamp":
            energy += joint(q[N - 1], p[10:14], h / 2, N)
        elif self.modes["right"] == "tangent":
            energy += joint(q[N - 1], q[N], h / 2, N)
        bend_twist = energy
        t = [qtangent(q[j]) for j in range(N)]
        xs = [p[0:3]]
        for j in range(N):
            xs.append(xs[-1] + h * t[j])
        X = ca.horzcat(*xs)  # 3 × (N+1)
        D = st.weight_per_length(s_mid)
        g_unit = problem.gravity_unit
        centres = 0.5 * (X[:, :-1] + X[:, 1:])
        grav = -p[14] * h * ca.dot(ca.DM(D), ca.mtimes(ca.DM(g_unit).T, centres).T)
        work = 0
        for ld in problem.loads:
            i = min(int(np.floor(ld.s / h + 1e-9)), N - 1)
            u = ld.s / h - i
            work += ca.dot(ca.DM(ld.force), (1 - u) * X[:, i] + u * X[:, i + 1])
        sigma = L / st.bend_stiffness.maximum
        f = sigma * (bend_twist + grav - work)
        rows, lb, ub = [X[:, N] - p[3:6]], [0.0] * 3, [0.0] * 3
        for j in range(self.nq):
            rows.append(ca.dot(q[j], q[j]) - 1.0)
            lb.append(0.0); ub.append(0.0)
        if extra:
            tt = quat_to_matrix(problem.grip("right").pose.orientation)[:, 0]
            e1 = np.cross(tt, [0, 0, 1.0]) if abs(tt[2]) < 0.9 else np.cross(tt, [1.0, 0, 0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(tt, e1)
            t_end = qtangent(q[N])
            rows += [ca.dot(ca.DM(e1), t_end), ca.dot(ca.DM(e2), t_end)]
            lb += [0.0, 0.0]; ub += [0.0, 0.0]
            self._tangent_target = tt
        r = st.radius
        for ob in problem.obstacles:
            if ob.type != "halfspace":
                raise ValueError("Rod3D supports half-space obstacles only")
            pt, n = ob.point, ob.normal
            for i in range(1, N):  # interior nodes: the ends are held by the grips
                rows.append(-ca.dot(ca.DM(n), X[:, i] - ca.DM(pt)) + r)
                lb.append(-np.inf); ub.append(0.0)
        self.nlp = CasadiNLP(z, p, f, ca.vertcat(*rows), lb, ub)
        self.energy_fn = ca.Function("e", [z, p], [bend_twist + grav - work])
        self.nodes_fn = ca.Function("x", [z, p], [X])
        self.build_time_s = time.perf_counter() - t0

    def params(self, problem: Problem, weight_scale: float = 1.0) -> np.ndarray:
        gl, gr = problem.grip("left"), problem.grip("right")
        return np.concatenate([gl.pose.position, gr.pose.position, gl.pose.orientation, gr.pose.orientation,
                               [weight_scale]])

    def guess(self, problem: Problem, tau: float = 0.0, sag_sign: float | None = None) -> np.ndarray:
        """Planar buckled guess in the x–z plane with the end's turn τ spread linearly along s."""
        gl, gr = problem.grip("left"), problem.grip("right")
        pr = {"left_pos": gl.pose.position[[0, 2]], "right_pos": gr.pose.position[[0, 2]],
              "left_angle": tangent_angle(gl.pose.orientation), "right_angle": tangent_angle(gr.pose.orientation)}
        u = (np.arange(self.N) + 0.5) / self.N
        beta = guess_angles(u, problem, pr, sag_sign)
        qs = [quat_twisted(b, tau * uu) for b, uu in zip(beta, u)]
        if self.nq > self.N:
            qs.append(quat_twisted(pr["right_angle"], tau))
        return np.concatenate(qs)

    def cold(self, problem: Problem, tau: float = 0.0, weight_scale: float = 1.0, sag_sign: float | None = None,
             check: bool = True):
        p = self.params(problem, weight_scale)
        return self._finish(self.nlp.solve(self.guess(problem, tau, sag_sign), p), p, check)

    def warm(self, problem: Problem, previous: NLPSolution, weight_scale: float = 1.0, check: bool = True):
        p = self.params(problem, weight_scale)
        return self._finish(self.nlp.solve(previous.z, p, warm_from=previous), p, check)

    def _finish(self, sol: NLPSolution, p, check: bool = True):
        """time_s is IPOPT's; the stability verdict (dense reduced Hessian) is not timed."""
        stable = self.nlp.is_stable(sol.z, p, sol.lam_g) if (sol.ok and check) else None
        out = Outcome(sol.ok, self.points(sol.z, p), sol.time_s, sol.iterations, stable,
                      float(self.energy_fn(sol.z, p)), sol.status)
        sol.p = p
        return out, sol

    def points(self, z, p) -> np.ndarray:
        X = np.asarray(self.nodes_fn(z, p)).T
        return interp_points(self.s_nodes, X, S_OUT * self.L)

    def twist_turns(self, z) -> float:
        """Total rotation of the frames about the tangent, summed joint by joint [rad] (diagnostic)."""
        qs = z.reshape(-1, 4)
        total = 0.0
        for a, b in zip(qs[:-1], qs[1:]):
            r = np.asarray(qmul(qconj(ca.DM(a)), ca.DM(b))).ravel()
            total += 2 * np.arctan2(r[0], r[3])
        return total
