"""What an auto result reports: its ``model`` (a ModelSummary), solve time and contact keys.

Pure functions of the values handed in; :meth:`.auto_solver.AutoShapeSolver.model_summary` and
:meth:`~.auto_solver.AutoShapeSolver.finish` gather them from the solver.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..results.element_error import SAFETY
from ..results.outputs import RAISE_ORDER
from ..results.result import ShapeResult
from ..results.summary import ModelSummary
from ..shape_solver import ShapeSolver
from .choice import ModelChoice


def model_summary(
    choice: ModelChoice,
    solver: ShapeSolver,
    *,
    tolerance: float,
    checks: str,
    changes: tuple[str, ...],
    checked: bool,
    changes_at: tuple[int, ...] = (),
    updates_ago: int,
    changed: tuple[str, ...] = (),
    estimate: float | None = None,
) -> ModelSummary:
    """Return the ``model`` object of a result solved on ``solver``, a model of ``choice``.

    estimated_error_m: the basis-order estimate of the last check of this model (the change of the
    centreline when the order is raised; at the highest order, the estimate that led there) plus
    the deepest cut into an obstacle between its samples, None until the first check has finished
    (``checked``: whether one has, for this model).  It does not include the a-priori bounds of
    the dropped gravity (≤ δ/10) and stretch (≤ δ/2).  In background mode it describes a solve up
    to recheck_every updates earlier: checked_updates_ago says how many (``updates_ago``; 0: this
    very shape).  ``tolerance``: δ [m]; ``checks``: 'sync' or 'background'; ``changes``: every
    change of model so far (the newest 50), ``changes_at`` the update index each took effect at
    (the first update solved on the new model, :mod:`.check_schedule`); ``changed``: the
    changes this very solve made.  ``estimate``: a refined query's own checked estimate
    (``refine_query``): checked, 0 updates ago.
    """
    c = choice
    est = c.estimated_error_m if checked and np.isfinite(c.estimated_error_m) else None
    if estimate is not None and np.isfinite(estimate):
        checked, est = True, float(estimate)
    inner = solver.model_summary()
    return ModelSummary(
        planar=c.planar,
        twist=c.twist,
        stretch=c.stretch,
        gravity=c.gravity,
        order=c.order,
        obstacles=len(c.obstacles),
        # rows on the mesh nodes: no uniform samples (the mesh's nodes are in ``elements``)
        obstacle_samples=None if solver.options.obstacle_points == "nodes" else c.samples,
        estimated_error_m=est,
        tolerance_m=tolerance,
        tolerance_met=None if est is None else bool(est <= tolerance),
        variables=solver.model.layout.size,
        auto=True,
        checked=checked,
        checks=checks,
        checked_updates_ago=(0 if estimate is not None else updates_ago) if checked else None,
        reasons=tuple(c.reasons),
        changes=changes,
        changes_at=changes_at,
        rotation=inner.rotation,
        elements=inner.elements,
        breakpoints=inner.breakpoints,
        self_contact_pairs=inner.self_contact_pairs,
        changed=changed,
    )


def with_own_residual(model: ModelSummary, residual_m: float) -> ModelSummary:
    """Return ``model`` with its estimate at least ``SAFETY`` × the answer's own residual [m].

    A check's estimate describes the shape it checked; the answer of a later update at the same
    targets is that equilibrium only to its Newton tolerance (on the post at δ = 1e-4 m, streamed:
    6.6e-7 m from the exact answer, the check's estimate 3.2e-7 m, the answer's residual
    8.4e-7 m).  Its strong-form residual (``results/residual.py``) measures that departure.
    """
    if model.estimated_error_m is None or not np.isfinite(residual_m):
        return model
    own = SAFETY * float(residual_m)
    if own <= model.estimated_error_m:
        return model
    met = None if model.tolerance_m is None else bool(own <= model.tolerance_m)
    return replace(model, estimated_error_m=own, tolerance_met=met)


#: what an 'unverified' answer of auto says in place of a fixed model's advice (``RAISE_ORDER``)
AUTO_REFINES = "; auto refines its model as far as its checks can"


def finished(
    result: ShapeResult, t0: float, obstacles: tuple[int, ...], scene_obstacles: int
) -> ShapeResult:
    """Return ``result`` with its solve time and contact forces keyed by scene obstacle index.

    ``t0``: when the solve started (``time.perf_counter``); ``obstacles``: the scene indices of
    the obstacles in the model that solved it, ``scene_obstacles`` how many the scene has.
    """
    result.solve_time_ms = (time.perf_counter() - t0) * 1e3
    if result.status == "unverified":  # auto chooses the model: no advice to raise its order
        result.message = result.message.replace(RAISE_ORDER, AUTO_REFINES)
    if result.ok and result.contact_forces and len(obstacles) != scene_obstacles:
        result.contact_forces = {
            obstacles[i]: f for i, f in result.contact_forces.items() if i < len(obstacles)
        }
    return result
