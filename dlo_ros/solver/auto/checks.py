"""The a-posteriori checks of a committed shape: keep its model, or escalate to which one.

:meth:`ModelChecks.evaluate` takes a :class:`CheckSnapshot` (what a check needs of one committed
solve, safe to hand to the worker thread) and returns a :class:`CheckVerdict`: ``choice`` None to
keep the model (with its error estimate), or the richer model and why.  The checks, in order; the
first that fails decides, the sampling part is always measured:

1. planar stability in 3D (:mod:`.shadows`): an unstable planar shape → the 3D model;
2. the elongation bound max|F_grip|·L / min Re > δ/2 → the extensible model;
3. the Euler-angle pole within POLE_MIN_DEG of a tangent → the frame turned away;
4. the basis order: the next order's shadow moves the centreline by more than δ/2 (or the
   equilibrium residual is larger) → the next order; once per model the next lower order is tried
   and taken within δ/4;
5. the obstacle samples: the cut between samples, and while touching the samples shadow's doubled
   change, over δ/2 → 2n − 1 samples.

Every model a verdict names is built (and warm) before it is returned, so the streaming thread's
switch builds nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...model.problem import Problem
from ..shape_solver import ShapeSolver
from ..state import SolverState
from .choice import MAX_SAMPLES, ORDERS, ModelChoice, full_choice
from .mesh_check import has_elements, mesh_verdict
from .pool import ModelPool
from .shadows import penetration, planar_3d_eigenvalue, shadow_error, turned_frame


@dataclass
class CheckSnapshot:
    """What a check needs of one committed solve (taken on the streaming thread).

    ``inner``/``state``: the solver that committed it and a copy of its state; ``choice``: a copy
    of its model; ``points``: its output points [m]; ``max_grip_force`` [N]; ``generation``: the
    AutoShapeSolver's switch count then (an older verdict is stale); ``residual_m``: its
    strong-form equilibrium residual (solver/results/residual.py, inf when unknown);
    ``touching``: it presses on an obstacle; ``update``: the streamed-update count then;
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


@dataclass
class CheckVerdict:
    """A check's outcome: escalate to ``choice`` (with ``reason``), or keep with ``estimate``.

    ``estimate`` [m]: the kept model's error estimate (order part + sampling part);
    ``order_error``/``sampling_error`` [m]: its two parts (nan: not measured).
    """

    snapshot: CheckSnapshot
    choice: ModelChoice | None = None
    reason: str = ""
    estimate: float = float("nan")
    order_error: float = float("nan")
    sampling_error: float = float("nan")


def _escalated(choice: ModelChoice, **changes) -> ModelChoice:
    """Return ``choice`` changed as given, its estimates unknown and its reasons copied."""
    return replace(
        choice,
        **{
            "estimated_error_m": float("nan"),
            "order_error_m": float("nan"),
            "reasons": list(choice.reasons),
            **changes,
        },
    )


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

    def evaluate(self, snap: CheckSnapshot, prepare: bool, lower: bool = True) -> CheckVerdict:
        """Run one pass of the checks on a snapshot; the first that fails decides.

        prepare: also create the IPOPT solvers of the model it escalates to (background checks,
        so the streaming thread's switch builds nothing).  lower: try the next lower order (once
        per model; a query's checks do not, so that they leave the stream's record of tries
        alone).
        """
        choice = snap.choice
        verdict = CheckVerdict(snap, estimate=choice.estimated_error_m)
        self._model_checks(snap, verdict)
        order_error = choice.order_error_m
        if verdict.choice is None and has_elements(snap.inner) and snap.state is not None:
            order_error = self._mesh_check(snap, verdict)
        elif verdict.choice is None:
            order_error = self._order_checks(snap, verdict, order_error, lower)
        self._sampling_check(snap, verdict, order_error)
        # prepare only a pooled model: never build one here, the stream may be switching to it
        target = (
            self.pool.pooled(verdict.choice) if verdict.choice is not None and prepare else None
        )
        if target is not None:
            target.prepare()
        return verdict

    def _model_checks(self, snap: CheckSnapshot, verdict: CheckVerdict) -> None:
        """Run checks 1–3: planar stability in 3D, the elongation bound, the Euler-angle pole."""
        tol, choice, problem = self.tolerance, snap.choice, snap.problem
        if choice.planar:
            eig = planar_3d_eigenvalue(self.pool, snap)  # None when stable (or neutral)
            if eig is not None:
                verdict.choice = replace(
                    full_choice(choice, problem),
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
                verdict.choice = _escalated(choice, stretch=True)
                verdict.reason = (
                    f"elongation bound {elongation:.3g} m > {tol / 2:.3g} m: extensible model"
                )
        if verdict.choice is None and not choice.planar:
            turned = turned_frame(self.pool, snap)
            if turned is not None:
                verdict.choice, verdict.reason = turned

    def _mesh_check(self, snap: CheckSnapshot, verdict: CheckVerdict) -> float:
        """Check 4 on an element model: its own error estimate, refine or coarsen the mesh.

        Returns the discretisation part of the estimate (``mesh_check.py``); the refined model is
        built and warm-started here (the worker thread in the node), so a switch builds nothing.
        """
        reduced = self.pool.reduced.reduce(snap.choice, snap.problem)[0]
        assert snap.state is not None
        found = mesh_verdict(
            snap.inner, snap.state, snap.choice, reduced, self.tolerance, coarsen=snap.limited
        )
        if found.choice is not None:
            verdict.choice, verdict.reason = found.choice, found.reason
            self.pool.solver_for(
                found.choice, snap.problem, stream=False, source=snap.inner, state=snap.state
            )
        return found.estimate

    def _order_checks(
        self, snap: CheckSnapshot, verdict: CheckVerdict, order_error: float, lower: bool
    ) -> float:
        """Check 4: the next order's shadow, then once per model the next lower order.

        Returns the basis-order part of the estimate (``order_error`` when not measured).  At the
        highest order the estimate stays the one that led there (order 24 against 32): the best
        available, and conservative; model.tolerance_met compares it with the tolerance.
        """
        tol, choice = self.tolerance, snap.choice
        i = ORDERS.index(choice.order)
        if i + 1 < len(ORDERS):
            error = shadow_error(self.pool, snap, replace(choice, order=ORDERS[i + 1]))
            if np.isfinite(error):  # a shadow that failed to solve is inconclusive: retried
                order_error = error
            # the equilibrium residual is an error estimate of its own: the larger counts
            error = max(error, snap.residual_m) if np.isfinite(error) else snap.residual_m
            if np.isfinite(snap.residual_m):
                order_error = (
                    max(order_error, snap.residual_m)
                    if np.isfinite(order_error)
                    else snap.residual_m
                )
            if error > tol / 2 and np.isfinite(error):
                up = ORDERS[i + 1]
                verdict.choice = _escalated(
                    choice, order=up, estimated_error_m=error, order_error_m=error
                )
                verdict.reason = (
                    f"order {choice.order} error estimate {error:.3g} m > {tol / 2:.3g} m: "
                    f"order {up}"
                )
        lower_key = replace(choice, order=ORDERS[i - 1]).key() if i > 0 else None
        if (
            verdict.choice is None
            and lower
            and lower_key is not None
            and lower_key not in self.lower_tried
        ):
            # the lowest order that meets the tolerance: try the next lower one once per model
            # (tol/4, not tol/2: a margin against switching back and forth)
            self.lower_tried.add(lower_key)
            down = ORDERS[i - 1]
            error = shadow_error(self.pool, snap, replace(choice, order=down))
            if error <= tol / 4:  # (nan when the lower order failed to solve: stay)
                verdict.choice = _escalated(
                    choice, order=down, estimated_error_m=error, order_error_m=error
                )
                verdict.reason = (
                    f"order {down} error estimate {error:.3g} m ≤ {tol / 4:.3g} m: order {down}"
                )
        return order_error

    def _sampling_check(
        self, snap: CheckSnapshot, verdict: CheckVerdict, order_error: float
    ) -> None:
        """Check 5: the obstacle samples' error; sets the verdict's estimate and its parts.

        The sampling part is the larger of the deepest cut between the samples and, while the shape
        touches an obstacle, twice the samples shadow's change (the sampled contact converges to
        first order in h); at MAX_SAMPLES the last measured sampling error stays.
        """
        tol, choice, problem = self.tolerance, snap.choice, snap.problem
        depth, name = penetration(snap)  # (0, '') without obstacles
        finer = replace(
            choice,
            samples=min(2 * choice.samples - 1, MAX_SAMPLES),
            estimated_error_m=float("nan"),
            order_error_m=order_error,
            reasons=list(choice.reasons),
        )
        change = (
            shadow_error(self.pool, snap, finer)
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
            verdict.estimate = order_error + sampling  # the sampling error adds to the order's
        if verdict.choice is None and sampling > tol / 2 and choice.samples < MAX_SAMPLES:
            # the order's estimate carries over (same basis); the finer model's sampling error is
            # about half this one's (first order in h) until its own check measures it
            verdict.choice = replace(finer, sampling_error_m=change)
            verdict.reason = (
                f"the string cuts into obstacle {name!r} by {depth:.3g} m > {tol / 2:.3g} m "
                f"between its {choice.samples} samples: {finer.samples} samples"
                if depth >= sampling
                else f"the shape moves by {change:.3g} m when the obstacle samples go from "
                f"{choice.samples} to {finer.samples} (sampling error about {sampling:.3g} m > "
                f"{tol / 2:.3g} m): {finer.samples} samples"
            )
            # built and warm-started here (worker thread in the node), so the switch builds
            # nothing; the samples shadow, when it ran, already did both (the same pooled model)
            if not np.isfinite(change):
                self.pool.solver_for(
                    verdict.choice, problem, stream=False, source=snap.inner, state=snap.state
                )
