"""Reading a recording back (:func:`read_recording`) and re-solving it as a regression case (:func:`resolve`).

The reader of what :class:`dlo_ros.recording.Recorder` writes (entity paths in
:mod:`dlo_ros.recording.paths`; the format is documented in msg_docs/recording.md).  ``dlo replay``
(dlo_ros.cli.replay) is its command line.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from . import paths as P

if TYPE_CHECKING:
    from ..solver import Solver

DEFAULT_TOLERANCE = 1e-6


# ---- reading a recording back ------------------------------------------------------------------------
@dataclass
class RecordedResult:
    update: int
    ros_time_ns: int | None
    status: str
    message: str
    warm_started: bool
    warm_call: bool | None  # the solve's ``warm`` argument, when the recorder was told
    s: np.ndarray
    points: np.ndarray  # (N, 3), float64 as solved
    targets: dict[str, tuple[np.ndarray, np.ndarray]] | None
    energy: dict[str, float] = field(default_factory=dict)
    model: dict = field(default_factory=dict)  # ShapeResult.model as recorded (JSON in data/result)


@dataclass
class Recording:
    """What ``dlo replay`` needs from an .rrd (read with rerun's chunk API: ``rerun.chunk.RrdReader``)."""

    path: Path
    application_id: str
    recording_id: str
    entities: set[str]
    scene_yaml: str
    scene_name: str
    solver_kind: str
    scene_changes: list[tuple[int, str]]
    results: list[RecordedResult]
    targets: list[tuple[int, dict[str, tuple[np.ndarray, np.ndarray]]]]
    rejected: list[tuple[int, str]]
    events: list[tuple[str, int | None, str]]
    centrelines: dict[int, np.ndarray]  # update -> (N, 3) as drawn (float32 in the file)
    model_series: dict[str, list[tuple[int, float]]] = field(default_factory=dict)  # model/<key>: (update, value)

    @property
    def updates(self) -> list[int]:
        return sorted({r.update for r in self.results})


def rows_of(chunks: list[Any]) -> list[dict[str, Any]]:
    """Rows of one entity's chunks as dicts (index columns as int, components as Python lists), in
    logging order: by ``update`` then by row id."""
    import pyarrow as pa

    rows: list[dict[str, Any]] = []
    for chunk in chunks:
        rb = chunk.to_record_batch()
        cols = {}
        for name, col in zip(rb.schema.names, rb.columns):
            if pa.types.is_timestamp(col.type) or pa.types.is_duration(col.type):
                col = col.cast(pa.int64())
            cols[name] = col.to_pylist()
        for i in range(rb.num_rows):
            rows.append({name: values[i] for name, values in cols.items()})
    rows.sort(key=lambda r: (r.get(P.TIMELINE_UPDATE) if r.get(P.TIMELINE_UPDATE) is not None else -1,
                             r.get("rerun.controls.RowId") or b""))
    return rows


def _first(value: Any) -> Any:
    """A component cell (a list of instances) → its single instance, or None."""
    if isinstance(value, list):
        return value[0] if value else None
    return value


def _model(text: Any) -> dict:
    """data/result's ``model`` (JSON text) → dict; {} when absent or unreadable."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except (TypeError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}


def _poses(names: list | None, flat: list | None) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
    if not names or flat is None:
        return None
    arr = np.asarray(flat, dtype=float).reshape(len(names), 7)
    return {str(n): (arr[i, 0:3].copy(), arr[i, 3:7].copy()) for i, n in enumerate(names)}


def read_recording(path: str | Path) -> Recording:
    """Read a recording written by :class:`dlo_ros.recording.Recorder`.  Raises FileNotFoundError, or
    ValueError when the file is not a readable rerun recording."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        from rerun.chunk import RrdReader
    except ImportError as exc:
        raise ValueError(f"reading recordings needs rerun-sdk (Python >= 3.11): {exc}") from None
    try:
        reader = RrdReader(path)
        stores = reader.recordings()
        if not stores:
            raise ValueError(f"{path}: no recording in the file")
        by_entity: dict[str, list[Any]] = {}
        for chunk in reader.stream(store=stores[0]):
            by_entity.setdefault(chunk.entity_path.lstrip("/"), []).append(chunk)
    except ValueError:
        raise
    except Exception as exc:  # rerun raises plain exceptions for corrupt / foreign files
        raise ValueError(f"{path}: not a readable rerun recording ({type(exc).__name__}: {exc})") from None

    def rows(entity: str) -> list[dict[str, Any]]:
        return rows_of(by_entity.get(entity, []))

    scene_yaml, scene_name, solver_kind = "", "", ""
    for row in rows(P.E_SCENE):
        scene_yaml = _first(row.get("TextDocument:text")) or scene_yaml
        scene_name = _first(row.get("scene_name")) or scene_name
        solver_kind = _first(row.get("solver")) or solver_kind
    if scene_yaml.startswith("# scene not recorded"):
        scene_yaml = ""
    changes = [(int(r[P.TIMELINE_UPDATE]), _first(r.get("TextDocument:text")) or "")
               for r in rows(P.E_SCENE_CHANGES) if r.get(P.TIMELINE_UPDATE) is not None]

    results = []
    for row in rows(P.E_DATA_RESULT):
        status = _first(row.get("status")) or ""
        pts = row.get("points")
        s = row.get("s")
        energy_terms, energy = row.get("energy_terms") or [], row.get("energy") or []
        results.append(RecordedResult(
            update=int(row[P.TIMELINE_UPDATE]), ros_time_ns=row.get(P.TIMELINE_ROS), status=status,
            message=_first(row.get("message")) or "", warm_started=bool(_first(row.get("warm_started"))),
            warm_call=_first(row.get("warm")),
            s=np.asarray(s if s is not None else [], dtype=float),
            points=np.asarray(pts if pts is not None else [], dtype=float).reshape(-1, 3),
            targets=_poses(row.get("target_names"), row.get("target_poses")),
            energy={str(k): float(v) for k, v in zip(energy_terms, energy)},
            model=_model(_first(row.get("model"))),
        ))
    targets = []
    for row in rows(P.E_DATA_TARGETS):
        poses = _poses(row.get("grip_names"), row.get("poses"))
        if poses is not None:
            targets.append((int(row[P.TIMELINE_UPDATE]), poses))
    rejected = [(int(r[P.TIMELINE_UPDATE]), _first(r.get("TextLog:text")) or "") for r in rows(P.E_REJECTED)]
    events = [(entity, r.get(P.TIMELINE_UPDATE), _first(r.get("TextLog:text")) or "")
              for entity in (P.E_STATUS, P.E_MODEL, P.E_RECORDER) for r in rows(entity)]
    centrelines = {}
    for row in rows(P.E_CABLE):
        strips = row.get("LineStrips3D:strips")
        if strips and row.get(P.TIMELINE_UPDATE) is not None:
            centrelines[int(row[P.TIMELINE_UPDATE])] = np.array([seg[0] for seg in strips] + [strips[-1][-1]], dtype=float)
    model_series: dict[str, list[tuple[int, float]]] = {}
    for key in P.MODEL_SCALARS:
        for row in rows(f"{P.E_MODEL_SERIES}/{key}"):
            value = _first(row.get("Scalars:scalars"))
            if value is not None and row.get(P.TIMELINE_UPDATE) is not None:
                model_series.setdefault(key, []).append((int(row[P.TIMELINE_UPDATE]), float(value)))
    store = stores[0]
    return Recording(
        path=path, application_id=store.application_id, recording_id=store.recording_id,
        entities=set(by_entity), scene_yaml=scene_yaml, scene_name=scene_name, solver_kind=solver_kind,
        scene_changes=changes, results=results, targets=targets, rejected=rejected, events=events,
        centrelines=centrelines, model_series=model_series,
    )


# ---- re-solving ----------------------------------------------------------------------------------------
def _scene_from_yaml(text: str, where: str):
    import yaml

    from ..scene import scene_from_dict

    return scene_from_dict(yaml.safe_load(text), source=where)


def _make_solver(kind: str, scene, compile: str) -> Solver:
    from .. import solver as S

    if kind == "ShapeSolver" or not hasattr(S, "make_solver"):
        return S.ShapeSolver(scene.problem, scene.options, compile=compile)
    if kind == "AutoShapeSolver" and hasattr(S, "AutoShapeSolver"):
        return S.AutoShapeSolver(scene.problem, scene.options, compile=compile, checks="sync")
    return S.make_solver(scene.problem, scene.options, compile=compile, checks="sync")


def deviation(recorded: RecordedResult, result: Any) -> float:
    """Largest distance [m] between the recorded centreline and today's; 0 when both failed with the
    same status; inf when the statuses differ or the sampling changed."""
    if recorded.status != result.status:
        return math.inf
    if recorded.status != "ok":
        return 0.0
    now = np.asarray(result.points, dtype=float)
    if now.shape != recorded.points.shape:
        return math.inf
    return float(np.max(np.linalg.norm(now - recorded.points, axis=1))) if len(now) else 0.0


def resolve(rec: Recording, tolerance: float = DEFAULT_TOLERANCE, compile: str = "cached",
            progress: Callable[[str], None] | None = None) -> dict:
    """Re-run the solver on the recorded targets, update by update, and compare with the recorded shapes.

    The solver is the recorded kind (ShapeSolver / AutoShapeSolver) built from the recorded scene
    (``scene/yaml``, later ``scene/changes``).  Each update uses the grip poses recorded with its result
    (else the received targets folded up to it) and is called warm or cold as recorded (``warm`` given
    to log_result; else the first update cold, the others warm unless the result was not warm-started).
    Returns the report dict printed by ``dlo replay --resolve --json``.
    """
    if not rec.scene_yaml:
        raise ValueError(f"{rec.path}: the recording has no scene ({P.E_SCENE}); it cannot be re-solved")
    if not rec.results:
        raise ValueError(f"{rec.path}: the recording has no results ({P.E_DATA_RESULT}); nothing to re-solve")
    scene = _scene_from_yaml(rec.scene_yaml, f"{rec.path}#{P.E_SCENE}")
    solver = _make_solver(rec.solver_kind, scene, compile)
    changes = sorted(rec.scene_changes)
    current = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}
    received = sorted(rec.targets, key=lambda t: t[0])
    ti = ci = 0
    rows = []
    for recorded in sorted(rec.results, key=lambda r: r.update):
        while ci < len(changes) and changes[ci][0] <= recorded.update:
            new = _scene_from_yaml(changes[ci][1], f"{rec.path}#{P.E_SCENE_CHANGES}@{changes[ci][0]}")
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
        rows.append({"update": recorded.update, "recorded_status": recorded.status, "status": result.status,
                     "max_deviation_m": dev})
        if progress is not None:
            progress(f"update {recorded.update}: {dev:.3g} m")
    finite = [r["max_deviation_m"] for r in rows if math.isfinite(r["max_deviation_m"])]
    worst = max(rows, key=lambda r: (r["max_deviation_m"] if not math.isnan(r["max_deviation_m"]) else -1))
    exceeding = [r["update"] for r in rows if not r["max_deviation_m"] <= tolerance]
    return {
        "file": str(rec.path), "scene": scene.name, "solver": rec.solver_kind or "default",
        "tolerance_m": tolerance, "updates": rows, "count": len(rows),
        "max_deviation_m": worst["max_deviation_m"], "worst_update": worst["update"],
        "mean_deviation_m": float(np.mean(finite)) if finite else None,
        "exceeding": exceeding, "ok": not exceeding,
    }


def format_resolve(report: dict) -> str:
    lines = [f"replay  {report['file']}: scene {report['scene']}, {report['count']} updates, "
             f"solver {report['solver']}",
             f"{'update':>7}  {'recorded':<11} {'now':<11} max deviation [m]"]
    for r in report["updates"]:
        flag = "" if r["max_deviation_m"] <= report["tolerance_m"] else "   > tolerance"
        lines.append(f"{r['update']:>7}  {r['recorded_status']:<11} {r['status']:<11} {r['max_deviation_m']:.3g}{flag}")
    verdict = "OK" if report["ok"] else f"DIFFERS at updates {report['exceeding'][:20]}" + \
        (" ..." if len(report["exceeding"]) > 20 else "")
    mean = report["mean_deviation_m"]
    lines.append(f"summary {report['count']} updates re-solved: max deviation {report['max_deviation_m']:.3g} m "
                 f"(update {report['worst_update']}), mean {'n/a' if mean is None else f'{mean:.3g}'} m; "
                 f"{len(report['exceeding'])} above the tolerance {report['tolerance_m']:.3g} m -> {verdict}")
    return "\n".join(lines)
