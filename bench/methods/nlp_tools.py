"""A small CasADi NLP wrapper for the bench's own NLPs: IPOPT cold/warm solves, stability check,
and an augmented-Lagrangian + Nelder–Mead solver (the paper's multiplier method, sec. 3–4)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.linalg import null_space
from scipy.optimize import minimize

IPOPT_BASE = {
    "print_level": 0, "sb": "yes", "tol": 1e-10, "acceptable_tol": 1e-7, "constr_viol_tol": 1e-10,
    "max_iter": 500, "linear_solver": "mumps", "hessian_approximation": "exact",
}
IPOPT_WARM = {
    "warm_start_init_point": "yes", "mu_init": 1e-7, "warm_start_bound_push": 1e-9,
    "warm_start_slack_bound_push": 1e-9, "warm_start_mult_bound_push": 1e-9, "max_iter": 200,
}
SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass
class NLPSolution:
    ok: bool
    z: np.ndarray
    lam_g: np.ndarray
    lam_x: np.ndarray
    f: float
    g: np.ndarray
    iterations: int
    status: str
    time_s: float


class CasadiNLP:
    """minimise f(z; p) s.t. lbg ≤ g(z; p) ≤ ubg, with exact-Hessian IPOPT (MUMPS)."""

    def __init__(self, z: ca.SX, p: ca.SX, f: ca.SX, g: ca.SX, lbg, ubg, ipopt: dict | None = None, lbx=None, ubx=None):
        t0 = time.perf_counter()
        self.z, self.p = z, p
        self.lbg, self.ubg = np.asarray(lbg, float), np.asarray(ubg, float)
        self.lbx = -np.inf * np.ones(z.shape[0]) if lbx is None else np.asarray(lbx, float)
        self.ubx = np.inf * np.ones(z.shape[0]) if ubx is None else np.asarray(ubx, float)
        nlp = {"x": z, "p": p, "f": f, "g": g}
        opts = dict(IPOPT_BASE, **(ipopt or {}))
        common = {"print_time": False, "error_on_fail": False}
        self.cold = ca.nlpsol("cold", "ipopt", nlp, dict(common, ipopt=opts))
        self.warm = ca.nlpsol("warm", "ipopt", nlp, dict(common, ipopt=dict(opts, **IPOPT_WARM)))
        lam = ca.SX.sym("lam", g.shape[0])
        self.hess = ca.Function("h", [z, p, lam], [ca.hessian(f + ca.dot(lam, g), z)[0]])
        self.jac = ca.Function("j", [z, p], [ca.jacobian(g, z)])
        self.fg = ca.Function("fg", [z, p], [f, g])
        self.f_fn = ca.Function("f", [z, p], [f])
        self.g_fn = ca.Function("g", [z, p], [g])
        self.build_time_s = time.perf_counter() - t0

    def solve(self, z0, p, warm_from: NLPSolution | None = None) -> NLPSolution:
        args = {"x0": z0, "p": p, "lbg": self.lbg, "ubg": self.ubg, "lbx": self.lbx, "ubx": self.ubx}
        solver = self.cold
        if warm_from is not None:
            args.update(lam_g0=warm_from.lam_g, lam_x0=warm_from.lam_x)
            solver = self.warm
        t0 = time.perf_counter()
        sol = solver(**args)
        dt = time.perf_counter() - t0
        st = solver.stats()
        z = np.asarray(sol["x"]).ravel()
        g = np.asarray(sol["g"]).ravel()
        viol = self.violation(g)
        ok = st["return_status"] in SUCCESS and viol < 1e-6 and bool(np.all(np.isfinite(z)))
        return NLPSolution(ok, z, np.asarray(sol["lam_g"]).ravel(), np.asarray(sol["lam_x"]).ravel(),
                           float(sol["f"]), g, int(st.get("iter_count", 0)), st["return_status"], dt)

    def violation(self, g: np.ndarray) -> float:
        if g.size == 0:
            return 0.0
        return float(np.max(np.maximum(np.maximum(self.lbg - g, 0), np.maximum(g - self.ubg, 0))))

    def min_reduced_eigenvalue(self, z, p, lam_g) -> float:
        """Smallest eigenvalue of ∇²L on the null space of the active constraints' Jacobian."""
        h = np.asarray(self.hess(z, p, lam_g))
        if self.lbg.size:
            g = np.asarray(self.g_fn(z, p)).ravel()
            active = (self.lbg == self.ubg) | (np.abs(lam_g) > 1e-9) | (g > self.ubg - 1e-9) | (g < self.lbg + 1e-9)
            j = np.asarray(self.jac(z, p))[active]
            basis = null_space(j) if j.size else np.eye(h.shape[0])
        else:
            basis = np.eye(h.shape[0])
        if basis.shape[1] == 0:
            return float("inf")
        return float(np.linalg.eigvalsh(basis.T @ h @ basis)[0])

    def unstable_direction(self, z, p, lam_g):
        """The eigenvector of the most negative reduced curvature (None when stable)."""
        h = np.asarray(self.hess(z, p, lam_g))
        g = np.asarray(self.g_fn(z, p)).ravel()
        active = (self.lbg == self.ubg) | (np.abs(lam_g) > 1e-9) | (g > self.ubg - 1e-9) | (g < self.lbg + 1e-9)
        j = np.asarray(self.jac(z, p))[active]
        basis = null_space(j) if j.size else np.eye(h.shape[0])
        w, v = np.linalg.eigh(basis.T @ h @ basis)
        if w[0] > -1e-8 * max(1.0, float(np.abs(h).max())):
            return None
        d = basis @ v[:, 0]
        return d / np.max(np.abs(d))

    def escape_saddle(self, sol: "NLPSolution", p, step: float = 0.2):
        """Leave an unstable stationary point along its negative-curvature mode (both signs); the lower
        stable result, or the input if none is found (the same rule as ShapeSolver's)."""
        d = self.unstable_direction(sol.z, p, sol.lam_g)
        if d is None:
            return sol, False
        best = None
        for sign in (1.0, -1.0):
            trial = self.solve(sol.z + sign * step * d, p)
            if trial.ok and self.is_stable(trial.z, p, trial.lam_g) and trial.f < sol.f - 1e-12:
                if best is None or trial.f < best.f:
                    best = trial
        return (best, True) if best is not None else (sol, False)

    def is_stable(self, z, p, lam_g) -> bool:
        h = np.asarray(self.hess(z, p, lam_g))
        return self.min_reduced_eigenvalue(z, p, lam_g) > -1e-8 * max(1.0, float(np.abs(h).max()))


# ---------------------------------------------------------------------------------------------------
def augmented_lagrangian_nm(f_fn, z0: np.ndarray, lbg: np.ndarray, ubg: np.ndarray, *, lam0=None,
                            mu: float = 10.0, outer: int = 30, inner_maxfev: int = 40000, tol: float = 1e-8,
                            xatol: float = 1e-10, fatol: float = 1e-13, time_limit: float = 60.0):
    """The multiplier method (Hestenes–Powell–Rockafellar) with Nelder–Mead inner solves.

    Equality rows (lbg = ubg = c): Φ += λ (g − c) + μ/2 (g − c)².  Inequality rows g ≤ ubg (lbg = −∞):
    Rockafellar's form Φ += (max(0, λ + μ (g − u))² − λ²) / (2μ).  After each Nelder–Mead run
    (scipy.optimize.minimize, method='Nelder-Mead', adaptive simplex) the multipliers are updated,
    λ ← λ + μ (g − c) (equalities), λ ← max(0, λ + μ (g − u)) (inequalities), and μ grows ×5 when the
    violation did not fall below a quarter of the previous one.  Stops when the violation is < tol and
    the point stopped moving, or after ``outer`` updates / ``time_limit`` seconds.

    f_fn(z) returns (f, g).  Returns (z, lam, info) with info = {ok, violation, fevals, outer, time_s}.
    """
    t0 = time.perf_counter()
    eq = lbg == ubg
    lam = np.zeros(lbg.size) if lam0 is None else np.array(lam0, float)
    z = np.array(z0, float)
    fevals, prev_viol = 0, np.inf
    viol = np.inf

    def phi(x):
        f, g = f_fn(x)
        if not np.isfinite(f) or not np.all(np.isfinite(g)):
            return 1e30
        r = g - ubg
        val = f
        val += np.dot(lam[eq], r[eq]) + 0.5 * mu * np.dot(r[eq], r[eq])
        if (~eq).any():
            t = np.maximum(0.0, lam[~eq] + mu * r[~eq])
            val += (np.dot(t, t) - np.dot(lam[~eq], lam[~eq])) / (2 * mu)
        return val

    k = 0
    for k in range(1, outer + 1):
        n = z.size
        # initial simplex: 0.05 rad / 0.05 L steps (the paper gives none; this is scipy's 5 % rule made absolute)
        simplex = np.vstack([z] + [z + 0.05 * np.eye(n)[i] for i in range(n)])
        res = minimize(phi, z, method="Nelder-Mead",
                       options={"maxfev": inner_maxfev, "xatol": xatol, "fatol": fatol, "adaptive": True,
                                "initial_simplex": simplex})
        fevals += res.nfev
        step = np.max(np.abs(res.x - z))
        z = res.x
        f, g = f_fn(z)
        r = g - ubg
        viol_rows = np.where(eq, np.abs(r), np.maximum(r, 0.0))
        viol = float(np.max(viol_rows, initial=0.0))
        lam[eq] += mu * r[eq]
        if (~eq).any():
            lam[~eq] = np.maximum(0.0, lam[~eq] + mu * r[~eq])
        if viol < tol and step < 1e-7:
            break
        if viol > 0.25 * prev_viol:
            mu = min(mu * 5.0, 1e8)
        prev_viol = viol
        if time.perf_counter() - t0 > time_limit:
            break
    dt = time.perf_counter() - t0
    return z, lam, {"ok": bool(viol < 1e-6), "violation": viol, "fevals": fevals, "outer": k, "time_s": dt, "mu": mu}
