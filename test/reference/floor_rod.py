"""An independent reference for a heavy planar elastica clamped at both ends above a rigid floor
(the paper's Fig. 3 with its floor; numpy + scipy only, nothing here uses dlo_ros).

The rod (length L, bending stiffness Rf, weight w per length, centreline radius r) lies in the x–z
plane, gravity along −z, the floor is z ≥ z_f (its centreline keeps z ≥ z_f + r).  Two
computations:

**Discrete rod** (``solve_discrete``).  N straight segments of length h = L/N with tangent angles
θ_0 … θ_{N−1}; vertices x_i = x_0 + h Σ_{k<i} (cos θ_k, sin θ_k), i = 0 … N.  Energy

    E(θ) = Rf/(2h) [Σ_{j=0}^{N−2} (θ_{j+1} − θ_j)² + 2(θ_0 − α_0)² + 2(θ_{N−1} − α_1)²]
           + w h Σ_j (z_j^mid − z_0),          z_j^mid = (z_j + z_{j+1})/2

(joints of length h between segments, h/2 to each clamp's angle α; weight at segment midpoints),
subject to the far clamp h Σ (cos θ_k, sin θ_k) = x_N − x_0 (equalities, multipliers λ = the force
the far clamp exerts [N]) and the floor z_i − z_f − r ≥ 0 at the inner vertices i = 1 … N−1
(multipliers μ_i ≥ 0 = the floor's upward push on vertex i [N]).  All constraint Hessians are
diagonal in θ, so the Lagrangian's Hessian is tridiagonal + diagonal and exact.  Minimised by SLSQP
(global, from a caller's start, optionally with the mirror symmetry θ_{N−1−j} = −θ_j imposed) and
polished by a Newton active-set method on the KKT system (ours: Newton on the equality-constrained
problem with the working set W of floor rows, then drop the most negative μ or add the
violated rows,
until the KKT residual is below 1e-11).  On a flat contact run the floor carries each vertex's
weight share w h; at each end of the run (the lift-off points) it also carries a point force P, so
μ_end − w h/2 → P as h → 0 (``DiscreteFloorRod.end_forces``).  Stability: the Hessian of the
Lagrangian reduced to the null space of the equality rows and the floor rows with μ > 0 is positive
definite (``min_eig`` is its smallest eigenvalue divided by h, which converges as N grows).

**Shooting** (``shoot``), the sharper reference.  Each lifted span is a heavy elastica,
integrated in
s with state (x, z, θ, n_x, n_z, m) (n: the force that (s, L] exerts on [0, s], as
``post_contact``):

    x' = cos θ,  z' = sin θ,  θ' = m/Rf,  n_x' = 0,  n_z' = w,  m' = −(n_z cos θ − n_x sin θ).

On a flat contact run θ = 0 (or π), m = 0, hence n_z = 0, and n_x = H is the same on every span (a
frictionless floor).  So a span that ends on the floor ends with z = z_f + r, θ = 0 (π), m = 0
and a
span that starts on it starts from there with n_z = −P (P ≥ 0 the point force at that lift-off
point);
one that ends there has n_z = P.  Unknowns: H, the first span's n_z(0), m(0), every span's length,
every later span's n_z at its start, and every flat run's length; equations: three per span end on
the floor, the far clamp's x, z, θ, and the total length L (as many as unknowns).  Solved by
Levenberg–Marquardt on solve_ivp (DOP853, rtol = atol = 1e-12) from the discrete rod's answer; then
checked: every lifted point keeps z ≥ z_f + r, every P ≥ 0 and every run length ≥ 0.  Its lift-off
points and shape are exact to the integrator's tolerance (~1e-9 L), so it is the reference the
tests
compare with; the discrete rod supplies the contact topology, the multipliers and the stability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares, minimize


@dataclass(frozen=True)
class FloorProblem:
    """Rod data [SI]: clamps at (x, z) start/end with tangent angles angle0/angle1 [rad], floor
    height [m], centreline radius [m]."""

    length: float
    rf: float
    w: float
    start: tuple[float, float]
    end: tuple[float, float]
    angle0: float
    angle1: float
    floor: float
    radius: float = 0.0


def fig3_floor(rho: float) -> FloorProblem:
    """config/scenes/bench_fig3_floor.yaml at ρ = D L³/Rf: L = 1, Rf = 1, D = ρ, ends 0.7 L apart,
    both clamped along +x, the floor 0.08 L below the clamps."""
    return FloorProblem(1.0, 1.0, float(rho), (0.0, 0.0), (0.7, 0.0), 0.0, 0.0, -0.08)


@dataclass
class DiscreteFloorRod:
    """A KKT point of the discrete rod: angles θ (N,), vertices (N+1, 2) at arc lengths s, energy
    [J], far-clamp force λ [N], floor multipliers μ (N+1,) [N] (0 at the clamps), the contact runs
    (first, last vertex index), the smallest reduced-Hessian eigenvalue / h, the KKT residual."""

    problem: FloorProblem
    theta: np.ndarray
    points: np.ndarray
    s: np.ndarray
    energy: float
    lam: np.ndarray
    mu: np.ndarray
    runs: list[tuple[int, int]]
    min_eig: float
    kkt_residual: float

    @property
    def h(self) -> float:
        return self.problem.length / len(self.theta)

    @property
    def stable(self) -> bool:
        return self.min_eig > 0.0

    def lift_off(self) -> np.ndarray:
        """Arc lengths of the ends of the contact runs, in order along s."""
        return np.array([self.s[k] for run in self.runs for k in run])

    def end_forces(self) -> np.ndarray:
        """The point force at each lift-off point: the floor's push on the run's half next to it
        less the weight that half carries (w h per vertex, w h/2 at the end vertex).  The discrete
        rod spreads it over the last two or three vertices; a vertex deeper in carries w h."""
        wh, out = self.problem.w * self.h, []
        for a, b in self.runs:
            mid = (a + b) // 2
            out += [
                self.mu[a : mid + 1].sum() - wh * (mid - a + 0.5),
                self.mu[mid + 1 : b + 1].sum() - wh * (b - mid - 0.5),
            ]
        return np.array(out)


# ---- the discrete rod
# -----------------------------------------------------------------------------


class _Discrete:
    """Energy, constraints and their derivatives for N segments (module docstring)."""

    def __init__(self, pr: FloorProblem, n: int):
        self.pr, self.n, self.h = pr, n, pr.length / n
        self.c = n - np.arange(n) - 0.5  # weight of sin θ_k in Σ_j (z_j^mid − z_0) / h
        self.lower = np.tril(np.ones((n - 1, n)), 0)  # row i−1: [k < i] for inner vertex i
        self.chord = np.array(pr.end) - np.array(pr.start)
        self.gap = pr.start[1] - pr.floor - pr.radius

    def energy(self, t):
        d = np.diff(t)
        rf, h = self.pr.rf, self.h
        bend = (
            rf
            / (2 * h)
            * (d @ d + 2 * (t[0] - self.pr.angle0) ** 2 + 2 * (t[-1] - self.pr.angle1) ** 2)
        )
        return bend + self.pr.w * h * h * (self.c @ np.sin(t))

    def grad(self, t):
        rf, h = self.pr.rf, self.h
        g = np.zeros_like(t)
        d = np.diff(t)
        g[:-1] -= d
        g[1:] += d
        g[0] += 2 * (t[0] - self.pr.angle0)
        g[-1] += 2 * (t[-1] - self.pr.angle1)
        return rf / h * g + self.pr.w * h * h * self.c * np.cos(t)

    def bend_hessian(self):
        n = self.n
        k = np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)
        k[0, 0] = k[-1, -1] = 3.0
        return self.pr.rf / self.h * k

    def eq(self, t):
        return self.h * np.array([np.sum(np.cos(t)), np.sum(np.sin(t))]) - self.chord

    def eq_jac(self, t):
        return self.h * np.vstack([-np.sin(t), np.cos(t)])

    def floor(self, t):
        return self.gap + self.h * (self.lower @ np.sin(t))

    def floor_jac(self, t):
        return self.h * self.lower * np.cos(t)[None, :]

    def lagrangian_hessian(self, t, lam, mu_inner):
        """∇²(E − λ·c_eq − μ·g); μ_inner over the inner vertices 1 … N−1."""
        h, s, c = self.h, np.sin(t), np.cos(t)
        above = np.concatenate([np.cumsum(mu_inner[::-1])[::-1], [0.0]])  # Σ_{i>k} μ_i
        diag = -self.pr.w * h * h * self.c * s + h * (lam[0] * c + lam[1] * s) + h * s * above
        return self.bend_hessian() + np.diag(diag)

    def points(self, t):
        steps = self.h * np.stack([np.cos(t), np.sin(t)], axis=1)
        return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)]) + np.array(self.pr.start)


def _slsqp(rod: _Discrete, theta0: np.ndarray, symmetric: bool, maxiter: int) -> np.ndarray:
    n = rod.n
    if not symmetric:
        p = np.eye(n)
        cons = [
            {"type": "eq", "fun": rod.eq, "jac": rod.eq_jac},
            {"type": "ineq", "fun": rod.floor, "jac": rod.floor_jac},
        ]
    else:  # θ = P φ with θ_{N−1−j} = −θ_j (N even): the far clamp's z and half the floor hold
        half = n // 2
        p = np.vstack([np.eye(half), -np.eye(half)[::-1]])
        rows = np.arange(half)  # inner vertices 1 … N/2
        cons = [
            {
                "type": "eq",
                "fun": lambda f: rod.eq(p @ f)[:1],
                "jac": lambda f: rod.eq_jac(p @ f)[:1] @ p,
            },
            {
                "type": "ineq",
                "fun": lambda f: rod.floor(p @ f)[rows],
                "jac": lambda f: rod.floor_jac(p @ f)[rows] @ p,
            },
        ]
    res = minimize(
        lambda f: rod.energy(p @ f),
        np.linalg.lstsq(p, theta0, rcond=None)[0],
        jac=lambda f: rod.grad(p @ f) @ p,
        constraints=cons,
        method="SLSQP",
        options={"maxiter": maxiter, "ftol": 1e-12},
    )
    return p @ res.x


def _newton_active_set(rod: _Discrete, t: np.ndarray, active: np.ndarray, iters: int = 200):
    """Newton on the KKT system with a working set of floor rows (module docstring)."""
    n = rod.n
    lam = np.zeros(2)
    mu = np.zeros(n - 1)
    for _ in range(iters):
        w_idx = np.flatnonzero(active)
        for _newton in range(60):
            a_eq, a_w = rod.eq_jac(t), rod.floor_jac(t)[w_idx]
            a = np.vstack([a_eq, a_w])
            # multipliers by least squares at the current θ, then a full Newton step on (θ, λ, μ_W)
            mult = np.linalg.lstsq(a.T, rod.grad(t), rcond=None)[0]
            lam, mu[:] = mult[:2], 0.0
            mu[w_idx] = mult[2:]
            hl = rod.lagrangian_hessian(t, lam, mu)
            m = a.shape[0]
            kkt = np.block([[hl, -a.T], [a, np.zeros((m, m))]])
            rhs = -np.concatenate([rod.grad(t) - a.T @ mult, rod.eq(t), rod.floor(t)[w_idx]])
            step = np.linalg.solve(kkt, rhs)[:n]
            t = t + step * min(1.0, 0.3 / max(np.max(np.abs(step)), 1e-300))  # damped far away
            if np.max(np.abs(step)) < 1e-13:
                break
        a = np.vstack([rod.eq_jac(t), rod.floor_jac(t)[w_idx]])
        mult = np.linalg.lstsq(a.T, rod.grad(t), rcond=None)[0]
        lam, mu[:] = mult[:2], 0.0
        mu[w_idx] = mult[2:]
        gap = rod.floor(t)
        violated = (gap < -1e-12) & ~active
        if violated.any():
            active = active | violated
            continue
        if mu[w_idx].min(initial=0.0) < -1e-12:
            active = active.copy()  # drop every row that pulls (a resampled start errs on many)
            active[w_idx[mu[w_idx] < -1e-12]] = False
            continue
        return t, lam, mu, active
    raise RuntimeError("floor_rod: the active-set iteration did not settle")


def _runs(active: np.ndarray) -> list[tuple[int, int]]:
    """Contact runs as (first, last) vertex indices (vertex i = inner row i − 1)."""
    idx = np.flatnonzero(active) + 1
    if idx.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    firsts = np.concatenate([[idx[0]], idx[breaks + 1]])
    lasts = np.concatenate([idx[breaks], [idx[-1]]])
    return list(zip(firsts.tolist(), lasts.tolist(), strict=True))


def _reduced_min_eig(rod: _Discrete, t, lam, mu) -> float:
    from scipy.linalg import null_space

    strong = np.flatnonzero(mu > 1e-9)
    a = np.vstack([rod.eq_jac(t), rod.floor_jac(t)[strong]])
    z = null_space(a)
    hz = z.T @ rod.lagrangian_hessian(t, lam, mu) @ z
    return float(np.linalg.eigvalsh(hz)[0] / rod.h)


def polish(pr: FloorProblem, theta: np.ndarray, near: float = 1e-9) -> DiscreteFloorRod:
    """The KKT point of the discrete rod (N = len(theta)) that Newton's active-set method reaches
    from ``theta``; its working set starts from the rows within ``near`` of the floor."""
    rod = _Discrete(pr, len(theta))
    active = rod.floor(theta) < near
    t, lam, mu, active = _newton_active_set(rod, np.asarray(theta, float), active)
    a = np.vstack([rod.eq_jac(t), rod.floor_jac(t)])
    kkt = np.concatenate([rod.grad(t) - a.T @ np.concatenate([lam, mu]), rod.eq(t)])
    kkt = np.concatenate([kkt, rod.floor(t)[active]])
    mu_all = np.concatenate([[0.0], mu, [0.0]])
    return DiscreteFloorRod(
        pr,
        t,
        rod.points(t),
        np.arange(rod.n + 1) * rod.h,
        float(rod.energy(t)),
        lam,
        mu_all,
        _runs(active),
        _reduced_min_eig(rod, t, lam, mu),
        float(np.max(np.abs(kkt))),
    )


def solve_discrete(
    pr: FloorProblem, n: int, theta0: np.ndarray, symmetric: bool = False, maxiter: int = 1000
) -> DiscreteFloorRod:
    """SLSQP from ``theta0`` (resampled to N angles), then ``polish``: a KKT point of the discrete
    rod.  ``symmetric`` imposes the mirror symmetry during SLSQP only (Newton keeps it to rounding,
    so it reaches the symmetric equilibrium even where that is unstable)."""
    rod = _Discrete(pr, n)
    start = resample(np.asarray(theta0, float), n)
    return polish(pr, _slsqp(rod, start, symmetric, maxiter))


def resample(theta: np.ndarray, n: int) -> np.ndarray:
    """Segment angles at n segments by linear interpolation in s (segment midpoints)."""
    m = len(theta)
    if m == n:
        return theta.copy()
    return np.interp((np.arange(n) + 0.5) / n, (np.arange(m) + 0.5) / m, theta)


def refine(coarse: DiscreteFloorRod, n: int) -> DiscreteFloorRod:
    """The same equilibrium at N = n, Newton-polished from the coarse one resampled."""
    return polish(coarse.problem, resample(coarse.theta, n), near=1e-4 * coarse.problem.length)


def mirror(theta: np.ndarray) -> np.ndarray:
    """The mirror image about the chord's perpendicular bisector: θ_j → −θ_{N−1−j}."""
    return -np.asarray(theta)[::-1]


def start_angles(
    n: int, arch_at: float = 0.5, arch_length: float = 0.4, arch_angle: float = 2.0
) -> np.ndarray:
    """Starting angles: down to the floor over 0.15 L (θ = −0.84 sin), an Ω-shaped arch
    (θ = arch_angle·sin 2πv over ``arch_length``) centred at s = ``arch_at``·L, back up over the
    last 0.15 L; flat in between.  arch_at = 0.5: symmetric; nearer 0 or 1: skewed."""
    u = (np.arange(n) + 0.5) / n
    theta = np.zeros(n)
    ends = 0.15
    left, right = u < ends, u > 1 - ends
    theta[left] = -0.84 * np.sin(np.pi * u[left] / ends)
    theta[right] = 0.84 * np.sin(np.pi * (u[right] - 1 + ends) / ends)
    v = (u - arch_at) / arch_length + 0.5
    inside = (v > 0) & (v < 1)
    theta[inside] += arch_angle * np.sin(2 * np.pi * v[inside])
    return theta


# ---- shooting
# -------------------------------------------------------------------------------------


def _rhs(_s, y, rf: float, w: float, ell: float, z0: float):
    """d/dσ of (x, z, θ, n_x, n_z, m, E) on a span of length ℓ, σ = s/ℓ ∈ [0, 1]."""
    _x, z, th, nx, nz, m, _e = y
    c, sn = np.cos(th), np.sin(th)
    de = m * m / (2 * rf) + w * (z - z0)
    return [ell * c, ell * sn, ell * m / rf, 0.0, ell * w, -ell * (nz * c - nx * sn), ell * de]


@dataclass(frozen=True)
class Contact:
    """One contact of the floor along s: 'flat' (a run lying on the floor, m = 0) or 'point' (a
    touch with tangent along the floor); ``angle`` the tangent angle there (0 or π, mod 2π)."""

    kind: str
    angle: float


@dataclass
class ShotFloorRod:
    """The shooting solution: H [N] (horizontal force), the contacts, the lift-off arc lengths
    (start and end of each contact, equal for a point), the point force at each lift-off point [N]
    (a point contact's whole push), the spans' lengths, the least lifted point's height above
    z_f + r [m] (away from contacts), the final residual, and the energy [J]."""

    problem: FloorProblem
    contacts: list[Contact]
    unknowns: np.ndarray
    lift_off: np.ndarray
    point_forces: np.ndarray
    clearance: float
    residual: float
    energy: float
    _pieces: list

    def at(self, s: np.ndarray) -> np.ndarray:
        """(x, z) at arc lengths s."""
        s = np.atleast_1d(np.asarray(s, float))
        out = np.empty((len(s), 2))
        for s0, s1, f, _lifted in self._pieces:
            sel = (s >= s0 - 1e-15) & (s <= s1 + 1e-15)
            if sel.any():
                out[sel] = f(s[sel])
        return out


def _simulate(u: np.ndarray, pr: FloorProblem, contacts: list[Contact], dense: bool = False):
    """Integrate the spans for unknowns u (module docstring); residuals, pieces and forces."""
    zc = pr.floor + pr.radius
    kw = dict(method="DOP853", rtol=1e-12, atol=1e-12, dense_output=dense)
    h_force, v, m0, ell = u[:4]
    y = np.array([pr.start[0], pr.start[1], pr.angle0, h_force, v, m0, 0.0])
    s, k, res, pieces, lifts, forces = 0.0, 4, [], [], [], []
    for c in [*contacts, None]:
        ell = abs(ell)
        sol = solve_ivp(_rhs, (0.0, 1.0), y, args=(pr.rf, pr.w, ell, pr.start[1]), **kw)
        ye = sol.y[:, -1]
        if dense:
            pieces.append((s, s + ell, _span_eval(sol, s, ell), True))
        s += ell
        if c is None:
            break
        res += [(ye[1] - zc) / pr.length, ye[2] - c.angle]
        lifts.append(s)
        if c.kind == "flat":
            v_next, run, ell = u[k : k + 3]
            k += 3
            res.append(ye[5] * pr.length / pr.rf)
            forces += [ye[4], -v_next]
            start = np.array([ye[0], zc])
            if dense:
                pieces.append((s, s + run, _flat_eval(start, c.angle, s), False))
            s += run
            e = ye[6] + pr.w * (zc - pr.start[1]) * abs(run)
            y = np.array([ye[0] + np.cos(c.angle) * run, zc, c.angle, h_force, v_next, 0.0, e])
        else:
            push, ell = u[k : k + 2]
            k += 2
            forces.append(push)
            y = ye.copy()
            y[4] -= push
        lifts.append(s)
    res += [
        (ye[0] - pr.end[0]) / pr.length,
        (ye[1] - pr.end[1]) / pr.length,
        ye[2] - pr.angle1,
        (s - pr.length) / pr.length,
    ]
    return np.array(res), pieces, np.array(lifts), np.array(forces), float(ye[6])


def _span_eval(sol, s0: float, ell: float):
    return lambda s: sol.sol((s - s0) / ell)[0:2].T


def _flat_eval(start: np.ndarray, angle: float, s0: float):
    return lambda s: start + np.outer(s - s0, [np.cos(angle), 0.0])


def _guess(d: DiscreteFloorRod, contacts: list[Contact]) -> np.ndarray:
    """Shooting unknowns read off a discrete rod: n_z(s) = λ_z + Σ_{s_i > s} μ_i − w (L − s)."""
    pr, s, h = d.problem, d.s, d.h

    def nz_after(sk: float) -> float:
        return float(d.lam[1] + d.mu[s > sk + 1e-12].sum() - pr.w * (pr.length - sk))

    m0 = pr.rf * (d.theta[0] - pr.angle0) / (h / 2)
    edges = [0.0, *d.lift_off(), pr.length]
    u = [d.lam[0], nz_after(0.0), m0, edges[1] - edges[0]]
    for k, c in enumerate(contacts):
        a, b, nxt = edges[2 * k + 1], edges[2 * k + 2], edges[2 * k + 3]
        if c.kind == "flat":
            u += [nz_after(b), b - a, nxt - b]
        else:
            u += [float(d.mu[(s >= a - 1e-12) & (s <= b + 1e-12)].sum()), nxt - a]
    return np.array(u)


def shoot(
    d: DiscreteFloorRod, kinds: list[str] | None = None, symmetric: bool = False
) -> ShotFloorRod:
    """Shoot the equilibrium whose contact topology and starting unknowns a discrete rod gives
    (module docstring).  ``kinds``: 'flat' or 'point' per contact run (default: 'flat').
    A lifted span between two flat runs (an arch) slides along them at no cost: such equilibria
    come in a one-parameter family of equal energy.  ``symmetric`` picks the member whose first
    and last runs are equally long (the mirror-symmetric one) by one more (consistent) equation."""
    pr = d.problem
    kinds = kinds or ["flat"] * len(d.runs)
    contacts = []
    for (a, _b), kind in zip(d.runs, kinds, strict=True):
        angle = float(np.round(d.theta[a] / np.pi) * np.pi)
        contacts.append(Contact(kind, angle))
    runs = [k for k, c in enumerate(contacts) if c.kind == "flat"] or [0]
    first, last = _run_index(contacts, runs[0]), _run_index(contacts, runs[-1])

    def residual(u):
        r = _simulate(u, pr, contacts)[0]
        return np.append(r, (u[first] - u[last]) / pr.length) if symmetric and runs else r

    fit = least_squares(
        residual,
        _guess(d, contacts),
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
        max_nfev=4000,
    )
    res, pieces, lifts, forces, energy = _simulate(fit.x, pr, contacts, dense=True)
    shot = ShotFloorRod(
        pr, contacts, fit.x, lifts, forces, 0.0, float(np.max(np.abs(res))), energy, pieces
    )
    shot.clearance = _clearance(shot)
    return shot


def _run_index(contacts: list[Contact], k: int) -> int:
    """Index in the unknowns of contact k's run length (a flat one)."""
    i = 4
    for c in contacts[:k]:
        i += 3 if c.kind == "flat" else 2
    return i + 1


def _clearance(shot: ShotFloorRod) -> float:
    """Least height above z_f + r of the lifted spans, 1e-3 L away from their ends."""
    pr, lowest = shot.problem, np.inf
    for s0, s1, _f, lifted in shot._pieces:
        if lifted and s1 - s0 > 2e-3 * pr.length:
            ss = np.linspace(s0 + 1e-3 * pr.length, s1 - 1e-3 * pr.length, 4001)
            lowest = min(lowest, float(np.min(shot.at(ss)[:, 1])))
    return lowest - pr.floor - pr.radius
