"""The recording's default rerun blueprint: the 3D world, time series and event log.

The recording's default rerun blueprint: the 3D world beside the time series and the event
log.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .paths import (
    E_EIGEN,
    E_ENERGY,
    E_ITERATIONS,
    E_MODEL_SERIES,
    E_SOLVE_TIME,
    E_WORLD,
    TIMELINE_UPDATE,
)

if TYPE_CHECKING:
    from .scene_info import SceneInfo


def auto_model(info: SceneInfo | None) -> bool:
    """Say whether the recorded solver picks its model (solver.model 'auto').

    Whether the recorded solver picks its model (solver.model 'auto', not a ShapeSolver of
    it).
    """
    return (
        info is not None and info.model == "auto" and info.solver_kind in ("", "AutoShapeSolver")
    )


def default_blueprint(info: SceneInfo | None = None) -> Any:
    """Return the default layout: the 3D world beside the time series and the event log.

    3D world view (left) beside the time series and the event log (right); timeline
    ``update``.
    """
    import rerun.blueprint as rrb  # optional: rerun-sdk (Python >= 3.11), with pyarrow

    world = rrb.Spatial3DView(
        origin=E_WORLD, name="World (m, z up)", eye_controls=_eye(info) if info else None
    )
    views: list[Any] = [
        rrb.TimeSeriesView(origin=E_ENERGY, name="Energy [J]"),
        rrb.TimeSeriesView(origin=E_SOLVE_TIME, name="Solve time [ms]"),
        rrb.TimeSeriesView(origin=E_ITERATIONS, name="Iterations (Newton steps or IPOPT)"),
        rrb.TimeSeriesView(origin=E_EIGEN, name="Min reduced eigenvalue (< 0: unstable)"),
    ]
    shares = [3, 2, 2, 2]
    if auto_model(info):  # the model changes: its error estimate beside the tolerance
        views.append(
            rrb.TimeSeriesView(
                origin=E_MODEL_SERIES,
                name="Model: estimated error vs tolerance [m]",
                contents=["$origin/estimated_error_m", "$origin/tolerance_m"],
            )
        )
        shares.append(2)
    views.append(rrb.TextLogView(origin="events", name="Events: status, rejected inputs, model"))
    shares.append(2)
    right = rrb.Vertical(*views, row_shares=shares)
    return rrb.Blueprint(
        rrb.Horizontal(world, right, column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE_UPDATE, state="collapsed"),
    )


def _eye(info: SceneInfo) -> Any:
    """Return a camera looking at the cable from the side.

    Camera looking at the cable from the side: perpendicular to the grips' chord and to
    gravity.
    """
    import rerun.blueprint as rrb  # optional: rerun-sdk (Python >= 3.11), with pyarrow

    g, L = info.gravity, info.length
    pos = info.grip_positions
    chord = pos[-1] - pos[0] if len(pos) >= 2 else np.zeros(3)
    chord = chord - np.dot(chord, g) * g
    if np.linalg.norm(chord) < 1e-9 * L:
        chord = np.array([1.0, 0.0, 0.0]) - g[0] * g
    side = np.cross(chord, g)
    if np.linalg.norm(side) < 1e-12:
        side = np.array([0.0, 1.0, 0.0])
    side = side / np.linalg.norm(side)
    span = max(L, float(np.linalg.norm(chord)))
    position = info.centre - 1.2 * span * side - 0.3 * span * g
    return rrb.EyeControls3D(position=position, look_target=info.centre, eye_up=-g)
