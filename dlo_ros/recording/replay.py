"""Re-solving a recording as a regression case (:func:`resolve`).

Re-solving a recording as a regression case (:func:`resolve`); reading it back is
:mod:`.reading` (:func:`read_recording`, :func:`check_recording`, re-exported here).

The format is documented in msg_docs/recording.md.  ``dlo replay`` (dlo_ros.cli.replay) is its
command line.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
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
    "resolve",
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


def deviation(recorded: RecordedResult, result: Any) -> float:
    """Return the largest distance [m] between the recorded centreline and today's.

    Largest distance [m] between the recorded centreline and today's; 0 when both failed with
    the same status; inf when the statuses differ or the sampling changed.
    """
    if recorded.status != result.status:
        return math.inf
    if recorded.status != "ok":
        return 0.0
    now = np.asarray(result.points, dtype=float)
    if now.shape != recorded.points.shape:
        return math.inf
    return float(np.max(np.linalg.norm(now - recorded.points, axis=1))) if len(now) else 0.0


def resolve(
    rec: Recording,
    tolerance: float = DEFAULT_TOLERANCE,
    compile: str = "cached",
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Re-solve the recorded targets update by update and compare with the recorded shapes.

    The solver is the recorded kind (ShapeSolver / AutoShapeSolver) built from the recorded scene
    (``scene/yaml``, later ``scene/changes``).  Each update uses the grip poses recorded with its
    result (else the received targets folded up to it) and is called warm or cold as recorded
    (``warm`` given to log_result; else the first update cold, the others warm unless the result
    was not warm-started). Returns the report dict printed by ``dlo replay --resolve --json``.
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
    rows: list[dict[str, Any]] = []
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
        dev = deviation(recorded, result)
        rows.append(
            {
                "update": recorded.update,
                "recorded_status": recorded.status,
                "status": result.status,
                "max_deviation_m": dev,
            }
        )
        if progress is not None:
            progress(f"update {recorded.update}: {dev:.3g} m")
    return _report(rec, scene.name, tolerance, rows)


def _report(rec: Recording, scene: str, tolerance: float, rows: list[dict[str, Any]]) -> dict:
    """Return the report of :func:`resolve` from its rows, one per re-solved update."""
    finite = [r["max_deviation_m"] for r in rows if math.isfinite(r["max_deviation_m"])]
    worst = max(
        rows, key=lambda r: r["max_deviation_m"] if not math.isnan(r["max_deviation_m"]) else -1
    )
    exceeding = [r["update"] for r in rows if not r["max_deviation_m"] <= tolerance]
    return {
        "file": str(rec.path),
        "scene": scene,
        "solver": rec.solver_kind or "default",
        "tolerance_m": tolerance,
        "updates": rows,
        "count": len(rows),
        "max_deviation_m": worst["max_deviation_m"],
        "worst_update": worst["update"],
        "mean_deviation_m": float(np.mean(finite)) if finite else None,
        "exceeding": exceeding,
        "ok": not exceeding,
    }


def format_resolve(report: dict) -> str:
    """Return the human-readable table of a :func:`resolve` report, one line per update."""
    lines = [
        f"replay  {report['file']}: scene {report['scene']}, {report['count']} updates, "
        f"solver {report['solver']}",
        f"{'update':>7}  {'recorded':<11} {'now':<11} max deviation [m]",
    ]
    for r in report["updates"]:
        flag = "" if r["max_deviation_m"] <= report["tolerance_m"] else "   > tolerance"
        lines.append(
            f"{r['update']:>7}  {r['recorded_status']:<11} {r['status']:<11} "
            f"{r['max_deviation_m']:.3g}{flag}"
        )
    verdict = (
        "OK"
        if report["ok"]
        else f"DIFFERS at updates {report['exceeding'][:20]}"
        + (" ..." if len(report["exceeding"]) > 20 else "")
    )
    mean = report["mean_deviation_m"]
    lines.append(
        f"summary {report['count']} updates re-solved: max deviation "
        f"{report['max_deviation_m']:.3g} m "
        f"(update {report['worst_update']}), mean {'n/a' if mean is None else f'{mean:.3g}'} m; "
        f"{len(report['exceeding'])} above the tolerance {report['tolerance_m']:.3g} m -> "
        f"{verdict}"
    )
    return "\n".join(lines)
