"""``dlo replay FILE.rrd``: open a recording in the rerun viewer, render it, or re-solve it as a regression case.

    dlo replay FILE.rrd                      open it in the native viewer (needs a display; else says what to do)
    dlo replay FILE.rrd --web                serve it to a browser (rerun --web-viewer; no display needed)
    dlo replay FILE.rrd --screenshot PNG     render it headlessly to a PNG (needs a Vulkan driver, e.g. lavapipe)
    dlo replay FILE.rrd --resolve [--tolerance M] [--json]
                                             re-run today's solver on the recorded targets and compare shapes

Exit codes: 0 ok (``--resolve``: every update within the tolerance); 1 a deviation above the tolerance
(or a status that changed), or the viewer / the renderer failed; 2 unreadable file or bad usage.
The recording format is documented in msg_docs/recording.md; the writer is dlo_ros/recording.py.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .jsonio import json_safe, stdout_to_stderr

from . import recording as R

if TYPE_CHECKING:
    from .solver import Solver

HELP = "open a rerun recording (.rrd) in the viewer, or re-solve it and compare the shapes (--resolve)"
DEFAULT_TOLERANCE = 1e-6
EXIT_OK, EXIT_NOT_OK = 0, 1


class ReplayError(ValueError):
    """Bad input for ``dlo replay`` (unreadable recording, bad option): ``dlo: error: ...``, exit code 2.

    (dlo_ros.cli turns it into its UsageError; replay does not import the cli module, which may be
    running as ``__main__``.)
    """


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


def _table(chunks: list[Any]) -> list[dict[str, Any]]:
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
    rows.sort(key=lambda r: (r.get(R.TIMELINE_UPDATE) if r.get(R.TIMELINE_UPDATE) is not None else -1,
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
        return _table(by_entity.get(entity, []))

    scene_yaml, scene_name, solver_kind = "", "", ""
    for row in rows(R.E_SCENE):
        scene_yaml = _first(row.get("TextDocument:text")) or scene_yaml
        scene_name = _first(row.get("scene_name")) or scene_name
        solver_kind = _first(row.get("solver")) or solver_kind
    if scene_yaml.startswith("# scene not recorded"):
        scene_yaml = ""
    changes = [(int(r[R.TIMELINE_UPDATE]), _first(r.get("TextDocument:text")) or "")
               for r in rows(R.E_SCENE_CHANGES) if r.get(R.TIMELINE_UPDATE) is not None]

    results = []
    for row in rows(R.E_DATA_RESULT):
        status = _first(row.get("status")) or ""
        pts = row.get("points")
        s = row.get("s")
        energy_terms, energy = row.get("energy_terms") or [], row.get("energy") or []
        results.append(RecordedResult(
            update=int(row[R.TIMELINE_UPDATE]), ros_time_ns=row.get(R.TIMELINE_ROS), status=status,
            message=_first(row.get("message")) or "", warm_started=bool(_first(row.get("warm_started"))),
            warm_call=_first(row.get("warm")),
            s=np.asarray(s if s is not None else [], dtype=float),
            points=np.asarray(pts if pts is not None else [], dtype=float).reshape(-1, 3),
            targets=_poses(row.get("target_names"), row.get("target_poses")),
            energy={str(k): float(v) for k, v in zip(energy_terms, energy)},
            model=_model(_first(row.get("model"))),
        ))
    targets = []
    for row in rows(R.E_DATA_TARGETS):
        poses = _poses(row.get("grip_names"), row.get("poses"))
        if poses is not None:
            targets.append((int(row[R.TIMELINE_UPDATE]), poses))
    rejected = [(int(r[R.TIMELINE_UPDATE]), _first(r.get("TextLog:text")) or "") for r in rows(R.E_REJECTED)]
    events = [(entity, r.get(R.TIMELINE_UPDATE), _first(r.get("TextLog:text")) or "")
              for entity in (R.E_STATUS, R.E_MODEL, R.E_RECORDER) for r in rows(entity)]
    centrelines = {}
    for row in rows(R.E_CABLE):
        strips = row.get("LineStrips3D:strips")
        if strips and row.get(R.TIMELINE_UPDATE) is not None:
            centrelines[int(row[R.TIMELINE_UPDATE])] = np.array([seg[0] for seg in strips] + [strips[-1][-1]], dtype=float)
    model_series: dict[str, list[tuple[int, float]]] = {}
    for key in R.MODEL_SCALARS:
        for row in rows(f"{R.E_MODEL_SERIES}/{key}"):
            value = _first(row.get("Scalars:scalars"))
            if value is not None and row.get(R.TIMELINE_UPDATE) is not None:
                model_series.setdefault(key, []).append((int(row[R.TIMELINE_UPDATE]), float(value)))
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

    from .scene import scene_from_dict

    return scene_from_dict(yaml.safe_load(text), source=where)


def _make_solver(kind: str, scene, compile: str) -> Solver:
    from . import solver as S

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
        raise ValueError(f"{rec.path}: the recording has no scene ({R.E_SCENE}); it cannot be re-solved")
    if not rec.results:
        raise ValueError(f"{rec.path}: the recording has no results ({R.E_DATA_RESULT}); nothing to re-solve")
    scene = _scene_from_yaml(rec.scene_yaml, f"{rec.path}#{R.E_SCENE}")
    solver = _make_solver(rec.solver_kind, scene, compile)
    changes = sorted(rec.scene_changes)
    current = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}
    received = sorted(rec.targets, key=lambda t: t[0])
    ti = ci = 0
    rows = []
    for recorded in sorted(rec.results, key=lambda r: r.update):
        while ci < len(changes) and changes[ci][0] <= recorded.update:
            new = _scene_from_yaml(changes[ci][1], f"{rec.path}#{R.E_SCENE_CHANGES}@{changes[ci][0]}")
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


# ---- viewing ---------------------------------------------------------------------------------------------
has_display = R.has_display


def rerun_command() -> list[str]:
    """The rerun viewer executable: $DLO_RERUN_EXE, the venv's ``rerun``, ``rerun`` on PATH, or
    ``python -m rerun``."""
    if os.environ.get("DLO_RERUN_EXE"):
        return [os.environ["DLO_RERUN_EXE"]]
    beside = Path(sys.executable).parent / "rerun"
    if beside.exists():
        return [str(beside)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def no_display_message(path: Path) -> str:
    return "\n".join([
        f"dlo replay: no display here ($DISPLAY and $WAYLAND_DISPLAY are unset), so the rerun viewer cannot "
        f"open a window for {path}.",
        "Instead:",
        f"  * on a machine with a display: `dlo replay {path}` or `rerun {path}` (rerun-sdk 0.41: "
        "`pip install rerun-sdk==0.41.0`)",
        f"  * in a browser, no display needed: `dlo replay {path} --web` (serves http://localhost:9090;"
        " forward the ports 9090 and 9876 over ssh: `ssh -L 9090:localhost:9090 -L 9876:localhost:9876 HOST`)",
        f"  * as an image: `dlo replay {path} --screenshot out.png` (headless; needs a Vulkan driver, "
        "e.g. Debian's mesa-vulkan-drivers)",
        f"  * as a regression check: `dlo replay {path} --resolve`",
    ])


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def screenshot(path: str | Path, png: str | Path, *, update: int | None = None, wait: float = 6.0) -> Path:
    """Render a recording with a headless rerun viewer (its default blueprint, 1920×1080) into ``png``.

    ``update``: the update to show (default: the last).  Raises RuntimeError with the viewer's reason
    when it cannot start (e.g. no Vulkan adapter: install a software one, Debian's mesa-vulkan-drivers).
    """
    from rerun.experimental import ViewerClient

    path, png = Path(path).resolve(), Path(png).resolve()
    viewer = ViewerClient.spawn(headless=True, port=_free_port(), hide_welcome_screen=True)
    try:
        viewer.open(str(path))
        deadline = time.monotonic() + 60
        while viewer.get_state().loading and time.monotonic() < deadline:
            time.sleep(0.2)
        if update is not None:
            viewer.set_time(R.TIMELINE_UPDATE, sequence=int(update), play_state="paused")
        time.sleep(wait)  # let the software renderer paint and the start-up notifications fade
        data = viewer.take_screenshot()
        if not data:
            raise RuntimeError("the viewer returned an empty screenshot")
        png.parent.mkdir(parents=True, exist_ok=True)
        png.write_bytes(data)
    finally:
        try:
            viewer.quit()
        except Exception:  # noqa: BLE001 - best effort
            pass
    return png


# ---- the subcommand ------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.rrd", help="a recording made with --rrd (dlo solve / dlo demo / the node)")
    p.add_argument("--resolve", action="store_true",
                   help="re-run the solver on the recorded targets and report how far today's shapes are from the "
                        "recorded ones (exit 1 if any update exceeds --tolerance)")
    p.add_argument("--tolerance", type=float, default=DEFAULT_TOLERANCE, metavar="M",
                   help=f"with --resolve: largest allowed centreline deviation [m] (default {DEFAULT_TOLERANCE:g})")
    p.add_argument("--json", action="store_true", help="with --resolve: print the report as one JSON object")
    p.add_argument("--compile", action="store_true",
                   help="with --resolve: compile the solver's derivatives to C first (slow first build)")
    p.add_argument("--web", action="store_true", help="serve the recording to a browser (rerun --web-viewer)")
    p.add_argument("--screenshot", metavar="PNG", help="render the recording headlessly into PNG and exit")
    p.add_argument("--update", type=int, metavar="N", help="with --screenshot: show update N (default: the last)")


def cmd_replay(args: argparse.Namespace) -> int:
    path = Path(args.file)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if args.resolve:
        if not (args.tolerance >= 0 and math.isfinite(args.tolerance)):
            raise ReplayError(f"--tolerance: must be a finite number >= 0, got {args.tolerance}")
        try:
            rec = read_recording(path)
            with stdout_to_stderr():  # IPOPT's banner must not mix with the report
                report = resolve(rec, args.tolerance, compile="blocking" if args.compile else "cached")
        except ReplayError:
            raise
        except ValueError as exc:
            raise ReplayError(str(exc)) from None
        print(json.dumps(json_safe(report)) if args.json else format_resolve(report))
        return EXIT_OK if report["ok"] else EXIT_NOT_OK
    try:
        read_recording(path)  # a clear error for a file that is not a recording, before starting a viewer
    except ValueError as exc:
        raise ReplayError(str(exc)) from None
    if args.screenshot:
        try:
            out = screenshot(path, args.screenshot, update=args.update)
        except Exception as exc:  # noqa: BLE001 - the viewer's reasons are varied (no GPU, port, ...)
            print(f"dlo replay: could not render {path} headlessly: {type(exc).__name__}: {exc}\n"
                  "  the headless viewer needs a Vulkan adapter; a software one is Debian's mesa-vulkan-drivers "
                  "(lavapipe)", file=sys.stderr)
            return EXIT_NOT_OK
        print(f"dlo replay: screenshot saved to {out}")
        return EXIT_OK
    if args.web:
        return _run([*rerun_command(), "--web-viewer", str(path)])
    if not has_display():
        print(no_display_message(path))
        return EXIT_OK
    return _run([*rerun_command(), str(path)])


def _run(cmd: list[str]) -> int:
    try:
        code = subprocess.call(cmd)
    except OSError as exc:
        print(f"dlo replay: could not start the rerun viewer ({' '.join(cmd)}): {exc}", file=sys.stderr)
        return EXIT_NOT_OK
    if code not in (0, -2, 130):  # Ctrl-C in the viewer is a normal way out
        print(f"dlo replay: the rerun viewer exited with code {code} ({' '.join(cmd)})", file=sys.stderr)
        return EXIT_NOT_OK
    return EXIT_OK
