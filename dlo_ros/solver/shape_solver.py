"""ShapeSolver: warm-started, thread-safe equilibrium solves of one scene structure.

Contract:
* The NLP is built once per structure (StringNLP); ``solve`` only changes parameter values.
* ``solve(poses)`` warm-starts from the last committed equilibrium: Newton steps on the KKT
  conditions
  first (``newton.py``), then warm-started IPOPT (``ipopt.py``); if that fails the jump is split
  into 2, 4, … ``max_continuation_steps`` equal steps; if that fails too, a cold start from a
  buckled guess (``initial_guess.py``) is tried.  An unstable answer of IPOPT is left along its
  negative-curvature mode (``ipopt.escape_saddle``).  ``commit=False`` answers a query without
  touching the warm-start state.
* Grip orientations become parameter targets (``parameters.py``); for the Euler models, angles
  unwrapped
  to the current shape (φ, ψ + 2πk), so an end turned by several revolutions in small steps is
  tracked.
* Every call returns a ShapeResult (``outputs.py``); bad input gives status 'invalid', grips
  farther
  apart than the string reaches 'unreachable' — never an exception.
* One lock serialises every entry: CasADi's IPOPT must never run in two threads at once.  MUMPS
  (IPOPT's
  linear solver) is not thread-safe across instances either, so every IPOPT call in the process
  also holds the module-wide ``IPOPT_LOCK`` (Newton updates and derivative evaluations do not).
* With ``lazy_ipopt`` the IPOPT solvers are created on first use (``prepare()`` creates them
  ahead): a
  helper used only for Newton updates or stability checks never needs them.

ShapeSolver holds the state (NLP, scene, committed equilibrium, compile thread) and the lock; the
work is done by the modules named above and by ``functions.py`` (the NLP's derivatives, compiled in
the background), ``stability.py``, ``frames.py``, ``wrenches.py`` and ``warm_start.py``.
"""

from __future__ import annotations

import threading
import time
import weakref

import numpy as np

from ..model.director import quat_to_frame
from ..model.rotations import slerp
from ..model.problem import GripPose, Problem
from .build import frames as F
from .build.functions import COMPILE_MODES, NlpFunctions, check_compile_mode
from .build.initial_guess import initial_guess
from .update.ipopt import (
    INFEASIBLE,
    IPOPT_LOCK,
    LEFT_SADDLE,
    SUCCESS,
    TIME_LIMIT,
    Attempt,
    IpoptSolvers,
    call,
    escape_saddle,
    lower_than,
    witness,
)
from .build.moments import ExactMomentKKT
from .update.newton import fill_start, leave_saddle, newton
from .build.nlp import StringNLP, has_point_moments
from .options import SolverOptions
from .results.outputs import ShapeOutputs, no_shape
from .build.parameters import ProblemParameters, check_moments
from .results.residual import EquilibriumResidual, PointAction
from .results.result import GripWrench, ShapeResult
from .contact import obstacle_slots as OSL
from .contact import self_contact as SC
from .update import recovery as RC
from .contact import topology as TP
from .results.stability import is_stable, min_reduced_eigenvalue
from .state import SolverState
from .results.summary import ModelSummary
from .update.warm_start import sample_source, warm_state
from .results.wrenches import equilibrium

__all__ = [
    "COMPILE_MODES",
    "IPOPT_LOCK",
    "MOMENT_CONTINUATION_SOLVES",
    "MOMENT_NEWTON_STEPS",
    "SUCCESS",
    "ShapeSolver",
    "SolverState",
    "is_stable",
    "structure_key",
    "with_checked_poses",
]

#: point moments (director models): Newton steps per solve of the exact equilibrium equations, and
#: Newton solves for raising the moments from zero when one solve does not get there
MOMENT_NEWTON_STEPS = 25
MOMENT_CONTINUATION_SOLVES = 40
#: the messages of a warm update refused as a jump of the solver (retried in substeps,
# ``_in_substeps``)
JUMP_REFUSALS = (
    "self-contact: the string passed through itself",
    "self-contact: this shape is not reached",
    "topology:",
)
#: substeps a refused warm update, or one Newton cannot take at once, is retried in (each count in
# turn)
SUBSTEPS = (2, 4)

#: how many times a solve is repeated with the obstacle contact slots placed on its own answer
SLOT_ROUNDS = 2

#: ('cached' mode) the least time [s] between two looks into the cache for libraries that another
#: solver or process has compiled since (e.g. a node's query model, for its query workers)
CACHE_RECHECK_S = 1.0


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


def only_poses_differ(problem: Problem, other: Problem) -> bool:
    """Whether ``problem`` is ``other`` but for its grips' poses: the same string, gravity, loads,
    obstacles and relative positions (the same objects), and grips of the same names, arc lengths
    and modes.  Then both validate alike (a pose is checked where it is made: ``GripPose.checked``)
    and share their NLP's structure (``structure_key``).
    """
    return (
        problem.string is other.string
        and problem.gravity is other.gravity
        and problem.loads is other.loads
        and problem.obstacles is other.obstacles
        and problem.relative_positions is other.relative_positions
        and len(problem.grips) == len(other.grips)
        and all(
            a.name == b.name and a.s == b.s and a.mode == b.mode
            for a, b in zip(problem.grips, other.grips)
        )
    )


def with_checked_poses(problem: Problem, poses: dict | None) -> Problem:
    """``problem`` with new grip poses (GripPose or (position, quaternion) per grip name),
    validated: unknown names, NaN and bad quaternions raise ValueError naming the grip.
    """
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


class ShapeSolver:
    """Solve the string's static shape for changing grip targets (see module docstring)."""

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions | None = None,
        compile: str = "background",
        lazy_ipopt: bool = False,
        reference_frame: np.ndarray | None = None,
    ):
        """compile: 'background' (solve at once with interpreted derivatives, compile them to C in
        a background thread and switch when ready; cached per machine), 'blocking' (compile or load
        now), 'cached' (use a library compiled earlier, never compile), or 'off'. $DLO_NO_COMPILE
        forces 'off'.  lazy_ipopt: create the IPOPT solvers on first use (helpers that may only
        take Newton steps); otherwise now, so that a stream's first IPOPT fallback does not pay for
        them.  reference_frame: a fixed R0 for the Euler angles (3D models; default: chosen from
        the scene, ``choose_reference_frame``).
        """
        check_compile_mode(compile)
        self.options = options or SolverOptions()
        self.compile_mode = compile
        self.lazy_ipopt = lazy_ipopt
        self.reference_frame = (
            None if reference_frame is None else np.array(reference_frame, dtype=float)
        )
        self._lock = threading.Lock()
        self._deadline: float | None = (
            None  # perf_counter() at which the warm update in progress stops trying
        )
        self._compile_thread: threading.Thread | None = None
        self._cache_checked = time.monotonic()  # ('cached' mode) the last look into the cache
        self.compile_pending = (
            False  # a compile is about to start (AutoShapeSolver._compile_ahead)
        )
        self._build(problem)

    def _build(self, problem: Problem) -> None:
        t0 = time.perf_counter()
        nlp = StringNLP(problem, self.options, self.reference_frame)
        check_moments(
            nlp, problem
        )  # before anything is replaced: a refused scene leaves the solver as it was
        self.nlp = nlp
        if hasattr(self, "_ipopt"):
            self._ipopt.free()
        self._ipopt = IpoptSolvers(self.nlp)
        if not self.lazy_ipopt:
            self._ipopt.prepare()
        if hasattr(self, "functions"):
            self.functions.retire()  # a compile still running for the old NLP stops there
        self.functions = NlpFunctions(self.nlp)
        # the first Newton steps in one call of newton_fn (around the compiled contact-free
        # function once that is loaded); False: one evaluation and one LAPACK solve per step from
        # Python
        self.fused_newton = True
        self.parameters = ProblemParameters(self.nlp)
        self._outputs = ShapeOutputs(self.nlp, self.functions, self.parameters, self.options)
        self._compile_thread = (
            None  # the old NLP's compile (retired above) must not block a new one
        )
        self._start_compile()
        self.problem = problem
        self._key = structure_key(problem, self.options)
        self._state: SolverState | None = None
        # (source solver, its state, the state adopted from it, this solver's scene then):
        # adopt_warm_start's last mapping (weak references: a pooled model must not keep an evicted
        # one alive)
        self._adopted: tuple[weakref.ref, weakref.ref, SolverState, Problem] | None = None
        self._contact: SC.ContactSlots | None = (
            None  # the self-contact pairs of the solve under way
        )
        self._slot_override: list | None = (
            None  # the obstacle slots of a repeated solve (_place_slots_again)
        )
        # the clamps' turns over the targets since the committed shape (None: none asked for
        # since), and those of the solve under way (topology.ClampTurns; the linking-number check)
        self._clamp_turns: TP.ClampTurns | None = None
        self._turns_start: tuple | None = (
            None  # (z, clamp names, ClampTurns): _committed_turns' last answer
        )
        # (the clamps' target quaternions as bytes, their frames, (ClampTurns, it advanced to them)
        # or None)
        self._clamp_frames: tuple | None = None
        self._turns_now: TP.ClampTurns | None = None
        # the solve under way reached its Newton answer far from the committed shape (substeps, a
        # saddle left)
        self._newton_far = False
        self.build_time_s = time.perf_counter() - t0

    # ---- compiled derivatives and IPOPT instances ----------------------------------------------------
    def prepare(self) -> None:
        """Create the IPOPT solvers now (they are otherwise created on first use)."""
        with self._lock:
            self._ipopt.prepare()

    def start_compile(self, mode: str) -> None:
        """Switch the compile mode (e.g. a helper solver promoted to stream) and start compiling if
        that mode asks for it and nothing is compiled or compiling yet (any thread: the libraries
        already cached are swapped in under the solver's lock).
        """
        check_compile_mode(mode)
        with self._lock:
            self.compile_mode = mode
            if not self.all_compiled and self._compile_thread is None:
                self._start_compile()

    def _start_compile(self) -> None:
        thread = self.functions.start_compile(self.compile_mode, self._lock)
        if thread is not None:
            self._compile_thread = thread

    def wait_for_compile(self, timeout: float | None = None) -> bool:
        """Block until a background compile has finished; True if compiled derivatives are in
        use.
        """
        if self._compile_thread is not None:
            self._compile_thread.join(timeout)
        return self.kkt_compiled

    @property
    def all_compiled(self) -> bool:
        """Whether every function a solve calls runs compiled C: the derivatives and, for the
        models that have one, the outputs' function (a new version may change it alone: its
        derivatives then load from the cache, and it still has to be compiled).
        """
        return self.functions.compiled and (
            self.functions.outputs is None or self.functions.outputs_compiled
        )

    @property
    def kkt_compiled(self) -> bool:
        """Whether every derivative function runs compiled C."""
        return self.functions.compiled

    @property
    def compile_time_s(self) -> float:
        """Wall time [s] of the compile that made ``kkt_compiled`` true (0 when loaded or not
        compiled).
        """
        return self.functions.compile_time_s

    # ---- public API ---------------------------------------------------------------------------------
    @property
    def model(self):
        return self.nlp.model

    @property
    def has_warm_start(self) -> bool:
        return self._state is not None

    @property
    def committed_state(self) -> SolverState | None:
        """The committed equilibrium itself, not a copy (``snapshot`` copies): for the thread that
        streams, between its solves.  A commit replaces the object; nothing changes its z, λ or p
        in place.
        """
        return self._state

    def snapshot(self) -> SolverState | None:
        """A copy of the committed equilibrium (for adopt_warm_start from another thread,
        later).
        """
        with self._lock:
            return None if self._state is None else self._state.copy()

    def adopt_warm_start(self, other: ShapeSolver, state: SolverState | None = None) -> bool:
        """Take ``other``'s committed equilibrium as this solver's warm start, across models
        (``warm_start.py``).  ``state``: an earlier ``other.snapshot()`` to adopt instead of
        other's current equilibrium.  False when there is nothing to adopt.
        """
        with other._lock:
            src = other._state if state is None else state
            if src is None:
                return False
            if self._adopt_again(other, src):
                return True
            source = sample_source(other, src, self.nlp)
            held = other._held_poses(src) if state is None else None
        with (
            self._lock
        ):  # warm_state evaluates this solver's functions: never beside a solve of it
            # at the grip targets ``src`` holds (its equilibrium's own), so that a solve from it
            # moves them from there: substeps (``_newton_in_substeps``) then split a real move
            at = self.problem if held is None else self.problem.with_grip_poses(held)
            state = warm_state(self.nlp, self.functions, self.parameters, at, source)
            contact = getattr(src, "contact", None)
            if contact is not None and len(contact.pairs) == self.nlp.self_contact_slots:
                # the same pairs in the same slots: the multipliers warm_state matched row by row
                # belong to them
                state.contact = contact.copy()
                SC.fill(state.p, state.contact, self.nlp, self.problem.string.length)
            self._state = state
            self._clamp_turns = None
            self._adopted = None
            if (
                contact is None
            ):  # what every query from it reuses: its derivatives, evaluated once here
                fill_start(self.nlp, self.functions, state)
                self._adopted = (weakref.ref(other), weakref.ref(src), state, self.problem)
                self._state = self._adopted_copy(state)
        return True

    def _held_poses(self, src: SolverState) -> dict[str, GripPose] | None:
        """The grip poses ``src`` (this solver's committed state) is the equilibrium of: the
        scene's, when its grip targets are the ones ``src.p`` holds; None when they are not (a
        scene set since, whose poses ``src`` was not solved for).  The caller holds the lock.
        """
        mask = self.nlp.grip_parameter_mask
        p = self.parameters.pack(self.problem, src.z, src.p)
        return (
            {g.name: g.pose for g in self.problem.grips}
            if np.array_equal(p[mask], src.p[mask])
            else None
        )

    def _adopted_copy(self, adopted: SolverState) -> SolverState:
        """A copy of the adopted state with its derivatives (a solve from it shifts g and the
        residual to its own targets: ``newton``).
        """
        state = adopted.copy()
        state.g = adopted.g
        state.jacobian, state.hessian, state.gradient, state.energies = (
            adopted.jacobian,
            adopted.hessian,
            adopted.gradient,
            adopted.energies,
        )
        state.kkt, state.residual = adopted.kkt, adopted.residual
        return state

    def _adopt_again(self, other: ShapeSolver, src: SolverState) -> bool:
        """Adopt the state adopted last time from the same state ``src`` of ``other``, without
        sampling and mapping it again, when this solver's scene differs from that adoption's in
        grip poses at most (``only_poses_differ``: the mapping is then the same, at the grip
        targets ``src`` holds; a solve from it moves them to the scene's).  What a query that
        another model answers does on every call: the held shape is the same until the stream
        commits.
        """
        adopted = self._adopted
        if adopted is None or adopted[0]() is not other or adopted[1]() is not src:
            return False
        with self._lock:
            if not only_poses_differ(self.problem, adopted[3]):
                return False
            self._state = self._adopted_copy(adopted[2])
            self._clamp_turns = None
        return True

    def unstable_eigenvalue(self) -> float | None:
        """The smallest eigenvalue of the reduced Hessian at the committed equilibrium when that is
        unstable (``stability.is_stable``); None when it is stable or neutral, when the active rows
        leave no freedom, or when nothing is committed.
        """
        with self._lock:
            state = self._state
            if state is None:
                return None
            eig = min_reduced_eigenvalue(self.nlp, self.functions, state)
            return None if eig is None or is_stable(eig, state.hessian) else eig

    def reset(self) -> None:
        """Forget the warm start: the next solve starts cold."""
        with self._lock:
            self._state = None
            self._clamp_turns = None

    def close(self) -> None:
        """Nothing to stop (a background compile is a daemon thread); the Solver protocol's
        close.
        """

    def set_problem(self, problem: Problem) -> None:
        """Replace the scene's values (properties, loads, obstacles, grips).

        Same structure: only parameter values change and the warm start is kept.  Otherwise the NLP
        is rebuilt (and the next solve is cold).  Raises ValueError naming the offending field.
        """
        with self._lock:
            if only_poses_differ(
                problem, self.problem
            ):  # validated already, the same structure and values
                self.problem = problem
                return
        problem.validate()
        with self._lock:
            if structure_key(problem, self.options) == self._key:
                check_moments(self.nlp, problem)
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

        checked: the poses are GripPose objects already validated (``with_checked_poses``) and, for
        a planar model, already found in its plane (AutoShapeSolver checks both before calling).
        check_now: accepted for the interface AutoShapeSolver shares; a fixed model's checks (the
        equilibrium residual and the stability eigenvalue) always run inside every solve.
        """
        with self._lock:
            t0 = time.perf_counter()
            try:
                problem = (
                    self.problem.with_grip_poses(poses)
                    if checked and poses
                    else with_checked_poses(self.problem, poses)
                )
            except (ValueError, KeyError) as exc:
                return self._failure("invalid", str(exc).strip("'\""), t0)
            if self.nlp.planar and not checked:
                from .build.nlp import planarity_violation

                why = planarity_violation(problem, self.nlp.r0[:, 2], tolerance=1e-7)
                if why:
                    return self._failure("invalid", f"solver.model planar: {why}", t0)
            reason = self.unreachable_reason(problem)
            if reason:
                return self._failure("unreachable", reason, t0)
            self._turns_now = self._advance_clamp_turns(problem)
            if self.functions.waiting and time.monotonic() - self._cache_checked > CACHE_RECHECK_S:
                self._cache_checked = time.monotonic()
                self.functions.load_cached()
            warm = warm and self._state is not None
            limit = self.options.update_time_limit
            self._deadline = t0 + limit if warm and limit > 0 else None
            try:
                result, state = self._solve_locked(problem, warm)
                if warm and result.status == "failed" and result.message.startswith(JUMP_REFUSALS):
                    result, state = self._in_substeps(problem, result)
            finally:
                self._deadline = None
            if (
                warm
                and limit > 0
                and result.status == "failed"
                and time.perf_counter() - t0 >= limit
            ):
                result.message = (
                    f"no answer within solver.update_time_limit ({limit:g} s): the update stopped; "
                    f"{result.message}"
                )
            result.solve_time_ms = (time.perf_counter() - t0) * 1e3
            result.derivatives = "compiled" if self.functions.compiled else "interpreted"
            if commit:  # every target of the stream counts, failed ones too (topology.ClampTurns)
                self._clamp_turns = self._turns_now
            # an unverified result is a converged stationary point of the discrete problem: a good
            # warm start
            if commit and result.status in ("ok", "unverified") and state is not None:
                self._state = state
                self.problem = problem
                self._clamp_turns = (
                    None if self._turns_now is None else self._turns_now.committed()
                )
            return result

    def _in_substeps(
        self, problem: Problem, refused: ShapeResult
    ) -> tuple[ShapeResult, SolverState | None]:
        """A warm update refused as a jump (the string passed through itself, or turns of twist
        were released: ``JUMP_REFUSALS``) solved again as SUBSTEPS[k] warm updates along the way
        from the committed poses to ``problem``'s (positions linear, orientations by slerp), each
        checked as any update is: IPOPT's iterates need not keep the contact rows, and a smaller
        move keeps it on the branch (Fig. 2 at radius 0).  Returns the last substep's (result,
        state), uncommitted; or ``refused`` (with the substeps' outcome added) when a substep fails
        too.  The committed state is restored either way: ``solve`` commits.
        """
        committed = (self._state, self.problem, self._clamp_turns, self._turns_now)
        start = {g.name: g.pose for g in self.problem.grips}
        why = ""
        try:
            for k in SUBSTEPS:
                self._state, self.problem, self._clamp_turns = committed[:3]
                for i in range(1, k + 1):
                    t = i / k
                    step = (
                        problem.with_grip_poses(
                            {
                                g.name: GripPose(
                                    (1.0 - t) * start[g.name].position + t * g.pose.position,
                                    slerp(start[g.name].orientation, g.pose.orientation, t),
                                )
                                for g in problem.grips
                            }
                        )
                        if i < k
                        else problem
                    )
                    self._turns_now = self._advance_clamp_turns(step)
                    result, state = self._solve_locked(step, True)
                    if (
                        result.status != "ok" or state is None
                    ):  # a rescue must be a verified equilibrium
                        why = f"; in {k} substeps, substep {i} {result.status}: {result.message}"
                        break
                    if i == k:
                        result.message += (
                            f"; solved in {k} substeps (one update was refused: {refused.message})"
                        )
                        result.continuation_steps = k
                        return result, state
                    self._state, self.problem = state, step  # the next substep starts here
                    self._clamp_turns = (
                        None if self._turns_now is None else self._turns_now.committed()
                    )
        finally:
            self._state, self.problem, self._clamp_turns, self._turns_now = committed
        refused.message += why
        return refused, None

    def query_many(self, targets, executor=None) -> list[ShapeResult]:
        """Answers to many independent queries (``{grip: pose}`` each) in worker processes, in
        order, with this solver's scene and options; this solver and its warm start are untouched
        (dlo_ros.solver.parallel.batch.query_many: ``executor`` defaults to a process pool on every
        core).
        """
        from .parallel.batch import query_many

        return query_many(ShapeSolver, self.problem, self.options, targets, executor)

    def unreachable_reason(self, problem: Problem) -> str:
        """Why the position constraints cannot all hold (empty string if they can)."""
        reach = 1.0 + (
            self.options.max_strain if problem.string.stretch_stiffness is not None else 0.0
        )
        pair = problem.farthest_apart(reach)
        if pair is not None:
            a, b, dist, span = pair
            return f"grips {a.name!r} and {b.name!r} are {dist:.4g} m apart but the string between them reaches at most {span:.4g} m"
        for k, rel in enumerate(problem.relative_positions):
            dist = float(np.linalg.norm(rel.offset))
            if dist > abs(rel.s_b - rel.s_a) * reach + 1e-12:
                return f"relative_positions[{k}].offset: {dist:.4g} m is longer than the string between s_a and s_b"
        return ""

    # ---- the solution's parameters, start and fields (parameters.py, initial_guess.py, frames.py) ------
    def pack_parameters(
        self, problem: Problem, z_reference: np.ndarray, keep: np.ndarray | None = None
    ) -> np.ndarray:
        """The NLP parameter vector for ``problem``; angles unwrapped to, and obstacle contact
        slots placed on, the shape ``z_reference`` (``keep``: a vector whose slots stay while still
        placed well).
        """
        p = self.parameters.pack(problem, z_reference, keep)
        for i, placement in enumerate(
            self._slot_override or ()
        ):  # a round's slots (_place_slots_again)
            self.parameters.write_slots(p, i, placement)
        if self._contact is not None:
            SC.fill(p, self._contact, self.nlp, problem.string.length)
        return p

    def grip_angles(self, pose: GripPose, reference: tuple[float, float, float]) -> np.ndarray:
        """Euler angles (φ, θ, ψ) of a grip orientation, on the branch nearest ``reference``."""
        return self.parameters.grip_angles(pose, reference)

    def initial_guess(self, problem: Problem) -> np.ndarray:
        """The buckled cold-start guess z for ``problem``."""
        return initial_guess(self.nlp, self.parameters, problem)

    def strain(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """ε(s) of solution z (zeros when inextensible)."""
        return F.strain(self.nlp, z, s)

    def frames_psi(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """ψ(s) as published: the solved field, or the zero-twist ψ anchored at the first held
        grip.
        """
        return F.frames_psi(self.nlp, self.parameters, self.problem, z, s, p)

    def pose_frames(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Frames (len(s), 3, 3) in the pose convention (columns: tangent, y, z) of solution z."""
        return F.pose_frames(self.nlp, self.parameters, self.problem, z, s)

    def frames(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """Material frames Q(s) (columns ξ, η, ζ) of solution z; ψ from the zero-twist rule if not
        solved.
        """
        return F.frames(self.nlp, self.parameters, self.problem, z, s, p)

    def equilibrium(
        self,
        problem: Problem,
        z: np.ndarray,
        grips: dict[str, GripWrench],
        contacts: list[PointAction] = (),
        lam_si: np.ndarray | None = None,
    ) -> EquilibriumResidual:
        """The strong-form equilibrium residual of shape z under the grip reactions ``grips``, the
        obstacle ``contacts`` and (given the SI multipliers) the relative positions' reactions
        (solver/results/residual.py).
        """
        return equilibrium(self.nlp, problem, z, grips, contacts, lam_si)

    # ---- solving ----------------------------------------------------------------------------------
    def _newton(
        self, start: SolverState, p: np.ndarray, problem: Problem | None = None
    ) -> tuple[bool, SolverState, int, float]:
        """``newton.newton`` from ``start`` to ``p``; given ``problem`` (what p packs), a compiled
        loop also evaluates the answer's outputs in its call.
        """
        plan = self.functions.output_function
        prof = plan.profiles(problem.string) if problem is not None and plan is not None else None
        return newton(self.nlp, self.functions, start, p, fused=self.fused_newton, prof=prof)

    def _newton_in_substeps(
        self, start: SolverState, p1: np.ndarray, problem: Problem | None = None
    ) -> tuple[bool, SolverState, int, float]:
        """Newton along the straight path from ``start.p`` to ``p1`` (``problem``'s) in SUBSTEPS
        equal parts, each warm-started from the last (the continuation IPOPT would do next, at the
        cost of Newton steps).
        """
        iterations = 0
        for parts in SUBSTEPS:
            state, ok = start, True
            for i in range(1, parts + 1):
                ok, state, it, viol = (
                    self._newton(state, p1, problem)
                    if i == parts
                    else self._newton(state, start.p + (p1 - start.p) * (i / parts))
                )
                iterations += it
                if not ok:
                    break
            if ok:
                return True, state, iterations, viol
        return False, start, iterations, np.inf

    def _ipopt_call(
        self,
        warm: bool,
        z0: np.ndarray,
        p: np.ndarray,
        start: SolverState | None = None,
        escape: bool = False,
    ) -> Attempt:
        """One IPOPT solve from z0 (warm: with ``start``'s multipliers; escape: cold, leaving a
        saddle). Within a warm update past its ``solver.update_time_limit`` none starts: a failed
        attempt, with IPOPT's own status for a call stopped by that limit.
        """
        in_update = self._deadline is not None
        if in_update and time.perf_counter() >= self._deadline:
            m, n = self.nlp.lbg.size, z0.size
            return False, SolverState(z0, np.zeros(m), np.zeros(n), p), TIME_LIMIT, 0, np.inf
        if start is None:
            return call(self.nlp, self._ipopt.get(warm, escape, in_update), z0, p)
        return call(
            self.nlp, self._ipopt.get(warm, in_update=in_update), z0, p, start.lam_g, start.lam_x
        )

    def _cold_ipopt(self, problem: Problem) -> Attempt:
        """IPOPT from the initial guess (``initial_guess``), cold."""
        z0 = self.initial_guess(problem)
        return self._ipopt_call(False, z0, self.pack_parameters(problem, z0))

    def _solve_locked(
        self, problem: Problem, warm: bool
    ) -> tuple[ShapeResult, SolverState | None]:
        if self.nlp.self_contact_slots:
            return self._solve_self_contact(problem, warm)
        start = self._state if warm else None
        self._newton_far = False
        result, state = self._solve_pairs_fixed(problem, warm)
        newton_only = result.ipopt_status.startswith("Newton")
        if self.nlp.obstacle_slots:
            result, state = self._place_slots_again(problem, result, state)
        # without self-contact the linking number is checked where a warm update left the Newton
        # path (IPOPT, continuation or the cold fallback can land a whole turn away; Newton
        # converges from next to the committed shape) or Newton went far from it (substeps, leaving
        # a saddle: ``_newton_far``), and where the clamps turned more than a quarter turn since
        # the committed shape (after refused updates: Newton then follows the clamp frame, which
        # cannot tell a turn from its opposite): a stream must not lose turns of twist to a cold
        # start
        turns = self._turns_now
        lagging = turns is not None and any(abs(a) > np.pi / 2 for a in turns.turns.values())
        if (
            start is not None
            and state is not None
            and result.status in ("ok", "unverified")
            and (lagging or self._newton_far or not newton_only)
        ):
            jump = self._linking_jump(problem, start, state)
            if jump is not None:
                return self._linking_failure(jump, result.iterations, True), None
        return result, state

    def _place_slots_again(
        self, problem: Problem, result: ShapeResult, state: SolverState | None
    ) -> tuple[ShapeResult, SolverState | None]:
        """The obstacle contact slots (``obstacle_slots.py``) are placed on the shape a solve
        starts from; while the answer touches an obstacle at a minimum that moved further than
        TOLERANCE·L from its slot, the solve is repeated warm from the answer (at most SLOT_ROUNDS
        times), each slot at the secant estimate of its fixed point σ = s*(σ) from the rounds so
        far (the first round: s* itself).  A repeat that fails keeps the previous answer (a
        converged solution of its own rows).
        """
        committed, iterations, first = self._state, result.iterations, result
        history: dict[tuple[int, int], list[tuple[float, float]]] = {}
        nlp = self.nlp
        for _ in range(SLOT_ROUNDS):
            if state is None or result.status not in ("ok", "unverified"):
                break
            self.parameters.pack(problem, state.z, keep=state.p)
            placements = self.parameters.placements
            moved = False
            for i, new in enumerate(placements):
                if new.kept:
                    continue
                used = self.parameters.slots(state.p, i)
                touching = (new.on > 0) & (new.clearance < OSL.TOUCH * nlp.length)
                moved |= bool(
                    np.any(
                        touching
                        & ((used.on == 0) | (np.abs(new.s - used.s) > OSL.TOLERANCE * nlp.length))
                    )
                )
            if not moved:
                break
            override = []
            for i, new in enumerate(placements):
                used, s = self.parameters.slots(state.p, i), new.s.copy()
                for k in np.flatnonzero((new.on > 0) & (used.on > 0)):
                    trail = history.setdefault((i, k), [])
                    trail.append((float(used.s[k]), float(new.s[k])))
                    if len(trail) >= 2:  # secant on g(σ) = s*(σ) − σ
                        (a, fa), (b, fb) = trail[-2], trail[-1]
                        ga, gb = fa - a, fb - b
                        if gb != ga:
                            s[k] = float(
                                np.clip(
                                    b - gb * (b - a) / (gb - ga),
                                    min(a, b, fa, fb),
                                    max(a, b, fa, fb),
                                )
                            )
                override.append(
                    OSL.assign(
                        (s[new.on > 0], new.clearance[new.on > 0]),
                        nlp.obstacle_s,
                        nlp.obstacle_slots,
                        new,
                        nlp.length,
                    )
                )
            self._state, self._slot_override = state, override
            try:
                again, new_state = self._solve_pairs_fixed(problem, True)
            finally:
                self._state, self._slot_override = committed, None
            iterations += again.iterations
            if new_state is None or again.status not in ("ok", "unverified"):
                break
            result, state = again, new_state
        # the rounds refine the answer the first solve found: its method and warm start describe
        # the result
        result.iterations, result.ipopt_status, result.warm_started = (
            iterations,
            first.ipopt_status,
            first.warm_started,
        )
        return result, state

    def _carry_slots(self, start: SolverState, p: np.ndarray) -> SolverState:
        """``start`` with the obstacle contact slots (and sample switches) of ``p``, when they
        differ: each row of the new placement takes the multiplier of the start's row nearest to it
        along s, within a quarter of the sample spacing (the contact force stays where it acts),
        the others none; the inequality rows' values are evaluated anew and the stored derivatives
        dropped.
        """
        nlp = self.nlp
        if not nlp.obstacle_slots:
            return start
        lay = nlp.params
        names = [n for i in range(len(nlp.slot_rows)) for n in nlp.slot_parameters(i)]
        if all(np.array_equal(start.p[lay[n]], p[lay[n]]) for n in names):
            return start
        moved = start.p.copy()
        for n in names:
            moved[lay[n]] = p[lay[n]]
        lam = start.lam_g.copy()
        reach = 0.25 * (nlp.obstacle_s[1] - nlp.obstacle_s[0])
        for i, slot_rows in enumerate(nlp.slot_rows):
            rows = np.concatenate([nlp.obstacle_rows[i], slot_rows])
            old, new = self.parameters.slots(start.p, i), self.parameters.slots(moved, i)
            on_old = np.flatnonzero(np.concatenate([old.samples_on, old.on]) > 0)
            on_new = np.flatnonzero(np.concatenate([new.samples_on, new.on]) > 0)
            s_old = np.concatenate([nlp.obstacle_s, old.s])
            s_new = np.concatenate([nlp.obstacle_s, new.s])
            carried = np.zeros(rows.size)
            for j in on_new:  # the start's row nearest along s, within a quarter sample spacing
                k = (
                    on_old[int(np.argmin(np.abs(s_old[on_old] - s_new[j])))]
                    if on_old.size
                    else None
                )
                if k is not None and abs(s_old[k] - s_new[j]) <= reach:
                    carried[j] = start.lam_g[rows[k]]
            lam[rows] = carried
        g = np.asarray(nlp.g_fn(start.z, moved)).ravel()
        return SolverState(start.z, lam, start.lam_x, moved, g=g, contact=start.contact)

    def _linking_failure(self, jump: TP.LinkChange, iterations: int, warm: bool) -> ShapeResult:
        """'failed': the update changed the clamped string's linking number (``_linking_jump``)."""
        return no_shape(
            self.options,
            self.model_summary(),
            "failed",
            (
                f"topology: the linking number of the clamped string changed by {jump.unexplained:+.2f} turns in one "
                f"update (twist {jump.twist:+.3f}, writhe {jump.writhe:+.3f} by {jump.method}, clamps turned "
                f"{jump.clamps:+.3f}): the solver jumped to another branch (whole turns of twist released, or the "
                f"string passed through itself); not published"
            ),
            iterations=iterations,
            warm_started=warm,
        )

    # ---- self-contact (solver/contact/self_contact.py) ----------------------------------------------------------
    def _solve_self_contact(
        self, problem: Problem, warm: bool
    ) -> tuple[ShapeResult, SolverState | None]:
        """Solve with the self-contact slots filled from the start's shape (the committed
        equilibrium, or the cold guess); a pair the answer penetrates is added and the solve
        repeated from the same start (at most ``CONTACT_ROUNDS`` times).  On a warm update a
        crossing sign that flipped since the committed shape, or two samples that meet when the
        shape is moved straight from the committed one to the answer, mean the string (may have)
        passed through itself: 'failed', not committed; so does a change of the clamped span's
        linking number Tw + Wr that the clamps' own turns do not explain (``_linking_jump``: whole
        turns of twist released without the centreline coming near itself).
        """
        st = problem.string
        geometry = SC.contact_geometry(
            st.length,
            st.radius,
            self.options.self_contact_samples,
            tuple(g.s for g in problem.grips),
        )
        capacity = self.nlp.self_contact_slots
        start = self._state if warm else None
        previous = start.contact if start is not None and start.contact is not None else None
        if previous is not None and previous.geometry.key != geometry.key:
            # another radius: the slots' indices mean other samples, and the start's multipliers on
            # them belong to the old pairs: start cold
            start, previous, warm = None, None, False
        slots = previous.pairs if previous is not None else [None] * capacity
        keep = self._loaded_slots(start) if start is not None and previous is not None else set()
        reference = start  # what the sweep and the linking number are checked against
        if (
            previous is not None and previous.candidates is not None
        ):  # the committed shape's, found when committed
            candidates = previous.candidates
        else:
            z0 = start.z if start is not None else self.initial_guess(problem)
            candidates = SC.candidate_pairs(self.model.positions(z0, geometry.s), geometry)
            if start is not None and RC.through_itself(candidates, geometry, st.length):
                # mapped from a model without self-contact, through itself (recovery.py)
                reference = None
        slots, _ = SC.assign(slots, [pair for pair, _ in candidates], keep, capacity)
        slack = RC.SLACK * st.length
        iterations = 0
        committed, round_start = self._state, start
        for _ in range(SC.CONTACT_ROUNDS):
            self._contact = SC.ContactSlots(geometry, slots)
            self._outputs.contact_slots = self._contact
            # a warm update repeats from its (non-penetrating) start; a cold solve from the
            # previous round's answer, whose strands already pass each other on the side they will
            # touch on
            self._state = round_start
            try:
                result, state = self._solve_pairs_fixed(problem, round_start is not None)
            finally:
                self._contact, self._state = None, committed
            iterations += result.iterations
            if state is None:
                return result, None
            points = self.model.positions(state.z, geometry.s)
            candidates = SC.candidate_pairs(points, geometry)
            missing = [
                pair for pair in SC.penetrations(candidates, geometry, slack) if pair not in slots
            ]
            if not missing:
                result.iterations, result.warm_started = iterations, warm
                result.min_self_distance = min((d for _, d in candidates), default=float("inf"))
                signs = (
                    SC.crossing_signs(
                        points, self.model.tangents_at(state.z, geometry.s), candidates
                    )
                    if candidates
                    else {}
                )
                flips = SC.crossing_flips(previous.signs, signs) if previous is not None else []
                if flips:
                    a, b = flips[0]
                    return no_shape(
                        self.options,
                        self.model_summary(),
                        "failed",
                        (
                            f"self-contact: the string passed through itself between the last shape and this one "
                            f"(the crossing at s = {geometry.s[a]:.4g} m and {geometry.s[b]:.4g} m changed sides)"
                        ),
                        iterations=iterations,
                        warm_started=warm,
                    ), None
                swept = (
                    None
                    if reference is None
                    else SC.swept_crossing(
                        self.model.positions(reference.z, geometry.s), points, geometry
                    )
                )
                if swept is not None:
                    a, b = swept
                    return no_shape(
                        self.options,
                        self.model_summary(),
                        "failed",
                        (
                            f"self-contact: this shape is not reached from the last one without the string passing "
                            f"through itself (moved straight, s = {geometry.s[a]:.4g} m and {geometry.s[b]:.4g} m "
                            f"meet on the way); a jump of the solver, not published"
                        ),
                        iterations=iterations,
                        warm_started=warm,
                    ), None
                jump = None if reference is None else self._linking_jump(problem, reference, state)
                if jump is not None:
                    return self._linking_failure(jump, iterations, warm), None
                if reference is None and start is not None:
                    result.message += (
                        "; its warm start passed through itself (mapped from a "
                        "model without self-contact): checked as a cold start"
                    )
                state.contact = SC.ContactSlots(geometry, list(slots), signs, candidates)
                return result, state
            if start is None:
                round_start = state
            # the next round starts from round_start: its loaded slots keep their pairs (Newton
            # uses λ there)
            keep = self._loaded_slots(round_start)
            slots, left = SC.assign(
                slots, missing + [pair for pair, _ in candidates], keep, capacity
            )
            if any(pair in left for pair in missing):
                break
        return no_shape(
            self.options,
            self.model_summary(),
            "failed",
            (
                f"self-contact: the shape still penetrates itself after {SC.CONTACT_ROUNDS} rounds of adding pairs "
                f"(capacity solver.self_contact_pairs = {capacity})"
            ),
            iterations=iterations,
            warm_started=warm,
        ), None

    def _linking_clamps(self, problem: Problem) -> list:
        """The first and the last clamp (by s) when the linking number is conserved (twist
        modelled, two clamps at different s); [] otherwise.
        """
        clamps = sorted((g for g in problem.grips if g.mode == "clamp"), key=lambda g: g.s)
        if (
            not self.nlp.director
            or not self.model.layout.frame
            or len(clamps) < 2
            or clamps[0].s == clamps[-1].s
        ):
            return []
        return [clamps[0], clamps[-1]]

    def _advance_clamp_turns(self, problem: Problem) -> TP.ClampTurns | None:
        """The clamps' turns after this target (``topology.ClampTurns``), from the committed
        shape's own clamp frames when nothing was asked for since it; None without a committed
        shape.
        """
        if self._state is None:
            return None
        clamps = self._linking_clamps(problem)
        if not clamps:
            return None
        turns = self._clamp_turns
        if turns is None or set(turns.frames) != {g.name for g in clamps}:
            turns = self._committed_turns(clamps)
        orientations = np.array([g.pose.orientation for g in clamps])
        key = orientations.tobytes()
        if (
            self._clamp_frames is None or self._clamp_frames[0] != key
        ):  # grips that moved without turning: kept
            self._clamp_frames = (key, quat_to_frame(orientations), None)
        key, frames, last = self._clamp_frames
        if (
            last is not None and last[0] is turns
        ):  # the same step as the last time (queries from one shape)
            return last[1]
        advanced = turns.advanced({g.name: f for g, f in zip(clamps, frames)})
        self._clamp_frames = (key, frames, (turns, advanced))
        return advanced

    def _committed_turns(self, clamps: list) -> TP.ClampTurns:
        """No turn yet, from the committed shape's own clamp frames; kept while that shape is the
        same (queries start from it every time).
        """
        z, names = self._state.z, tuple(g.name for g in clamps)
        cached = self._turns_start
        if cached is None or cached[1] != names or not np.array_equal(cached[0], z):
            s = np.array([g.s for g in clamps])
            cached = (
                z.copy(),
                names,
                TP.ClampTurns({g.name: f for g, f in zip(clamps, self.model.pose_frames(z, s))}),
            )
            self._turns_start = cached
        return cached[2]

    def _linking_jump(
        self, problem: Problem, start: SolverState, state: SolverState
    ) -> TP.LinkChange | None:
        """ΔLk (``topology.link_change``) of the span between the first and the last clamp from the
        committed shape ``start`` to ``state``, when it is a jump (|ΔLk| > ``topology.JUMP``); None otherwise,
        and when the twist is not modelled or fewer than two grips are clamps (Lk is then not
        conserved: a free roll lets the twist out).  The clamps' turns are those summed over every
        target since the committed shape (``_advance_clamp_turns``).
        """
        clamps = self._linking_clamps(problem)
        if not clamps:
            return None
        s = np.linspace(clamps[0].s, clamps[-1].s, TP.SAMPLES)
        turns = self._turns_now
        known = turns is not None and start is self._state
        change = TP.link_change(
            self.model.positions(start.z, s),
            self.model.pose_frames(start.z, s),
            self.model.positions(state.z, s),
            self.model.pose_frames(state.z, s),
            (turns.turns[clamps[0].name], turns.turns[clamps[-1].name]) if known else None,
        )
        return change if change.jumped else None

    def _loaded_slots(self, state: SolverState) -> set[int]:
        """Slots whose row is active in ``state`` as Newton counts it (at its bound with λ > 1e-8:
        IPOPT leaves ~1e-10 barrier multipliers on rows far from their bound).
        """
        g = state.g if state.g is not None else np.asarray(self.nlp.g_fn(state.z, state.p)).ravel()
        return {
            k
            for k, row in enumerate(self.nlp.self_contact_rows)
            if state.lam_g[row] > 1e-8 and g[row] > self.nlp.ubg[row] - 1e-7
        }

    def _solve_pairs_fixed(
        self, problem: Problem, warm: bool
    ) -> tuple[ShapeResult, SolverState | None]:
        moments = self.nlp.director and has_point_moments(problem)
        if (
            moments and warm
        ):  # a warm update under dead moments: Newton on the exact equations first
            ok, state, it, viol = self._exact_newton(self._state, problem)
            if ok:
                result = self._exact_result(problem, state, it, viol, True, 0)
                if result.status == "ok" and result.stable is not False:
                    return result, state
        result, state = self._solve_once(problem, warm)
        if moments and result.status in ("ok", "unverified") and state is not None:
            return self._solve_moments(problem, result, state)
        return result, state

    # ---- point moments (director models) ----------------------------------------------------------
    def _exact_newton(
        self, start: SolverState, problem: Problem, fraction: float = 1.0
    ) -> tuple[bool, SolverState, int, float]:
        """Newton on the exact equilibrium equations (``moments.ExactMomentKKT``) from ``start`` to
        ``problem`` with its point moments scaled by ``fraction``.
        """
        p = self.pack_parameters(problem, start.z, keep=start.p)
        start = self._carry_slots(start, p)
        if fraction != 1.0:
            for i, _ in enumerate(problem.loads):
                p[self.nlp.params[f"load:{i}:moment"]] *= fraction
        return newton(
            self.nlp,
            self.functions,
            start,
            p,
            max_steps=MOMENT_NEWTON_STEPS,
            kkt_fn=ExactMomentKKT(self.nlp, self.functions, self.parameters, problem),
        )

    def _exact_result(
        self,
        problem: Problem,
        state: SolverState,
        iterations: int,
        violation: float,
        warm: bool,
        steps: int,
    ) -> ShapeResult:
        """The result of an exact-moment Newton solution: the pseudo-potential re-centred on it
        (its gradient is then M·δθ exactly), derivatives re-evaluated there for the stability
        verdict.
        """
        p = self.pack_parameters(problem, state.z)
        for i in range(
            len(problem.obstacles) if self.nlp.obstacle_slots else 0
        ):  # the slots z was solved with
            for name in self.nlp.slot_parameters(i):
                p[self.nlp.params[name]] = state.p[self.nlp.params[name]]
        state.p = p
        state.hessian = state.jacobian = state.gradient = state.energies = state.kkt = (
            state.residual
        ) = None
        state.reduced_eigen = state.outputs = None
        state.g = None
        return self._result(
            problem, state, "Newton (exact moments)", iterations, violation, warm, steps
        )

    def _solve_moments(
        self, problem: Problem, result: ShapeResult, state: SolverState
    ) -> tuple[ShapeResult, SolverState | None]:
        """Dead point moments: the answer of ``_solve_once`` applied them through a
        pseudo-potential centred on its start, so it is polished by Newton on the exact equilibrium
        equations.  Where the moment turned the string too far for that, the moments are raised
        from zero along the exact equations (steps of a fraction of the moment, halved on a failed
        step, at most MOMENT_CONTINUATION_SOLVES Newton solves), starting from the scene without
        its moments (a true potential, solved by the usual warm update).
        """
        iterations = result.iterations
        ok, new, it, viol = self._exact_newton(state, problem)
        iterations += it
        if ok:
            return self._escape_saddle_moments(
                problem,
                self._exact_result(problem, new, iterations, viol, result.warm_started, 0),
                new,
            )
        p0 = self.pack_parameters(problem, state.z, keep=state.p)
        for i, _ in enumerate(problem.loads):
            p0[self.nlp.params[f"load:{i}:moment"]] = 0.0
        ok, base, it, viol = self._newton(state, p0)
        iterations += it
        if not ok:
            ok, base, _, it, viol = self._ipopt_call(True, state.z, p0, state)
            iterations += it
        if not ok:
            return self._moment_failure(
                result,
                iterations,
                "the scene without its moments did not solve from the pseudo-potential's answer",
            )
        fraction, step, solves = 0.0, 0.25, 0
        while fraction < 1.0 and solves < MOMENT_CONTINUATION_SOLVES:
            target = min(1.0, fraction + step)
            ok, new, it, viol = self._exact_newton(base, problem, target)
            iterations += it
            solves += 1
            if ok:
                base, fraction, step = new, target, min(0.5, 2.0 * step)
            else:
                step *= 0.5
        if fraction < 1.0:
            return self._moment_failure(
                result,
                iterations,
                (
                    f"raising the moments from zero along the exact equilibrium equations stopped at {fraction:.3g} of "
                    f"them after {solves} Newton solves (a limit point: the moment may snap the string through)"
                ),
            )
        return self._escape_saddle_moments(
            problem,
            self._exact_result(problem, base, iterations, viol, result.warm_started, solves),
            base,
        )

    def _escape_saddle_moments(
        self, problem: Problem, result: ShapeResult, state: SolverState
    ) -> tuple[ShapeResult, SolverState]:
        """``_escape_saddle`` where every re-solve is polished on the exact equilibrium
        equations.
        """

        def attempt(z0: np.ndarray, p: np.ndarray) -> Attempt:
            ok, trial, status, it, viol = self._ipopt_call(False, z0, p, escape=True)
            if not ok:
                return ok, trial, status, it, viol
            ok, polished, it2, viol = self._exact_newton(trial, problem)
            return ok, polished, status, it + it2, viol

        def build(
            trial: SolverState, status: str, iterations: int, viol: float, warm: bool, steps: int
        ) -> ShapeResult:
            return self._exact_result(problem, trial, iterations, viol, warm, steps)

        return escape_saddle(result, state, attempt, build)

    def _moment_failure(
        self, result: ShapeResult, iterations: int, why: str
    ) -> tuple[ShapeResult, None]:
        return no_shape(
            self.options,
            self.model_summary(),
            "failed",
            f"point moments: {why}",
            iterations=iterations,
        ), None

    def _solve_once(self, problem: Problem, warm: bool) -> tuple[ShapeResult, SolverState | None]:
        iterations, steps, last_status = 0, 0, ""
        unverified: tuple[ShapeResult, SolverState] | None = (
            None  # IPOPT's warm answer, over the residual tolerance
        )
        cold: Attempt | None = None  # the cold solve's attempt, once made
        # the warm and the cold attempt both found the targets infeasible (no continuation)
        agreed = False
        if warm:
            p1 = self.pack_parameters(problem, self._state.z, keep=self._state.p)
            start = self._carry_slots(self._state, p1)
            ok, state, it, viol = self._newton(start, p1, problem)
            iterations += it
            if not ok:
                ok, state, it, viol = self._newton_in_substeps(start, p1, problem)
                iterations += it
                self._newton_far = ok
            if ok:
                result = self._result(problem, state, "Newton", iterations, viol, True, 0)
                if (
                    result.stable is not False and result.status != "failed"
                ):  # (failed: a flipped branch)
                    return result, state
                if result.stable is False:
                    left, iterations = self._leave_saddle(problem, result, state, iterations)
                    if left is not None:
                        self._newton_far = True
                        return left
                ok = False
            ok, state, last_status, it, viol = self._ipopt_call(True, start.z, p1, start)
            iterations += it
            k = 2
            if not ok and last_status == INFEASIBLE:
                # the targets themselves may admit no shape: the cold solve says so at once, where
                # the continuation's steps would each be solved before its last one failed the same
                # way (the default cable's grip put under its table: 6.5 s, 15 IPOPT calls)
                cold = self._cold_ipopt(problem)
                iterations += cold[3]
                if not cold[0] and cold[2] == INFEASIBLE:
                    k, agreed = self.options.max_continuation_steps + 1, True
            while not ok and k <= self.options.max_continuation_steps:
                state, ok = start, True
                for i in range(1, k + 1):
                    p_i = start.p + (p1 - start.p) * (i / k)
                    ok, state, last_status, it, viol = self._ipopt_call(True, state.z, p_i, state)
                    iterations += it
                    if not ok:
                        break
                steps = k if ok else 0
                k *= 2
            if ok:
                result = self._result(problem, state, last_status, iterations, viol, True, steps)
                if result.status == "ok":
                    escaped = self._escape_saddle(problem, result, state)
                    return (
                        escaped
                        if escaped[0].stable is not False
                        else self._stable_cold(problem, *escaped)
                    )
                if result.status == "unverified":
                    # IPOPT from the warm start can end on a spurious stationary point of the
                    # discrete problem (a folded field, residual of metres); the cold guess
                    # decides, the smaller residual wins
                    unverified = (result, state)
        if cold is None:
            cold = self._cold_ipopt(problem)
            iterations += cold[3]
        ok, state, last_status, _, viol = cold
        if ok:
            result = self._result(problem, state, last_status, iterations, viol, False, 0)
            if unverified is not None and not (
                result.status == "ok"
                or result.status == "unverified"
                and result.equilibrium_residual_m < unverified[0].equilibrium_residual_m
            ):
                result, state = unverified
                result.iterations = iterations
            if result.status != "failed":
                return self._escape_saddle(problem, result, state)
            last_status = result.message
        elif unverified is not None:
            unverified[0].iterations = iterations
            return self._escape_saddle(problem, *unverified)
        status = "infeasible" if last_status == INFEASIBLE else "failed"
        message = (
            f"IPOPT: {last_status} (constraint violation {viol:.3g}{witness(self.nlp, state.g)})"
            + (
                "; so did the warm start"
                if agreed
                else "; warm start and continuation also failed"
                if warm
                else ""
            )
        )
        # a failed result carries no shape, energy, wrench or eigenvalue that could be mistaken for
        # one
        return no_shape(
            self.options,
            self.model_summary(),
            status,
            message,
            iterations=iterations,
            constraint_violation=viol,
            warm_started=warm,
            ipopt_status=last_status,
        ), None

    def _leave_saddle(
        self, problem: Problem, saddle: ShapeResult, state: SolverState, iterations: int
    ) -> tuple[tuple[ShapeResult, SolverState] | None, int]:
        """A warm Newton update that landed on an unstable equilibrium, continued downhill by
        shifted Newton steps (``newton.leave_saddle``, either way along the unstable mode): (the
        first stable, verified result of lower energy, or None: then IPOPT and ``_escape_saddle``
        take over; the iterations counted so far).  Where the steps reach only a lower but still
        unstable equilibrium, that one is left by ``_escape_saddle`` (a cable lying on a table that
        buckles out of its plane: the steps hold the table's contacts and stop on a lower saddle;
        IPOPT's warm start from the update's start falls back onto the first saddle, whose escapes
        can run to their iteration limit).
        """
        lower: tuple[ShapeResult, SolverState] | None = None
        for sign in (1.0, -1.0):
            ok, new, it, viol = leave_saddle(
                self.nlp,
                self.functions,
                state,
                state.p,
                saddle.min_eigenvalue,
                sign,
                fused=self.fused_newton,
            )
            iterations += it
            if not ok:
                continue
            result = self._result(problem, new, "Newton", iterations, viol, True, 0)
            if result.status != "ok" or not lower_than(result, saddle):
                continue
            if result.stable:
                result.message += LEFT_SADDLE
                return (result, new), iterations
            if result.stable is False and lower is None:
                lower = (result, new)
        if lower is not None:
            lower[0].iterations = iterations
            result, new = self._escape_saddle(problem, *lower)
            iterations = result.iterations
            if result.status == "ok" and result.stable:
                return (result, new), iterations
        return None, iterations

    def _stable_cold(
        self, problem: Problem, unstable: ShapeResult, state: SolverState
    ) -> tuple[ShapeResult, SolverState]:
        """A warm update that found only unstable equilibria near its start (Newton, IPOPT and the
        escapes): the cold solve from the initial guess instead, if it is verified, stable and
        lower. (The planar cable pressed onto the table: every escape from the planar saddle
        failed, the cold solve found the stable out-of-plane shape.)  Otherwise the unstable
        answer, as it was.
        """
        ok, cold, status, it, viol = self._cold_ipopt(problem)
        unstable.iterations += it
        if ok:
            result = self._result(problem, cold, status, unstable.iterations, viol, False, 0)
            if result.status == "ok":
                result, cold = self._escape_saddle(problem, result, cold)
            if result.status == "ok" and result.stable and lower_than(result, unstable):
                result.message += "; no stable equilibrium near the warm start: solved cold"
                return result, cold
        return unstable, state

    def _escape_saddle(
        self, problem: Problem, result: ShapeResult, state: SolverState
    ) -> tuple[ShapeResult, SolverState]:
        """Leave an unstable stationary point along its negative-curvature mode
        (``ipopt.escape_saddle``).
        """
        return escape_saddle(
            result,
            state,
            lambda z0, p: self._ipopt_call(False, z0, p, escape=True),
            lambda *attempt: self._result(problem, *attempt),
        )

    # ---- results ----------------------------------------------------------------------------------
    def _failure(self, status: str, message: str, t0: float) -> ShapeResult:
        return no_shape(
            self.options,
            self.model_summary(),
            status,
            message,
            solve_time_ms=(time.perf_counter() - t0) * 1e3,
        )

    def model_summary(self) -> ModelSummary:
        """What this solver models (the ``model`` of a result); made once per NLP, string and
        obstacle count (all it depends on).
        """
        key = (self.nlp, self.problem.string, len(self.problem.obstacles))
        known = getattr(self, "_summary", None)
        if (
            known is None
            or any(a is not b for a, b in zip(known[0][:2], key))
            or known[0][2] != key[2]
        ):
            known = self._summary = (key, self._model_summary())
        return known[1]

    def _model_summary(self) -> ModelSummary:
        lay = self.model.layout
        common = dict(
            planar=lay.planar,
            twist=lay.twist,
            stretch=lay.stretch,
            gravity=not self.problem.string.weight_per_length.is_zero,
            order=lay.order,
            obstacles=len(self.problem.obstacles),
            variables=lay.size,
        )
        if self.nlp.director:
            return ModelSummary(
                **common,
                rotation="quaternion" if lay.frame else "tangent",
                elements=lay.elements,
                breakpoints=tuple(float(b) for b in self.model.mesh.breakpoints),
                self_contact_pairs=self.nlp.self_contact_slots,
            )
        return ModelSummary(**common, rotation="planar" if lay.planar else "euler")

    def _result(
        self,
        problem: Problem,
        state: SolverState,
        ipopt_status: str,
        iterations: int,
        violation: float,
        warm: bool,
        steps: int,
    ) -> ShapeResult:
        return self._outputs.result(
            problem,
            self.problem,
            state,
            ipopt_status,
            iterations,
            violation,
            warm,
            steps,
            self.model_summary(),
        )
