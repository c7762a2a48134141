"""The a-posteriori checks of a committed shape: gather the evidence, and apply auto's policy.

:meth:`ModelChecks.evaluate` takes a :class:`CheckSnapshot` (what a check needs of one committed
solve, safe to hand to the worker thread), measures it through :class:`ShapeEvidence` as the
policy asks (:func:`.policy.decide`: planar stability in 3D, the elongation bound, the Euler-angle
pole, then the element mesh or the order ladder, then the obstacle samples) and returns a
:class:`CheckVerdict`: ``choice`` None to keep the model (with its error estimate), or the richer
model and why.  The measurements live in :mod:`.shadows` and :mod:`.mesh_check`; the rule in
:mod:`.policy`.

Every model a verdict names is built (and warm) before the check returns, after its decision is
known, so the streaming thread's switch builds nothing.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, field, replace

import numpy as np

from ...model.problem import Problem
from ..build.mesh import MeshSpec
from ..results.result import ShapeResult
from ..shape_solver import ShapeSolver
from ..state import SolverState
from .choice import ModelChoice, full_choice
from .mesh_check import MeshVerdict, has_elements, mesh_verdict
from .policy import decide
from .pool import ModelPool
from .shadows import (
    farthest_pole,
    penetration,
    pole_angle,
    planar_3d_eigenvalue,
    shadow_error,
    shadow_solve,
    turned_frame,
)


@dataclass
class CheckSnapshot:
    """What a check needs of one committed solve (taken on the streaming thread).

    ``inner``/``state``: the solver that committed it and a copy of its state; ``choice``: a copy
    of its model; ``points``: its output points [m]; ``max_grip_force`` [N]; ``generation``: the
    AutoShapeSolver's switch count then (an older verdict is stale); ``residual_m``: its
    strong-form equilibrium residual (solver/results/residual.py, inf when unknown);
    ``touching``: it presses on an obstacle, ``contacts``: which, with their total forces [N]
    (``reach.pressed_obstacles``); ``update``: the streamed-update count then;
    ``limited``: the check's re-solves stop at ``solver.update_time_limit`` (only a streamed
    update's check: a cold solve's or a query's runs to its end, ``update/time_limit.py``).
    """

    inner: ShapeSolver
    state: SolverState | None
    choice: ModelChoice
    problem: Problem
    poses: dict
    points: np.ndarray
    max_grip_force: float
    generation: int = 0
    residual_m: float = 0.0
    touching: bool = False
    update: int = 0
    limited: bool = True
    contacts: dict[int, float] = field(default_factory=dict)
    #: the check's own solves of other models at ``poses`` from this shape (``shadows``): model
    #: key → (its answer, a copy of the state it committed)
    answers: dict[tuple, tuple[ShapeResult, SolverState]] = field(default_factory=dict)


@dataclass
class CheckVerdict:
    """A check's outcome: escalate to ``choice`` (with ``reason``), or keep with ``estimate``.

    ``estimate`` [m]: the kept model's error estimate (order part + sampling part);
    ``order_error``/``sampling_error`` [m]: its two parts (nan: not measured).  ``answer``: the
    answer of ``choice`` at the snapshot's poses, solved by the check from the snapshot's shape,
    and the state it committed (None: not solved there) — what a re-solve on the switched-to
    model at those poses would repeat.
    """

    snapshot: CheckSnapshot
    choice: ModelChoice | None = None
    reason: str = ""
    estimate: float = float("nan")
    order_error: float = float("nan")
    sampling_error: float = float("nan")
    answer: tuple[ShapeResult, SolverState] | None = None


class ShapeEvidence:
    """The measurements of a snapshot's shape (:class:`.policy.Evidence`), taken when asked for.

    The models a measurement solves on are pooled (:mod:`.shadows`): they are the ones an
    escalation switches to.  ``lower``: a lower order may be tried (not in a query's checks, which
    leave the stream's record of tries alone); ``lower_tried``: model keys already tried as a
    lower order, to which a try is added.
    """

    def __init__(
        self,
        pool: ModelPool,
        snap: CheckSnapshot,
        tolerance: float,
        lower: tuple[bool, set[tuple]],
    ) -> None:
        """Measure ``snap``'s shape on the models of ``pool``; ``tolerance``: δ [m]."""
        self.pool, self.snap, self.tolerance = pool, snap, tolerance
        self.lower, self.lower_tried = lower
        self.problem = snap.problem
        self.touching = snap.touching
        self.residual_m = snap.residual_m
        self.on_elements = has_elements(snap.inner) and snap.state is not None
        self.node_rows = snap.inner.options.obstacle_points == "nodes"

    def planar_instability(self) -> float | None:
        """Return the 3D model's negative eigenvalue at the planar shape (None: stable)."""
        return planar_3d_eigenvalue(self.pool, self.snap)

    def elongation_bound(self) -> float | None:
        """Return max|F_grip|·L / min Re [m] (None: the string has no stretch stiffness)."""
        string = self.problem.string
        if string.stretch_stiffness is None:
            return None
        return self.snap.max_grip_force * string.length / string.stretch_stiffness.minimum

    def pole_angle(self) -> float | None:
        """Return the Euler-angle pole's angle to the nearest tangent [°] (None: no pole)."""
        return pole_angle(self.snap)

    def farthest_pole(self) -> tuple[np.ndarray, float]:
        """Return the direction farthest from every tangent, and its angle to them [°]."""
        return farthest_pole(self.snap)

    def turned(self, normal: np.ndarray) -> ModelChoice:
        """Return the model with its pole turned to ``normal``, built and warm-started."""
        return turned_frame(self.pool, self.snap, normal)

    def mesh(self, coarsen: bool) -> MeshVerdict:
        """Return the mesh check's verdict (a proposed mesh is built after the decision)."""
        snap = self.snap
        assert snap.state is not None
        reduced = self.pool.reduced.reduce(snap.choice, snap.problem)[0]

        def moved_shadow(spec: MeshSpec) -> tuple[ShapeSolver, ShapeResult]:
            return shadow_solve(self.pool, snap, replace(snap.choice, mesh=spec))

        return mesh_verdict(
            snap.inner, snap.state, snap.choice, reduced, self.tolerance, coarsen, moved_shadow
        )

    def order_change(self, order: int) -> float:
        """Return the centreline change [m] to basis ``order`` from the shape (nan: failed)."""
        return shadow_error(self.pool, self.snap, replace(self.snap.choice, order=order))

    def lower_order_change(self, order: int) -> float | None:
        """Return the change to the lower ``order``, once per model (None: not to be tried)."""
        key = replace(self.snap.choice, order=order).key()
        if not self.lower or key in self.lower_tried:
            return None
        self.lower_tried.add(key)
        return self.order_change(order)

    def penetration(self) -> tuple[float, str]:
        """Return the deepest cut into an obstacle between the samples [m], and its name."""
        return penetration(self.snap)

    def samples_change(self, finer: ModelChoice) -> float:
        """Return the centreline change [m] to ``finer``'s obstacle samples (nan: failed)."""
        return shadow_error(self.pool, self.snap, finer)


class ModelChecks:
    """The checks, on the pooled models of one AutoShapeSolver.

    ``lower_tried``: model keys already tried as a lower order (shared with the AutoShapeSolver,
    which adds the order it just found too coarse); ``tolerance`` [m]: δ.
    """

    def __init__(self, pool: ModelPool, tolerance: float) -> None:
        """Check on the models of ``pool`` against ``tolerance`` [m]."""
        self.pool = pool
        self.tolerance = tolerance
        self.lower_tried: set[tuple] = set()

    def evaluate(
        self,
        snap: CheckSnapshot,
        prepare: bool,
        lower: bool = True,
        decided: Future | None = None,
    ) -> CheckVerdict:
        """Gather the evidence of a snapshot and apply the policy (:func:`.policy.decide`).

        The model the verdict names is then built and warm-started here (the worker thread in the
        node), so that the stream's switch builds nothing; ``decided`` gets the verdict before
        that build (:mod:`.check_schedule`: a switch takes effect later than a decision to keep).
        prepare: also create the IPOPT solvers of the model it escalates to (background checks).
        lower: try the next lower order (once per model; a query's checks do not, so that they
        leave the stream's record of tries alone).
        """
        evidence = ShapeEvidence(self.pool, snap, self.tolerance, (lower, self.lower_tried))
        # a stream's mesh may coarsen (its later updates get cheaper); a cold answer's never does
        decision = decide(evidence, snap.choice, self.tolerance, coarsen=snap.limited)
        verdict = CheckVerdict(
            snap,
            decision.choice,
            decision.reason,
            decision.estimate,
            decision.order_error,
            decision.sampling_error,
            None if decision.choice is None else snap.answers.get(decision.choice.key()),
        )
        if decided is not None:
            decided.set_result(verdict)
        if decision.build and decision.choice is not None:
            named = self.pool.solver_for(
                decision.choice,
                snap.problem,
                stream=False,
                source=snap.inner,
                state=snap.state,
                once=True,
            )
            if snap.limited:
                # a stream's verdict names the model it switches to (a shadow of this check, maybe,
                # built for one answer): its outputs' function is built here, on the worker, not
                # at the switch on the stream's thread; a checked solve's answers on it once
                named.functions.build_outputs(named.compile_mode)
            if prepare and decision.choice.may_leave_plane:
                # a refined planar mesh's 3D model too: its first check and a switch to 3D soon
                # after would wait for that build (shadows.planar_3d_eigenvalue)
                full = full_choice(decision.choice, snap.problem)
                self.pool.worker.claim(("",) + full.key())
                self.pool.solver_for(full, snap.problem, stream=False).prepare()
        # prepare only a pooled model: never build one here, the stream may be switching to it
        target = (
            self.pool.pooled(decision.choice) if decision.choice is not None and prepare else None
        )
        if target is not None:
            target.prepare()
            if snap.limited:  # a stream switches to it
                self.pool.compile_ahead(target, switch=True)
        return verdict
