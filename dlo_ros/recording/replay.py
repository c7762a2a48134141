"""Re-solving a recording as a regression case (:func:`resolve`).

Re-solving a recording as a regression case (:func:`resolve`); reading it back is
:mod:`.reading` (:func:`read_recording`, :func:`check_recording`, re-exported here).

The format is documented in msg_docs/recording.md.  ``dlo replay`` (dlo_ros.cli.replay) is its
command line.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Callable

import yaml

from .. import solver as S
from ..scene import Scene, scene_from_dict
from . import paths as P
from .reading import (
    RecordedResult,
    Recording,
    RecordingCheck,
    RecordingError,
    check_recording,
    read_recording,
    rows_of,
)
from .resolve_report import (
    ModelKey,
    ResolveReport,
    UpdateComparison,
    changed_of,
    compare,
    format_report,
    model_history,
    model_key,
    recorded_models,
    slowest,
    switches,
)

if TYPE_CHECKING:
    from ..solver import Solver

__all__ = [
    "DEFAULT_TOLERANCE",
    "RecordedResult",
    "Recording",
    "RecordingCheck",
    "RecordingError",
    "check_recording",
    "deviation",
    "format_resolve",
    "read_recording",
    "ResolveReport",
    "resolve",
    "resolve_report",
    "rows_of",
]

DEFAULT_TOLERANCE = 1e-6


# ---- re-solving ---------------------------------------------------------------------------------
def _scene_from_yaml(text: str, where: str) -> Scene:
    return scene_from_dict(yaml.safe_load(text), source=where)


def _make_solver(kind: str, scene: Scene, compile: str) -> Solver:
    if kind == "ShapeSolver" or not hasattr(S, "make_solver"):
        return S.ShapeSolver(scene.problem, scene.options, compile=compile)
    if kind == "AutoShapeSolver" and hasattr(S, "AutoShapeSolver"):
        return S.AutoShapeSolver(scene.problem, scene.options, compile=compile, checks="sync")
    return S.make_solver(scene.problem, scene.options, compile=compile, checks="sync")


def deviation(recorded: RecordedResult, result: Any) -> float | None:
    """Return the largest distance [m] between the recorded centreline and today's.

    Only an ``ok`` result against an ``ok`` recording has one; None otherwise (statuses are
    compared instead, :func:`dlo_ros.recording.resolve_report.compare`) or when the sampling
    changed.  Never inf or NaN.
    """
    return compare(recorded, result, math.inf).max_deviation_m


def resolve(
    rec: Recording,
    tolerance: float = DEFAULT_TOLERANCE,
    compile: str = "cached",
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Re-solve a recording and return :func:`resolve_report`'s ``--json`` dict (``as_dict``)."""
    return resolve_report(rec, tolerance, compile, progress).as_dict()


def resolve_report(
    rec: Recording,
    tolerance: float = DEFAULT_TOLERANCE,
    compile: str = "cached",
    progress: Callable[[str], None] | None = None,
) -> ResolveReport:
    """Re-solve the recorded targets update by update and compare with the recorded results.

    The solver is the recorded kind (ShapeSolver / AutoShapeSolver) built from the recorded scene
    (``scene/yaml``, later ``scene/changes``).  Each update uses the grip poses recorded with its
    result (else the received targets folded up to it) and is called warm or cold as recorded
    (``warm`` given to log_result; else the first update cold, the others warm unless the result
    was not warm-started).  Each update is compared by status, and ``ok`` against ``ok`` by shape
    (:func:`dlo_ros.recording.resolve_report.compare`); the model histories are compared from the
    recording's ``model/<key>`` series.
    """
    if not rec.scene_yaml:
        raise ValueError(
            f"{rec.path}: the recording has no scene ({P.E_SCENE}); it cannot be re-solved"
        )
    if not rec.results:
        raise ValueError(
            f"{rec.path}: the recording has no results ({P.E_DATA_RESULT}); nothing to re-solve"
        )
    scene = _scene_from_yaml(rec.scene_yaml, f"{rec.path}#{P.E_SCENE}")
    solver = _make_solver(rec.solver_kind, scene, compile)
    changes = sorted(rec.scene_changes)
    current = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}
    received = sorted(rec.targets, key=lambda t: t[0])
    ti = ci = 0
    rows: list[UpdateComparison] = []
    models: dict[int, ModelKey] = {}
    made: tuple[list, list] = ([], [])  # (update, reason) of the recorded and re-solved changes
    for recorded in sorted(rec.results, key=lambda r: r.update):
        while ci < len(changes) and changes[ci][0] <= recorded.update:
            new = _scene_from_yaml(
                changes[ci][1], f"{rec.path}#{P.E_SCENE_CHANGES}@{changes[ci][0]}"
            )
            if new.options == scene.options:
                solver.set_problem(new.problem)
            else:
                solver = _make_solver(rec.solver_kind, new, compile)
            scene, ci = new, ci + 1
        while ti < len(received) and received[ti][0] <= recorded.update:
            current = {**current, **received[ti][1]}
            ti += 1
        poses = recorded.targets if recorded.targets is not None else current
        if recorded.targets is not None:
            current = {**current, **recorded.targets}
        if recorded.warm_call is not None:
            warm = bool(recorded.warm_call)
        else:
            warm = bool(rows) and recorded.warm_started
        result = solver.solve(poses, warm=warm)
        rows.append(compare(recorded, result, tolerance))
        made[0].extend((recorded.update, c) for c in changed_of(recorded.model))
        made[1].extend((recorded.update, c) for c in changed_of(result.model_dict()))
        key = model_key(result.model_dict())
        if key is not None:
            models[recorded.update] = key
        if progress is not None:
            progress(f"update {recorded.update}: {rows[-1].verdict}")
    return ResolveReport(
        file=str(rec.path),
        scene=scene.name,
        solver=rec.solver_kind or "default",
        tolerance_m=tolerance,
        updates=rows,
        models=model_history(recorded_models(rec.model_series), models),
        switches=switches(*made),
        slowest=slowest(rec.solve_times),
    )


def format_resolve(report: ResolveReport) -> str:
    """Return the human-readable report of :func:`resolve_report`, one line per update."""
    return format_report(report)
