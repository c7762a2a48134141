"""ShapeSolver: warm-started, thread-safe equilibrium solves of one scene structure.

Contract:
* The NLP is built once per structure (StringNLP); ``solve`` only changes parameter values.
* ``solve(poses)`` warm-starts from the last committed equilibrium.  The update itself is a
  pipeline of stages in ``solver/update/`` (``pipeline.py``: Newton, IPOPT, continuation, the
  cold fallback, saddle escapes, point moments, self-contact rounds, obstacle slots, the
  linking-number check, substeps), each taking and giving an explicit ``UpdateContext``
  (``update/context.py``).  ``commit=False`` answers a query without touching the warm-start
  state.
* Grip orientations become parameter targets (``parameters.py``); for the Euler models, angles
  unwrapped to the current shape (φ, ψ + 2πk), so an end turned by several revolutions in small
  steps is tracked.
* Every call returns a ShapeResult (``outputs.py``); bad input gives status 'invalid', grips
  farther apart than the string reaches 'unreachable' — never an exception.
* One lock serialises every entry: CasADi's IPOPT must never run in two threads at once.  MUMPS
  (IPOPT's linear solver) is not thread-safe across instances either, so every IPOPT call in the
  process also holds the module-wide ``IPOPT_LOCK`` (Newton updates and derivative evaluations do
  not).
* With ``lazy_ipopt`` the IPOPT solvers are created on first use (``prepare()`` creates them
  ahead): a helper used only for Newton updates or stability checks never needs them.
  ``lazy_outputs``: ``NlpFunctions``' (``functions.py``).

ShapeSolver holds the lock, the state (NLP, scene, committed equilibrium, compile thread) and the
public API; the work is done by the stages named above and by ``functions.py`` (the NLP's
derivatives, compiled in the background), ``stability.py``, ``frames.py``, ``wrenches.py`` and
``warm_start.py``.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections.abc import Mapping, Sequence

import numpy as np

from ..model.problem import GripPose, Problem
from .build import frames as F
from .build.functions import COMPILE_MODES, NlpFunctions, check_compile_mode
from .build.initial_guess import initial_guess
from .build.mesh import MeshSpec
from .build.mesh_clone import clone_or_build
from .build.nlp import StringNLP
from .build.parameters import ProblemParameters, check_moments
from .contact import topology as TP
from .contact.apart_memo import ApartMemo
from .options import SolverOptions
from .parallel.batch import query_many
from .results.outputs import ShapeOutputs, no_shape
from .results.residual import EquilibriumResidual, PointAction, equilibrium_residual
from .results.result import GripWrench, ShapeResult
from .results.stability import is_stable, stability_verdict
from .results.summary import ModelSummary
from .results.wrenches import balance_inputs
from .state import SolverState
from .update import attempts as AT
from .update.context import SolverParts, UpdateContext
from .update.inputs import admit, only_poses_differ, structure_key, unreachable_reason
from .update.inputs import with_checked_poses
from .update.ipopt import IPOPT_LOCK, SUCCESS, IpoptSolvers
from .update.linking import ClampTurnTracker
from .update.moments import MOMENT_CONTINUATION_SOLVES, MOMENT_NEWTON_STEPS
from .update.newton import fill_start
from .update.pipeline import run_update
from .update.summary import ModelSummaries
from .update.time_limit import LimitStrikes, is_limited, limit_message
from .update.warm_start import Adoption, adopted_copy, adopted_state, held_poses, sample_source
from .update.warm_start import only_mesh_differs

__all__ = [
    "COMPILE_MODES",
    "IPOPT_LOCK",
    "MOMENT_CONTINUATION_SOLVES",
    "MOMENT_NEWTON_STEPS",
    "SUCCESS",
    "ShapeSolver",
    "SolverState",
    "is_stable",
    "only_poses_differ",
    "structure_key",
    "with_checked_poses",
]


class ShapeSolver:
    """Solve the string's static shape for changing grip targets (see module docstring)."""

    # set by _build (which frees the previous ones when it rebuilds)
    _ipopt: IpoptSolvers
    functions: NlpFunctions
    nlp: StringNLP
    _key: tuple

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions | None = None,
        compile: str = "background",
        lazy_ipopt: bool = False,
        reference_frame: np.ndarray | None = None,
        mesh: MeshSpec | None = None,
        template: ShapeSolver | None = None,
        lazy_outputs: bool = False,
    ):
        """Build the NLP of ``problem``'s structure; raise ValueError naming a refused field.

        compile: 'background' (solve at once with interpreted derivatives, compile them to C in a
        background thread and switch when ready; cached per machine), 'blocking' (compile or load
        now), 'cached' (use a library compiled earlier, never compile), 'on_query' ('cached' until
        a query finds a library missing, then compile it: ``build/functions.py``), or 'off'.
        $DLO_NO_COMPILE forces 'off'.  lazy_ipopt: create the IPOPT solvers on first use (helpers
        that may only take Newton steps); otherwise now, so that a stream's first IPOPT fallback
        does not pay for them.  lazy_outputs: ``NlpFunctions``'.  reference_frame: a fixed R0 for
        the Euler angles (3D models; default: chosen from the scene, ``choose_reference_frame``).
        mesh: the element mesh a refinement chose (``build/mesh.py``; default: the scene's
        breakpoints).  template: a solver of this structure whose functions serve ``mesh`` too
        (``build/mesh_clone.py``), or None.
        """
        check_compile_mode(compile)
        self.options = options or SolverOptions()
        self.compile_mode = compile
        self.lazy_ipopt, self.lazy_outputs = lazy_ipopt, lazy_outputs
        self.reference_frame = (
            None if reference_frame is None else np.array(reference_frame, dtype=float)
        )
        self.mesh_spec = mesh
        self._lock = threading.Lock()
        self._compile_thread: threading.Thread | None = None
        # a compile is about to start (AutoShapeSolver._compile_ahead)
        self.compile_pending = False
        #: (answer, its state) of the last solve that did not commit: a refined query's start
        self.query_answer: tuple[ShapeResult, SolverState] | None = None
        self._summaries = ModelSummaries()
        self._build(problem, template)

    def _build(self, problem: Problem, template: ShapeSolver | None = None) -> None:
        """Build the NLP of ``problem``'s structure and its parts; forget the warm start."""
        t0 = time.perf_counter()
        key = structure_key(problem, self.options) if template is not None else None
        shared = template.nlp if template is not None and template._key == key else None
        nlp = clone_or_build(problem, self.options, self.reference_frame, self.mesh_spec, shared)
        # before anything is replaced: a refused scene leaves the solver as it was
        check_moments(nlp, problem)
        self.nlp = nlp
        if hasattr(self, "_ipopt"):
            self._ipopt.free()
        self._ipopt = IpoptSolvers(self.nlp)
        if not self.lazy_ipopt:
            self._ipopt.prepare()
        if hasattr(self, "functions"):
            self.functions.retire()  # a compile still running for the old NLP stops there
        self.functions = NlpFunctions(self.nlp, lazy_outputs=self.lazy_outputs)
        # the first Newton steps in one call of newton_fn (around the compiled contact-free
        # function once that is loaded); False: one evaluation and one LAPACK solve per step from
        # Python
        self.fused_newton = True
        self.parameters = ProblemParameters(self.nlp)
        #: the results' outputs (shape, wrenches, contacts) of this NLP
        self.outputs = ShapeOutputs(self.nlp, self.functions, self.parameters, self.options)
        # the old NLP's compile (retired above) must not block a new one
        self._compile_thread = None
        self._start_compile()
        self.problem = problem
        self._key = structure_key(problem, self.options)
        self._state: SolverState | None = None
        self._adopted: Adoption | None = None  # adopt_warm_start's last mapping
        # the clamps' turns over the targets since the committed shape (None: none asked for
        # since; topology.ClampTurns, the linking-number check), and the frames computed for them
        self._clamp_turns: TP.ClampTurns | None = None
        self._turn_tracker = ClampTurnTracker(nlp)
        # the shape the self-pass check proved apart last (contact/apart_memo.py)
        self._apart = ApartMemo()
        self._strikes = LimitStrikes()  # update/time_limit.py: one strike of the time limit
        self.build_time_s = time.perf_counter() - t0

    # ---- compiled derivatives and IPOPT instances ---------------------------------------------
    def prepare(self) -> None:
        """Create the IPOPT solvers and the contact-free Newton functions now, not on first use."""
        with self._lock:
            self._ipopt.prepare()
            self.functions.prepare_newton()

    def start_compile(self, mode: str) -> None:
        """Switch the compile mode and start compiling if that mode asks for it.

        E.g. a helper solver promoted to stream; a compile starts when nothing is compiled or
        compiling yet (any thread: the libraries already cached are swapped in under the solver's
        lock).
        """
        check_compile_mode(mode)
        with self._lock:
            self.compile_mode = mode
            if mode in ("background", "blocking"):  # it streams now: its outputs compile too
                self.functions.build_outputs()
            if not self.all_compiled and self._compile_thread is None:
                self._start_compile()

    def _start_compile(self) -> None:
        """Load or compile the derivatives as the compile mode says; keep a background thread."""
        thread = self.functions.start_compile(self.compile_mode, self._lock)
        if thread is not None:
            self._compile_thread = thread

    def wait_for_compile(self, timeout: float | None = None) -> bool:
        """Wait for a background compile to finish; True if compiled derivatives are in use."""
        if self._compile_thread is not None:
            self._compile_thread.join(timeout)
        return self.kkt_compiled

    @property
    def compile_thread(self) -> threading.Thread | None:
        """The background compile's thread, once started (None before, and after a rebuild)."""
        return self._compile_thread

    @property
    def all_compiled(self) -> bool:
        """Whether every function a solve calls runs compiled C.

        The derivatives and, for the models that have one, the outputs' function (a new version
        may change it alone: its derivatives then load from the cache, and it still has to be
        compiled).
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
        """Wall time [s] of the compile that made ``kkt_compiled`` true (0: loaded or none)."""
        return self.functions.compile_time_s

    # ---- public API ----------------------------------------------------------------------------
    @property
    def model(self):
        """Discretised field model of the NLP: a ``RitzModel`` or a ``DirectorModel``."""
        return self.nlp.model

    @property
    def has_warm_start(self) -> bool:
        """Whether an equilibrium is committed (the next solve is warm)."""
        return self._state is not None

    @property
    def committed_state(self) -> SolverState | None:
        """The committed equilibrium itself, not a copy (``snapshot`` copies).

        For the thread that streams, between its solves.  A commit replaces the object; nothing
        changes its z, λ or p in place.
        """
        return self._state

    def snapshot(self) -> SolverState | None:
        """Return a copy of the committed equilibrium (for a later adopt_warm_start elsewhere)."""
        with self._lock:
            return None if self._state is None else self._state.copy()

    def adopt_warm_start(self, other: ShapeSolver, state: SolverState | None = None) -> bool:
        """Take ``other``'s committed equilibrium as this solver's warm start, across models.

        The mapping is ``warm_start.py``'s.  ``state``: an earlier ``other.snapshot()`` to adopt
        instead of other's current equilibrium.  False when there is nothing to adopt.
        """
        with other._lock:
            src = other._state if state is None else state
            if src is None:
                return False
            if self._adopt_again(other, src):
                return True
            source = sample_source(other, src, self.nlp)
            held = held_poses(other.parameters, other.problem, src) if state is None else None
        # warm_state evaluates this solver's functions: never beside a solve of it
        with self._lock:
            # at the grip targets ``src`` holds (its equilibrium's own), so that a solve from it
            # moves them from there: substeps (``substeps.newton_in_substeps``) then split a real
            # move
            at = self.problem if held is None else self.problem.with_grip_poses(held)
            contact = getattr(src, "contact", None)
            length = self.problem.string.length
            parts = self.nlp, self.functions, self.parameters
            state = adopted_state(*parts, at, source, contact, length)
            state.remeshed = only_mesh_differs(self, other)
            self._state, self._clamp_turns, self._adopted = state, None, None
            if contact is None:  # what every query from it reuses: its derivatives, evaluated once
                fill_start(self.nlp, self.functions, state)
                self._adopted = Adoption(weakref.ref(other), weakref.ref(src), state, self.problem)
                self._state = adopted_copy(state)
        return True

    def install_warm_start(self, state: SolverState) -> None:
        """Commit ``state`` (this NLP's z, λ, p and ``fill_start``'s derivatives) as warm start."""
        with self._lock:
            self._state, self._clamp_turns, self._adopted = state, None, None

    def _adopt_again(self, other: ShapeSolver, src: SolverState) -> bool:
        """Adopt again what was adopted last time from the same state ``src`` of ``other``.

        Without sampling and mapping it again, when this solver's scene differs from that
        adoption's in grip poses at most (``only_poses_differ``: the mapping is then the same, at
        the grip targets ``src`` holds; a solve from it moves them to the scene's).  What a query
        that another model answers does on every call: the held shape is the same until the
        stream commits.
        """
        adopted = self._adopted
        if adopted is None or not adopted.is_of(other, src):
            return False
        with self._lock:
            if not only_poses_differ(self.problem, adopted.scene):
                return False
            self._state = adopted_copy(adopted.adopted)
            self._clamp_turns = None
        return True

    def forget_adoption(self) -> None:
        """Forget the last adoption's mapping: the next ``adopt_warm_start`` maps afresh."""
        self._adopted = None

    def unstable_eigenvalue(self) -> float | None:
        """Return the reduced Hessian's smallest eigenvalue at the committed shape if unstable.

        Unstable as ``stability.is_stable`` says; None when it is stable or neutral, when the
        active rows leave no freedom, or when nothing is committed.
        """
        with self._lock:
            state = self._state
            if state is None:
                return None
            stable, eig = stability_verdict(self.nlp, self.functions, state)
            if stable:
                return None
            assert isinstance(eig, float)  # an unstable verdict is the eigenvalue path's number
            return eig

    def reset(self) -> None:
        """Forget the warm start: the next solve starts cold."""
        with self._lock:
            self._state = None
            self._clamp_turns = None

    def close(self) -> None:
        """Release nothing: a background compile is a daemon thread (the Solver protocol's)."""

    def set_problem(self, problem: Problem) -> None:
        """Replace the scene's values (properties, loads, obstacles, grips).

        Same structure: only parameter values change and the warm start is kept.  Otherwise the NLP
        is rebuilt (and the next solve is cold).  Raises ValueError naming the offending field.
        """
        with self._lock:
            # validated already, the same structure and values
            if only_poses_differ(problem, self.problem):
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
        poses: Mapping[str, GripPose | tuple] | None = None,
        *,
        warm: bool = True,
        commit: bool = True,
        checked: bool = False,
        check_now: bool = False,
        limited: bool | None = None,
    ) -> ShapeResult:
        """Equilibrium with the given grip poses (missing grips keep their current target).

        checked: the poses are GripPose objects already validated (``with_checked_poses``) and, for
        a planar model, already found in its plane (AutoShapeSolver checks both before calling).
        check_now: accepted for the interface AutoShapeSolver shares; a fixed model's checks (the
        equilibrium residual and the stability eigenvalue) always run inside every solve.
        limited: whether a warm solve stops at ``solver.update_time_limit``; None: exactly when it
        commits (a streamed update; never a cold solve or a query, ``update/time_limit.py``).
        """
        with self._lock:
            t0 = time.perf_counter()
            admitted = admit(self.problem, self.nlp, self.options, poses, checked)
            if isinstance(admitted, tuple):  # (status, message): refused
                return self._failure(*admitted, t0)
            problem = admitted
            ctx = self.update_context()
            ctx.turns = self._turn_tracker.advance(self._state, self._clamp_turns, problem)
            self.functions.solved(self.compile_mode)
            started = self.functions.refresh(self.compile_mode, not commit, self._lock)
            self._compile_thread = started or self._compile_thread
            warm, limit = warm and self._state is not None, self.options.update_time_limit
            ctx.streamed = is_limited(warm, commit, limited)
            ctx.deadline = self._strikes.deadline(t0, limit, ctx.streamed)
            result, state = run_update(ctx, problem, warm, self._turn_tracker, self._apart)
            self.query_answer = None if commit or state is None else (result, state)
            if self._strikes.stopped(ctx.deadline, result.status):
                result.message = limit_message(limit, result.message)
            result.solve_time_ms = (time.perf_counter() - t0) * 1e3
            result.derivatives = "compiled" if self.functions.compiled else "interpreted"
            if commit:  # every target of the stream counts, failed ones too (topology.ClampTurns)
                self._clamp_turns = ctx.turns
            # an unverified result is a converged stationary point of the discrete problem: a good
            # warm start
            if commit and result.status in ("ok", "unverified") and state is not None:
                self._state = state
                self.problem = problem
                self._clamp_turns = None if ctx.turns is None else ctx.turns.committed()
            return result

    def update_context(self) -> UpdateContext:
        """Return a fresh update context at the committed state (the caller holds the lock).

        What ``solve`` hands down the stages of ``solver/update/``; also a test's way to run one
        stage by itself.
        """
        own = (self.nlp, self.functions, self.parameters, self.outputs, self._ipopt)
        parts = SolverParts(*own, self.options, self.fused_newton, self.model_summary)
        return UpdateContext(parts, self.problem, self._state, self._clamp_turns)

    def query_many(self, targets, executor=None) -> list[ShapeResult]:
        """Answer many independent queries (``{grip: pose}`` each) in worker processes, in order.

        With this solver's scene and options; this solver and its warm start are untouched
        (dlo_ros.solver.parallel.batch.query_many: ``executor`` defaults to a process pool on
        every core).
        """
        return query_many(ShapeSolver, self.problem, self.options, targets, executor)

    def unreachable_reason(self, problem: Problem) -> str:
        """Return why the position constraints cannot all hold (empty string if they can)."""
        return unreachable_reason(problem, self.options)

    # ---- the solution's parameters, start and fields (parameters, initial_guess, frames) ------
    def pack_parameters(
        self, problem: Problem, z_reference: np.ndarray, keep: np.ndarray | None = None
    ) -> np.ndarray:
        """Return the NLP parameter vector for ``problem`` (``attempts.pack_parameters``).

        Angles unwrapped to, and obstacle contact slots placed on, the shape ``z_reference``
        (``keep``: a vector whose slots stay while still placed well).
        """
        return AT.pack_parameters(self.parameters, problem, z_reference, keep)

    def grip_angles(self, pose: GripPose, reference: tuple[float, float, float]) -> np.ndarray:
        """Euler angles (φ, θ, ψ) of a grip orientation, on the branch nearest ``reference``."""
        return self.parameters.grip_angles(pose, reference)

    def initial_guess(self, problem: Problem) -> np.ndarray:
        """Return the buckled cold-start guess z for ``problem``."""
        return initial_guess(self.nlp, self.parameters, problem)

    def strain(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return ε(s) of solution z (zeros when inextensible)."""
        return F.strain(self.nlp, z, s)

    def frames_psi(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """Return ψ(s) as published: the solved field, or the zero-twist ψ from the first grip."""
        return F.frames_psi(self.nlp, self.parameters, self.problem, z, s, p)

    def pose_frames(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """Return z's frames (len(s), 3, 3), pose convention; at parameters ``p`` if given."""
        return F.pose_frames(self.nlp, self.parameters, self.problem, z, s, p)

    def frames(self, z: np.ndarray, s: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """Return the material frames Q(s) (columns ξ, η, ζ) of z (zero-twist ψ if unsolved)."""
        return F.frames(self.nlp, self.parameters, self.problem, z, s, p)

    def equilibrium(
        self,
        problem: Problem,
        z: np.ndarray,
        grips: dict[str, GripWrench],
        contacts: Sequence[PointAction] = (),
        lam_si: np.ndarray | None = None,
    ) -> EquilibriumResidual:
        """Return the strong-form equilibrium residual of shape z under the given reactions.

        The grip reactions ``grips``, the obstacle ``contacts`` and (given the SI multipliers) the
        relative positions' reactions (solver/results/residual.py).
        """
        return equilibrium_residual(balance_inputs(self.nlp, problem, z, grips, contacts, lam_si))

    # ---- results -------------------------------------------------------------------------------
    def _failure(self, status: str, message: str, t0: float) -> ShapeResult:
        """Return the result without a shape: ``status`` and ``message``, timed from ``t0``."""
        ms = (time.perf_counter() - t0) * 1e3
        return no_shape(self.options, self.model_summary(), status, message, solve_time_ms=ms)

    def model_summary(self) -> ModelSummary:
        """Return what this solver models (the ``model`` of a result; ``update/summary.py``)."""
        return self._summaries.get(self.nlp, self.problem)
