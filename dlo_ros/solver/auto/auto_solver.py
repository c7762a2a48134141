"""Model no more than a scene needs: ``solver.model: auto``.

AutoShapeSolver picks the smallest model for the scene, runs a ShapeSolver on it, and checks the
choice a posteriori against ``error_tolerance`` (δ, default 1e-3·L), escalating on its own when a
check fails.  Reductions and their checks:

* planar — grips, held tangents, gravity, forces, relative offsets and obstacles in one plane,
  moments
  along its normal, and the clamps impose no twist about the tangent: solve for φ alone.  Exact by
  symmetry *if* the planar equilibrium is stable in 3D: checked by the smallest eigenvalue of the
  full model's reduced Hessian at the embedded planar shape (a twist-free strip under compression
  leaves its plane); unstable → full model.
* twist — ψ is an unknown only when two clamps and Rt > 0 can hold it (otherwise ω ≡ 0 exactly).
* stretch — inextensible first; the elongation bound max|F_grip|·L / min Re > δ/2 → extensible model.
  Grips farther apart than the inextensible string between them reaches (an extensible scene)
  choose the extensible model at once, or switch to it when a stream carries them there.
* gravity — dropped when D_max L⁴ / (8 Rf_min) (a cantilever's tip deflection, the largest a string
  held at ≥ 1 point sags under its weight at small deflection) is below δ/10.
* obstacles — an obstacle is in the NLP only if the string can reach it: within max(s_g, L − s_g) +
  L/4
  of every grip g (the L/4 margin adds it a move before it can touch).  A move that brings a new
  one within that range rebuilds the NLP with it, keeping the warm start.
* order — starts at 12; the lowest of 8, 12, 16, 24, 32 whose centreline moves by less than δ/2
  when
  the order is raised to the next one (the a-posteriori estimate, reported as estimated_error_m),
  re-checked every ``recheck_every`` updates with a warm shadow solver; over δ/2 → next order.
  Once per model the next lower order is tried: if it is within δ/4 of the current one, it is used.
  At the highest order the last estimate stays (with "tolerance not met" in reasons).  Known limit:
  with a neutral mode (no gravity, clamps along one axis) the shadow can drift along it and inflate
  the estimate.
* reference frame (3D with ``rotation: euler`` only) — when a tangent of the checked shape comes
  within
  POLE_MIN_DEG of the Euler angles' pole n = R0 e_z, the same model with n turned to the direction
  farthest from every tangent (near the pole the basis order stops converging).  The default 3D
  model (``rotation: director``) has no pole and never turns.
* equilibrium residual — every check also takes the checked result's strong-form residual
  (ShapeResult.equilibrium_residual_m) as an error estimate: the order's estimate is the larger of
  the shadow's centreline change and the residual, so a shape that is not an equilibrium raises the
  order.
* obstacle samples — obstacles are enforced at ``obstacle_samples`` points (41), an error the order
  shadows cannot see (they share the samples).  Two parts, the larger counts: between the samples
  the string can cut into an obstacle (a chord of spacing h cuts a sphere of radius R by about
  h²/8R), measured over 8× as many points; and, while the shape touches an obstacle, the samples
  shadow: the same model with 2n − 1 samples solved from the checked shape, whose centreline
  change, doubled (the sampled contact converges to first order in h: a string lying over a sphere
  can slide along it with almost no change of energy, and each sample spacing leaves its own
  shallow well along that slide), estimates the error of the n-sample answer.  The sampling part is
  added to estimated_error_m; over δ/2 the samples go to 2n − 1 (81, 161, 321, 641: the old samples
  stay), the model the shadow already built and warmed.  At MAX_SAMPLES the last shadow's change
  (undoubled: the error of the finer model) stays the sampling estimate.
* self-contact — modelled only once a committed shape comes within reach of itself (two samples the
  exclusion arc apart closer than the candidate reach D + max(4h, 0.03 L), solver/contact/self_contact.py):
  then the 3D director model with ``self_contact_pairs`` slots (the option's value, or
  AUTO_SELF_CONTACT_PAIRS when it is 0) replaces the current one and the update is solved again on
  it, so no shape that passes through itself is published; it says so in ``reasons``
  ("self-contact: …").  Not with ``rotation: euler`` (self-contact needs the director model).  Once
  in, it stays.

Switching models maps the previous solution into the new one (ShapeSolver.adopt_warm_start), so a
stream keeps its warm start.  Every change is kept in ``changes`` (time, reason) and reported in
ShapeResult.model (``changed``: the changes made during that solve).

Checks run on a worker thread from a snapshot of the solve (``checks='background'``, the default:
the library and the node) or synchronously inside ``solve`` (``checks='sync'``: the CLI's one-shot
answers), so that a stream never waits for a build: the worker builds the order shadow and the 3D
checker into a pool of models, and a verdict to escalate is applied at the next ``solve`` by
switching to the pooled model the check already built. The 3D model of a planar choice is built
ahead (at start, and again after any change), so targets leaving the plane switch without a build;
an obstacle within L/2 of reach is built ahead, and enters the NLP at L/4.  Only the basis order
goes down during a run (tried once per model); a 3D model never returns to planar, and an obstacle,
once in, stays (a scene change re-chooses).
"""

from __future__ import annotations

import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field, replace

import numpy as np

from ...model.obstacles import Obstacle
from ...model.problem import Problem
from ...model.profile import Profile
from ...model.rotations import (
    TANGENT_X,
    euler_from_frame,
    farthest_pole,
    frame_with_pole,
    pole_angle_deg,
    quat_to_matrix,
)
from ..build.nlp import choose_reference_frame, has_point_moments, planarity_violation
from ..options import SolverOptions
from ..protocol import Solver
from .query_verify import QueryBudget, verified_answer
from ..update import recovery as RC
from ..contact import self_contact as SC
from ..results.result import ShapeResult
from ..shape_solver import IPOPT_LOCK, ShapeSolver, with_checked_poses
from ..results.summary import ModelSummary

ORDERS = (8, 12, 16, 24, 32)
POLE_MIN_DEG = (
    40.0  # a 3D model turns its Euler-angle pole away when a tangent comes closer (degrees)
)
#: With background checks the stream thread waits for the GIL whenever the worker runs Python, up
# to the : interpreter's switch interval (5 ms by default).  AutoShapeSolver lowers it to this for
# the process : (never raises it), which bounds that wait (bench/perf/auto_vs_full.py measures the
# stream with checks).
SWITCH_INTERVAL_S = 1e-4
#: obstacle samples auto may go up to (each step 2n − 1: the old samples stay, one between each
# pair)
MAX_SAMPLES = 641
#: the penetration check looks at this many times the samples (between them the sampled constraints
# let : the string cut into an obstacle: a chord of spacing h cuts a sphere of radius R by about
# h²/8R)
PENETRATION_OVERSAMPLING = 8
#: self-contact slots of the model auto switches to when a shape comes within reach of itself
#: (``solver.self_contact_pairs`` when set)
AUTO_SELF_CONTACT_PAIRS = 16
START_ORDER = (
    12  # the first answer is within 1e-3·L for typical scenes; checks go up, or down to 8
)


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
    frame: tuple | None = (
        None  # R0 (row-major 9) of a 3D model turned away from its Euler-angle pole
    )
    samples: int = 41  # obstacle_samples: points along s where the obstacles are enforced
    self_contact: bool = False  # self-contact rows in the NLP (3D director models only)
    order_error_m: float = float(
        "nan"
    )  # the basis-order part of estimated_error_m (the rest: sampling)
    #: the samples shadow's estimate of this model's sampling error (nan: not measured)
    sampling_error_m: float = float("nan")

    def key(self) -> tuple:
        return (
            self.planar,
            self.stretch,
            self.gravity,
            self.order,
            self.obstacles,
            self.frame,
            self.samples,
            self.self_contact,
        )

    def reference_frame(self) -> np.ndarray | None:
        return None if self.frame is None else np.array(self.frame, dtype=float).reshape(3, 3)


def obstacle_distance(ob: Obstacle, x: np.ndarray) -> float:
    """A lower bound of the distance [m] from x to the obstacle (≤ 0 inside)."""
    p = np.asarray(ob.params, dtype=float)
    return ob.obstacle_type.distance_bound(np.asarray(x, dtype=float), p)


def touches_obstacle(result: ShapeResult) -> bool:
    """Does the result press on an obstacle?  A contact force above 1e-6 of the largest grip force
    (an interior-point answer leaves ~1e-10 N of barrier multipliers on samples that do not
    touch).
    """
    scale = max((float(np.linalg.norm(w.force)) for w in result.grips.values()), default=0.0)
    return any(
        float(np.linalg.norm(f)) > 1e-6 * max(scale, 1e-3) for f in result.contact_forces.values()
    )


def reachable_obstacles(problem: Problem, margin: float) -> tuple[int, ...]:
    L, r = problem.string.length, problem.string.radius
    keep = []
    for i, ob in enumerate(problem.obstacles):
        if all(
            obstacle_distance(ob, g.pose.position) - r <= max(g.s, L - g.s) + margin
            for g in problem.grips
        ):
            keep.append(i)
    return tuple(keep)


def clear_of_plane(ob: Obstacle, origin: np.ndarray, normal: np.ndarray, margin: float) -> bool:
    """Is the obstacle more than ``margin`` from the plane through ``origin`` with unit ``normal``?
    A string lying in the plane cannot touch it, so the planar equilibrium is an equilibrium of the
    3D problem with that obstacle inactive (the planar model leaves it out; its 3D stability is
    checked with it).
    """
    p = np.asarray(ob.params, dtype=float)
    return bool(ob.obstacle_type.clear_of_plane(p, origin, normal, margin))


def imposes_twist(problem: Problem, r0: np.ndarray) -> bool:
    """Do the clamps' orientations differ by a rotation about the tangent (ψ targets not all
    equal)?
    """
    if problem.string.twist_stiffness.is_zero:
        return False
    psis = [
        euler_from_frame(r0, quat_to_matrix(g.pose.orientation) @ TANGENT_X.T)[2]
        for g in problem.grips
        if g.mode == "clamp"
    ]
    return any(abs(np.angle(np.exp(1j * (p - psis[0])))) > 1e-9 for p in psis[1:])


@dataclass
class _Snapshot:
    """What a check needs of one committed solve (taken on the streaming thread)."""

    inner: ShapeSolver
    state: object
    choice: ModelChoice
    problem: Problem
    poses: dict
    points: np.ndarray
    max_grip_force: float
    generation: int = 0
    residual_m: float = 0.0  # the strong-form equilibrium residual of the checked result (solver/results/residual.py)
    touching: bool = False  # the checked result presses on an obstacle
    update: int = 0  # AutoShapeSolver's streamed-update count when it was taken


@dataclass
class _Verdict:
    """A check's outcome: escalate to ``choice`` (with ``reason``), or keep with ``estimate``."""

    snapshot: _Snapshot
    choice: ModelChoice | None = None
    reason: str = ""
    estimate: float = float("nan")
    order_error: float = float("nan")
    sampling_error: float = float("nan")


class AutoShapeSolver:
    """The Solver protocol (solver/protocol.py) with model selection.

    checks: 'sync' runs the a-posteriori checks inside ``solve`` (a one-shot solve is checked
    before it is returned: the CLI); 'background' runs them on a worker thread from a snapshot of
    the solve, so a stream never waits for them (the node): their verdict is applied at the next
    ``solve`` — an escalation switches to the model the check has already built and warmed, so the
    switch costs no build.  'background' lowers the process's ``sys.setswitchinterval`` to
    SWITCH_INTERVAL_S, so that the worker's Python holds the stream thread up for at most that
    long.  Until the first check of a model has finished, ``model.checked`` is false and
    ``estimated_error_m`` is None.
    """

    POOL_SIZE = 6

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions | None = None,
        compile: str = "background",
        checks: str = "background",
    ):
        options = options or SolverOptions()
        if options.model != "auto":
            raise ValueError("AutoShapeSolver needs solver.model 'auto'")
        if checks not in ("sync", "background"):
            raise ValueError(f"checks: must be 'sync' or 'background', got {checks!r}")
        problem.validate()
        options.validate()
        self.options = options
        self.compile = compile
        self.checks = checks
        self.problem = problem
        self.tolerance = options.error_tolerance or 1e-3 * problem.string.length
        self.changes: list[tuple[float, str]] = []
        self._lock = threading.RLock()
        self._pool: dict[
            tuple, ShapeSolver
        ] = {}  # built models by (tag,) + ModelChoice.key(), newest last
        self._pool_lock = threading.Lock()  # guards the dict only (builds run outside it)
        self._job_keys: frozenset = frozenset()  # pool keys the running job may use
        self._worker = (
            ThreadPoolExecutor(1, thread_name_prefix="dlo-auto-check")
            if checks == "background"
            else None
        )
        if self._worker is not None and sys.getswitchinterval() > SWITCH_INTERVAL_S:
            sys.setswitchinterval(SWITCH_INTERVAL_S)  # the stream gets the GIL back within 0.1 ms
        self._job: Future | None = None
        self._since_check = 0
        self._unchecked = True
        self._updates = 0  # streamed updates solved so far
        self._checked_update = 0  # the update whose shape the last kept check described
        self._lower_tried: set[tuple] = set()  # model keys already tried as a lower order
        self._generation = (
            0  # bumped by every switch, reset and scene change: older verdicts are stale
        )
        # pool key of the 3D model a planar stream switches to (kept built)
        self._full_key: tuple = ()
        self.choice = self._initial_choice(problem)
        self.inner = self._solver_for(self.choice, problem, stream=True)
        if (
            self._worker is not None
        ):  # build ahead: the 3D model a stream leaving the plane switches to, first,
            # then the order shadows the first check needs
            i = ORDERS.index(self.choice.order)
            ahead = [self._full_choice(self.choice, problem)] if self.choice.planar else []
            self._full_key = ("",) + ahead[0].key() if ahead else ()
            ahead += [
                replace(self.choice, order=o)
                for o in ORDERS[i + 1 : i + 2] + ORDERS[max(i - 1, 0) : i]
            ]
            self._submit(self._prebuild, {("",) + c.key() for c in ahead}, ahead, problem)
            # the constructor returns once the 3D model is built, so that a stream leaving the
            # plane at its first update never waits for the build
            job = self._job
            while (
                self._full_key
                and job is not None
                and not job.done()
                and self._full_key in self._job_keys
            ):
                time.sleep(0.002)

    # ---- choosing ----------------------------------------------------------------------------------
    def _initial_choice(self, problem: Problem) -> ModelChoice:
        L, tol = problem.string.length, self.tolerance
        reasons = []
        obstacles = reachable_obstacles(problem, L / 4)
        if len(obstacles) < len(problem.obstacles):
            reasons.append(f"{len(problem.obstacles) - len(obstacles)} obstacle(s) out of reach")
        planar = False
        if self.options.frame == "auto":
            r0 = choose_reference_frame(problem, "auto")
            in_plane = self._in_plane_obstacles(problem, obstacles, r0)
            why = self._not_planar(problem, in_plane, r0)
            planar = not why
            reasons.append("planar: scene lies in one plane" if planar else f"3D: {why}")
            if planar and len(in_plane) < len(obstacles):
                reasons.append(f"{len(obstacles) - len(in_plane)} obstacle(s) clear of the plane")
                obstacles = in_plane
        sag = (
            problem.string.weight_per_length.maximum
            * L**4
            / (8 * problem.string.bend_stiffness.minimum)
        )
        gravity = sag >= tol / 10
        reasons.append(
            f"gravity {'kept' if gravity else 'dropped'}: sag bound {sag:.3g} m vs {tol / 10:.3g} m"
        )
        stretch = bool(stretch_needed(problem))
        if stretch:
            reasons.append(stretch_needed(problem))
        return ModelChoice(
            planar,
            False,
            stretch,
            gravity,
            START_ORDER,
            obstacles,
            reasons=reasons,
            samples=self.options.obstacle_samples,
        )

    @staticmethod
    def _in_plane_obstacles(problem: Problem, obstacles, r0: np.ndarray) -> tuple[int, ...]:
        """The ``obstacles`` (indices) a string in the plane of ``r0`` could touch."""
        origin, margin = (
            problem.grips[0].pose.position,
            problem.string.radius + 1e-3 * problem.string.length,
        )
        return tuple(
            i
            for i in obstacles
            if not clear_of_plane(problem.obstacles[i], origin, r0[:, 2], margin)
        )

    def _full_choice(self, choice: ModelChoice, problem: Problem) -> ModelChoice:
        """The 3D model of ``choice``: every obstacle within reach is in it."""
        reach = set(reachable_obstacles(problem, problem.string.length / 4)) | set(
            choice.obstacles
        )
        return replace(
            choice, planar=False, obstacles=tuple(sorted(reach)), reasons=list(choice.reasons)
        )

    @staticmethod
    def _not_planar(
        problem: Problem, obstacles, r0: np.ndarray, tolerance: float | None = None
    ) -> str:
        """Why the scene (with only the ``obstacles`` indices in it) is not planar in the plane of
        reference frame ``r0`` (normal r0[:, 2]); '' if it is.
        """
        scene = replace(problem, obstacles=tuple(problem.obstacles[i] for i in sorted(obstacles)))
        kw = {} if tolerance is None else {"tolerance": tolerance}
        return planarity_violation(scene, r0[:, 2], **kw) or (
            "the clamps impose twist" if imposes_twist(scene, r0) else ""
        )

    def _reduced(self, choice: ModelChoice, problem: Problem) -> tuple[Problem, SolverOptions]:
        """``problem`` as ``choice`` models it (the options of that model too).  The reduced string
        and obstacle tuple are reused while the scene's are the same objects, so that a stream of
        new grip poses keeps the inner solver's cached parameters.
        """
        key = (choice.gravity, choice.stretch, choice.obstacles)
        hit = getattr(self, "_reduced_cache", None)
        if (
            hit is not None
            and hit[0] == key
            and hit[1] is problem.string
            and hit[2] is problem.obstacles
        ):
            st, obstacles = hit[3], hit[4]
        else:
            st = problem.string
            if not choice.gravity:
                st = replace(st, weight_per_length=Profile.constant(0.0))
            if not choice.stretch:
                st = replace(st, stretch_stiffness=None)
            obstacles = tuple(problem.obstacles[i] for i in choice.obstacles)
            self._reduced_cache = (key, problem.string, problem.obstacles, st, obstacles)
        reduced = replace(problem, string=st, obstacles=obstacles)
        model = (choice.planar, choice.order, choice.samples, choice.self_contact)
        known = getattr(self, "_reduced_options", {})
        opts = known.get(model)
        if (
            opts is None
        ):  # made once per model: a frozen dataclass's replace costs more than the lookup
            opts = self.options.with_model(
                "planar" if choice.planar else "full",
                order=choice.order,
                quadrature_nodes=max(self.options.quadrature_nodes, 2 * choice.order + 8),
                obstacle_samples=choice.samples,
                self_contact_pairs=(self.options.self_contact_pairs or AUTO_SELF_CONTACT_PAIRS)
                if choice.self_contact
                else 0,
            )
            self._reduced_options = {**known, model: opts}
        return reduced, opts

    def _solver_for(
        self,
        choice: ModelChoice,
        problem: Problem,
        *,
        stream: bool,
        source: ShapeSolver | None = None,
        state=None,
        tag: str = "",
    ) -> ShapeSolver:
        """The pooled ShapeSolver of ``choice`` set to ``problem`` (built if new), warm-started
        from ``source`` (its ``state`` snapshot if given).  Helpers (order shadow, 3D checker)
        never start a compile and create IPOPT lazily; a solver that streams compiles as
        ``compile`` says.  ``tag`` keeps a separate copy (the 3D checker, so that a switch to 3D
        never waits for a check).
        """
        reduced, opts = self._reduced(choice, problem)
        key = (tag,) + choice.key()
        with self._pool_lock:
            solver = self._pool.pop(key, None)
        if solver is None:
            solver = ShapeSolver(
                reduced,
                opts,
                compile=self.compile if stream else ("off" if self.compile == "off" else "cached"),
                lazy_ipopt=not stream,
                reference_frame=choice.reference_frame(),
            )
        else:
            solver.set_problem(reduced)
        evicted = []
        with self._pool_lock:
            self._pool[key] = solver
            keep = set(self._job_keys) | {key, self._full_key} | set(list(self._pool)[-2:])
            while len(self._pool) > self.POOL_SIZE:  # drop the least recently used that is idle
                old = next(
                    (
                        k
                        for k, s in self._pool.items()
                        if s is not getattr(self, "inner", None) and k not in keep
                    ),
                    None,
                )
                if old is None:
                    break
                evicted.append(self._pool.pop(old))
        with (
            IPOPT_LOCK
        ):  # freeing IPOPT/MUMPS instances must not overlap a solve in the other thread
            evicted.clear()
        if stream:
            solver.start_compile(self.compile)
        choice.twist = solver.model.layout.twist
        if source is not None and not solver.adopt_warm_start(source, state):
            solver.reset()  # nothing to map: never keep an older, unrelated warm start
        return solver

    def _compile_ahead(self, solver: ShapeSolver) -> None:
        """A model that a switch, the queries or a background check will use: compile it in the
        background, once the streaming model's own compile is done (the stream reaches full speed
        first), if the stream compiles at all.  Its libraries land in the cache, where the query
        workers find them.
        """
        if (
            self.compile not in ("background", "blocking")
            or solver.all_compiled
            or solver.compile_pending
        ):
            return
        streaming = self.inner.compile_thread

        def start() -> None:
            if streaming is not None:
                streaming.join()
            if (
                solver.compile_mode == "cached"
            ):  # not streaming meanwhile (a stream compiles by itself)
                solver.start_compile("background")
            solver.compile_pending = False

        solver.compile_pending = True
        threading.Thread(target=start, name="dlo-compile-ahead", daemon=True).start()

    def _submit(self, fn, keys: set, *args) -> None:
        """Run ``fn(*args)`` on the worker; ``keys``: the pooled models it may use meanwhile."""
        self._job_keys = frozenset(keys)
        self._job = self._worker.submit(fn, *args)

    def _pooled(self, choice: ModelChoice, tag: str = "") -> ShapeSolver | None:
        with self._pool_lock:
            return self._pool.get((tag,) + choice.key())

    def _wait_for_model(self, choice: ModelChoice) -> None:
        """Until the running background job is done, if it may be using (or building) the pooled
        model of ``choice``: one solver is never called from two threads at once.
        """
        job, key = self._job, ("",) + choice.key()
        while job is not None and not job.done() and key in self._job_keys:
            wait([job], timeout=0.005)

    def _switch(self, choice: ModelChoice, reason: str, start: tuple | None = None) -> None:
        """Stream on ``choice`` from now on, mapping the warm start; unchecked until its first
        check. Waits for a running background job only if that job may be using the model switched
        to. ``start``: (solver, its state or None, problem) to map instead of the streaming model's
        committed shape at ``self.problem`` (None: a cold start).
        """
        t0 = time.perf_counter()
        self._wait_for_model(choice)
        t1 = time.perf_counter()
        pooled = self._pooled(choice) is not None
        self.changes.append((time.time(), reason))
        del self.changes[:-50]  # the newest 50 (all are in the log and the recording)
        if choice.order > self.choice.order and choice.planar == self.choice.planar:
            self._lower_tried.add(
                replace(choice, order=self.choice.order).key()
            )  # just found too coarse
        source, state, problem = (self.inner, None, self.problem) if start is None else start
        self.inner = self._solver_for(choice, problem, stream=True, source=source, state=state)
        if start is not None and state is None:
            self.inner.reset()
        waited, built = t1 - t0, time.perf_counter() - t1
        if (
            waited > 0.05 or built > 0.2
        ):  # visible in the change's reason: the stream stalled this long
            self.changes[-1] = (
                self.changes[-1][0],
                f"{reason} [waited {waited:.2f} s for the worker's build, "
                f"{built:.2f} s to set up the "
                f"{'pooled' if pooled else 'missing, so built here,'} model]",
            )
        # the reasons say why this model: drop the planar one when leaving the plane, add this
        # change
        choice.reasons = [
            r for r in choice.reasons if choice.planar or not r.startswith("planar:")
        ] + [reason]
        self.choice = choice
        self._unchecked = True
        self._generation += 1

    # ---- public API ---------------------------------------------------------------------------------
    @property
    def has_warm_start(self) -> bool:
        return self.inner.has_warm_start

    @property
    def kkt_compiled(self) -> bool:
        return self.inner.kkt_compiled

    @property
    def checks_pending(self) -> bool:
        """A background job (a model check or a build ahead) is running, or its verdict has not
        been applied yet (a later solve applies it). Always False with ``checks="sync"``.
        """
        return self._job is not None

    def reset(self) -> None:
        """Forget every warm start (the streaming model's and the pooled ones'): the next solve is
        cold. A background verdict still pending is dropped (it describes a shape that is gone).
        """
        with self._lock:
            self._wait_for_check()
            self._job = None
            with self._pool_lock:
                pooled = list(self._pool.values())
            for solver in pooled + [self.inner]:
                solver.reset()
            self._unchecked = True
            self._generation += 1

    def close(self) -> None:
        """Stop the check worker (waits for a running check); later solves check inline
        ('sync').
        """
        with self._lock:
            if self._worker is not None:
                self._worker.shutdown(wait=True, cancel_futures=True)
                self._worker, self._job, self.checks = None, None, "sync"

    def query_many(self, targets, executor=None) -> list[ShapeResult]:
        """Answers to many independent queries in worker processes (see ShapeSolver.query_many);
        each worker runs its own auto solver of this scene, with inline checks.
        """
        from ..parallel.batch import query_many

        return query_many(self.problem, self.options, targets, executor)

    def set_problem(self, problem: Problem) -> None:
        problem.validate()
        with self._lock:
            self._wait_for_check()
            self._job = None  # its verdict is about the old scene
            self._generation += 1
            self.problem = problem
            self.tolerance = self.options.error_tolerance or 1e-3 * problem.string.length
            self._lower_tried.clear()
            choice = self._initial_choice(problem)
            choice.order, choice.stretch = self.choice.order, self.choice.stretch or choice.stretch
            if choice.key() != self.choice.key():
                self._switch(choice, "scene changed")
            else:
                self.inner.set_problem(self._reduced(self.choice, problem)[0])
                self._unchecked = True

    def solve(
        self,
        poses: dict | None = None,
        *,
        warm: bool = True,
        commit: bool = True,
        check_now: bool = False,
    ) -> ShapeResult:
        """Equilibrium with the given grip poses (missing grips keep their current target).

        check_now: run the a-posteriori checks on this (committed) result before returning it, even
        in background mode, escalating and re-solving while one fails — for a re-solve after a
        change of the scene's values, whose answer must not be published before it is checked.  A
        running background check is waited for first (its verdict is about an earlier solve and is
        dropped).
        """
        with self._lock:
            t0 = time.perf_counter()
            before_problem = self.problem
            try:
                problem = with_checked_poses(self.problem, poses)
            except (ValueError, KeyError) as exc:
                return self._finish(
                    ShapeResult(status="invalid", message=str(exc).strip("'\"")), t0, []
                )
            notes: list[str] = []
            if commit:
                self._apply_check(notes)
            L = problem.string.length
            reach = reachable_obstacles(problem, L / 4)
            if self.choice.planar:
                reach = self._in_plane_obstacles(problem, reach, self.inner.nlp.r0)
            entering = set(reach) - set(self.choice.obstacles)
            obstacles = tuple(sorted(entering | set(self.choice.obstacles)))
            why = (
                self._not_planar(problem, obstacles, self.inner.nlp.r0, tolerance=1e-7)
                if self.choice.planar
                else ""
            )
            stretch_why = "" if self.choice.stretch else stretch_needed(problem)
            if (
                why or entering or stretch_why
            ):  # out of the plane, an obstacle in reach, or beyond L: a richer model
                richer = (
                    self._full_choice(self.choice, problem)
                    if why
                    else replace(self.choice, obstacles=obstacles)
                )
                if stretch_why:
                    richer = replace(richer, stretch=True, reasons=list(richer.reasons))
                if (
                    not commit
                ):  # a query must not change the streaming model: answer with the richer one
                    self._wait_for_check()
                    other = self._solver_for(richer, problem, stream=False, source=self.inner)
                    self._compile_ahead(
                        other
                    )  # it answers every such query: compiled, as the stream
                    # the poses are checked, and in the plane if ``other`` is planar (above)
                    answer = other.solve(
                        {g.name: g.pose for g in problem.grips}, commit=False, checked=True
                    )
                    return self._refine_query(problem, answer, t0, richer, other)
                reasons = (
                    ([f"targets left the plane ({why}): full model"] if why else [])
                    + ([f"obstacle(s) {sorted(entering)} came within reach"] if entering else [])
                    + ([stretch_why] if stretch_why else [])
                )
                self.problem = problem
                self._switch(richer, "; ".join(reasons))
                notes.append(self.changes[-1][1])
            elif (
                self._worker is not None
                and commit
                and self._job is None
                and self.choice.planar
                and self._pooled(full := self._full_choice(self.choice, problem)) is None
            ):
                self._full_key = (
                    "",
                ) + full.key()  # the 3D model leaving the plane switches to: build it ahead
                self._submit(self._prebuild, {self._full_key}, [full], problem)
            elif (
                self._worker is not None and commit and self._job is None
            ):  # build an approaching obstacle's model ahead
                near = set(reachable_obstacles(problem, L / 2))
                if self.choice.planar:
                    near = set(self._in_plane_obstacles(problem, tuple(near), self.inner.nlp.r0))
                near -= set(self.choice.obstacles)
                if near:
                    ahead = replace(
                        self.choice, obstacles=tuple(sorted(near | set(self.choice.obstacles)))
                    )
                    if self._pooled(ahead) is None:
                        self._submit(self._prebuild, {("",) + ahead.key()}, [ahead], problem)
            reduced = self._reduced(self.choice, problem)[0]
            inner_poses = {g.name: g.pose for g in reduced.grips}
            # the shape this update starts from (a switch to self-contact may start there)
            before = (self.inner, self.inner.committed_state if warm else None, before_problem)
            # the poses are checked and the plane too (above): the inner solver need not check them
            # again
            result = self.inner.solve(inner_poses, warm=warm, commit=commit, checked=True)
            if commit and result.status == "failed" and result.message.startswith("topology:"):
                result = self._richer_for_topology(problem, result, notes)
            if result.status == "ok" and result.stable is False:
                result, answered_by = self._richer_for_stability(problem, result, notes, commit)
                if answered_by is not None:  # a query answered by the next order's model
                    return self._refine_query(problem, result, t0, *answered_by)
            # an unverified result (residual over the tolerance) is committed as the warm start and
            # checked: the check escalates the order
            if not commit:
                return self._refine_query(problem, result, t0)
            if result.status not in ("ok", "unverified"):
                return self._finish(result, t0, notes)
            approach = self._self_approach(problem)
            if (
                approach
            ):  # the shape came within reach of itself: solve this update again with self-contact
                start, why = self._contact_start(problem, before)
                self.problem = problem if start is None else before_problem
                contact = replace(self._full_choice(self.choice, problem), self_contact=True)
                self._switch(contact, approach + why, start)
                notes.append(self.changes[-1][1])
                reduced = self._reduced(self.choice, problem)[0]
                inner_poses = {g.name: g.pose for g in reduced.grips}
                result = self.inner.solve(inner_poses, warm=warm, commit=commit, checked=True)
                if result.status not in ("ok", "unverified"):
                    return self._finish(result, t0, notes)
            self.problem = problem
            self._since_check += 1
            self._updates += 1
            if check_now:
                self._wait_for_check()
                self._job = None
                return self._finish(
                    self._check_now(self._snapshot(problem, inner_poses, result), result, notes),
                    t0,
                    notes,
                )
            due = self._unchecked or self._since_check >= self.options.recheck_every
            if due and (
                self._worker is None or self._job is None
            ):  # a running check: snapshot later
                snap = self._snapshot(problem, inner_poses, result)
                if self._worker is None:
                    result = self._check_now(snap, result, notes)
                else:
                    i = ORDERS.index(snap.choice.order)
                    keys = {
                        ("",) + replace(snap.choice, order=o).key()
                        for o in ORDERS[max(i - 1, 0) : i + 2]
                    }
                    keys.add(("checker",) + self._full_choice(snap.choice, problem).key())
                    self._submit(self._evaluate, keys, snap, True)
            return self._finish(result, t0, notes)

    def _self_approach(self, problem: Problem) -> str:
        """Why self-contact must be modelled now ('' if not): the committed shape of a model
        without it has two samples the exclusion arc apart within the candidate reach of each other
        (k-d tree query).
        """
        if (
            self.choice.self_contact
            or self.options.rotation != "director"
            or not self.inner.has_warm_start
        ):
            return ""
        st = problem.string
        geometry = SC.contact_geometry(
            st.length,
            st.radius,
            self.options.self_contact_samples,
            tuple(g.s for g in problem.grips),
        )
        points = self.inner.model.positions(self.inner.snapshot().z, geometry.s)
        if SC.certainly_apart(
            points, geometry
        ):  # the usual answer, proved without the k-d tree search
            return ""
        d = SC.closest_distance(points, geometry)
        if not d < geometry.reach:
            return ""
        return (
            f"self-contact: the shape comes within {d:.3g} m of itself (reach {geometry.reach:.3g} m, "
            f"2·radius {2 * st.radius:.3g} m): full model with self-contact"
        )

    def _contact_start(self, problem: Problem, before: tuple) -> tuple[tuple | None, str]:
        """Where the self-contact model starts when a committed shape without self-contact came
        within reach of itself: that shape, when it is a topology reference
        (``recovery.why_not_reference``); else the shape committed before this update (the last one
        apart from itself), or a cold start when there was none.  ``before``: (solver, its state
        before this update or None, the scene then).  Returns (``_switch``'s start: None for the
        answer itself; the reason added to the change's).
        """
        solver, state, previous = before
        st = problem.string
        geometry = SC.contact_geometry(
            st.length,
            st.radius,
            self.options.self_contact_samples,
            tuple(g.s for g in problem.grips),
        )
        after = self.inner.model.positions(self.inner.committed_state.z, geometry.s)
        earlier = None if state is None else solver.model.positions(state.z, geometry.s)
        why = RC.why_not_reference(earlier, after, geometry, st.length)
        if not why:
            return None, ""
        where = "the shape before this update" if state is not None else "a cold start"
        why = f" (from {where}: the answer without self-contact is no reference, {why})"
        return (solver, state, previous), why

    def _richer_for_topology(
        self, problem: Problem, result: ShapeResult, notes: list[str]
    ) -> ShapeResult:
        """A warm update refused because the clamped string's linking number changed (the model
        jumped to a branch with whole turns released, ``topology.py``): too coarse a basis cannot
        hold the twist, so the update is tried again on the next orders, each warm-started from the
        committed shape; the first answer that is not refused for its topology is returned (the
        refusal if every order is).
        """
        for order in ORDERS:
            if order <= self.choice.order:
                continue
            self._switch(
                replace(self.choice, order=order, reasons=list(self.choice.reasons)),
                f"order {order}: the order-{self.choice.order} model changed the linking number",
            )
            notes.append(self.changes[-1][1])
            reduced = self._reduced(self.choice, problem)[0]
            result = self.inner.solve(
                {g.name: g.pose for g in reduced.grips}, warm=True, commit=True, checked=True
            )
            if not (result.status == "failed" and result.message.startswith("topology:")):
                return result
        return result

    def _richer_for_stability(
        self, problem: Problem, result: ShapeResult, notes: list[str], commit: bool = True
    ) -> tuple[ShapeResult, tuple[ModelChoice, ShapeSolver] | None]:
        """An equilibrium that is unstable, after the inner solver's own attempts to leave it (its
        shifted Newton steps, IPOPT's escapes, the cold solve).  Where the model is too coarse the
        smallest eigenvalue of the reduced Hessian can be a discretisation error
        (``paper_rect_paper``'s strip circling: -0.009 at order 12, +0.012 at order 16 and +0.008
        at order 24 at one target), and the shape answered is not one the string rests in.  The
        update is tried on the next order, warm-started from the stream's committed shape (for an
        update: the unstable answer itself), without touching the stream; if that answer is stable
        it is returned, and an update (``commit``) switches the stream to that order and answers
        there.  Else the unstable answer stands.  Returns (the answer, the next order's (choice,
        solver) when that answered a query, else None).
        """
        higher = [order for order in ORDERS if order > self.choice.order]
        if not higher:
            return result, None
        richer = replace(self.choice, order=higher[0], reasons=list(self.choice.reasons))
        poses = {g.name: g.pose for g in self._reduced(richer, problem)[0].grips}
        self._wait_for_model(richer)  # a running check may be using that order as its shadow
        other = self._solver_for(richer, problem, stream=False, source=self.inner)
        trial = other.solve(poses, warm=True, commit=False, checked=True)
        if not (trial.status == "ok" and trial.stable):
            return result, None
        if not commit:  # a query: the stream keeps its model
            return trial, (richer, other)
        self._switch(
            richer,
            f"order {richer.order}: the order-{self.choice.order} equilibrium is unstable "
            f"(eigenvalue {result.min_eigenvalue:.3g}), the order-{richer.order} one stable",
        )
        notes.append(self.changes[-1][1])
        return self.inner.solve(poses, warm=True, commit=True, checked=True), None

    # ---- checks -------------------------------------------------------------------------------------
    def _refine_query(
        self,
        problem: Problem,
        result: ShapeResult,
        t0: float,
        choice: ModelChoice | None = None,
        solver: ShapeSolver | None = None,
    ) -> ShapeResult:
        """A query's answer (``commit=False``; ``result`` of the model ``choice`` on ``solver``, by
        default the stream's).  One whose residual is over the tolerance ('unverified') is refined
        as a cold solve's is (``_check_now``): the checks run on the query's own shape and escalate
        (3D when the planar shape is unstable in 3D, the next order, more obstacle samples) until
        they pass, on pooled copies, never the streaming model.  Stops at
        ``solver.update_time_limit`` from ``t0``; 'ok' only when the checks passed
        (``query_verify.verified_answer``).
        """
        if result.status != "unverified":
            return self._finish(result, t0, [], choice=choice, solver=solver)
        self._wait_for_check()  # a running check may hold the pooled models the refinement uses
        budget = QueryBudget(self.options.update_time_limit, t0)
        base = choice or self.choice
        choice = replace(base, reasons=list(base.reasons))
        # the same answer again on a copy that keeps its state (the checks start from it); the copy
        # is tagged apart from the stream's model, which a query never touches
        solver = self._solver_for(
            choice, problem, stream=False, source=solver or self.inner, tag="query"
        )
        poses = {g.name: g.pose for g in self._reduced(choice, problem)[0].grips}
        answer = solver.solve(poses, warm=True, commit=True, checked=True)
        estimate, stopped = None, ""
        for _ in range(2 * len(ORDERS) + 2):
            if answer.status not in ("ok", "unverified"):
                stopped = f"the model {choice.order}/{choice.samples} failed ({answer.message})"
                answer = result  # the previous model's shape stays the answer
                break
            result = answer
            if budget.expired():
                stopped = budget.reason()
                break
            verdict = self._evaluate(
                self._snapshot(problem, poses, answer, solver, choice), False, lower=False
            )
            if verdict.choice is None:
                estimate = verdict.estimate
                break
            choice = replace(
                verdict.choice, reasons=list(choice.reasons) + [f"query: {verdict.reason}"]
            )
            same = choice.key() == self.choice.key()  # never the stream's own model
            solver = self._solver_for(
                choice, problem, stream=False, source=solver, tag="query" if same else ""
            )
            poses = {g.name: g.pose for g in self._reduced(choice, problem)[0].grips}
            answer = solver.solve(poses, warm=True, commit=True, checked=True)
        else:
            stopped = "the model checks kept escalating"
        answer = verified_answer(answer, estimate, self.tolerance, stopped)
        return self._finish(answer, t0, [], choice=choice, solver=solver, estimate=estimate)

    def _check_now(self, snap: _Snapshot, result: ShapeResult, notes: list[str]) -> ShapeResult:
        """Synchronous checks: escalate and re-solve while one fails."""
        for _ in range(2 * len(ORDERS) + 2):
            verdict = self._evaluate(snap, False)
            if verdict.choice is None:
                self._keep(verdict)
                return result
            self._switch(verdict.choice, verdict.reason)
            notes.append(self.changes[-1][1])
            previous, result = result, self.inner.solve(snap.poses)
            if result.status not in ("ok", "unverified"):  # keep the answer we had, and say so
                previous.message += f"; the richer model failed to solve ({result.message}): answer of the previous model"
                return previous
            snap = self._snapshot(snap.problem, snap.poses, result)
        return result

    def _snapshot(
        self,
        problem: Problem,
        poses: dict,
        result: ShapeResult,
        solver: ShapeSolver | None = None,
        choice: ModelChoice | None = None,
    ) -> _Snapshot:
        """What a check needs of the streaming model's committed ``result`` (a copy, for another
        thread), or of a query's: ``result`` committed on ``solver``, a model of ``choice``.
        """
        solver, choice = solver or self.inner, choice or self.choice
        return _Snapshot(
            solver,
            solver.snapshot(),
            replace(choice, reasons=list(choice.reasons)),
            problem,
            poses,
            result.points.copy(),
            max((float(np.linalg.norm(w.force)) for w in result.grips.values()), default=0.0),
            self._generation,
            float(np.nan_to_num(result.equilibrium_residual_m, nan=np.inf)),
            touches_obstacle(result),
            self._updates,
        )

    def _keep(self, verdict: _Verdict) -> None:
        self.choice.estimated_error_m = verdict.estimate
        self.choice.order_error_m = verdict.order_error
        if np.isfinite(verdict.sampling_error):
            self.choice.sampling_error_m = verdict.sampling_error
        self._unchecked = False
        self._since_check = 0
        self._checked_update = verdict.snapshot.update

    def _apply_check(self, notes: list[str]) -> None:
        """Apply a finished background check (streaming thread)."""
        job = self._job
        if job is None or not job.done():
            return
        self._job = None
        try:
            verdict = job.result()
        except Exception as exc:  # a check that raised is reported, never fatal to the stream
            notes.append(f"model check failed: {type(exc).__name__}: {exc}")
            self._unchecked, self._since_check = (
                False,
                0,
            )  # retry after recheck_every updates, not at once
            return
        if (
            verdict is None or verdict.snapshot.generation != self._generation
        ):  # a prebuild, or stale
            return
        if verdict.choice is None:
            self._keep(verdict)
        else:
            self._switch(
                verdict.choice, verdict.reason
            )  # maps the latest committed shape, not the snapshot's
            notes.append(self.changes[-1][1])

    def _wait_for_check(self) -> None:
        """Let a running background job finish first: it owns the pooled helper solvers meanwhile
        (its verdict is applied, or found stale, at the next solve).
        """
        if self._job is not None:
            wait([self._job])

    def _prebuild(self, choices: list[ModelChoice], problem: Problem) -> None:
        """Build (worker thread) the models a coming check or switch will need; the 3D model and
        obstacle models get their IPOPT solvers too (a switch to them streams at once).
        """
        for choice in choices:
            solver = self._solver_for(choice, problem, stream=False)
            if ("",) + choice.key() == self._full_key or choice.obstacles != self.choice.obstacles:
                solver.prepare()
                self._compile_ahead(solver)
            self._job_keys = self._job_keys - {
                ("",) + choice.key()
            }  # built: a switch to it need not wait

    def _evaluate(self, snap: _Snapshot, prepare: bool, lower: bool = True) -> _Verdict:
        """One pass of the a-posteriori checks on a snapshot; the first that fails decides.

        prepare: also create the IPOPT solvers of the model it escalates to (background checks, so
        the streaming thread's switch builds nothing).  lower: try the next lower order (once per
        model; a query's checks do not, so that they leave the stream's record of tries alone).
        """
        tol, choice, problem = self.tolerance, snap.choice, snap.problem
        verdict = _Verdict(snap, estimate=choice.estimated_error_m)
        order_error = choice.order_error_m
        if choice.planar:
            eig = self._planar_3d_eigenvalue(snap)  # None when stable (or neutral)
            if eig is not None:
                verdict.choice = replace(
                    self._full_choice(choice, problem),
                    estimated_error_m=float("nan"),
                    order_error_m=float("nan"),
                )
                verdict.reason = f"planar shape unstable in 3D (eigenvalue {eig:.3g}): full model"
        if (
            verdict.choice is None
            and problem.string.stretch_stiffness is not None
            and not choice.stretch
        ):
            elongation = (
                snap.max_grip_force
                * problem.string.length
                / problem.string.stretch_stiffness.minimum
            )
            if elongation > tol / 2:
                verdict.choice = replace(
                    choice,
                    stretch=True,
                    estimated_error_m=float("nan"),
                    order_error_m=float("nan"),
                    reasons=list(choice.reasons),
                )
                verdict.reason = (
                    f"elongation bound {elongation:.3g} m > {tol / 2:.3g} m: extensible model"
                )
        if verdict.choice is None and not choice.planar:
            turned = self._turned_frame(snap)
            if turned is not None:
                verdict.choice, verdict.reason = turned
        if verdict.choice is None:
            i = ORDERS.index(choice.order)
            if i + 1 < len(ORDERS):
                error = self._shadow_error(snap, replace(choice, order=ORDERS[i + 1]))
                if np.isfinite(
                    error
                ):  # a shadow that failed to solve is inconclusive: the next check retries
                    order_error = error
                # the equilibrium residual is an error estimate of its own: the larger of the two
                # counts
                error = max(error, snap.residual_m) if np.isfinite(error) else snap.residual_m
                if np.isfinite(snap.residual_m):
                    order_error = (
                        max(order_error, snap.residual_m)
                        if np.isfinite(order_error)
                        else snap.residual_m
                    )
                if error > tol / 2 and np.isfinite(error):
                    verdict.choice = replace(
                        choice,
                        order=ORDERS[i + 1],
                        estimated_error_m=error,
                        order_error_m=error,
                        reasons=list(choice.reasons),
                    )
                    verdict.reason = f"order {choice.order} error estimate {error:.3g} m > {tol / 2:.3g} m: order {ORDERS[i + 1]}"
            # at the highest order the estimate stays the one that led there (order 24 against 32):
            # the best available, and conservative; model.tolerance_met compares it with the
            # tolerance
            lower_key = replace(choice, order=ORDERS[i - 1]).key() if i > 0 else None
            if (
                verdict.choice is None
                and lower
                and lower_key is not None
                and lower_key not in self._lower_tried
            ):
                # the lowest order that meets the tolerance: try the next lower one once per model
                # (tol/4, not tol/2: a margin against switching back and forth)
                self._lower_tried.add(lower_key)
                error = self._shadow_error(snap, replace(choice, order=ORDERS[i - 1]))
                if error <= tol / 4:  # (nan when the lower order failed to solve: stay)
                    verdict.choice = replace(
                        choice,
                        order=ORDERS[i - 1],
                        estimated_error_m=error,
                        order_error_m=error,
                        reasons=list(choice.reasons),
                    )
                    verdict.reason = f"order {ORDERS[i - 1]} error estimate {error:.3g} m ≤ {tol / 4:.3g} m: order {ORDERS[i - 1]}"
        depth, name = self._penetration(snap)  # (0, '') without obstacles
        finer = replace(
            choice,
            samples=min(2 * choice.samples - 1, MAX_SAMPLES),
            estimated_error_m=float("nan"),
            order_error_m=order_error,
            reasons=list(choice.reasons),
        )
        change = (
            self._shadow_error(snap, finer)
            if snap.touching and choice.samples < MAX_SAMPLES
            else np.nan
        )
        verdict.sampling_error = (
            (choice.sampling_error_m if snap.touching else np.nan)
            if choice.samples >= MAX_SAMPLES
            else 2.0 * change
        )
        sampling = max(depth, np.nan_to_num(verdict.sampling_error, nan=0.0))
        verdict.order_error = order_error
        if np.isfinite(order_error):
            verdict.estimate = (
                order_error + sampling
            )  # the sampling error adds to the basis order's
        if verdict.choice is None and sampling > tol / 2 and choice.samples < MAX_SAMPLES:
            # the order's estimate carries over (same basis); the finer model's sampling error is
            # about half this one's (first order in h) until its own check measures it
            verdict.choice = replace(finer, sampling_error_m=change)
            verdict.reason = (
                f"the string cuts into obstacle {name!r} by {depth:.3g} m > {tol / 2:.3g} m between "
                f"its {choice.samples} samples: {finer.samples} samples"
                if depth >= sampling
                else f"the shape moves by {change:.3g} m when the obstacle samples go from {choice.samples} "
                f"to {finer.samples} (sampling error about {sampling:.3g} m > {tol / 2:.3g} m): "
                f"{finer.samples} samples"
            )
            # built and warm-started here (worker thread in the node), so the switch builds
            # nothing; the samples shadow, when it ran, already did both (the same pooled model)
            if not np.isfinite(change):
                self._solver_for(
                    verdict.choice, problem, stream=False, source=snap.inner, state=snap.state
                )
        # prepare only a pooled model: never build one here, the stream may be switching to it
        target = self._pooled(verdict.choice) if verdict.choice is not None and prepare else None
        if target is not None:
            target.prepare()
        return verdict

    def _turned_frame(self, snap: _Snapshot) -> tuple[ModelChoice, str] | None:
        """The same 3D model with its Euler-angle pole turned away from the checked shape, when a
        tangent has come within POLE_MIN_DEG of it (near the pole φ and ψ turn about the same axis,
        the fields get steep and the basis order stops converging: on the main job's post the order
        16/24/32 shapes differed by 1–2 cm with the pole 28° from a tangent, by 0.6 mm/0.03 mm with
        it 46° away). The new model is built and warm-started here (worker thread), so the switch
        builds nothing.
        """
        inner, state = snap.inner, snap.state
        if inner.nlp.director:  # no pole
            return None
        if state is None or has_point_moments(snap.problem):  # moments are modelled about the pole
            return None
        tangents = inner.model.node_tangents(state.z).T
        angle = pole_angle_deg(tangents, inner.nlp.r0[:, 2])
        if angle >= POLE_MIN_DEG:
            return None
        normal, best = farthest_pole(tangents)
        if best < angle + 10.0:
            return None
        r0 = frame_with_pole(normal, inner.nlp.r0[:, 0])
        choice = replace(
            snap.choice,
            frame=tuple(np.round(r0.ravel(), 12)),
            estimated_error_m=float("nan"),
            order_error_m=float("nan"),
            reasons=list(snap.choice.reasons),
        )
        self._solver_for(choice, snap.problem, stream=False, source=inner, state=state)
        return choice, (
            f"Euler-angle pole {angle:.0f}° from the tangent: reference frame turned "
            f"(pole {np.round(normal, 3).tolist()}, {best:.0f}° from every tangent)"
        )

    def _penetration(self, snap: _Snapshot) -> tuple[float, str]:
        """(depth [m], obstacle name): how far the checked shape enters its obstacles between the
        samples where they are enforced, over PENETRATION_OVERSAMPLING × as many points (the
        string's radius included).  The sampled constraints cannot see it, the order shadows
        neither (they share the samples); it is the sampling part of the error estimate.
        """
        inner, state = snap.inner, snap.state
        if state is None or not inner.problem.obstacles:
            return 0.0, ""
        s = np.linspace(
            0.0, inner.nlp.length, PENETRATION_OVERSAMPLING * (snap.choice.samples - 1) + 1
        )
        x = inner.model.positions(state.z, s)
        radius = inner.problem.string.radius
        depths = [
            (float(np.max(ob.h_many(x))) + radius, ob.name) for ob in inner.problem.obstacles
        ]
        depth, name = max(depths)
        return max(depth, 0.0), name

    def _shadow_error(self, snap: _Snapshot, choice: ModelChoice) -> float:
        """max |x(s) − x'(s)| over the output points between the checked shape and the model ``choice``
        (the next or the previous order, or 2n − 1 obstacle samples) solved from the checked shape
        (same branch): the a-posteriori estimate of the coarser of the two; nan when that solve
        fails (inconclusive: the next check retries).  The shadow is pooled: it is the model an
        escalation switches to.  With background checks it is compiled ahead (``_compile_ahead``),
        as the models a switch or the queries use.
        """
        shadow = self._solver_for(
            choice, snap.problem, stream=False, source=snap.inner, state=snap.state
        )
        if self._worker is not None:
            # beside a stream: an interpreted shadow holds the GIL through long CasADi calls, and
            # the stream's updates during a check waited for them (compiled once, later checks
            # release it)
            self._compile_ahead(shadow)
        result = shadow.solve(snap.poses)
        if not result.ok:
            return float("nan")
        return float(np.max(np.linalg.norm(result.points - snap.points, axis=1)))

    def _planar_3d_eigenvalue(self, snap: _Snapshot) -> float | None:
        """Smallest reduced-Hessian eigenvalue of the full 3D model at the embedded planar
        solution; None when that is stable.  The 3D model is pooled: it is also the model a switch
        to 3D uses.
        """
        full = self._solver_for(
            self._full_choice(snap.choice, snap.problem),
            snap.problem,
            stream=False,
            source=snap.inner,
            state=snap.state,
            tag="checker",
        )
        return full.unstable_eigenvalue()

    # ---- plumbing -----------------------------------------------------------------------------------
    def model_summary(
        self,
        choice: ModelChoice | None = None,
        solver: ShapeSolver | None = None,
        changed: tuple[str, ...] = (),
        estimate: float | None = None,
    ) -> ModelSummary:
        """The ``model`` object of a result: the streaming model, or ``choice``/``solver`` (a
        query's).

        estimated_error_m: the basis-order estimate of the last check of this model (the change of
        the centreline when the order is raised; at the highest order, the estimate that led there)
        plus the deepest cut into an obstacle between its samples, None until the first check has
        finished.  It does not include the a-priori bounds of the dropped gravity (≤ δ/10) and
        stretch (≤ δ/2).  In background mode it describes a solve up to recheck_every updates
        earlier: checked_updates_ago says how many (0: this very shape).  ``changed``: the changes
        of model this very solve made. ``estimate``: a refined query's own checked estimate
        (``_refine_query``): checked, 0 updates ago.
        """
        streaming = choice is None
        c, s = (self.choice, self.inner) if streaming else (choice, solver)
        checked = streaming and not self._unchecked
        est = c.estimated_error_m if checked and np.isfinite(c.estimated_error_m) else None
        if estimate is not None and np.isfinite(estimate):
            checked, est = True, float(estimate)
        inner = s.model_summary()
        return ModelSummary(
            planar=c.planar,
            twist=c.twist,
            stretch=c.stretch,
            gravity=c.gravity,
            order=c.order,
            obstacles=len(c.obstacles),
            obstacle_samples=c.samples,
            estimated_error_m=est,
            tolerance_m=self.tolerance,
            tolerance_met=None if est is None else bool(est <= self.tolerance),
            variables=s.model.layout.size,
            auto=True,
            checked=checked,
            checks=self.checks,
            checked_updates_ago=(
                0 if estimate is not None else self._updates - self._checked_update
            )
            if checked
            else None,
            reasons=tuple(c.reasons),
            changes=tuple(r for _, r in self.changes),
            rotation=inner.rotation,
            elements=inner.elements,
            breakpoints=inner.breakpoints,
            self_contact_pairs=inner.self_contact_pairs,
            changed=changed,
        )

    def _finish(
        self,
        result: ShapeResult,
        t0: float,
        notes: list[str],
        choice: ModelChoice | None = None,
        solver: ShapeSolver | None = None,
        estimate: float | None = None,
    ) -> ShapeResult:
        """Attach the model (the streaming one, or the query's ``choice``/``solver``) and the time;
        give contact forces the scene's obstacle indices.
        """
        c = choice or self.choice
        result.model = self.model_summary(choice, solver, tuple(notes), estimate)
        result.solve_time_ms = (time.perf_counter() - t0) * 1e3
        if result.ok and result.contact_forces and len(c.obstacles) != len(self.problem.obstacles):
            result.contact_forces = {
                c.obstacles[i]: f for i, f in result.contact_forces.items() if i < len(c.obstacles)
            }
        return result


def stretch_needed(problem: Problem) -> str:
    """Why an extensible scene needs its stretch field from the start: two grips farther apart than
    the inextensible string between them reaches ('' when none are, or when the string is
    inextensible).
    """
    pair = problem.farthest_apart() if problem.string.stretch_stiffness is not None else None
    if pair is None:
        return ""
    a, b, dist, span = pair
    return f"extensible: grips {a.name!r} and {b.name!r} are {dist:.4g} m apart, beyond the {span:.4g} m the inextensible string reaches"


def make_solver(
    problem: Problem,
    options: SolverOptions | None = None,
    compile: str = "background",
    checks: str = "background",
) -> Solver:
    """AutoShapeSolver for solver.model 'auto' (the default; ``checks`` as there: 'background' by
    default, so that a stream never builds or switches a model on the caller's thread; 'sync' for
    one-shot answers that must be checked before they return, as the CLI's), else a ShapeSolver of
    that model.
    """
    options = options or SolverOptions()
    if options.model == "auto":
        return AutoShapeSolver(problem, options, compile=compile, checks=checks)
    return ShapeSolver(problem, options, compile=compile)
