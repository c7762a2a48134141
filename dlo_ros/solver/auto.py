"""Model no more than a scene needs: ``solver.model: auto``.

AutoShapeSolver picks the smallest model for the scene, runs a ShapeSolver on it, and checks the
choice a posteriori against ``error_tolerance`` (δ, default 1e-3·L), escalating on its own when a check
fails.  Reductions and their checks:

* planar — grips, held tangents, gravity, forces, relative offsets and obstacles in one plane, moments
  along its normal, and the clamps impose no twist about the tangent: solve for φ alone.  Exact by
  symmetry *if* the planar equilibrium is stable in 3D: checked by the smallest eigenvalue of the full
  model's reduced Hessian at the embedded planar shape (a twist-free strip under compression leaves its
  plane); unstable → full model.
* twist — ψ is an unknown only when two clamps and Rt > 0 can hold it (otherwise ω ≡ 0 exactly).
* stretch — inextensible first; the elongation bound max|F_grip|·L / min Re > δ/2 → extensible model.
* gravity — dropped when D_max L⁴ / (8 Rf_min) (a cantilever's tip deflection, the largest a string
  held at ≥ 1 point sags under its weight at small deflection) is below δ/10.
* obstacles — an obstacle is in the NLP only if the string can reach it: within max(s_g, L − s_g) + L/4
  of every grip g (the L/4 margin adds it a move before it can touch).  A move that brings a new one
  within that range rebuilds the NLP with it, keeping the warm start.
* order — the lowest of 8, 12, 16, 24, 32 whose centreline moves by less than δ/2 when the order is
  raised to the next one (the a-posteriori estimate, reported as estimated_error_m), re-checked every
  ``recheck_every`` updates with a warm shadow solver; over δ/2 → next order.  At the highest order the
  last estimate stays (with "tolerance not met" in reasons).  Known limit: with a neutral mode (no
  gravity, clamps along one axis) the shadow can drift along it and inflate the estimate.

Switching models maps the previous solution into the new one (ShapeSolver.adopt_warm_start), so a
stream keeps its warm start.  Every change is kept in ``changes`` (time, reason) and reported in
ShapeResult.model.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..model.obstacles import Obstacle
from ..model.problem import Problem
from ..model.profile import Profile
from ..model.rotations import TANGENT_X, euler_from_frame, quat_to_matrix
from .nlp import choose_reference_frame, planarity_violation, twist_is_held
from .options import SolverOptions
from .result import ShapeResult
from .shape_solver import ShapeSolver, is_stable, with_checked_poses

ORDERS = (8, 12, 16, 24, 32)


@dataclass
class ModelChoice:
    """The reduced model in use and why."""

    planar: bool
    twist: bool
    stretch: bool
    gravity: bool
    order: int
    obstacles: tuple[int, ...]  # indices into the scene's obstacles that are in the NLP
    estimated_error_m: float = float("nan")
    reasons: list[str] = field(default_factory=list)

    def key(self) -> tuple:
        return (self.planar, self.stretch, self.gravity, self.order, self.obstacles)


def obstacle_distance(ob: Obstacle, x: np.ndarray) -> float:
    """A lower bound of the distance [m] from x to the obstacle (≤ 0 inside)."""
    if ob.type == "box":  # the solver's box is inscribed in the box; bound with the circumscribed sphere
        return float(np.linalg.norm(x - ob.params[0:3]) - np.linalg.norm(ob.params[12:15]))
    return -ob.h(np.asarray(x, dtype=float))


def reachable_obstacles(problem: Problem, margin: float) -> tuple[int, ...]:
    L, r = problem.string.length, problem.string.radius
    keep = []
    for i, ob in enumerate(problem.obstacles):
        if all(obstacle_distance(ob, g.pose.position) - r <= max(g.s, L - g.s) + margin for g in problem.grips):
            keep.append(i)
    return tuple(keep)


def imposes_twist(problem: Problem, r0: np.ndarray) -> bool:
    """Do the clamps' orientations differ by a rotation about the tangent (ψ targets not all equal)?"""
    if problem.string.twist_stiffness.is_zero:
        return False
    psis = [euler_from_frame(r0, quat_to_matrix(g.pose.orientation) @ TANGENT_X.T)[2] for g in problem.grips if g.mode == "clamp"]
    return any(abs(np.angle(np.exp(1j * (p - psis[0])))) > 1e-9 for p in psis[1:])


class AutoShapeSolver:
    """The ShapeSolver interface (solve, reset, set_problem, problem, options) with model selection."""

    def __init__(self, problem: Problem, options: SolverOptions | None = None, compile: str = "background"):
        options = options or SolverOptions()
        if options.model != "auto":
            raise ValueError("AutoShapeSolver needs solver.model 'auto'")
        problem.validate()
        options.validate()
        self.options = options
        self.compile = compile
        self.problem = problem
        self.tolerance = options.error_tolerance or 1e-3 * problem.string.length
        self.changes: list[tuple[float, str]] = []
        self._lock = threading.RLock()
        self._updates = 0
        self._shadow: ShapeSolver | None = None
        self._checker: ShapeSolver | None = None
        self.choice = self._initial_choice(problem)
        self.inner = self._make_inner(self.choice)

    # ---- choosing ----------------------------------------------------------------------------------
    def _initial_choice(self, problem: Problem) -> ModelChoice:
        L, tol = problem.string.length, self.tolerance
        reasons = []
        planar = False
        if self.options.frame == "auto":
            r0 = choose_reference_frame(problem, "auto")
            why = planarity_violation(problem, r0[:, 2]) or ("the clamps impose twist" if imposes_twist(problem, r0) else "")
            planar = not why
            reasons.append("planar: scene lies in one plane" if planar else f"3D: {why}")
        sag = problem.string.weight_per_length.maximum * L**4 / (8 * problem.string.bend_stiffness.minimum)
        gravity = sag >= tol / 10
        reasons.append(f"gravity {'kept' if gravity else 'dropped'}: sag bound {sag:.3g} m vs {tol / 10:.3g} m")
        obstacles = reachable_obstacles(problem, L / 4)
        if len(obstacles) < len(problem.obstacles):
            reasons.append(f"{len(problem.obstacles) - len(obstacles)} obstacle(s) out of reach")
        order = self.options.order if self.options.order in ORDERS else ORDERS[0]
        return ModelChoice(planar, False, False, gravity, ORDERS[0], obstacles, reasons=reasons)

    def _reduced(self, choice: ModelChoice, problem: Problem) -> tuple[Problem, SolverOptions]:
        st = problem.string
        if not choice.gravity:
            st = replace(st, weight_per_length=Profile.constant(0.0))
        if not choice.stretch:
            st = replace(st, stretch_stiffness=None)
        reduced = replace(problem, string=st, obstacles=tuple(problem.obstacles[i] for i in choice.obstacles))
        opts = replace(self.options, model="planar" if choice.planar else "full", order=choice.order,
                       quadrature_nodes=max(self.options.quadrature_nodes, 2 * choice.order + 8))
        return reduced, opts

    def _make_inner(self, choice: ModelChoice, previous: ShapeSolver | None = None, helper: bool = False) -> ShapeSolver:
        """A ShapeSolver of ``choice``; helpers (order shadow, 3D checker) never start a compile."""
        reduced, opts = self._reduced(choice, self.problem)
        mode = ("off" if self.compile == "off" else "cached") if helper else self.compile
        inner = ShapeSolver(reduced, opts, compile=mode)
        choice.twist = inner.model.layout.twist
        if previous is not None:
            inner.adopt_warm_start(previous)
        return inner

    def _switch(self, choice: ModelChoice, reason: str) -> None:
        """Change model, mapping the warm start; the estimate carries over until re-measured."""
        self.changes.append((time.time(), reason))
        self.choice = choice
        self.inner = self._make_inner(choice, self.inner)
        self._shadow = self._checker = None

    # ---- public API ---------------------------------------------------------------------------------
    @property
    def has_warm_start(self) -> bool:
        return self.inner.has_warm_start

    @property
    def kkt_compiled(self) -> bool:
        return self.inner.kkt_compiled

    def reset(self) -> None:
        with self._lock:
            self.inner.reset()
            self._shadow = None

    def set_problem(self, problem: Problem) -> None:
        problem.validate()
        with self._lock:
            self.problem = problem
            self.tolerance = self.options.error_tolerance or 1e-3 * problem.string.length
            choice = self._initial_choice(problem)
            choice.order, choice.stretch = self.choice.order, self.choice.stretch
            if choice.key() != self.choice.key():
                self._switch(choice, "scene changed")
            else:
                self.inner.set_problem(self._reduced(self.choice, problem)[0])

    def solve(self, poses: dict | None = None, *, warm: bool = True, commit: bool = True) -> ShapeResult:
        with self._lock:
            t0 = time.perf_counter()
            try:
                problem = self._with_poses(poses)
            except (ValueError, KeyError) as exc:
                return self._finish(ShapeResult(status="invalid", message=str(exc).strip("'\"")), t0, [])
            notes: list[str] = []
            if self.choice.planar:  # new targets may leave the plane (or twist a clamp): 3D before solving
                why = planarity_violation(problem, self.inner.nlp.r0[:, 2], tolerance=1e-7) or (
                    "the clamps impose twist" if imposes_twist(problem, self.inner.nlp.r0) else "")
                if why:
                    if not commit:  # a query must not change the streaming model: answer with a full model
                        full = ShapeSolver(self._reduced(replace(self.choice, planar=False), problem)[0],
                                           self._reduced(replace(self.choice, planar=False), problem)[1], compile="cached")
                        full.adopt_warm_start(self.inner)
                        return self._finish(full.solve({g.name: g.pose for g in problem.grips}, commit=False), t0, [])
                    self.problem = problem
                    self._switch(replace(self.choice, planar=False), f"targets left the plane ({why}): full model")
                    notes.append(self.changes[-1][1])
            reach = reachable_obstacles(problem, problem.string.length / 4)
            if set(reach) - set(self.choice.obstacles) and commit:
                new = replace(self.choice, obstacles=tuple(sorted(set(reach) | set(self.choice.obstacles))))
                self._switch(new, f"obstacle(s) {sorted(set(reach) - set(self.choice.obstacles))} came within reach")
                notes.append(self.changes[-1][1])
            reduced = self._reduced(self.choice, problem)[0]
            inner_poses = {g.name: g.pose for g in reduced.grips}
            result = self.inner.solve(inner_poses, warm=warm, commit=commit)
            if not result.ok:
                return self._finish(result, t0, notes)
            if not commit:
                return self._finish(result, t0, notes)
            self.problem = problem  # the checks build models of the current targets
            self._updates += 1
            first = not np.isfinite(self.choice.estimated_error_m)
            if first or self._updates % self.options.recheck_every == 0:
                result = self._check(problem, result, inner_poses, notes)
            return self._finish(result, t0, notes)

    # ---- checks -------------------------------------------------------------------------------------
    def _check(self, problem: Problem, result: ShapeResult, poses: dict, notes: list[str]) -> ShapeResult:
        """A-posteriori checks; escalate (and re-solve) while one fails."""
        tol = self.tolerance
        for _ in range(8):
            reason = ""
            if self.choice.planar:
                eig = self._planar_3d_eigenvalue(problem)  # None when stable (or neutral)
                if eig is not None:
                    reason = f"planar shape unstable in 3D (eigenvalue {eig:.3g}): full model"
                    new = replace(self.choice, planar=False)
            if not reason and problem.string.stretch_stiffness is not None and not self.choice.stretch:
                force = max(np.linalg.norm(w.force) for w in result.grips.values())
                elongation = force * problem.string.length / problem.string.stretch_stiffness.minimum
                if elongation > tol / 2:
                    reason = f"elongation bound {elongation:.3g} m > {tol / 2:.3g} m: extensible model"
                    new = replace(self.choice, stretch=True)
            if not reason:
                if self.choice.order >= ORDERS[-1]:  # nothing higher to compare with: keep the last estimate
                    if self.choice.estimated_error_m > tol / 2 and not any("not met" in r for r in self.choice.reasons):
                        self.choice.reasons.append(f"tolerance not met: highest order {ORDERS[-1]} reached")
                    return result
                error = self._order_error(poses, result)
                self.choice.estimated_error_m = error
                if error > tol / 2:
                    nxt = ORDERS[ORDERS.index(self.choice.order) + 1]
                    reason = f"order {self.choice.order} error estimate {error:.3g} m > {tol / 2:.3g} m: order {nxt}"
                    new = replace(self.choice, order=nxt)
            if not reason:
                return result
            self._switch(new, reason)
            notes.append(reason)
            result = self.inner.solve(poses)
            if not result.ok:
                return result
        return result

    def _order_error(self, poses: dict, result: ShapeResult) -> float:
        """max |x_n(s) − x_{n+}(s)| over the output points: the change when the order is raised."""
        higher = replace(self.choice, order=ORDERS[ORDERS.index(self.choice.order) + 1])
        if self._shadow is None or self._shadow.options.order != higher.order:
            self._shadow = self._make_inner(higher, self.inner, helper=True)
        else:  # start from the current shape, not the shadow's own (older) one: same branch
            self._shadow.set_problem(self._reduced(higher, self.problem)[0])
            self._shadow.adopt_warm_start(self.inner)
        shadow = self._shadow.solve(poses)
        if not shadow.ok:
            self._shadow = None
            return float("inf")
        return float(np.max(np.linalg.norm(shadow.points - result.points, axis=1)))

    def _planar_3d_eigenvalue(self, problem: Problem) -> float | None:
        """Smallest reduced-Hessian eigenvalue of the full 3D model at the embedded planar solution.

        The 3D checker is built once and refreshed with the current targets and shape."""
        choice = replace(self.choice, planar=False)
        full = self._checker
        if full is None or full.options.order != choice.order or len(full.problem.obstacles) != len(choice.obstacles):
            full = self._checker = self._make_inner(choice, self.inner, helper=True)
        else:
            full.set_problem(self._reduced(choice, self.problem)[0])
            full.adopt_warm_start(self.inner)
        state = full._state
        if state is None:
            return None
        eig = full._min_reduced_eigenvalue(state)
        return None if eig is None or is_stable(eig, state.hessian) else eig

    # ---- plumbing -----------------------------------------------------------------------------------
    def _with_poses(self, poses: dict | None) -> Problem:
        return with_checked_poses(self.problem, poses)

    def model_summary(self) -> dict:
        c = self.choice
        return {
            "planar": c.planar, "twist": c.twist, "stretch": c.stretch, "gravity": c.gravity, "order": c.order,
            "obstacles": len(c.obstacles), "estimated_error_m": None if not np.isfinite(c.estimated_error_m) else c.estimated_error_m,
            "tolerance_m": self.tolerance, "variables": self.inner.model.layout.size, "auto": True,
            "reasons": list(c.reasons), "changes": [r for _, r in self.changes],
        }

    def _finish(self, result: ShapeResult, t0: float, notes: list[str]) -> ShapeResult:
        result.model = self.model_summary()
        result.model["changed"] = notes
        result.solve_time_ms = (time.perf_counter() - t0) * 1e3
        if result.ok and result.contact_forces and len(self.choice.obstacles) != len(self.problem.obstacles):
            result.contact_forces = {self.choice.obstacles[i]: f for i, f in result.contact_forces.items()}
        return result


def make_solver(problem: Problem, options: SolverOptions | None = None, compile: str = "background"):
    """AutoShapeSolver for solver.model 'auto' (the default), else a ShapeSolver of that model."""
    options = options or SolverOptions()
    if options.model == "auto":
        return AutoShapeSolver(problem, options, compile=compile)
    return ShapeSolver(problem, options, compile=compile)
