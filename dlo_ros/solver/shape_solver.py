"""ShapeSolver: warm-started, thread-safe equilibrium solves of one scene structure.

Contract:
* The NLP is built once per structure (StringNLP); ``solve`` only changes parameter values.
* ``solve(poses)`` warm-starts from the last committed equilibrium (primal z and IPOPT multipliers);
  if that fails the jump is split into 2, 4, … ``max_continuation_steps`` equal steps; if that fails too,
  a cold start from a buckled guess is tried.  ``commit=False`` answers a query without touching the
  warm-start state.
* Grip orientations become Euler-angle targets unwrapped to the current shape (φ, ψ + 2πk), so an end
  turned by several revolutions in small steps is tracked continuously.
* Every call returns a ShapeResult; bad input gives status 'invalid', grips farther apart than the
  string reaches 'unreachable' — never an exception.
* One lock serialises every entry: CasADi's IPOPT must never run in two threads at once.  MUMPS (IPOPT's
  linear solver) is not thread-safe across instances either, so every IPOPT call in the process also
  holds the module-wide ``IPOPT_LOCK`` (Newton updates and derivative evaluations do not).
* With ``lazy_ipopt`` the IPOPT solvers are created on first use (``prepare()`` creates them ahead):
  building them is about half of a build, and a helper used only for Newton updates or stability
  checks never needs them.
"""
from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
from scipy.linalg.lapack import dgeqp3 as _geqp3
from scipy.linalg.lapack import dgesv as _gesv
from scipy.linalg.lapack import dorgqr as _orgqr
from scipy.linalg.lapack import dsyevr as _syevr
from scipy.special import j0

from ..model.director import frame_to_quat, transported_frames
from ..model.problem import GripPose, Problem
from ..model.rotations import TANGENT_X, euler_from_frame, material_frames, pose_quaternions, quat_to_matrix
from .compiled import InterpretedFunction, NativeFunction, compiled, compiler, library_path
from .nlp import NEWTON_STEPS, StringNLP
from .options import SolverOptions
from .residual import EquilibriumResidual, PointAction, equilibrium_residual, evaluation_grid
from .result import GripWrench, ShapeResult

SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
IPOPT_LOCK = threading.Lock()  # MUMPS is not thread-safe across IPOPT instances (coin-or/Ipopt#733)
COMPILE_MODES = ("background", "blocking", "cached", "off")
#: point moments (director models): re-centre their pseudo-potential until the rotation at each load is
#: this close to its centre [rad] (the moment's work is then M·δθ to relative 1e-9/2), in at most this
#: many warm updates
MOMENT_RECENTRE_RAD = 1e-9
MOMENT_RECENTRE_ROUNDS = 30


@dataclass
class _State:
    """A committed equilibrium: the warm start of the next solve."""

    z: np.ndarray
    lam_g: np.ndarray
    lam_x: np.ndarray
    p: np.ndarray
    hessian: np.ndarray | None = None   # ∇²L at z, when the solve already has it
    jacobian: np.ndarray | None = None  # ∂g/∂z at z
    energies: np.ndarray | None = None  # bend, twist, stretch, gravity, work at z
    gradient: np.ndarray | None = None  # ∇f at z
    g: np.ndarray | None = None  # constraint values (scaled rows) at z
    unstable_direction: np.ndarray | None = None  # eigenvector of the most negative reduced curvature
    kkt: np.ndarray | None = None       # contact-free Newton matrix [∇²L Jᵀ; J 0] at z (free rows)
    residual: np.ndarray | None = None  # contact-free residual [∇f + Jᵀλ; g] at z (free rows)


def structure_key(problem: Problem, options: SolverOptions) -> tuple:
    """What fixes the NLP's structure; problems with equal keys share one NLP."""
    return (
        problem.string.length,
        tuple((g.name, g.s, g.mode) for g in problem.grips),
        tuple(ld.s for ld in problem.loads),
        tuple((r.s_a, r.s_b) for r in problem.relative_positions),
        tuple(o.type for o in problem.obstacles),
        problem.string.stretch_stiffness is not None,
        problem.string.twist_stiffness.is_zero,
        options,
    )


class ShapeSolver:
    """Solve the string's static shape for changing grip targets (see module docstring)."""

    def __init__(self, problem: Problem, options: SolverOptions | None = None, compile: str = "background",
                 lazy_ipopt: bool = False, reference_frame: np.ndarray | None = None):
        """compile: 'background' (solve at once with interpreted derivatives, compile them to C in a
        background thread and switch when ready; cached per machine), 'blocking' (compile or load
        now), 'cached' (use a library compiled earlier, never compile), or 'off'.
        $DLO_NO_COMPILE forces 'off'.  lazy_ipopt: create the IPOPT solvers on first use (helpers that
        may only take Newton steps); otherwise now, so that a stream's first IPOPT fallback does not
        pay for them.  reference_frame: a fixed R0 for the Euler angles (3D models; default: chosen from
        the scene, ``choose_reference_frame``)."""
        if compile not in COMPILE_MODES:
            raise ValueError(f"compile: must be one of {COMPILE_MODES}, got {compile!r}")
        self.options = options or SolverOptions()
        self.compile_mode = compile
        self.lazy_ipopt = lazy_ipopt
        self.reference_frame = None if reference_frame is None else np.array(reference_frame, dtype=float)
        self._lock = threading.Lock()
        self._compile_thread: threading.Thread | None = None
        self._build(problem)

    def _build(self, problem: Problem) -> None:
        t0 = time.perf_counter()
        self.nlp = StringNLP(problem, self.options, self.reference_frame)
        self._check_moments(problem)
        old = getattr(self, "_ipopt", {})
        with IPOPT_LOCK:  # freeing an IPOPT/MUMPS instance must not overlap a solve in another thread
            old.clear()
        self._ipopt: dict[bool, object] = {}  # warm? → IPOPT nlpsol
        if not self.lazy_ipopt:
            self._ipopt_solver(False), self._ipopt_solver(True)
        self._kkt = InterpretedFunction(self.nlp.kkt_fn)
        self._kkt_free = InterpretedFunction(self.nlp.kkt_free_fn)
        self._newton_step = InterpretedFunction(self.nlp.newton_fn)
        # the first Newton steps in one call of newton_fn (around the compiled contact-free function once
        # that is loaded); False: one evaluation and one LAPACK solve per step from Python
        self.fused_newton = True
        self._obstacle_g = InterpretedFunction(self.nlp.obstacle_g_fn) if self.nlp.obstacle_g_fn is not None else None
        self.kkt_compiled = False
        self.compile_time_s = 0.0
        self._start_compile()
        self.problem = problem
        self._key = structure_key(problem, self.options)
        self._state: _State | None = None
        self.build_time_s = time.perf_counter() - t0

    @property
    def _cold(self):
        return self._ipopt_solver(False)

    @property
    def _warm(self):
        return self._ipopt_solver(True)

    def _ipopt_solver(self, warm: bool):
        if warm not in self._ipopt:
            self._ipopt[warm] = self.nlp.make_solver(warm=warm)
        return self._ipopt[warm]

    def prepare(self) -> None:
        """Create the IPOPT solvers now (they are otherwise created on first use)."""
        with self._lock:
            self._ipopt_solver(False), self._ipopt_solver(True)

    def start_compile(self, mode: str) -> None:
        """Switch the compile mode (e.g. a helper solver promoted to stream) and start compiling if
        that mode asks for it and nothing is compiled or compiling yet."""
        if mode not in COMPILE_MODES:
            raise ValueError(f"compile: must be one of {COMPILE_MODES}, got {mode!r}")
        self.compile_mode = mode
        if not self.kkt_compiled and self._compile_thread is None:
            self._start_compile()

    def _start_compile(self) -> None:
        mode = "off" if os.environ.get("DLO_NO_COMPILE") else self.compile_mode
        if mode == "off":
            return
        if compiler() is None:
            return
        nlp = self.nlp
        # the contact-free function first: it is the one a stream uses while nothing touches
        todo = []
        for name, fn in (("_kkt_free", nlp.kkt_free_fn), ("_obstacle_g", nlp.obstacle_g_fn),
                         ("_kkt", nlp.kkt_fn)):
            if fn is None:
                continue
            lib = library_path(fn)
            if lib.exists():  # compiled on an earlier start: load now, no waiting
                setattr(self, name, NativeFunction(lib, fn))
                if name == "_kkt_free":
                    self._newton_step = self._compiled_newton_step(nlp, fn, lib)
            else:
                todo.append((name, fn, lib))
        self.kkt_compiled = not todo
        if not todo or mode == "cached":
            return

        def work(locked: bool) -> None:
            t0 = time.perf_counter()
            for name, fn, lib in todo:
                native, ok = compiled(fn, nice=10 if mode == "background" else 0, lib=lib)
                with (threading.Lock() if locked else self._lock):  # blocking: the caller may hold self._lock
                    if not ok or self.nlp is not nlp:  # no compiler, or the scene was rebuilt meanwhile
                        return
                    setattr(self, name, native)
                    if name == "_kkt_free":
                        self._newton_step = self._compiled_newton_step(nlp, fn, lib)
            with (threading.Lock() if locked else self._lock):
                if self.nlp is nlp:
                    self.kkt_compiled = True
                    self.compile_time_s = time.perf_counter() - t0

        if mode == "blocking":
            work(locked=True)
        else:
            self._compile_thread = threading.Thread(target=work, args=(False,), name="dlo-compile", daemon=True)
            self._compile_thread.start()

    def _compiled_newton_step(self, nlp: StringNLP, fn, lib) -> "InterpretedFunction":
        """``newton_fn`` calling the compiled contact-free library (``casadi.external``); the interpreted
        one if it cannot be loaded (then the steps are still right, only slower)."""
        try:
            return InterpretedFunction(nlp.newton_function(ca.external(fn.name(), str(lib))))
        except RuntimeError:
            return self._newton_step

    def wait_for_compile(self, timeout: float | None = None) -> bool:
        """Block until a background compile has finished; True if compiled derivatives are in use."""
        if self._compile_thread is not None:
            self._compile_thread.join(timeout)
        return self.kkt_compiled

    # ---- public API ---------------------------------------------------------------------------------
    @property
    def model(self):
        return self.nlp.model

    @property
    def has_warm_start(self) -> bool:
        return self._state is not None

    def snapshot(self) -> "_State | None":
        """A copy of the committed equilibrium (for adopt_warm_start from another thread, later)."""
        with self._lock:
            s = self._state
            return None if s is None else _State(s.z.copy(), s.lam_g.copy(), s.lam_x.copy(), s.p.copy())

    def adopt_warm_start(self, other: "ShapeSolver", state: "_State | None" = None) -> bool:
        """Take ``other``'s committed equilibrium as this solver's warm start, across models.

        Fields are re-expanded in this model's basis from their values at this model's quadrature nodes
        (a planar solution gets θ ≡ π/2, a solution without ψ gets its zero-twist ψ, an inextensible one
        ε ≡ 0); multipliers are matched by constraint-row identity (grip, name, component) and are
        zero for rows the other model did not have.  A different reference frame is handled by
        re-extracting the Euler angles of the material frames in this model's frame (unwrapped along s).
        ``state``: an earlier ``other.snapshot()`` to adopt instead of other's current equilibrium.
        """
        with other._lock:
            src = other._state if state is None else state
            if src is None:
                return False
            if self.nlp.director:
                nodes = self.model.mesh.nodes
                frames = other.pose_frames(src.z, nodes)
                eps = other.strain(src.z, nodes) if self.model.layout.stretch else None
            else:
                nodes = self.model.quad.nodes
                f = other.model.fields(src.z, nodes) if not other.nlp.director else {"eps": other.strain(src.z, nodes)}
                if other.nlp.director or not np.allclose(other.nlp.r0, self.nlp.r0):
                    frames = other.frames(src.z, nodes, src.p)
                    angles = np.array([euler_from_frame(self.nlp.r0, q) for q in frames])
                    f["phi"], f["theta"], f["psi"] = np.unwrap(angles[:, 0]), angles[:, 1], np.unwrap(angles[:, 2])
                elif not other.model.layout.twist and self.model.layout.twist:
                    f["psi"] = other.frames_psi(src.z, nodes, src.p)
            src_rows = {kind: i for i, kind in enumerate(other.nlp.row_kind)}
            lam_src = src.lam_g / (other.nlp.row_scale * other.nlp.sigma) if src.lam_g.size else src.lam_g
        lay = self.model.layout
        if self.nlp.director:
            if lay.frame:
                frames = self._match_clamp_rolls(frames, self.problem)
            z = self.model.z_from_frames(src.z[0:3] * other.model.length, frames, eps)
        else:
            z = np.zeros(lay.size)
            z[0:3] = src.z[0:3] * other.model.length / self.model.length
            for name in ("phi", "theta", "psi", "eps"):
                if self.model.coefficients(z, name) is not None:
                    z[lay.slice(name)] = np.linalg.lstsq(self.model.B, f[name], rcond=None)[0]
        # grip position rows: carry the reaction force vector, whatever axes each model's rows use
        forces = {}
        for name, rows in other.nlp.grip_rows.items():
            forces[name] = other.nlp.grip_axes[name].T @ lam_src[rows["position"]]
        lam = np.zeros(self.nlp.lbg.size)
        for i, kind in enumerate(self.nlp.row_kind):
            if kind[0] == "grip" and kind[2] == "position" and kind[1] in forces:
                value = float(np.dot(np.array(kind[3]), forces[kind[1]]))
            elif kind in src_rows:
                value = lam_src[src_rows[kind]]
            else:
                continue
            lam[i] = value * self.nlp.row_scale[i] * self.nlp.sigma
        p = self.pack_parameters(self.problem, z)
        if self.nlp.director:
            # rows the other model had no twin for (unit norms, folds, the frame rows): least-squares
            # multipliers of the equality rows at z, ∇f + J_freeᵀ λ ≈ 0 (zero ones would make the first
            # Newton update fail and fall back to IPOPT)
            nf = self.nlp.n_free_rows
            _, _, grad, _ = self._kkt_free(z, p, lam[:nf])
            jac = np.asarray(self.nlp.jac_g_fn(z, p))
            rest = np.asarray(grad).ravel() + jac[nf:].T @ lam[nf:]  # contacts keep their matched multipliers
            lam[:nf] = np.linalg.lstsq(jac[:nf].T, -rest, rcond=None)[0]
        with self._lock:
            self._state = _State(z, lam, np.zeros(lay.size), p)
        return True

    def _match_clamp_rolls(self, frames: np.ndarray, problem: Problem) -> np.ndarray:
        """Node frames turned about their tangents by the piecewise-linear interpolant of the roll misfit
        at the clamps (each in (−π, π]): a shape from a model without twist (or a target turned while
        the plane was held) then meets the clamps' rolls, so Newton does not settle on the flipped sheet
        d1 = −d1_g that the clamp rows also admit."""
        clamps = sorted((g for g in problem.grips if g.mode == "clamp"), key=lambda g: g.s)
        if not clamps:
            return frames
        mesh = self.model.mesh
        rolls = []
        for g in clamps:
            f = frames[mesh.node_index(g.s)]
            target = quat_to_matrix(g.pose.orientation)[:, 1]
            rolls.append(math.atan2(float(np.dot(np.cross(f[:, 1], target), f[:, 0])), float(np.dot(f[:, 1], target))))
        gamma = np.interp(mesh.nodes, [g.s for g in clamps], rolls)
        t, d1, d2 = frames[:, :, 0], frames[:, :, 1], frames[:, :, 2]
        d1n = np.cos(gamma)[:, None] * d1 + np.sin(gamma)[:, None] * d2
        return np.stack([t, d1n, np.cross(t, d1n)], axis=-1)

    def strain(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """ε(s) of solution z (zeros when inextensible)."""
        m = self.model
        if not m.layout.stretch:
            return np.zeros(np.shape(s))
        if self.nlp.director:
            return m.mesh.interpolation(s)[0] @ m.strain_nodes(z)
        return m.fields(z, np.asarray(s), ("eps",))["eps"]

    def frames_psi(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """ψ(s) as published: the solved field, or the zero-twist ψ anchored at the first held grip."""
        m = self.model
        if m.layout.twist:
            return m.fields(z, s)["psi"]
        anchor = next((g for g in sorted(self.problem.grips, key=lambda g: g.s) if g.mode != "pin"), None)
        psi_anchor = 0.0
        if anchor is not None:
            pp = p if p is not None else self.pack_parameters(self.problem, z)
            psi_anchor = float(pp[self.nlp.params[f"grip:{anchor.name}:angles"]][2])
        if m.layout.planar:  # θ ≡ π/2: ψ' = −φ' cosθ = 0, so ψ is the anchor's everywhere
            return np.full(np.shape(s), psi_anchor)
        return m.zero_twist_psi(z, s, anchor.s if anchor is not None else 0.0, psi_anchor)

    def reset(self) -> None:
        """Forget the warm start: the next solve starts cold."""
        with self._lock:
            self._state = None

    def set_problem(self, problem: Problem) -> None:
        """Replace the scene's values (properties, loads, obstacles, grips).

        Same structure: only parameter values change and the warm start is kept.  Otherwise the NLP is
        rebuilt (and the next solve is cold).  Raises ValueError naming the offending field.
        """
        problem.validate()
        with self._lock:
            if structure_key(problem, self.options) == self._key:
                self._check_moments(problem)
                self.problem = problem
            else:
                self._build(problem)

    def solve(
        self,
        poses: dict[str, GripPose | tuple] | None = None,
        *,
        warm: bool = True,
        commit: bool = True,
        checked: bool = False,
        check_now: bool = False,
    ) -> ShapeResult:
        """Equilibrium with the given grip poses (missing grips keep their current target).

        checked: the poses are GripPose objects already validated (``with_checked_poses``) and, for a
        planar model, already found in its plane (AutoShapeSolver checks both before calling).
        check_now: accepted for the interface AutoShapeSolver shares; a fixed model's checks (the
        equilibrium residual and the stability eigenvalue) always run inside every solve.
        """
        with self._lock:
            t0 = time.perf_counter()
            try:
                problem = self.problem.with_grip_poses(poses) if checked and poses else self._with_poses(poses)
            except (ValueError, KeyError) as exc:
                return self._failure("invalid", str(exc).strip("'\""), t0)
            if self.nlp.planar and not checked:
                from .nlp import planarity_violation

                why = planarity_violation(problem, self.nlp.r0[:, 2], tolerance=1e-7)
                if why:
                    return self._failure("invalid", f"solver.model planar: {why}", t0)
            reason = self.unreachable_reason(problem)
            if reason:
                return self._failure("unreachable", reason, t0)
            result, state = self._solve_locked(problem, warm and self._state is not None)
            result.solve_time_ms = (time.perf_counter() - t0) * 1e3
            # an unverified result is a converged stationary point of the discrete problem: a good warm start
            if commit and result.status in ("ok", "unverified") and state is not None:
                self._state = state
                self.problem = problem
            return result

    def query_many(self, targets, executor=None) -> list[ShapeResult]:
        """Answers to many independent queries (``{grip: pose}`` each) in worker processes, in order, with
        this solver's scene and options; this solver and its warm start are untouched
        (dlo_ros.solver.batch.query_many: ``executor`` defaults to a process pool on every core)."""
        from .batch import query_many

        return query_many(self.problem, self.options, targets, executor)

    # ---- input handling -----------------------------------------------------------------------------
    def _with_poses(self, poses: dict | None) -> Problem:
        return with_checked_poses(self.problem, poses)

    def _check_moments(self, problem: Problem) -> None:
        if self.nlp.director:  # moments about any axis (model/director.py)
            return
        n = self.nlp.r0[:, 2]
        for i, ld in enumerate(problem.loads):
            m = np.asarray(ld.moment, dtype=float)
            if np.linalg.norm(m - np.dot(m, n) * n) > 1e-9 * max(1.0, np.linalg.norm(m)):
                raise ValueError(
                    f"loads[{i}].moment: only moments about the working-plane normal n = {np.round(n, 6).tolist()} "
                    "are supported (their work −m·φ is exact); this moment has other components"
                )

    def unreachable_reason(self, problem: Problem) -> str:
        """Why the position constraints cannot all hold (empty string if they can)."""
        reach = 1.0 + (self.options.max_strain if problem.string.stretch_stiffness is not None else 0.0)
        pair = problem.farthest_apart(reach)
        if pair is not None:
            a, b, dist, span = pair
            return f"grips {a.name!r} and {b.name!r} are {dist:.4g} m apart but the string between them reaches at most {span:.4g} m"
        for k, rel in enumerate(problem.relative_positions):
            dist = float(np.linalg.norm(rel.offset))
            if dist > abs(rel.s_b - rel.s_a) * reach + 1e-12:
                return f"relative_positions[{k}].offset: {dist:.4g} m is longer than the string between s_a and s_b"
        return ""

    # ---- parameters -------------------------------------------------------------------------------
    def _reference_angles(self, z: np.ndarray, s: float) -> tuple[float, float, float]:
        f = self.model.fields(z, np.array([s]), ("phi", "theta", "psi"))
        return float(f["phi"][0]), float(f["theta"][0]), float(f["psi"][0])

    def grip_angles(self, pose: GripPose, reference: tuple[float, float, float]) -> np.ndarray:
        """Euler angles (φ, θ, ψ) of a grip orientation, on the branch nearest ``reference``."""
        phi, theta, psi = self._pose_euler(pose)
        best, best_d = None, math.inf
        two_pi = 2.0 * math.pi
        for ph, th, ps in ((phi, theta, psi), (phi + math.pi, -theta, psi + math.pi)):
            th = th + two_pi * round((reference[1] - th) / two_pi)
            ph = ph + two_pi * round((reference[0] - ph) / two_pi)
            ps = ps + two_pi * round((reference[2] - ps) / two_pi)
            d = (ph - reference[0]) ** 2 + (th - reference[1]) ** 2 + (ps - reference[2]) ** 2
            if d < best_d:
                best, best_d = (ph, th, ps), d
        return np.array(best)

    def _pose_euler(self, pose: GripPose) -> tuple[float, float, float]:
        """``euler_from_frame`` of a grip pose in this NLP's frame, remembered for the pose objects of the
        last few calls (a stream moves one grip; the others keep their GripPose objects)."""
        cache = self.__dict__.setdefault("_euler_cache", {})
        hit = cache.get(id(pose))
        if hit is not None and hit[0] is pose and hit[1] is self.nlp:
            return hit[2]
        if len(cache) > 16:
            cache.clear()
        angles = euler_from_frame(self.nlp.r0, quat_to_matrix(pose.orientation) @ TANGENT_X.T)
        cache[id(pose)] = (pose, self.nlp, angles)
        return angles

    def pack_parameters(self, problem: Problem, z_reference: np.ndarray) -> np.ndarray:
        """The NLP parameter vector for ``problem``; angles unwrapped to the shape ``z_reference``."""
        nlp, lay = self.nlp, self.nlp.params
        p = self._scene_parameters(problem).copy()
        if nlp.director:
            for g in problem.grips:
                p[lay[f"grip:{g.name}:position"]] = g.pose.position
                p[lay[f"grip:{g.name}:frame"]] = quat_to_matrix(g.pose.orientation).ravel(order="F")
            self._moment_references(problem, z_reference, p)
            return p
        references = self._grip_reference_angles(problem, z_reference)
        for g, reference in zip(problem.grips, references):
            p[lay[f"grip:{g.name}:position"]] = g.pose.position
            p[lay[f"grip:{g.name}:angles"]] = self.grip_angles(g.pose, reference)
        return p

    def _moment_references(self, problem: Problem, z: np.ndarray, p: np.ndarray) -> None:
        """Centre each point moment's pseudo-potential on the rotation of shape z at the load."""
        m, lay = self.model, self.nlp.params
        values = m.node_values(z)
        for i, ld in enumerate(problem.loads):
            ref = np.zeros(4)
            v = values[m.mesh.node_index(ld.s)]
            ref[: v.size] = v / np.linalg.norm(v)
            p[lay[f"load:{i}:reference"]] = ref

    def moment_mismatch(self, state: "_State") -> float:
        """Largest angle [rad] between a load's rotation in ``state`` and the reference its moment's
        pseudo-potential was centred on (0 without point moments): where it is 0 the moment's work is
        exactly M·δθ."""
        nlp = self.nlp
        if not (nlp.director and self.problem.loads):
            return 0.0
        m, lay, worst = self.model, nlp.params, 0.0
        values = m.node_values(state.z)
        for i, ld in enumerate(self.problem.loads):
            if not np.any(np.asarray(ld.moment) != 0.0):
                continue
            v = values[m.mesh.node_index(ld.s)]
            v = v / np.linalg.norm(v)
            ref = state.p[lay[f"load:{i}:reference"]][: v.size]
            worst = max(worst, 2.0 * math.acos(min(1.0, abs(float(np.dot(v, ref))))) if v.size == 4 else
                        math.acos(min(1.0, float(np.dot(v, ref)))))
        return worst

    def _grip_reference_angles(self, problem: Problem, z: np.ndarray) -> list[list[float]]:
        """(φ, θ, ψ) of shape z at every grip's s, in one product B(s_grips) [c_φ c_θ c_ψ] (θ ≡ π/2 and
        ψ ≡ 0 where they are not unknowns, as ``RitzModel.fields``)."""
        m = self.model
        s_grips = np.array([g.s for g in problem.grips])
        b = m.matrices(s_grips)[0]
        out = np.empty((len(s_grips), 3))
        for k, (name, constant) in enumerate((("phi", 0.0), ("theta", np.pi / 2), ("psi", 0.0))):
            c = m.coefficients(z, name)
            out[:, k] = b @ c if c is not None else constant
        return out.tolist()

    def _scene_parameters(self, problem: Problem) -> np.ndarray:
        """The parameter vector without grip targets (zeros there), cached while the string, gravity, loads,
        relative positions and obstacles are the same objects (a stream only changes grip poses)."""
        key = (problem.string, problem.loads, problem.relative_positions, problem.obstacles)
        cached = getattr(self, "_scene_p", None)
        if cached is not None and cached[0] is self.nlp and all(a is b for a, b in zip(cached[1], key)) \
                and np.array_equal(cached[2], problem.gravity):
            return cached[3]
        nlp, lay = self.nlp, self.nlp.params
        nodes = nlp.model.quad.nodes
        st = problem.string
        p = np.zeros(lay.size)
        p[lay["Rf"]] = st.bend_stiffness(nodes)
        p[lay["Rt"]] = st.twist_stiffness(nodes)
        p[lay["Re"]] = st.stretch_stiffness(nodes) if st.stretch_stiffness is not None else 0.0
        p[lay["D"]] = st.weight_per_length(nodes)
        nlp.material_parameters(p)
        p[lay["gravity"]] = problem.gravity_unit
        p[lay["radius"]] = st.radius
        n = nlp.r0[:, 2]
        for i, ld in enumerate(problem.loads):
            p[lay[f"load:{i}:force"]] = ld.force
            p[lay[f"load:{i}:moment"]] = ld.moment if nlp.director else float(np.dot(ld.moment, n))
        for i, rel in enumerate(problem.relative_positions):
            p[lay[f"relative:{i}"]] = rel.offset
        for i, ob in enumerate(problem.obstacles):
            p[lay[f"obstacle:{i}"]] = ob.params
        p.flags.writeable = False
        self._scene_p = (nlp, key, np.array(problem.gravity, dtype=float), p)
        return p

    # ---- initial guess ----------------------------------------------------------------------------
    def initial_guess(self, problem: Problem) -> np.ndarray:
        """A buckled planar guess: tangent angle β(s) = β0 − α sin(2π u) between the outermost grips.

        u = (s − s_a)/(s_b − s_a); α solves J0(α) = chord/span so the guess has the grips' chord; the
        buckle bends toward gravity (a hanging cable's sag).  A single grip gives a straight string
        along its tangent.  x0 is chosen so the first grip sits on its target.
        """
        if self.nlp.director:
            return self._director_guess(problem)
        m, lay = self.model, self.model.layout
        nodes = m.quad.nodes
        grips = sorted(problem.grips, key=lambda g: g.s)
        a, b = grips[0], grips[-1]
        r0 = self.nlp.r0
        ring = False
        if len(grips) >= 2 and np.linalg.norm(b.pose.position - a.pose.position) > 1e-9:
            chord = b.pose.position - a.pose.position
            span = b.s - a.s
            ratio = min(1.0, np.linalg.norm(chord) / span)
            alpha = _inverse_j0(ratio)
            d = chord / np.linalg.norm(chord)
        else:
            d = quat_to_matrix(a.pose.orientation)[:, 0]
            alpha, span = 0.0, (b.s - a.s if len(grips) >= 2 else 1.0)
            ring = len(grips) >= 2  # the outer grips at one point: a ring through it (as _director_guess)
        local = r0.T @ d
        theta0 = float(np.arccos(np.clip(local[2], -1, 1)))
        phi0 = float(np.arctan2(local[1], -local[0])) if np.hypot(local[0], local[1]) > 1e-12 else 0.0
        u = np.clip((nodes - a.s) / span, 0.0, 1.0)
        wave = 2 * np.pi * u if ring else alpha * np.sin(2 * np.pi * u)
        # bend toward gravity, within the plane of the chord and gravity; a planar model bends in φ
        g = problem.gravity_unit
        down_perp = g - np.dot(g, d) * d
        phi, theta = np.full_like(nodes, phi0), np.full_like(nodes, theta0)
        bend_in_phi = lay.planar or (np.linalg.norm(down_perp) > 1e-9 and abs(np.sin(theta0)) > 0.3)
        if bend_in_phi:
            # dζ/dφ at (φ0, θ0): +φ turns the tangent toward this direction
            dz_dphi = r0 @ np.array([np.sin(theta0) * np.sin(phi0), np.sin(theta0) * np.cos(phi0), 0.0])
            sign = np.sign(np.dot(dz_dphi, down_perp)) or 1.0
            phi = phi0 + sign * wave
        else:
            theta = theta0 + wave
        z = np.zeros(lay.size)
        fit = lambda f: np.linalg.lstsq(m.B, f, rcond=None)[0]  # noqa: E731
        z[lay.slice("phi")] = fit(phi)
        if not lay.planar:
            z[lay.slice("theta")] = fit(theta)
        # bend the guess so it meets every held angle: add the piecewise-linear interpolant of the
        # residuals at the grips (a guess that breaks the clamps lets IPOPT wander into loops)
        p = self.pack_parameters(problem, z)
        fields = {"phi": phi, "theta": theta, "psi": np.zeros_like(nodes)}
        for k, name in enumerate(("phi", "theta", "psi")):
            if lay.planar and name != "phi" or name == "psi" and not lay.twist:
                continue
            holders = [g for g in grips if g.mode == "clamp" or (g.mode == "tangent" and name != "psi")]
            if not holders:
                continue
            current = m.fields(z, np.array([g.s for g in holders]))[name]
            residual = [p[self.nlp.params[f"grip:{g.name}:angles"]][k] - c for g, c in zip(holders, current)]
            z[lay.slice(name)] = fit(fields[name] + np.interp(nodes, [g.s for g in holders], residual))
        x_a = m.positions(z, np.array([a.s]))[0]
        z[0:3] = (a.pose.position - x_a) / m.length
        return z

    def _director_guess(self, problem: Problem) -> np.ndarray:
        """The buckled guess of ``initial_guess`` for a director model, as nodal frames: tangent
        t(s) = cos β d + sin β e with β = α sin 2πu (d the chord, e toward gravity), bent to meet every
        held tangent (the piecewise-linear interpolant of the misfits at the grips is added), frames
        carried along without twist from the first clamp and turned about t by the interpolated roll
        misfit at the other clamps.  Outer grips at one point get a ring, β = 2πu, instead."""
        m, r0 = self.model, self.nlp.r0
        nodes = m.mesh.nodes
        grips = sorted(problem.grips, key=lambda g: g.s)
        a, b = grips[0], grips[-1]
        ring = False
        if len(grips) >= 2 and np.linalg.norm(b.pose.position - a.pose.position) > 1e-9:
            chord = b.pose.position - a.pose.position
            span = b.s - a.s
            alpha = _inverse_j0(min(1.0, np.linalg.norm(chord) / span))
            d = chord / np.linalg.norm(chord)
        else:
            d = quat_to_matrix(a.pose.orientation)[:, 0]
            alpha, span = 0.0, (b.s - a.s if len(grips) >= 2 else 1.0)
            # the outer grips at one point: a ring through it (β = 2πu), which closes and does not cross
            # itself; the straight guess misses the second grip by the whole span
            ring = len(grips) >= 2
        g = problem.gravity_unit
        e = g - np.dot(g, d) * d
        if np.linalg.norm(e) < 1e-6:
            e = np.cross(r0[:, 2], d)
        if np.linalg.norm(e) < 1e-6:  # chord along gravity and the frame's normal: any perpendicular
            e = np.cross(np.eye(3)[int(np.argmin(np.abs(d)))], d)
        e /= np.linalg.norm(e)
        u = np.clip((nodes - a.s) / span, 0.0, 1.0)
        beta = 2 * np.pi * u if ring else alpha * np.sin(2 * np.pi * u)
        t = np.cos(beta)[:, None] * d[None, :] + np.sin(beta)[:, None] * e[None, :]
        holders = [gr for gr in grips if gr.mode != "pin"]
        if holders:
            idx = [m.mesh.node_index(gr.s) for gr in holders]
            misfit = np.array([quat_to_matrix(gr.pose.orientation)[:, 0] - t[i] for gr, i in zip(holders, idx)])
            s_h = [gr.s for gr in holders]
            t = t + np.stack([np.interp(nodes, s_h, misfit[:, k]) for k in range(3)], axis=1)
            t /= np.linalg.norm(t, axis=1)[:, None]
        clamps = [gr for gr in grips if gr.mode == "clamp"]
        k0 = int(np.argmin(np.abs(nodes - (clamps[0].s if clamps else nodes[0]))))
        if clamps:
            hint = quat_to_matrix(clamps[0].pose.orientation)[:, 1]
        else:
            hint = r0[:, 2] if abs(np.dot(r0[:, 2], t[k0])) < 0.9 else r0[:, 0]
        frames = transported_frames(t, k0, hint)
        if m.layout.frame:
            frames = self._match_clamp_rolls(frames, problem)
        z = m.z_from_frames(np.zeros(3), frames)
        z[0:3] = (a.pose.position - m.positions(z, np.array([a.s]))[0]) / m.length
        return z

    # ---- solving ----------------------------------------------------------------------------------
    def _call(self, solver, z0, p, lam_g0=None, lam_x0=None):
        nlp = self.nlp
        args = {"x0": z0, "p": p, "lbg": nlp.lbg, "ubg": nlp.ubg}
        if lam_g0 is not None:
            args["lam_g0"] = lam_g0
            args["lam_x0"] = lam_x0
        with IPOPT_LOCK:
            sol = solver(**args)
            stats = solver.stats()
        z = np.asarray(sol["x"]).ravel()
        lam_g = np.asarray(sol["lam_g"]).ravel()
        lam_x = np.asarray(sol["lam_x"]).ravel()
        g = np.asarray(sol["g"]).ravel()
        violation = self._violation_from_g(g)
        ok = stats["return_status"] in SUCCESS and violation < 1e-6 * nlp.length and np.all(np.isfinite(z))
        return ok, _State(z, lam_g, lam_x, p, g=g), stats["return_status"], int(stats.get("iter_count", 0)), violation

    def _newton(self, start: _State, p: np.ndarray, max_steps: int = 10) -> tuple[bool, _State, int, float]:
        """Warm update by Newton's method on the KKT conditions with the start's active set.

        Solves [H Jᵀ; J 0] [Δz; Δλ] = −[∇f + Jᵀλ; g − g_bound] over the equality rows and the
        inequality rows active at the start (λ > 0), until both residuals are below tolerance.
        Gives up (→ IPOPT) if a step is large (> 0.5 in any scaled unknown), the active set changes
        (an inactive obstacle row is violated or an active one's λ turns negative), or it does not
        converge in ``max_steps``.  It lands on the stationary point nearest the start, so the caller
        still checks stability.
        """
        nlp = self.nlp
        z, lam = start.z.copy(), np.zeros_like(start.lam_g)
        equality = nlp.equality
        # active = at its bound with a positive multiplier (IPOPT leaves ~1e-10 barrier multipliers
        # on rows far from their bound; those are inactive)
        if start.g is None:  # a warm start adopted from another model
            start.g = np.asarray(nlp.g_fn(start.z, start.p)).ravel()
        active = equality | ((start.lam_g > 1e-8) & (start.g > nlp.ubg - 1e-7))
        if not np.any(active[nlp.n_free_rows:]):
            return self._newton_free(start, p, max_steps)
        lam[active] = start.lam_g[active]
        idx = np.flatnonzero(active)
        bound = nlp.ubg[idx]
        n, m = z.size, idx.size
        kkt, rhs = np.zeros((n + m, n + m)), np.empty(n + m)
        # Only grip targets changed → they enter g linearly (row = (x − target)/scale), so ∇f, J and H
        # stored at the start stay exact and g shifts by a known amount: the first step needs no evaluation.
        keep = ~nlp.grip_parameter_mask
        reuse = (
            start.hessian is not None and start.g is not None and start.gradient is not None
            and np.array_equal(start.p[keep], p[keep])
        )
        for it in range(max_steps + 1):
            if it == 0 and reuse:
                grad, jac, hess, energies = start.gradient, start.jacobian, start.hessian, None
                g = start.g + nlp.target_shift(start.p, p)
            else:
                grad, g, jac, hess, energies = self._kkt(z, p, lam)
                grad, g = grad.ravel(), g.ravel()
            ja = jac[idx]
            r_dual = grad + lam[idx] @ ja
            r_prim = g[idx] - bound
            converged = np.abs(r_dual).max(initial=0.0) < 1e-9 and np.abs(r_prim).max(initial=0.0) < 1e-11
            if converged and energies is not None:
                inactive_ok = np.all(g[~active] <= nlp.ubg[~active] + 1e-9)
                signs_ok = np.all(lam[active & ~equality] >= -1e-12)
                if not (inactive_ok and signs_ok):
                    return False, start, it, np.inf
                violation = self._violation_from_g(g)
                state = _State(z, lam, start.lam_x, p, hessian=hess, jacobian=jac, energies=energies.ravel(), g=g, gradient=grad)
                return True, state, it, violation
            if it == max_steps:
                break
            kkt[:n, :n] = hess
            kkt[:n, n:] = ja.T
            kkt[n:, :n] = ja
            rhs[:n] = -r_dual
            rhs[n:] = -r_prim
            # LAPACK's gesv directly: numpy.linalg.solve's checks cost more than the solve at this size
            _, _, step, info = _gesv(kkt, rhs)
            if info != 0 or not np.isfinite(step).all() or np.abs(step[:n]).max() > 0.5:
                return False, start, it, np.inf
            z += step[:n]
            lam[idx] += step[n:]
        return False, start, max_steps, np.inf

    def _newton_free(self, start: _State, p: np.ndarray, max_steps: int) -> tuple[bool, _State, int, float]:
        """``_newton`` while no obstacle row is active: the active rows are the free rows (all equalities),
        and the contact-free function returns the Newton matrix K and residual r themselves.  Steps
        K [Δz; Δλ] = −r start from the start's own K with r shifted by the new targets, when only targets
        changed.  The first NEWTON_STEPS steps are one call of ``StringNLP.newton_fn`` (around the
        compiled contact-free function once it is loaded); if r is not yet converged, each further step
        is one evaluation and one LAPACK solve.  The obstacle rows' values are evaluated once, at the
        end, to check that none is violated (else the caller falls back to IPOPT)."""
        nlp = self.nlp
        nf, n, rows = nlp.n_free_rows, start.z.size, nlp.lbg.size
        unknowns = np.concatenate([start.z, start.lam_g[:nf]])
        keep = ~nlp.grip_parameter_mask
        if start.kkt is not None and np.array_equal(start.p[keep], p[keep]):  # targets enter g linearly
            kkt, residual, energies = start.kkt, start.residual.copy(), None
            residual[n:] += nlp.target_shift(start.p, p)[:nf]
        else:
            kkt, residual, grad, energies = self._kkt_free(unknowns[:n], p, unknowns[n:])
            residual = residual[:, 0]
        first = 0
        if self.fused_newton:
            try:
                u, kkt, residual, grad, energies, largest = self._newton_step(unknowns, p, kkt, residual)
            except RuntimeError:  # CasADi's LAPACK LU raises on a singular Newton matrix (gesv says info > 0)
                return False, start, 0, np.inf
            if not (np.isfinite(u).all() and largest[0, 0] <= 0.5):
                return False, start, NEWTON_STEPS, np.inf
            unknowns, residual, first = u[:, 0], residual[:, 0], NEWTON_STEPS
        for it in range(first, max_steps + 1):
            z, lam_free = unknowns[:n], unknowns[n:]
            if energies is not None and np.abs(residual[:n]).max() < 1e-9 and \
                    np.abs(residual[n:]).max(initial=0.0) < 1e-11:
                g, jac = self._all_rows(z, p, kkt, residual)
                if np.any(g[nf:] > nlp.ubg[nf:] + 1e-9):  # a contact appeared: the active set changed
                    return False, start, it, np.inf
                lam = np.zeros(rows)
                lam[:nf] = lam_free
                state = _State(z.copy(), lam, start.lam_x, p, hessian=kkt[:n, :n], jacobian=jac,
                               energies=energies.ravel(), g=g, gradient=grad.ravel(), kkt=kkt, residual=residual)
                return True, state, it, self._violation_from_g(g)
            if it == max_steps:
                break
            _, _, step, info = _gesv(kkt, residual)
            if info != 0 or not np.isfinite(step).all() or np.abs(step[:n]).max() > 0.5:
                return False, start, it, np.inf
            unknowns = unknowns - step
            kkt, residual, grad, energies = self._kkt_free(unknowns[:n], p, unknowns[n:])
            residual = residual[:, 0]
        return False, start, max_steps, np.inf

    def _derivatives(self, z: np.ndarray, p: np.ndarray, lam: np.ndarray, active: np.ndarray) -> list[np.ndarray]:
        """[∇f, g, ∂g/∂z, ∇²L, energies] at (z, p, λ).  When no obstacle row is ``active`` (so λ is zero on
        them) the contact-free function is used: the obstacle rows' Jacobian rows are returned as zeros
        and left out of ∇²L, which is exact for every use here (only active rows' Jacobians are used, and
        inactive rows have λ = 0)."""
        nf = self.nlp.n_free_rows
        if np.any(active[nf:]):
            return self._kkt(z, p, lam)
        kkt, residual, grad, energies = self._kkt_free(z, p, lam[:nf])
        g, jac = self._all_rows(z, p, kkt, residual[:, 0])
        return [grad, g[:, None], jac, kkt[: z.size, : z.size], energies]  # g as a column, as kkt_fn gives it

    def _all_rows(self, z: np.ndarray, p: np.ndarray, kkt: np.ndarray,
                  residual: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(g, ∂g/∂z) over every row from the contact-free system (K, r) at z: the free rows' values are r's
        last rows and their Jacobian K's lower-left block; the obstacle rows' values are evaluated, their
        Jacobian rows are zeros (unused while they are inactive)."""
        n, nf, rows = z.size, self.nlp.n_free_rows, self.nlp.lbg.size
        g = np.empty(rows)
        g[:nf] = residual[n:]
        if nf < rows:
            g[nf:] = self._obstacle_g(z, p)[0].ravel()
        jac = np.zeros((rows, n))
        jac[:nf] = kkt[n:, :n]
        return g, jac

    def _violation_from_g(self, g: np.ndarray) -> float:
        nlp = self.nlp
        if g.size == 0:
            return 0.0
        return float(np.max(np.maximum(np.maximum(nlp.lbg - g, 0.0), np.maximum(g - nlp.ubg, 0.0)) * nlp.row_scale))

    def _solve_locked(self, problem: Problem, warm: bool) -> tuple[ShapeResult, _State | None]:
        result, state = self._solve_once(problem, warm)
        if result.status in ("ok", "unverified") and state is not None and self.nlp.director and problem.loads:
            return self._recentre_moments(problem, result, state)
        return result, state

    def _recentre_moments(self, problem: Problem, result: ShapeResult, state: _State) -> tuple[ShapeResult, _State | None]:
        """Re-centre the point moments' pseudo-potentials on the solution until the rotation at every
        load is within MOMENT_RECENTRE_RAD = α of its reference (the pseudo-potential's gradient is then
        M·(I + α/2 [n]×)·δθ, so the moment is applied to relative α/2), or until the mismatch stops
        halving below 1000 α (the precision of the solves themselves); each round is a warm update with
        the new references.  Fails when 30 rounds leave it above 1000 α."""
        previous = np.inf
        for _ in range(MOMENT_RECENTRE_ROUNDS):
            mismatch = self.moment_mismatch(state)
            # converged, or stalled at the precision of the solves themselves (then α/2 ≤ 5e-8 relative)
            if mismatch <= MOMENT_RECENTRE_RAD or (mismatch <= 1e3 * MOMENT_RECENTRE_RAD and mismatch > 0.5 * previous):
                return result, state
            previous = mismatch
            p = self.pack_parameters(problem, state.z)
            ok, new, it, viol = self._newton(state, p)
            status = "Newton"
            if not ok:
                ok, new, status, it, viol = self._call(self._warm, state.z, p, state.lam_g, state.lam_x)
            if not ok:
                break
            state = new
            result = self._result(problem, state, status, result.iterations + it, viol, result.warm_started,
                                  result.continuation_steps)
            if result.status not in ("ok", "unverified"):
                return result, None
        if self.moment_mismatch(state) <= 1e3 * MOMENT_RECENTRE_RAD:
            return result, state
        return ShapeResult(status="failed", message=(
            f"point moments: the rotation at a load is still {self.moment_mismatch(state):.2g} rad from the "
            f"pseudo-potential's centre after {MOMENT_RECENTRE_ROUNDS} re-centring rounds"),
            iterations=result.iterations, basis=self.options.basis, order=self.options.order,
            model=self.model_summary()), None

    def _solve_once(self, problem: Problem, warm: bool) -> tuple[ShapeResult, _State | None]:
        iterations, steps, last_status = 0, 0, ""
        unverified: tuple[ShapeResult, _State] | None = None  # IPOPT's warm answer, over the residual tolerance
        if warm:
            start = self._state
            p1 = self.pack_parameters(problem, start.z)
            ok, state, it, viol = self._newton(start, p1)
            iterations += it
            if ok:
                result = self._result(problem, state, "Newton", iterations, viol, True, 0)
                if result.stable is not False and result.status != "failed":  # (failed: a flipped branch)
                    return result, state
                ok = False
            ok, state, last_status, it, viol = self._call(self._warm, start.z, p1, start.lam_g, start.lam_x)
            iterations += it
            k = 2
            while not ok and k <= self.options.max_continuation_steps:
                state, ok = start, True
                for i in range(1, k + 1):
                    p_i = start.p + (p1 - start.p) * (i / k)
                    ok, state, last_status, it, viol = self._call(self._warm, state.z, p_i, state.lam_g, state.lam_x)
                    iterations += it
                    if not ok:
                        break
                steps = k if ok else 0
                k *= 2
            if ok:
                result = self._result(problem, state, last_status, iterations, viol, True, steps)
                if result.status == "ok":
                    return self._escape_saddle(problem, result, state)
                if result.status == "unverified":
                    # IPOPT from the warm start can end on a spurious stationary point of the discrete
                    # problem (a folded field, residual of metres); the cold guess decides, the smaller
                    # residual wins
                    unverified = (result, state)
        z0 = self.initial_guess(problem)
        p = self.pack_parameters(problem, z0)
        ok, state, last_status, it, viol = self._call(self._cold, z0, p)
        iterations += it
        if ok:
            result = self._result(problem, state, last_status, iterations, viol, False, 0)
            if unverified is not None and not (result.status == "ok" or result.status == "unverified" and
                                               result.equilibrium_residual_m < unverified[0].equilibrium_residual_m):
                result, state = unverified
                result.iterations = iterations
            if result.status != "failed":
                return self._escape_saddle(problem, result, state)
            last_status = result.message
        elif unverified is not None:
            unverified[0].iterations = iterations
            return self._escape_saddle(problem, *unverified)
        status = "infeasible" if last_status == "Infeasible_Problem_Detected" else "failed"
        message = f"IPOPT: {last_status} (constraint violation {viol:.3g}{self._witness(state.g)})" + (
            "; warm start and continuation also failed" if warm else "")
        # a failed result carries no shape, energy, wrench or eigenvalue that could be mistaken for one
        return ShapeResult(status=status, message=message, iterations=iterations, constraint_violation=viol,
                           warm_started=warm, basis=self.options.basis, order=self.options.order,
                           ipopt_status=last_status, model=self.model_summary()), None

    def _witness(self, g: np.ndarray | None) -> str:
        """', most violated: <row> by <amount>' at the best point IPOPT found (the witness of an
        'infeasible' or 'failed' verdict), '' when nothing is violated."""
        nlp = self.nlp
        if g is None or not g.size:
            return ""
        excess = np.maximum(np.maximum(nlp.lbg - g, 0.0), np.maximum(g - nlp.ubg, 0.0)) * nlp.row_scale
        i = int(np.argmax(excess))
        if not excess[i] > 0:
            return ""
        kind = nlp.row_kind[i]
        names = {"grip": lambda k: f"grip {k[1]!r} {k[2]}", "obstacle": lambda k: f"obstacle {k[1]} at s = "
                 f"{nlp.obstacle_s[k[2]]:.4g} m", "relative": lambda k: f"relative position {k[1]}",
                 "norm": lambda k: f"unit norm at node {k[1]}", "fold": lambda k: f"fold guard at node {k[1]}"}
        return f", most violated: {names.get(kind[0], str)(kind)} by {excess[i]:.3g}"

    def _escape_saddle(self, problem: Problem, result: ShapeResult, state: _State, depth: int = 3) -> tuple[ShapeResult, _State]:
        """A stationary point with negative reduced curvature is not a shape a string rests in.

        Step along the unstable eigenvector (both signs, 0.2 then 0.6 rad at most in any coefficient) and
        re-solve; keep the first stable result of lower energy.  A lower but still unstable stationary
        point is left the same way, up to ``depth`` saddles deep (a compressed twist-free strip falls
        from the planar buckle through a half-twisted saddle).  Symmetric starts (a planar guess for a
        scene whose minimum is twisted, paper Fig. 2) land on such saddles.
        """
        if result.stable is not False or state.unstable_direction is None:
            return result, state
        d = state.unstable_direction / np.max(np.abs(state.unstable_direction))
        lower: tuple[ShapeResult, _State] | None = None
        for step in (0.2, 0.6):  # a larger step when IPOPT falls back onto the saddle from the small one
            for sign in (1.0, -1.0):
                ok, trial, status, it, viol = self._call(self._cold, state.z + sign * step * d, state.p)
                result.iterations += it
                if not ok:
                    continue
                candidate = self._result(problem, trial, status, result.iterations, viol, result.warm_started,
                                         result.continuation_steps)
                if candidate.status == "failed":
                    continue
                if candidate.energy["total"] >= result.energy["total"] - 1e-12 * abs(result.energy["total"]):
                    continue
                if candidate.stable:
                    candidate.message += "; left an unstable equilibrium along its negative-curvature mode"
                    return candidate, trial
                if lower is None:
                    lower = (candidate, trial)
        if lower is not None and depth > 1:
            candidate, trial = self._escape_saddle(problem, lower[0], lower[1], depth - 1)
            if candidate.stable:
                return candidate, trial
        result.message += "; unstable equilibrium (no stable one found nearby)"
        return result, state

    # ---- results ----------------------------------------------------------------------------------
    def _failure(self, status: str, message: str, t0: float) -> ShapeResult:
        return ShapeResult(status=status, message=message, solve_time_ms=(time.perf_counter() - t0) * 1e3,
                           basis=self.options.basis, order=self.options.order, model=self.model_summary())

    def model_summary(self) -> dict:
        """What this solver models (the ``model`` object of a result)."""
        lay = self.model.layout
        summary = {
            "planar": lay.planar, "twist": lay.twist, "stretch": lay.stretch,
            "gravity": not self.problem.string.weight_per_length.is_zero, "order": lay.order,
            "obstacles": len(self.problem.obstacles), "estimated_error_m": None, "variables": lay.size,
        }
        if self.nlp.director:
            summary["rotation"] = "quaternion" if lay.frame else "tangent"
            summary["elements"] = lay.elements
            summary["breakpoints"] = [float(b) for b in self.model.mesh.breakpoints]
        else:
            summary["rotation"] = "planar" if lay.planar else "euler"
        return summary

    def _sample(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centreline points (N, 3) and φ, θ at the published arc lengths: ``RitzModel.positions`` and
        ``fields`` with the output matrices looked up once and each field's coefficients multiplied once."""
        m, s_out = self.model, self._output_s()
        b_out, _, w_out = m.matrices(s_out)
        cphi, cth, ceps = (m.coefficients(z, name) for name in ("phi", "theta", "eps"))
        theta_nodes = m.B @ cth if cth is not None else np.full(m.quad.count, np.pi / 2)
        t = m.tangents(m.B @ cphi, theta_nodes, m.B @ ceps if ceps is not None else None, lib=np)
        points = (z[0:3] * m.length)[None, :] + w_out @ t.T
        theta = b_out @ cth if cth is not None else np.full(len(s_out), np.pi / 2)
        return points, b_out @ cphi, theta

    def _output_s(self) -> np.ndarray:
        """The published arc lengths: ``output_points`` evenly spaced over [0, L] (computed once)."""
        key = (self.nlp.length, self.options.output_points)
        if getattr(self, "_s_out", (None,))[0] != key:
            self._s_out = (key, np.linspace(0.0, self.nlp.length, self.options.output_points))
        return self._s_out[1]

    def _result(self, problem, state: _State, ipopt_status, iterations, violation, warm, steps) -> ShapeResult:
        nlp, m = self.nlp, self.model
        z, p = state.z, state.p
        lam_si = state.lam_g / (nlp.row_scale * nlp.sigma) if state.lam_g.size else state.lam_g
        s_out = self._output_s().copy()
        if nlp.director:
            points = m.positions(z, s_out)
            quats = frame_to_quat(self.pose_frames(z, s_out))
        else:
            points, phi, theta = self._sample(z)
            quats = pose_quaternions(nlp.r0, phi, theta, self.frames_psi(z, s_out, p))
        min_eig = self._min_reduced_eigenvalue(state)  # also fills state.energies
        bend, twist, stretch, grav, work = (float(v) for v in state.energies.ravel())
        energy = {"bend": bend, "twist": twist, "stretch": stretch, "gravity": grav, "external_work": work,
                  "total": bend + twist + stretch + grav - work}
        grips = {g.name: self._wrench(g, z, lam_si) for g in problem.grips}
        contacts = {}
        actions = []  # point actions on the string, for the equilibrium residual
        if nlp.obstacle_rows:
            touching = np.any(lam_si[nlp.n_free_rows:] > 0)  # obstacle rows come last
            sample_x = m.positions(z, nlp.obstacle_s) if touching else None
            for i, rows in enumerate(nlp.obstacle_rows):
                ob = problem.obstacles[i]
                lam = lam_si[rows]
                force = np.zeros(3)
                for j in np.flatnonzero(lam > 0):
                    grad = np.asarray(nlp.obstacle_gradient[ob.type](sample_x[j], ob.params)).ravel()
                    force -= lam[j] * grad
                    actions.append(PointAction(float(nlp.obstacle_s[j]), sample_x[j], -lam[j] * grad, np.zeros(3)))
                contacts[i] = force
        residual = self.equilibrium(problem, z, grips, actions)
        stable = None if min_eig is None else is_stable(min_eig, state.hessian)
        status, message = "ok", "converged" + (f" after {steps} continuation steps" if steps else "")
        flipped = self._flipped_grips(problem, z) if nlp.director else ""
        tolerance = self.options.error_tolerance or 1e-3 * problem.string.length
        if flipped:  # not the grip's pose at all: no shape
            return ShapeResult(status="failed", message=f"landed on a flipped branch: {flipped}", iterations=iterations,
                               constraint_violation=violation, warm_started=warm, basis=self.options.basis,
                               order=self.options.order, ipopt_status=ipopt_status, model=self.model_summary())
        if not residual.metres <= tolerance:
            status, stable = "unverified", None
            message = (f"not a verified equilibrium: the equilibrium residual is {residual.metres:.3g} m, over the "
                       f"tolerance {tolerance:.3g} m (solver.error_tolerance; raise solver.order)")
        return ShapeResult(
            model=self.model_summary(), status=status, message=message,
            s=s_out, points=points, orientations=quats, energy=energy, grips=grips, contact_forces=contacts,
            stable=stable, min_eigenvalue=min_eig, iterations=iterations, constraint_violation=violation,
            warm_started=warm, continuation_steps=steps, basis=self.options.basis, order=self.options.order,
            ipopt_status=ipopt_status, equilibrium_residual_m=residual.metres,
        )

    def equilibrium(self, problem: Problem, z: np.ndarray, grips: dict[str, GripWrench],
                    contacts: list[PointAction] = ()) -> EquilibriumResidual:
        """The strong-form equilibrium residual of shape z under the grip reactions ``grips`` and the
        obstacle ``contacts`` (solver/residual.py)."""
        m, st, L = self.model, problem.string, problem.string.length
        grip_s = {g.name: g.s for g in problem.grips}
        events = list(grip_s.values()) + [ld.s for ld in problem.loads] + [a.s for a in contacts]
        if self.nlp.director:
            events += list(m.mesh.breakpoints)
        s = evaluation_grid(L, events)
        x = m.positions(z, s)
        rf = st.bend_stiffness(s)
        if self.nlp.director and m.layout.frame:
            frames = m.pose_frames(z, s)
            c = np.stack([st.twist_stiffness(s), rf, rf], axis=1)
            moment_c = np.einsum("kij,kj->ki", frames, c * m.curvature(z, s))
        elif self.nlp.director:
            moment_c = rf[:, None] * m.world_curvature(z, s)
        else:
            moment_c = self._euler_moments(z, s, rf, st.twist_stiffness(s))
        nodes = m.quad.nodes
        d_nodes = st.weight_per_length(nodes)
        w = m.position_matrix(s)
        x_nodes = m.positions(z, nodes)
        point_s = np.array(list(grip_s.values()) + [ld.s for ld in problem.loads])
        point_x = m.positions(z, point_s) if point_s.size else np.zeros((0, 3))
        actions = [PointAction(grip_s[name], point_x[k], wr.force, wr.torque) for k, (name, wr) in enumerate(grips.items())]
        for k, ld in enumerate(problem.loads):
            moment = np.asarray(ld.moment, dtype=float)
            if not self.nlp.director:  # the Euler models apply the moment's component along n only
                n = self.nlp.r0[:, 2]
                moment = np.dot(moment, n) * n
            actions.append(PointAction(ld.s, point_x[len(grips) + k], np.asarray(ld.force, dtype=float), moment))
        total = float(m.quad.weights @ d_nodes)
        return equilibrium_residual(s, x, moment_c, w @ d_nodes, w @ (d_nodes[:, None] * x_nodes), actions + list(contacts),
                                    problem.gravity_unit, total, L, st.bend_stiffness.minimum, rf)

    def _euler_moments(self, z: np.ndarray, s: np.ndarray, rf: np.ndarray, rt: np.ndarray) -> np.ndarray:
        """m = Q diag(Rf, Rf, Rt) ω with ω = axial(Qᵀ Q') by central differences of the Euler frames
        (Rt = 0 where the twist is not modelled: the frames then carry no twist moment)."""
        h = 1e-6 * self.problem.string.length
        q0, qm, qp = self.frames(z, s), self.frames(z, s - h), self.frames(z, s + h)
        skew = np.einsum("kji,kjl->kil", q0, (qp - qm) / (2 * h))
        omega = 0.5 * np.stack([skew[:, 2, 1] - skew[:, 1, 2], skew[:, 0, 2] - skew[:, 2, 0],
                                skew[:, 1, 0] - skew[:, 0, 1]], axis=1)
        c = np.stack([rf, rf, rt if self.model.layout.twist else np.zeros_like(rf)], axis=1)
        return np.einsum("kij,kj->ki", q0, c * omega)

    def _flipped_grips(self, problem: Problem, z: np.ndarray) -> str:
        """Grips whose orientation rows hold on the wrong sheet (t = −t_g, or d1 = −d1_g for a clamp
        with twist): the rows t·R_g e_y = t·R_g e_z = 0 allow it, the grip does not."""
        bad = []
        for g in problem.grips:
            if g.mode == "pin":
                continue
            t, d1 = self._node_frame(z, g.s)
            target = quat_to_matrix(g.pose.orientation)
            if np.dot(t, target[:, 0]) < 0 or (g.mode == "clamp" and d1 is not None and np.dot(d1, target[:, 1]) < 0):
                bad.append(g.name)
        return ", ".join(bad)

    def _node_frame(self, z: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray | None]:
        """(t, d1) of a director model at the node at arc length s (d1 None for the tangent model)."""
        v = self.model.node_values(z)[self.model.mesh.node_index(s)]
        if self.model.layout.frame:
            r = quat_to_matrix(v / np.linalg.norm(v))
            return r[:, 0], r[:, 1]
        return v / np.linalg.norm(v), None

    def pose_frames(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Frames (len(s), 3, 3) in the pose convention (columns: tangent, y, z) of solution z.  A
        director model without twist carries its frames without twist from the first held grip."""
        if not self.nlp.director:
            return self.frames(z, s) @ TANGENT_X
        anchor = next((g for g in sorted(self.problem.grips, key=lambda g: g.s) if g.mode != "pin"), None)
        return self.model.pose_frames(z, s, None if anchor is None else
                                      (anchor.s, quat_to_matrix(anchor.pose.orientation)))

    def frames(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """Material frames Q(s) (columns ξ, η, ζ) of solution z; ψ from the zero-twist rule if not solved."""
        if self.nlp.director:
            return self.pose_frames(z, s) @ TANGENT_X.T
        f = self.model.fields(z, s)
        return material_frames(self.nlp.r0, f["phi"], f["theta"], self.frames_psi(z, s, p))

    def _wrench(self, grip, z: np.ndarray, lam_si: np.ndarray) -> GripWrench:
        """Force = −λ_position; torque T solves J_aᵀ T = −μ_a for the held angles a (J_a = ∂ω/∂ȧ),
        plus T·ζ = 0 when the twist about the tangent is free."""
        rows = self.nlp.grip_rows[grip.name]
        force = -self.nlp.grip_axes[grip.name].T @ lam_si[rows["position"]]
        torque = np.zeros(3)
        if rows["angles"] and self.nlp.director:
            # T = ∂U/∂θ = −Σ_r λ_r ∂g_r/∂θ with ∂(t·a)/∂θ = t × a and ∂(d1·b)/∂θ = d1 × b
            t, d1 = self._node_frame(z, grip.s)
            target = quat_to_matrix(grip.pose.orientation)
            lam = lam_si[rows["angles"]]
            torque = -(lam[0] * np.cross(t, target[:, 1]) + lam[1] * np.cross(t, target[:, 2]))
            if len(lam) == 3:
                torque -= lam[2] * np.cross(d1, target[:, 2])
        elif rows["angles"] and self.nlp.planar:
            # only φ is held: the reaction torque is along the plane normal, n·T = μ_φ
            torque = lam_si[rows["angles"][0]] * self.nlp.r0[:, 2]
        elif rows["angles"]:
            phi, theta, _ = self._reference_angles(z, grip.s)
            r0 = self.nlp.r0
            j_phi = -r0[:, 2]
            sp, cp, st, ct = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
            j_theta = -(r0 @ np.array([sp, cp, 0.0]))  # −R0 Rz(−φ) e_y
            tangent = r0 @ np.array([-st * cp, st * sp, ct])  # R0 Rz(−φ) Ry(−θ) e_z
            mu = lam_si[rows["angles"]]
            a = [j_phi, j_theta]
            rhs = [-mu[0], -mu[1]]
            if len(mu) == 3:
                a.append(-tangent)
                rhs.append(-mu[2])
            else:
                a.append(tangent)
                rhs.append(0.0)
            a = np.array(a)
            torque = _solve_unit_rows(a, rhs)
            if torque is None and grip.s in (0.0, self.problem.string.length):
                # Euler pole (θ = 0 or π): φ and ψ rotate about the same axis, so the multipliers cannot
                # give the torque; use the internal moment the clamp balances instead
                torque = self._end_moment(z, grip.s)
            elif torque is None:
                torque = np.linalg.lstsq(a, np.array(rhs), rcond=None)[0]
        return GripWrench(force=force, torque=torque)

    def _end_moment(self, z: np.ndarray, s_end: float) -> np.ndarray:
        """Torque [N·m] a clamp at an end exerts: −M(0) at s = 0, +M(L) at s = L, where
        M = Q diag(Rf, Rf, Rt) ω is the internal moment and ω = axial(Qᵀ Q') the Darboux vector
        (Q' by a second-order one-sided difference; Q(s) is smooth even where the Euler angles are not)."""
        length = self.problem.string.length
        h = 1e-4 * length
        sign = 1.0 if s_end > 0 else -1.0
        s = np.array([s_end, s_end - sign * h, s_end - 2 * sign * h])
        q = self.frames(z, s)
        dq = sign * (3 * q[0] - 4 * q[1] + q[2]) / (2 * h)
        skew = q[0].T @ dq
        omega = 0.5 * np.array([skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1]])
        st = self.problem.string
        rt = float(st.twist_stiffness(np.array([s_end]))[0]) if self.model.layout.twist else 0.0
        rf = float(st.bend_stiffness(np.array([s_end]))[0])
        moment = q[0] @ (np.array([rf, rf, rt]) * omega)
        return sign * moment

    def _min_reduced_eigenvalue(self, state: _State) -> float | None:
        nlp = self.nlp
        active = np.zeros(0, dtype=bool)
        if nlp.lbg.size:
            g = state.g if state.g is not None else np.asarray(nlp.g_fn(state.z, state.p)).ravel()
            active = nlp.equality | (np.abs(state.lam_g) > 1e-9) | (g > nlp.ubg - 1e-9)
        if state.hessian is None:
            gradient, _, state.jacobian, state.hessian, state.energies = self._derivatives(state.z, state.p, state.lam_g,
                                                                                          active)
            state.gradient = gradient.ravel()
        h = state.hessian
        jac = state.jacobian[active]
        basis = _null_space(jac) if jac.size else np.eye(h.shape[0])
        if basis.shape[1] == 0:
            return None
        value, vector = _lowest_eigenpair(basis.T @ h @ basis)
        state.unstable_direction = basis @ vector if value < 0 else None
        return value


def with_checked_poses(problem: Problem, poses: dict | None) -> Problem:
    """``problem`` with new grip poses (GripPose or (position, quaternion) per grip name), validated:
    unknown names, NaN and bad quaternions raise ValueError naming the grip."""
    if not poses:
        return problem
    names = {g.name for g in problem.grips}
    checked = {}
    for name, pose in poses.items():
        if name not in names:
            raise ValueError(f"grip {name!r}: unknown (configured grips: {sorted(names)})")
        pos, quat = (pose.position, pose.orientation) if isinstance(pose, GripPose) else pose
        checked[name] = GripPose.checked(pos, quat, f"grips.{name}")
    return problem.with_grip_poses(checked)


def _solve_unit_rows(a: np.ndarray, rhs: list[float]) -> np.ndarray | None:
    """x with a x = rhs for a 3×3 ``a`` of unit rows by Cramer's rule, x = Σ_k rhs_k (a_{k+1} × a_{k+2}) / det;
    None when |det| ≤ 1e-8 (unit rows: nearly dependent).  Plain floats: numpy's cross and solve cost
    tens of µs each on 3-vectors."""
    (a0, a1, a2), (b0, b1, b2) = a.tolist(), rhs

    def cross(u, v):
        return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])

    c0, c1, c2 = cross(a1, a2), cross(a2, a0), cross(a0, a1)
    det = a0[0] * c0[0] + a0[1] * c0[1] + a0[2] * c0[2]
    if abs(det) <= 1e-8:
        return None
    return np.array([(b0 * c0[k] + b1 * c1[k] + b2 * c2[k]) / det for k in range(3)])


def _lowest_eigenpair(a: np.ndarray) -> tuple[float, np.ndarray]:
    """Smallest eigenvalue of the symmetric matrix ``a`` and its unit eigenvector (LAPACK syevr for that
    one pair: a third of the time of a full eigendecomposition at the sizes here)."""
    w, v, _, _, info = _syevr(a, compute_v=1, range="I", il=1, iu=1)
    if info != 0:
        values, vectors = np.linalg.eigh(a)
        return float(values[0]), vectors[:, 0]
    return float(w[0]), v[:, 0]


def _null_space(a: np.ndarray) -> np.ndarray:
    """Orthonormal basis of {v : a v = 0} from a column-pivoted QR of aᵀ (LAPACK geqp3, rank-revealing):
    rank = number of |R_kk| above max(a.shape)·eps·|R_00|, the tolerance scipy.linalg.null_space puts on
    singular values.  Half the time of an SVD at the sizes here (12 × 39: 32 µs against 54 µs)."""
    m, n = a.shape
    qr, _, tau, _, info = _geqp3(np.array(a.T, order="F"))
    if info != 0:
        _, sv, vh = np.linalg.svd(a, full_matrices=True)
        rank = int(np.sum(sv > max(a.shape) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)))
        return vh[rank:].T.conj()
    k = min(m, n)
    d = np.abs(np.diagonal(qr)[:k])
    rank = int(np.sum(d > max(m, n) * np.finfo(float).eps * (d[0] if k else 0.0)))
    q_in = np.zeros((n, n), order="F")
    q_in[:, :k] = qr[:, :k]
    q, _, info = _orgqr(q_in, np.concatenate([tau[:k], np.zeros(n - k)]))
    return q[:, rank:]


def is_stable(min_eigenvalue: float, hessian: np.ndarray) -> bool:
    """The stability verdict: a neutral mode (e.g. rotation about the chord without gravity) shows as
    ±1e-8·max|H|, so only eigenvalues below that count as unstable."""
    return bool(min_eigenvalue > -1e-8 * max(1.0, float(np.abs(hessian).max())))


def _inverse_j0(ratio: float) -> float:
    """α in [0, 2.4048] with J0(α) = ratio (chord/length of the guess β = −α sin 2πu)."""
    lo, hi = 0.0, 2.404825557695773
    if ratio >= 1.0:
        return 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if j0(mid) > ratio:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
