"""Planar models of the bench's own (the x–z plane, tangent (cos β, 0, sin β), β the tangent angle).

* ``PlanarRitz``: β(s) = Σ c_k b_k(s) in a Ritz basis ('fourier' = the paper's 1, s, sin, cos …, or
  'chebyshev'); energies by Clenshaw–Curtis quadrature, x(s) by spectral cumulative integration (the
  same machinery as dlo_ros.model, restricted to one angle).  In the paper's frame (R0 = I) a string in
  the z–x plane has φ ≡ π and θ = π/2 − β, so this *is* the paper's planar Euler-angle model (its
  examples 2 and 3 are planar).  Used by method 1 (paper, Nelder–Mead) and method 2 (Fourier + IPOPT)
  on the planar cases.
* ``PlanarRod``: N straight segments of length h = L/N with angles β_1 … β_N (sampled at segment
  midpoints); bending Σ ½ Rf (Δβ)²/h over the joints, half joints (h/2) to a clamp's angle; weight at
  segment centres; positions x_i = x_0 + h Σ_{j≤i} (cos β_j, sin β_j).  Second order in h.  Method 4.

Both take a dlo_ros Problem whose grips sit at s = 0 and s = L in the x–z plane; grip targets and the
weight scale are NLP parameters (moving a grip or changing ρ never rebuilds).
Work of a moment M about +y at s_k: W = −M_y β(s_k) (a rotation about +y lowers β).
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

from dlo_ros.model.basis import make_basis
from dlo_ros.model.problem import Problem
from dlo_ros.model.quadrature import ChebyshevQuadrature
from dlo_ros.model.rotations import quat_to_matrix
from dlo_ros.solver.build.initial_guess import inverse_j0

from bench.common import S_OUT, Outcome, interp_points
from bench.methods.nlp_tools import CasadiNLP, NLPSolution, augmented_lagrangian_nm


def tangent_angle(q: np.ndarray) -> float:
    t = quat_to_matrix(q)[:, 0]
    return float(np.arctan2(t[2], t[0]))


def default_sag(problem: Problem) -> float:
    """Buckle toward gravity (as ShapeSolver's guess does): −1 (down) when gravity points down."""
    return -1.0 if problem.gravity_unit[2] <= 0 else 1.0


def guess_angles(u: np.ndarray, problem: Problem, params: dict, sag_sign: float | None = None) -> np.ndarray:
    """Buckled guess β(u) = β_c + sag·α sin 2πu (J0(α) = chord/L), corrected linearly to the held angles.
    sag −1 buckles down (−z), +1 up; None: toward gravity."""
    if sag_sign is None:
        sag_sign = default_sag(problem)
    xl, xr = params["left_pos"], params["right_pos"]
    chord = np.hypot(*(xr - xl))
    beta_c = float(np.arctan2(xr[1] - xl[1], xr[0] - xl[0]))
    alpha = inverse_j0(min(1.0, chord / problem.string.length))
    beta = beta_c + sag_sign * alpha * np.sin(2 * np.pi * u)
    modes = {g.name: g.mode for g in problem.grips}
    if modes["left"] != "pin":
        beta += (params["left_angle"] - beta_c) * (1 - u)
    if modes["right"] != "pin":
        beta += (params["right_angle"] - beta_c) * u
    return beta


class _PlanarBase:
    """Common parameter handling: p = [x_left(2), x_right(2), β_left, β_right, weight scale]."""

    P_SIZE = 7

    def __init__(self, problem: Problem):
        self.problem = problem
        self.L = problem.string.length
        g = problem.gravity_unit
        if abs(g[1]) > 1e-12:
            raise ValueError("planar models need gravity in the x–z plane")
        self.g = g
        self.modes = {gr.name: gr.mode for gr in problem.grips}
        assert set(self.modes) == {"left", "right"}
        assert problem.grip("left").s == 0.0 and problem.grip("right").s == self.L
        self.current_beta = (0.0, 0.0)

    def params(self, problem: Problem, weight_scale: float = 1.0, reference=None) -> np.ndarray:
        gl, gr = problem.grip("left"), problem.grip("right")
        bl, br = tangent_angle(gl.pose.orientation), tangent_angle(gr.pose.orientation)
        ref = reference if reference is not None else (0.0, 0.0)
        bl += 2 * np.pi * np.round((ref[0] - bl) / (2 * np.pi))
        br += 2 * np.pi * np.round((ref[1] - br) / (2 * np.pi))
        return np.array([gl.pose.position[0], gl.pose.position[2], gr.pose.position[0], gr.pose.position[2], bl, br,
                         weight_scale])

    @staticmethod
    def unpack(p: np.ndarray) -> dict:
        return {"left_pos": np.array(p[0:2]), "right_pos": np.array(p[2:4]), "left_angle": p[4], "right_angle": p[5]}

    def _constraints(self, xr, beta_l, beta_r, obstacle_x, p):
        """Rows: right end position (2), held angles, obstacle samples h ≤ 0."""
        if getattr(self, "right_slide", False):
            # paper Fig. 5: the right end stays at the fingers' height and may slide inward: x(L) ≤ l, z(L) = z_l
            rows, lb, ub = [xr[0] - p[2], xr[1] - p[3]], [-np.inf, 0.0], [0.0, 0.0]
        else:
            rows, lb, ub = [xr[0] - p[2], xr[1] - p[3]], [0.0, 0.0], [0.0, 0.0]
        if self.modes["left"] != "pin" and beta_l is not None:
            rows.append(beta_l - p[4]); lb.append(0.0); ub.append(0.0)
        if self.modes["right"] != "pin" and beta_r is not None:
            rows.append(beta_r - p[5]); lb.append(0.0); ub.append(0.0)
        r = self.problem.string.radius
        for ob in self.problem.obstacles:
            if ob.type != "halfspace":
                raise ValueError("planar bench models support half-space obstacles only")
            pt, n = ob.point, ob.normal
            for j in range(obstacle_x.shape[1]):
                h = -(n[0] * (obstacle_x[0, j] - pt[0]) + n[2] * (obstacle_x[1, j] - pt[2]))
                rows.append(h + r); lb.append(-np.inf); ub.append(0.0)
        return ca.vertcat(*rows), lb, ub

    def _loads_work(self, pos_at, beta_at):
        work = 0
        for ld in self.problem.loads:
            F = ld.force
            if abs(F[1]) > 1e-12 or abs(ld.moment[0]) > 1e-12 or abs(ld.moment[2]) > 1e-12:
                raise ValueError("planar bench models: forces in x–z, moments about y only")
            x = pos_at(ld.s)
            work += F[0] * x[0] + F[2] * x[1] - ld.moment[1] * beta_at(ld.s)
        return work

    # ---- solving -------------------------------------------------------------------------------
    def cold(self, problem: Problem, weight_scale: float = 1.0, sag_sign: float | None = None) -> tuple[Outcome, NLPSolution]:
        p = self.params(problem, weight_scale)
        z0 = self.guess(p, problem, sag_sign)
        return self._finish(self.nlp.solve(z0, p), p)

    def warm(self, problem: Problem, previous: NLPSolution, weight_scale: float = 1.0) -> tuple[Outcome, NLPSolution]:
        p = self.params(problem, weight_scale, reference=self.end_angles(previous.z))
        return self._finish(self.nlp.solve(previous.z, p, warm_from=previous), p)

    def _finish(self, sol: NLPSolution, p) -> tuple[Outcome, NLPSolution]:
        stable = self.nlp.is_stable(sol.z, p, sol.lam_g) if sol.ok else None
        out = Outcome(sol.ok, self.points(sol.z, p), sol.time_s, sol.iterations, stable,
                      float(self.energy_fn(sol.z, p)), sol.status)  # energy in J (sol.f is scaled by σ = L/Rf)
        sol.p = p
        return out, sol


class PlanarRitz(_PlanarBase):
    def __init__(self, problem: Problem, basis: str = "fourier", order: int = 10, nodes: int | None = None,
                 obstacle_samples: int = 41):
        t0 = time.perf_counter()
        super().__init__(problem)
        L = self.L
        self.order = order
        self.basis = make_basis(basis, order, L)
        self.quad = ChebyshevQuadrature(nodes or max(40, order + 8), L)
        s = self.quad.nodes
        B, dB = self.basis.values(s), self.basis.derivatives(s)
        w = self.quad.weights
        st = problem.string
        Rf, D = st.bend_stiffness(s), st.weight_per_length(s)
        c = ca.SX.sym("c", order)
        p = ca.SX.sym("p", self.P_SIZE)
        beta, dbeta = ca.mtimes(ca.DM(B), c), ca.mtimes(ca.DM(dB), c)
        cosb, sinb = ca.cos(beta), ca.sin(beta)
        self.obstacle_s = np.linspace(0, L, obstacle_samples) if problem.obstacles else np.zeros(0)

        def positions(s_q):
            W = ca.DM(self.quad.integration_matrix(np.atleast_1d(s_q)))
            return ca.vertcat(ca.reshape(p[0] + ca.mtimes(W, cosb), 1, -1), ca.reshape(p[1] + ca.mtimes(W, sinb), 1, -1))

        bend = 0.5 * ca.dot(ca.DM(w * Rf), dbeta**2)
        xn = positions(s)
        grav = -p[6] * ca.dot(ca.DM(w * D), self.g[0] * xn[0, :].T + self.g[2] * xn[1, :].T)
        beta_at = lambda sq: ca.mtimes(ca.DM(self.basis.values(np.array([sq]))), c)  # noqa: E731
        work = self._loads_work(lambda sq: positions(sq), beta_at)
        sigma = L / st.bend_stiffness.maximum
        f = sigma * (bend + grav - work)
        xr = positions(L)
        obs_x = positions(self.obstacle_s) if len(self.obstacle_s) else ca.SX(2, 0)
        g, lb, ub = self._constraints(xr, beta_at(0.0), beta_at(L), obs_x, p)
        self.nlp = CasadiNLP(c, p, f, g, lb, ub)
        self.energy_fn = ca.Function("e", [c, p], [bend + grav - work])
        self.out_fn = ca.Function("x", [c, p], [positions(S_OUT * L)])
        self.beta_ends = ca.Function("b", [c], [ca.vertcat(beta_at(0.0), beta_at(L))])
        self.build_time_s = time.perf_counter() - t0

    def guess(self, p, problem, sag_sign=None):
        s = self.quad.nodes
        beta = guess_angles(s / self.L, problem, self.unpack(p), sag_sign)
        return np.linalg.lstsq(self.basis.values(s), beta, rcond=None)[0]

    def end_angles(self, z):
        return tuple(np.asarray(self.beta_ends(z)).ravel())

    def points(self, z, p):
        xz = np.asarray(self.out_fn(z, p))
        return np.stack([xz[0], np.zeros_like(xz[0]), xz[1]], axis=1)

    # ---- the paper's method: multiplier method + Nelder–Mead ------------------------------------
    def solve_nelder_mead(self, problem: Problem, z0=None, weight_scale: float = 1.0, lam0=None, time_limit=60.0,
                          sag_sign: float | None = None, reference=None):
        p = self.params(problem, weight_scale, reference=reference)
        if z0 is None:
            z0 = self.guess(p, problem, sag_sign)
        fg = self.nlp.fg

        def f_fn(x):
            f, g = fg(x, p)
            return float(f), np.asarray(g).ravel()

        z, lam, info = augmented_lagrangian_nm(f_fn, z0, self.nlp.lbg, self.nlp.ubg,
                                               lam0=lam0, time_limit=time_limit)
        # the multipliers of the AL are IPOPT's sign convention (∇f + Jᵀλ = 0): stability from the same check
        stable = self.nlp.is_stable(z, p, lam) if info["ok"] else None
        out = Outcome(info["ok"], self.points(z, p), info["time_s"], info["fevals"], stable,
                      float(self.energy_fn(z, p)), f"AL outer {info['outer']}, viol {info['violation']:.1e}",
                      extra=info)
        return out, z, lam, p


class PlanarRod(_PlanarBase):
    def __init__(self, problem: Problem, segments: int = 40, right_slide: bool = False, symmetric: bool = False):
        t0 = time.perf_counter()
        super().__init__(problem)
        self.right_slide = right_slide
        L, N = self.L, segments
        self.N = N
        h = L / N
        self.h = h
        st = problem.string
        s_mid = (np.arange(N) + 0.5) * h
        s_nodes = np.arange(N + 1) * h
        self.s_nodes = s_nodes
        b = ca.SX.sym("b", N)
        p = ca.SX.sym("p", self.P_SIZE)
        cosb, sinb = ca.cos(b), ca.sin(b)
        xs = ca.vertcat(p[0], p[0] + h * ca.cumsum(cosb))
        zs = ca.vertcat(p[1], p[1] + h * ca.cumsum(sinb))
        rf_joint = st.bend_stiffness(s_nodes)
        bend = 0
        for j in range(N - 1):
            bend += 0.5 * rf_joint[j + 1] * (b[j + 1] - b[j]) ** 2 / h
        if self.modes["left"] != "pin":
            bend += 0.5 * rf_joint[0] * (b[0] - p[4]) ** 2 / (h / 2)
        if self.modes["right"] != "pin":
            bend += 0.5 * rf_joint[N] * (p[5] - b[N - 1]) ** 2 / (h / 2)
        D = st.weight_per_length(s_mid)
        xm, zm = 0.5 * (xs[:-1] + xs[1:]), 0.5 * (zs[:-1] + zs[1:])
        grav = -p[6] * h * ca.dot(ca.DM(D), self.g[0] * xm + self.g[2] * zm)

        def pos_at(sq):
            i = min(int(np.floor(sq / h + 1e-9)), N - 1)
            t = sq / h - i
            return ca.vertcat((1 - t) * xs[i] + t * xs[i + 1], (1 - t) * zs[i] + t * zs[i + 1])

        ext = ca.vertcat(p[4] if self.modes["left"] != "pin" else b[0], b, p[5] if self.modes["right"] != "pin" else b[N - 1])
        s_ext = np.concatenate([[0.0], s_mid, [L]])

        def beta_at(sq):
            i = int(np.searchsorted(s_ext, sq, side="right") - 1)
            i = min(max(i, 0), N)
            t = (sq - s_ext[i]) / (s_ext[i + 1] - s_ext[i])
            return (1 - t) * ext[i] + t * ext[i + 1]

        work = self._loads_work(pos_at, beta_at)
        sigma = L / st.bend_stiffness.maximum
        f = sigma * (bend + grav - work)
        # obstacle rows at the interior nodes (the end nodes are held by the grips; a row that depends on
        # parameters only would be degenerate for IPOPT when a grip sits on the surface, as in paper Fig. 5)
        obs = (ca.vertcat(ca.reshape(xs[1:N], 1, -1), ca.reshape(zs[1:N], 1, -1)) if problem.obstacles
               else ca.SX(2, 0))
        g, lb, ub = self._constraints(ca.vertcat(xs[N], zs[N]), None, None, obs, p)  # clamps act through the half joints
        if symmetric:  # mirror symmetry about the mid-span vertical: β(s) = −β(L − s)
            g = ca.vertcat(g, *[b[j] + b[N - 1 - j] for j in range(N // 2)])
            lb, ub = list(lb) + [0.0] * (N // 2), list(ub) + [0.0] * (N // 2)
        self.nlp = CasadiNLP(b, p, f, g, lb, ub)
        self.energy_fn = ca.Function("e", [b, p], [bend + grav - work])
        self.nodes_fn = ca.Function("x", [b, p], [xs, zs])
        self.build_time_s = time.perf_counter() - t0

    def guess(self, p, problem, sag_sign=None):
        return guess_angles((np.arange(self.N) + 0.5) / self.N, problem, self.unpack(p), sag_sign)

    def end_angles(self, z):
        return (float(z[0]), float(z[-1]))

    def points(self, z, p):
        xs, zs = (np.asarray(a).ravel() for a in self.nodes_fn(z, p))
        nodes = np.stack([xs, np.zeros_like(xs), zs], axis=1)
        return interp_points(self.s_nodes, nodes, S_OUT * self.L)
