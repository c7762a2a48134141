"""The benchmarked methods behind one interface: ``make_runner(method, setting, case)`` → a runner with
``cold(problem)``, ``warm(problem)`` (from the last committed equilibrium) and ``build_time_s``.

1. ``paper``    the paper's method: Euler angles in the paper's frame, its 10-function Fourier basis, the
                multiplier (augmented Lagrangian) method with Nelder–Mead inner solves (scipy).
2. ``fourier``  Euler angles (paper frame) + Fourier basis + IPOPT, orders 4 … 16.
3. ``default``  the project's ShapeSolver defaults (the 3D director model: quaternions on spectral elements), orders 4 … 16;
   ``default-planar`` the same with ``model: planar`` (planar cases only).
4. ``rod``      a discretised rod, N segments + IPOPT (planar: angles; 3D: unit quaternions).
5. ``pyelastica`` / ``mujoco`` / ``mujoco-rod``: the dynamic peers (bench/methods/peers.py).

Planar cases: methods 1–2 use the planar Euler-angle model (φ ≡ π, θ = π/2 − β; the paper's examples
2–3 are planar) from bench/methods/planar.py.  3D cases: methods 1–2 use dlo_ros's StringNLP / ShapeSolver with
``frame: paper``.  Twist cases: a "cold" solve is a continuation from the untwisted state in
``TWIST_STEPS`` equal turns (an Euler-angle target cannot carry a turn count; every method gets the same
path), a "warm" solve is one more step of the grip.
"""
from __future__ import annotations

import time

import numpy as np

from dlo_ros.model.problem import GripPose
from dlo_ros.solver import ShapeSolver, SolverOptions

from bench.common import S_OUT, Case, Outcome, interp_points, quat_twisted
from bench.methods.nlp_tools import augmented_lagrangian_nm
from bench.methods.planar import PlanarRitz, PlanarRod
from bench.methods.rod3d import Rod3D

TWIST_STEPS = 8
NM_TIME_LIMIT = 60.0


def twisted_problem(case: Case, tau: float, problem=None):
    """The case's problem with the right grip turned by τ about its tangent (position unchanged)."""
    problem = problem or case.problem
    right = problem.grip("right")
    from .planar import tangent_angle

    beta = tangent_angle(right.pose.orientation)
    return problem.with_grip_poses({"right": GripPose(right.pose.position, quat_twisted(beta, tau))})


#: the paper's 3D model: Euler angles in one Ritz basis (SolverOptions' defaults are the director model,
#: which has no basis and no frame: without these the Fourier rows silently ran the default)
EULER_3D = {"model": "full", "rotation": "euler"}


class _Runner:
    label = ""

    def cold(self, problem) -> Outcome:  # pragma: no cover - interface
        raise NotImplementedError

    def warm(self, problem) -> Outcome:  # pragma: no cover - interface
        raise NotImplementedError


# ---------------------------------------------------------------------------------------------------
class ShapeSolverRunner(_Runner):
    """Methods 2 (3D) and 3: dlo_ros's ShapeSolver, interpreted derivatives (compile='off')."""

    def __init__(self, case: Case, options: SolverOptions, compile: str = "off"):
        self.case = case
        t0 = time.perf_counter()
        self.solver = ShapeSolver(case.problem, options, compile=compile)
        self.build_time_s = time.perf_counter() - t0

    def _outcome(self, r, dt) -> Outcome:
        # output_points = 101 puts r.s on S_OUT: no interpolation error enters the comparison
        pts = interp_points(r.s, r.points) if r.ok else None
        return Outcome(r.ok, pts, dt, r.iterations, r.stable, r.energy.get("total", np.nan) if r.ok else np.nan,
                       f"{r.status}: {r.ipopt_status} {r.message}")

    def _solve(self, problem, warm: bool) -> Outcome:
        poses = {g.name: g.pose for g in problem.grips}
        if problem.string != self.solver.problem.string:
            self.solver.set_problem(problem.with_grip_poses({}))
        t0 = time.perf_counter()
        try:
            r = self.solver.solve(poses, warm=warm)
        except Exception as exc:  # ShapeSolver promises never to raise; record it when it does
            self.solver.reset()
            return Outcome(False, None, time.perf_counter() - t0, 0, None, np.nan,
                           f"ShapeSolver.solve raised {type(exc).__name__}: {exc}")
        return self._outcome(r, time.perf_counter() - t0)

    def cold(self, problem) -> Outcome:
        self.solver.reset()
        if self.case.planar or self.case.tau == 0.0:
            return self._solve(problem, warm=False)
        return self._continuation(problem)

    def _continuation(self, problem) -> Outcome:
        t0 = time.perf_counter()
        out = self._solve(twisted_problem(self.case, 0.0, problem), warm=False)
        iters = out.iterations
        for k in range(1, TWIST_STEPS + 1):
            if not out.ok:
                break
            out = self._solve(twisted_problem(self.case, self.case.tau * k / TWIST_STEPS, problem), warm=True)
            iters += out.iterations
        out.time_s, out.iterations = time.perf_counter() - t0, iters
        return out

    def warm(self, problem) -> Outcome:
        return self._solve(problem, warm=True)


# ---------------------------------------------------------------------------------------------------
class PlanarRunner(_Runner):
    """Methods 2 (planar cases, Fourier + IPOPT), 4 (planar rod) and the planar references."""

    def __init__(self, case: Case, model):
        self.case, self.model = case, model
        self.build_time_s = model.build_time_s
        self.state = None
        self.weight_scale = 1.0

    def cold(self, problem) -> Outcome:
        out, sol = self.model.cold(problem, self.weight_scale)
        self.state = sol if out.ok else None
        return out

    def warm(self, problem) -> Outcome:
        if self.state is None:
            return self.cold(problem)
        out, sol = self.model.warm(problem, self.state, self.weight_scale)
        if out.ok:
            self.state = sol
        return out


class Rod3DRunner(PlanarRunner):
    """Method 4 on the 3D case: the quaternion rod; a cold solve turns the end in TWIST_STEPS steps."""

    def __init__(self, case: Case, segments: int):
        super().__init__(case, Rod3D(case.problem, segments))

    def cold(self, problem) -> Outcome:
        if self.case.tau == 0.0:
            out, sol = self.model.cold(problem, 0.0, self.weight_scale)
            self.state = sol if out.ok else None
            return out
        out, sol = self.model.cold(twisted_problem(self.case, 0.0, problem), 0.0, self.weight_scale, check=False)
        iters, total = out.iterations, out.time_s
        for k in range(1, TWIST_STEPS + 1):
            if not out.ok:
                break
            out, sol = self.model.warm(twisted_problem(self.case, self.case.tau * k / TWIST_STEPS, problem), sol,
                                       self.weight_scale, check=(k == TWIST_STEPS))
            iters += out.iterations
            total += out.time_s
        self.state = sol if out.ok else None
        out.time_s, out.iterations = total, iters  # IPOPT time summed over the continuation
        return out


# ---------------------------------------------------------------------------------------------------
class PaperPlanarRunner(_Runner):
    """Method 1 on planar cases: PlanarRitz(fourier, 10) solved by the multiplier method + Nelder–Mead."""

    def __init__(self, case: Case, order: int = 10, time_limit: float = NM_TIME_LIMIT):
        self.case = case
        self.model = PlanarRitz(case.problem, "fourier", order)
        self.build_time_s = self.model.build_time_s
        self.state = None
        self.time_limit = time_limit
        self.weight_scale = 1.0

    def cold(self, problem) -> Outcome:
        out, z, lam, p = self.model.solve_nelder_mead(problem, weight_scale=self.weight_scale, time_limit=self.time_limit)
        self.state = (z, lam) if out.ok else None
        return out

    def warm(self, problem) -> Outcome:
        if self.state is None:
            return self.cold(problem)
        z, lam = self.state
        out, z2, lam2, p = self.model.solve_nelder_mead(problem, z0=z, lam0=lam, weight_scale=self.weight_scale,
                                                        time_limit=self.time_limit,
                                                        reference=self.model.end_angles(z))
        if out.ok:
            self.state = (z2, lam2)
        return out


class Paper3DRunner(_Runner):
    """Method 1 on 3D cases: dlo_ros's StringNLP (frame 'paper', Fourier, 10 functions per field) with
    x(0) substituted from the left grip; every other constraint (the far grip's position, held angles)
    goes through the multiplier method; Nelder–Mead inner solves.  Grip angle targets come from
    ShapeSolver.pack_parameters (unwrapped to the current shape, so a continuation tracks turns)."""

    def __init__(self, case: Case, order: int = 10, time_limit: float = NM_TIME_LIMIT):
        self.case = case
        t0 = time.perf_counter()
        self.helper = ShapeSolver(case.problem, SolverOptions(basis="fourier", order=order, frame="paper", **EULER_3D), compile="off")
        import casadi as ca

        nlp = self.helper.nlp
        self.fg = ca.Function("fg", [nlp.z_sym, nlp.p_sym], [nlp.nlp["f"], nlp.g_sym])
        self.build_time_s = time.perf_counter() - t0
        self.time_limit = time_limit
        self.state = None

    def _run(self, problem, z_full0, lam0=None):
        nlp, helper = self.helper.nlp, self.helper
        p = helper.pack_parameters(problem, z_full0)
        left = problem.grip("left")
        x_left = left.pose.position / nlp.length
        # x(0) = x0 exactly (the left grip sits at s = 0): its three rows are satisfied by substitution
        rows = np.ones(nlp.lbg.size, dtype=bool)
        rows[nlp.grip_rows["left"]["position"]] = False
        fg = self.fg

        def f_fn(c):
            z = np.concatenate([x_left, c])
            f, g = fg(z, p)
            return float(f), np.asarray(g).ravel()[rows]

        c, lam, info = augmented_lagrangian_nm(f_fn, z_full0[3:], nlp.lbg[rows], nlp.ubg[rows],
                                               lam0=lam0, time_limit=self.time_limit)
        z = np.concatenate([x_left, c])
        lam_full = np.zeros(nlp.lbg.size)
        lam_full[rows] = lam
        return z, lam, lam_full, p, info

    def _outcome(self, problem, z, lam_full, p, info, dt):
        nlp = self.helper.nlp
        pts = nlp.model.positions(z, S_OUT * nlp.length)
        bend, twist, stretch, grav, work = (float(v) for v in nlp.energy_fn(z, p))
        stable = None
        if info["ok"]:
            # reduced Hessian on the equality rows' null space (the AL multipliers of the other rows; the
            # substituted left-grip rows' multipliers are zero, which leaves H unchanged: they are linear)
            from scipy.linalg import null_space

            h = np.asarray(nlp.hessian_fn(z, p, lam_full))
            j = np.asarray(nlp.jac_g_fn(z, p))
            active = nlp.lbg == nlp.ubg
            basis = null_space(j[active])
            red = basis.T @ h @ basis
            stable = bool(np.linalg.eigvalsh(red)[0] > -1e-6 * max(1.0, np.abs(h).max())) if red.size else None
        return Outcome(info["ok"], pts, dt, info["fevals"], stable, bend + twist + stretch + grav - work,
                       f"AL outer {info['outer']}, violation {info['violation']:.1e}", extra=info)

    def cold(self, problem) -> Outcome:
        t0 = time.perf_counter()
        steps = [0.0] if self.case.tau == 0.0 else [self.case.tau * k / TWIST_STEPS for k in range(TWIST_STEPS + 1)]
        z = self.helper.initial_guess(twisted_problem(self.case, 0.0, problem))
        lam, fevals, info = None, 0, None
        for tau in steps:
            pr = twisted_problem(self.case, tau, problem) if self.case.tau else problem
            z, lam, lam_full, p, info = self._run(pr, z, lam)
            fevals += info["fevals"]
            if not info["ok"] or time.perf_counter() - t0 > self.time_limit * 2:
                info["ok"] = info["ok"] and tau == steps[-1]
                break
        info["fevals"] = fevals
        out = self._outcome(problem, z, lam_full, p, info, time.perf_counter() - t0)
        self.state = (z, lam) if out.ok else None
        return out

    def warm(self, problem) -> Outcome:
        if self.state is None:
            return self.cold(problem)
        t0 = time.perf_counter()
        z, lam, lam_full, p, info = self._run(problem, *self.state)
        out = self._outcome(problem, z, lam_full, p, info, time.perf_counter() - t0)
        if out.ok:
            self.state = (z, lam)
        return out


# ---------------------------------------------------------------------------------------------------
R_X_TO_Z = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # R_y(−90°): x → z
Q_X_TO_Z = np.array([0.0, np.sin(-np.pi / 4), 0.0, np.cos(-np.pi / 4)])


def rotate_problem(problem, R=R_X_TO_Z, q=Q_X_TO_Z):
    """The same scene turned rigidly by R (grips, gravity, loads, half-space obstacles)."""
    from dataclasses import replace

    from dlo_ros.model.obstacles import Obstacle

    from bench.common import quat_mul

    grips = tuple(replace(g, pose=GripPose(R @ g.pose.position, quat_mul(q, g.pose.orientation))) for g in problem.grips)
    loads = tuple(replace(ld, force=R @ ld.force, moment=R @ ld.moment) for ld in problem.loads)
    obstacles = []
    for ob in problem.obstacles:
        if ob.type != "halfspace":
            raise ValueError("rotate_problem: half-spaces only")
        obstacles.append(Obstacle("halfspace", np.concatenate([R @ ob.point, R @ ob.normal]), ob.name))
    return replace(problem, grips=grips, loads=loads, obstacles=tuple(obstacles), gravity=R @ problem.gravity_unit)


class RotatedRunner(_Runner):
    """Solve the scene turned by R (so the chord runs along z, the paper's own geometry: its Euler frame's
    singular axis is then the chord) and turn the answer back."""

    def __init__(self, case: Case, inner_factory, R=R_X_TO_Z):
        from dataclasses import replace

        self.R = R
        self.inner = inner_factory(replace(case, problem=rotate_problem(case.problem)))
        self.build_time_s = self.inner.build_time_s

    def _back(self, out: Outcome) -> Outcome:
        if out.points is not None:
            out.points = out.points @ self.R  # rows: R⁻¹ x = Rᵀ x
        return out

    def cold(self, problem) -> Outcome:
        return self._back(self.inner.cold(rotate_problem(problem)))

    def warm(self, problem) -> Outcome:
        return self._back(self.inner.warm(rotate_problem(problem)))


ORDERS = (4, 6, 8, 10, 12, 14, 16)
SEGMENTS = (10, 20, 40, 80, 160, 200)


def make_runner(method: str, setting, case: Case, **kw) -> _Runner:
    if method == "paper":
        return (PaperPlanarRunner if case.planar else Paper3DRunner)(case, int(setting or 10), **kw)
    if method == "fourier":
        if case.planar:
            return PlanarRunner(case, PlanarRitz(case.problem, "fourier", int(setting)))
        return ShapeSolverRunner(case, SolverOptions(basis="fourier", order=int(setting), frame="paper", output_points=101, **EULER_3D))
    if method == "fourier-3d":  # Euler angles in the paper's frame, full 3D model, also on planar cases
        return ShapeSolverRunner(case, SolverOptions(basis="fourier", order=int(setting), frame="paper", output_points=101, **EULER_3D))
    if method == "fourier-3d-z":  # the same, with the scene turned so the chord runs along z (the paper's geometry)
        return RotatedRunner(case, lambda c: ShapeSolverRunner(
            c, SolverOptions(basis="fourier", order=int(setting), frame="paper", output_points=101, **EULER_3D)))
    if method == "default":
        return ShapeSolverRunner(case, SolverOptions(order=int(setting), output_points=101), **kw)
    if method == "default-planar":
        return ShapeSolverRunner(case, SolverOptions(order=int(setting), model="planar", output_points=101), **kw)
    if method == "rod":
        if case.planar:
            return PlanarRunner(case, PlanarRod(case.problem, int(setting)))
        return Rod3DRunner(case, int(setting))
    if method in PEERS:
        from . import peers

        return peers.make_peer(method, setting, case, **kw)
    raise ValueError(method)


METHOD_LABELS = {
    "paper": "1 paper: Euler+Fourier10+AL/Nelder–Mead",
    "fourier": "2 Euler (paper frame)+Fourier+IPOPT",
    "fourier-3d": "2' same, full 3D model on planar cases",
    "fourier-3d-z": "2'' same, scene turned so the chord is along z",
    "default": "3 default: 3D director model (quaternions on spectral elements)+IPOPT/Newton",
    "default-planar": "3p default, model: planar",
    "rod": "4 discretised rod+IPOPT",
    "pyelastica": "5a PyElastica (damped Cosserat)",
    "mujoco": "5b MuJoCo cable (damped)",
    "mujoco-rod": "5c MuJoCo 4 rod: 1D flex, discrete elastic rod (damped)",
}

#: the dynamic peers (bench/methods/peers.py), relaxed to rest by damped time stepping
PEERS = ("pyelastica", "mujoco", "mujoco-rod")
