"""Reading a recording back: :func:`read_recording` (typed, bounded) and :func:`check_recording`.

The reader of what :class:`dlo_ros.recording.Recorder` writes (entity paths in
:mod:`dlo_ros.recording.paths`; the format and the limits are documented in msg_docs/recording.md).
The file is opened and walked by :mod:`.rrd_file` (regular file, size, message framing, a cut-off
end); rerun's chunk API (``rerun.chunk.RrdReader(...).stream()``) then yields one chunk at a time,
of which :mod:`.columns` keeps only the typed columns dlo_ros needs: no chunk is held after it
was read.  Every failure is one :class:`RecordingError` line naming the file.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from . import paths as P
from .columns import Budget, ColumnError, Columns, updates_of
from ..text import safe_text
from .rrd_file import LIMITS, RrdFileError, RrdLayout, open_rrd

Pose = tuple[np.ndarray, np.ndarray]  # position (3,), quaternion (4,) x, y, z, w


class RecordingError(RrdFileError):
    """The file is not a readable dlo recording: one line naming the file and what is wrong."""


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
    targets: dict[str, Pose] | None
    energy: dict[str, float | None] = field(default_factory=dict)
    model: dict = field(default_factory=dict)  # ShapeResult.model as recorded (JSON text)


@dataclass
class Recording:
    """What ``dlo replay`` needs from an .rrd (rerun's chunk API: ``rerun.chunk.RrdReader``)."""

    path: Path
    application_id: str
    recording_id: str
    entities: set[str]
    scene_yaml: str
    scene_name: str
    solver_kind: str
    scene_changes: list[tuple[int, str]]
    results: list[RecordedResult]
    targets: list[tuple[int, dict[str, Pose]]]
    rejected: list[tuple[int, str]]
    events: list[tuple[str, int | None, str]]
    centrelines: dict[int, np.ndarray]  # update -> (N, 3) as drawn (float32 in the file)
    # model/<key>: [(update, value)]
    model_series: dict[str, list[tuple[int, float]]] = field(default_factory=dict)
    # timeseries/solve_time_ms: [(update, ms)], each solve's wall time as recorded
    solve_times: list[tuple[int, float]] = field(default_factory=list)
    truncated: bool = False  # it ends early (a killed writer): read to its last complete message
    file_bytes: int = 0
    complete_bytes: int = 0  # bytes of the complete messages read (== file_bytes unless truncated)

    @property
    def updates(self) -> list[int]:
        return sorted({r.update for r in self.results})


def rows_of(chunks: list[Any]) -> list[dict[str, Any]]:
    """Return the rows of one entity's chunks as dicts, in logging order.

    Rows of one entity's chunks as dicts (index columns as int, components as Python lists), in
    logging order: by ``update`` then by row id.  For tests and small recordings: it converts every
    column to Python objects (:func:`read_recording` reads only the columns it needs).
    """
    import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

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

    def key(row: dict[str, Any]) -> tuple[int, bytes]:
        update = row.get(P.TIMELINE_UPDATE)
        return (update if update is not None else -1, row.get("rerun.controls.RowId") or b"")

    rows.sort(key=key)
    return rows


def _model(text: Any) -> dict:
    """data/result's ``model`` (JSON text) → dict; {} when absent or unreadable."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except (TypeError, ValueError, RecursionError):
        return {}
    return value if isinstance(value, dict) else {}


def _poses(names: list | None, flat: np.ndarray | None, where: str) -> dict[str, Pose] | None:
    """Grip names and their poses, 7 numbers each (position, quaternion) → {name: pose}."""
    if not names or flat is None:
        return None
    if len(flat) != 7 * len(names):
        raise ColumnError(
            f"{where}: {len(flat)} pose values for {len(names)} grips, expected 7 per grip"
        )
    arr = flat.reshape(len(names), 7)
    return {str(n): (arr[i, 0:3].copy(), arr[i, 3:7].copy()) for i, n in enumerate(names)}


#: Entities whose presence makes a file a dlo recording (the recorder's scene and results, or a
#: ``dlo fit --rrd`` drawing); a rerun recording with none of them is from another program.
DLO_ENTITIES = (P.E_SCENE, P.E_DATA_RESULT, P.E_FIT)
#: Application ids dlo_ros writes (the recorder's default, ``dlo fit --rrd``): a cut-off file of
#: theirs may end before any of :data:`DLO_ENTITIES`.
DLO_APPLICATIONS = ("dlo_ros", "dlo_fit")
EVENTS = (P.E_STATUS, P.E_MODEL, P.E_RECORDER)  # the TextLog entities read into Recording.events


def _or_empty(values: np.ndarray | None) -> np.ndarray:
    return values if values is not None else np.zeros(0)


class _Rows:
    """Rows of one entity collected chunk by chunk, sorted on demand.

    Rows of one entity collected chunk by chunk as ``(update, row id, value)`` (or only
    counted, ``keep=False``), sorted on demand.
    """

    def __init__(self, entity: str, limit: int, budget: Budget, keep: bool = True) -> None:
        self.entity, self.limit, self.budget, self.keep = entity, limit, budget, keep
        self.items: list[tuple[int, bytes, Any]] = []
        self.count = 0

    def add(self, updates: list, row_ids: list[bytes], values: list) -> None:
        self.count += len(values)
        if self.count > self.limit:
            raise ColumnError(
                f"{self.entity}: more than {self.limit} rows (msg_docs/recording.md, Limits)"
            )
        if self.keep:  # the Python objects of a kept row, beyond the numbers Columns counted
            self.budget.take(LIMITS["row_bytes"] * len(values), self.entity)
            self.items.extend(
                (-1 if u is None else u, rid, v) for u, rid, v in zip(updates, row_ids, values)
            )

    def sorted(self) -> list[tuple[int, bytes, Any]]:
        return sorted(self.items, key=lambda t: (t[0], t[1]))


class _Reader:
    """Reader of a recording's chunks that keeps only the typed values dlo_ros needs.

    Reads the chunks of one recording as rerun streams them, one at a time, keeping only the
    typed values of the columns dlo_ros needs (no chunk is held after it was read).
    """

    def __init__(self, path: Path, details: bool, keep: bool = True) -> None:
        self.path, self.details = path, details
        self.budget = Budget(LIMITS["kept_bytes"])
        self.entities: set[str] = set()
        self.scene: list[tuple[str | None, str | None, str | None]] = []
        n = LIMITS["updates"]
        kept = (
            P.E_SCENE_CHANGES,
            P.E_DATA_RESULT,
            P.E_DATA_TARGETS,
            P.E_REJECTED,
            P.E_STATUS,
            P.E_MODEL,
            P.E_RECORDER,
            P.E_CABLE,
        )
        self.keep = keep
        self.rows = {e: _Rows(e, n, self.budget, keep) for e in kept}
        self.series = {
            key: _Rows(f"{P.E_MODEL_SERIES}/{key}", n, self.budget, keep)
            for key in P.MODEL_SCALARS
        }
        self.solve_times = _Rows(P.E_SOLVE_TIME, n, self.budget, keep)

    def chunk(self, entity: str, batch: Any) -> None:
        if entity not in self.entities:
            self.entities.add(entity)
            if len(self.entities) > LIMITS["entities"]:
                raise ColumnError(
                    f"more than {LIMITS['entities']} entities (msg_docs/recording.md, Limits)"
                )
        if not self.keep:  # nothing is kept: the budget bounds one chunk's converted columns
            self.budget.used = 0
        cols = Columns(batch, entity, self.budget)
        if entity == P.E_SCENE:
            self.scene.extend(
                zip(
                    cols.texts("TextDocument:text"), cols.texts("scene_name"), cols.texts("solver")
                )
            )
        elif entity == P.E_SCENE_CHANGES:
            self.rows[entity].add(
                updates_of(cols, True), cols.row_ids(), cols.texts("TextDocument:text")
            )
        elif entity == P.E_DATA_RESULT:
            self._results(cols)
        elif entity == P.E_DATA_TARGETS:
            ups = updates_of(cols, True)
            names = cols.texts("grip_names", first=False)
            poses = [
                _poses(n, flat, f"{entity} update {u} poses")
                for u, n, flat in zip(ups, names, cols.numbers("poses"))
            ]
            self.rows[entity].add(ups, cols.row_ids(), poses)
        elif entity == P.E_REJECTED or (self.details and entity in EVENTS):
            self.rows[entity].add(
                updates_of(cols, entity == P.E_REJECTED),
                cols.row_ids(),
                cols.texts("TextLog:text"),
            )
        elif self.details and entity == P.E_CABLE:
            self.rows[entity].add(
                updates_of(cols, False),
                cols.row_ids(),
                cols.strips("LineStrips3D:strips", LIMITS["samples"]),
            )
        elif (  # kept also without details: --resolve compares the model histories
            self.keep
            and entity.startswith(P.E_MODEL_SERIES + "/")
            and entity[len(P.E_MODEL_SERIES) + 1 :] in self.series
        ):
            self._scalars(cols, self.series[entity[len(P.E_MODEL_SERIES) + 1 :]])
        elif self.keep and entity == P.E_SOLVE_TIME:  # --resolve names the slowest solves
            self._scalars(cols, self.solve_times)

    def _scalars(self, cols: Columns, rows: _Rows) -> None:
        """Add a Scalars entity's values on the update timeline to ``rows``."""
        values = [
            None if v is None or not len(v) else float(v[0])
            for v in cols.numbers("Scalars:scalars", finite=False)
        ]
        # only the rows on the update timeline: the writer's static series-name row
        # (SeriesLines) is no value and must not count against the updates limit
        kept = [
            t for t in zip(updates_of(cols, False), cols.row_ids(), values) if t[0] is not None
        ]
        rows.add([t[0] for t in kept], [t[1] for t in kept], [t[2] for t in kept])

    def _results(self, cols: Columns) -> None:
        where = P.E_DATA_RESULT
        samples = LIMITS["samples"]
        ups = updates_of(cols, True)
        ros = cols.index(P.TIMELINE_ROS)
        status, message = cols.texts("status"), cols.texts("message")
        warm_started, warm = cols.flags("warm_started"), cols.flags("warm")
        pts = cols.numbers("points", per_row=3 * samples)
        names, poses = cols.texts("target_names", first=False), cols.numbers("target_poses")
        none = [None] * cols.rows
        s = cols.numbers("s", per_row=samples) if self.details else none
        terms = cols.texts("energy_terms", first=False) if self.details else none
        energy = cols.numbers("energy", finite=False) if self.details else none
        model = cols.texts("model")  # also for --resolve: it compares the model changes
        values = []
        for i in range(cols.rows):
            p = pts[i]
            p = p if p is not None else np.zeros(0)
            s_i = s[i]
            if len(p) % 3:
                raise ColumnError(
                    f"{where}: update {ups[i]} has {len(p)} point values, not a multiple of 3"
                )
            values.append(
                RecordedResult(
                    update=int(cast(int, ups[i])),  # updates_of(cols, True): never None
                    ros_time_ns=ros[i],
                    status=status[i] or "",
                    message=message[i] or "",
                    warm_started=bool(warm_started[i]),
                    warm_call=warm[i],
                    s=s_i if s_i is not None else np.zeros(0),
                    points=p.reshape(-1, 3),
                    targets=_poses(names[i], poses[i], f"{where} update {ups[i]} target_poses"),
                    # NaN: the result's term was None (msg_docs/recording.md, data/result)
                    energy={
                        str(k): None if np.isnan(v) else float(v)
                        for k, v in zip(terms[i] or [], _or_empty(energy[i]))
                    },
                    model=_model(model[i]),
                )
            )
        self.rows[where].add(ups, cols.row_ids(), values)

    def recording(self, store: Any, layout: RrdLayout) -> Recording:
        scene_yaml = scene_name = solver_kind = ""
        for text, name, kind in self.scene:
            scene_yaml = text or scene_yaml
            scene_name, solver_kind = name or scene_name, kind or solver_kind
        if scene_yaml.startswith("# scene not recorded"):
            scene_yaml = ""
        rows = {e: r.sorted() for e, r in self.rows.items()}
        series = {
            k: [(u, v) for u, _, v in r.sorted() if u >= 0 and v is not None]
            for k, r in self.series.items()
        }
        targets = [(u, poses) for u, _, poses in rows[P.E_DATA_TARGETS] if poses is not None]
        return Recording(
            path=self.path,
            application_id=str(store.application_id),
            recording_id=str(store.recording_id),
            entities=self.entities,
            scene_yaml=scene_yaml,
            scene_name=scene_name,
            solver_kind=solver_kind,
            scene_changes=[(u, t or "") for u, _, t in rows[P.E_SCENE_CHANGES]],
            results=[v for _, _, v in rows[P.E_DATA_RESULT]],
            targets=targets,
            rejected=[(u, t or "") for u, _, t in rows[P.E_REJECTED]],
            events=[(e, None if u < 0 else u, t or "") for e in EVENTS for u, _, t in rows[e]],
            centrelines={u: c for u, _, c in rows[P.E_CABLE] if u >= 0 and c is not None},
            model_series={k: v for k, v in series.items() if v},
            solve_times=[
                (u, v) for u, _, v in self.solve_times.sorted() if u >= 0 and v is not None
            ],
            truncated=layout.truncated,
            file_bytes=layout.file_bytes,
            complete_bytes=layout.complete_bytes,
        )


_PASS_THROUGH = (KeyboardInterrupt, SystemExit, GeneratorExit)


def read_recording(path: str | Path, *, details: bool = True) -> Recording:
    """Read a recording written by :class:`dlo_ros.recording.Recorder` (or ``dlo fit --rrd``).

    Bounded (:data:`dlo_ros.recording.rrd_file.LIMITS`): a regular file only, at most 1 GiB; rerun
    streams the chunks one at a time and only the columns dlo_ros needs are kept, as numpy arrays.
    ``details=False`` reads only what ``--resolve`` needs (the scene, ``data/targets``, and of each
    result its status, message, warm flags, points, target poses and ``model``, and the
    ``model/*`` series): no ``s``, ``energy``, centrelines or ``events/status|model|recorder``.
    A file cut inside a message (a killed writer) is read up to its last complete message
    (``Recording.truncated``).

    Raises FileNotFoundError, or :class:`RecordingError` (a ValueError) with one line naming the
    file when it is not a readable dlo recording.
    """
    path = Path(path)
    reader = _Reader(path, details)
    store, layout = _stream(path, reader)
    try:
        return reader.recording(store, layout)
    except ColumnError as exc:
        raise RecordingError(f"{path}: {exc}") from None


@dataclass(frozen=True)
class RecordingCheck:
    """What :func:`check_recording` found: the file reads, and how much of it."""

    path: Path
    application_id: str
    entities: frozenset[str]
    updates: int  # rows of data/result
    truncated: bool
    file_bytes: int
    complete_bytes: int


def check_recording(path: str | Path) -> RecordingCheck:
    """Check that ``path`` is a readable dlo recording without keeping its data.

    Check that ``path`` is a readable dlo recording without keeping its data: every chunk is
    read and its columns checked as :func:`read_recording` would (same limits and errors), then
    dropped, so the memory used does not grow with the number of updates.  What ``dlo replay
    FILE`` does before it starts a viewer.
    """
    path = Path(path)
    reader = _Reader(path, details=False, keep=False)
    store, layout = _stream(path, reader)
    return RecordingCheck(
        path,
        str(store.application_id),
        frozenset(reader.entities),
        reader.rows[P.E_DATA_RESULT].count,
        layout.truncated,
        layout.file_bytes,
        layout.complete_bytes,
    )


def _stream(path: Path, reader: _Reader) -> tuple[Any, RrdLayout]:
    """Feed every chunk of the file's first recording to ``reader``, one at a time.

    Feed every chunk of the file's first recording to ``reader``, one chunk at a time; (its
    store entry, the file's layout).  Every failure is a :class:`RecordingError` naming the
    file.
    """
    try:  # optional: rerun-sdk (Python >= 3.11)
        from rerun.chunk import RrdReader
    except ImportError as exc:
        raise RecordingError(
            f"reading recordings needs rerun-sdk (Python >= 3.11): {exc}"
        ) from None
    with open_rrd(path) as (name, layout):
        try:
            with warnings.catch_warnings():  # "no footer/manifest": expected for a truncated file
                warnings.simplefilter("ignore")
                rrd = RrdReader(name)
                stores = rrd.recordings()
                if not stores:
                    raise RecordingError(f"{path}: no recording in the file")
                for chunk in rrd.stream(store=stores[0]):
                    reader.chunk(chunk.entity_path.lstrip("/"), chunk.to_record_batch())
        except (RecordingError, RrdFileError):
            raise
        except ColumnError as exc:
            raise RecordingError(f"{path}: {exc}") from None
        except _PASS_THROUGH:
            raise
        except BaseException as exc:  # noqa: BLE001 - rerun raises plain errors for corrupt or
            # foreign files, and a Rust panic (pyo3's PanicException) is a BaseException
            raise RecordingError(
                f"{path}: not a readable rerun recording ({type(exc).__name__}: "
                f"{_one_line(str(exc).replace(name, str(path)))})"
            ) from None
    application = str(stores[0].application_id)
    if not reader.entities & set(DLO_ENTITIES) and application not in DLO_APPLICATIONS:
        raise RecordingError(
            f"{path}: not a dlo_ros recording (application "
            f"'{_one_line(application)}' has none of the entities "
            f"{', '.join(DLO_ENTITIES)})"
        )
    return stores[0], layout


def _one_line(text: str, limit: int = 200) -> str:
    """``text`` on one line, at most ``limit`` characters (rerun's messages may span lines)."""
    return safe_text(" ".join(text.split()), limit)
