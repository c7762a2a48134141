"""The writer: turns queued items into rerun calls, in one thread.

The writer: owns the rerun RecordingStream and turns queued items into rerun calls, in one
thread.

It runs in the recorder's child process or thread (dlo_ros.recording.transport); nothing here is
called from the solver's thread.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from .blueprint import default_blueprint
from .envelope_drawing import EnvelopeDrawing
from .codec import decode, FitSnap, QueueItem, ResultSnap
from .paths import (
    E_DATA_RESULT,
    E_DATA_TARGETS,
    E_EIGEN,
    E_ENERGY,
    E_FIT,
    E_FIT_EVENTS,
    E_ITERATIONS,
    E_LEGEND,
    E_MODEL,
    E_MODEL_SERIES,
    E_OBSTACLES,
    E_RECORDER,
    E_REJECTED,
    E_SCENE,
    E_SCENE_CHANGES,
    E_SOLVE_TIME,
    E_STATUS,
    E_WORLD,
    ENERGY_TERMS,
    MODEL_SCALARS,
    TIMELINE_ROS,
    TIMELINE_UPDATE,
    path_part,
)
from .scene_info import SceneInfo
from .shape_columns import ShapeBatch, legend_markdown, shape_columns, target_columns
from .visuals import ENERGY_COLORS

log = logging.getLogger(__name__)


class RecordingUnavailable(RuntimeError):
    """Recording was asked for but rerun-sdk cannot be imported (it needs Python >= 3.11)."""


@dataclass
class WriterConfig:
    """Where and how the writer records: the Recorder's arguments, as plain picklable data.

    rrd: file to save (None: none); spawn/spawn_port: start a viewer; urls: viewers to stream to;
    application_id/recording_id: rerun's; frames: material frames drawn per shape.
    """

    rrd: str | None
    spawn: bool
    spawn_port: int
    urls: list
    application_id: str
    recording_id: str | None
    frames: int


# rows wait at most this long in the writer before they are sent (live viewers lag this much)
BATCH_SECONDS = 0.1
BATCH_ROWS = 512  # ... or until this many rows are buffered


def _instances(value: Any) -> Any:
    """Return a field value as a batch of instances (leading axis = instances)."""
    if isinstance(value, np.ndarray):
        return value if value.ndim else value.reshape(1)
    if isinstance(value, (list, tuple)):
        return list(value)
    return [value]


def _concat(values: list) -> Any:
    if all(isinstance(v, np.ndarray) for v in values):
        return np.concatenate(values, axis=0)
    out: list = []
    for v in values:
        out.extend(v.tolist() if isinstance(v, np.ndarray) else v)
    return out


class Writer(EnvelopeDrawing):
    """Owns the rerun RecordingStream and turns items into rerun calls, in one thread.

    Static data is logged at once; time-stamped rows are buffered per (entity, archetype) and sent
    with ``send_columns`` at most every BATCH_SECONDS (or BATCH_ROWS rows, or on flush/close): one
    rerun call per entity per batch instead of one per row, because the per-row Python cost is what
    the CPU pays (the bench's recording-overhead script measures it).
    """

    def __init__(self, cfg: WriterConfig) -> None:
        try:
            import rerun as rr  # optional: rerun-sdk (Python >= 3.11), with pyarrow
        except ImportError as exc:  # Python 3.10, or a broken install
            raise RecordingUnavailable(
                f"recording needs rerun-sdk (Python >= 3.11; see requirements.txt): {exc}"
            ) from None
        self._rr = rr
        self.cfg = cfg
        self.rec = rr.RecordingStream(cfg.application_id, recording_id=cfg.recording_id)
        sinks: list[Any] = []
        if cfg.rrd:
            Path(cfg.rrd).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(cfg.rrd)))
        if cfg.spawn:
            # Starts the `rerun` viewer and waits until it listens; it needs a display for its
            # window.
            rr.spawn(port=cfg.spawn_port, connect=False, recording=self.rec)
        for url in dict.fromkeys(cfg.urls):
            sinks.append(rr.GrpcSink(url))
        self.rec.set_sinks(*sinks)
        self.recording_id = self.rec.get_recording_id()
        self.n_frames = max(0, int(cfg.frames))
        self.errors = 0
        self.last_error = ""
        self.scene: SceneInfo | None = None
        self.blueprint_sent = False
        self.energy_scale: float | None = None
        self.last_status: tuple | None = None
        self.dropped_reported = 0
        self._rows: dict[tuple[str, str], list[tuple[int, int, dict]]] = {}
        self._pending_targets: list[QueueItem] = []
        self._pending_results: list[QueueItem] = []
        self._n_rows = 0
        self._oldest: float | None = None

    def stats(self) -> dict:
        return {"errors": self.errors, "last_error": self.last_error}

    def _error(self, what: str, exc: BaseException) -> None:
        self.errors += 1
        self.last_error = f"{what}: {type(exc).__name__}: {exc}"
        if self.errors <= 3:
            log.warning("recorder: %s", self.last_error)

    def handle(self, message: Any, dropped_total: int = 0) -> None:
        """Log one message (an QueueItem or an encoded tuple, see :func:`decode`)."""
        item = QueueItem("?", None, 0)
        try:
            item = decode(message)
            if dropped_total != self.dropped_reported:
                self._report_drops(dropped_total, item)
            if item.kind == "scene":
                self._handle_scene(item)
            else:
                if not self.blueprint_sent:
                    self._send_blueprint(None)
                getattr(self, "_handle_" + item.kind)(item)
        except Exception as exc:  # noqa: BLE001 - recording must never take the caller down
            self._error(f"logging a {item.kind}", exc)
        if self._n_rows >= BATCH_ROWS:
            self.send_batches()

    def due(self) -> float | None:
        """Seconds until the buffered rows must be sent (None: nothing buffered)."""
        if self._oldest is None:
            return None
        return max(0.0, self._oldest + BATCH_SECONDS - time.monotonic())

    def send_batches(self) -> None:
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        targets, results = self._pending_targets, self._pending_results
        self._pending_targets, self._pending_results = [], []
        if targets:
            self._send_targets(targets)
        if results:
            self._send_results(results)
        rows, self._rows, self._n_rows, self._oldest = self._rows, {}, 0, None
        for (entity, arch), entries in rows.items():
            try:
                names = list(dict.fromkeys(k for _, _, f in entries for k in f))
                groups: dict[tuple, dict] = {}
                for name in names:
                    values = [_instances(f[name]) if name in f else [] for _, _, f in entries]
                    data = _concat(values)
                    if (
                        arch == "AnyValues"
                    ):  # as an Arrow array: rerun's generic path boxes every number
                        data = pa.array(data)
                    groups.setdefault(tuple(len(v) for v in values), {})[name] = data
                self._send_columns(
                    entity, arch, [u for u, _, _ in entries], [t for _, t, _ in entries], groups
                )
            except Exception as exc:  # noqa: BLE001 - reported by _error, never raised
                self._error(f"sending {entity}", exc)

    def flush(self, timeout: float = 10.0) -> None:
        self.send_batches()
        self.rec.flush(timeout_sec=max(0.1, timeout))

    def close(self, timeout: float = 10.0) -> None:
        try:
            self.send_batches()
            self.rec.flush(timeout_sec=max(0.1, timeout))
            self.rec.disconnect()
        except Exception as exc:  # noqa: BLE001 - a dead viewer must not break shutdown
            self._error("closing the sinks", exc)

    # -- items
    def _row(self, entity: str, arch: str, item: QueueItem, **fields: Any) -> None:
        self._rows.setdefault((entity, arch), []).append(
            (int(cast(int, item.update)), int(item.ros_time_ns), fields)
        )
        self._count_row()

    def _count_row(self) -> None:
        self._n_rows += 1
        if self._oldest is None:
            self._oldest = time.monotonic()

    def _report_drops(self, dropped: int, item: QueueItem) -> None:
        text = (
            f"recorder queue full: {dropped - self.dropped_reported} item(s) dropped before this "
            f"one ({dropped} in total)"
        )
        if item.update is not None:
            self._row(E_RECORDER, "TextLog", item, text=text, level="WARN")
        else:
            self.rec.log(
                E_RECORDER, self._rr.TextLog(text, level=self._rr.TextLogLevel.WARN), static=True
            )
        self.dropped_reported = dropped

    def _handle_scene(self, item: QueueItem) -> None:
        rr = self._rr
        info: SceneInfo = item.payload
        first = self.scene is None
        self.scene = info
        static = item.update is None
        if not static:
            self.send_batches()  # rows of earlier updates are drawn with the earlier scene
            self.rec.set_time(TIMELINE_UPDATE, sequence=int(cast(int, item.update)))
            self.rec.set_time(TIMELINE_ROS, timestamp=np.datetime64(int(item.ros_time_ns), "ns"))
        if first or static:
            self.rec.log(E_WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for i, (kind, kwargs, label, colour) in enumerate(info.obstacles):
            arch = getattr(rr, kind)(
                **kwargs, colors=[colour], labels=[label], fill_mode=rr.components.FillMode.Solid
            )
            self.rec.log(f"{E_OBSTACLES}/{i}_{path_part(label)}", arch, static=static)
        doc = rr.TextDocument(
            info.yaml_text or "# scene not recorded (a Problem was logged)",
            media_type="text/plain",
        )
        props = rr.AnyValues(
            scene_name=info.name,
            frame_id=info.frame_id,
            solver=info.solver_kind,
            grip_names=list(info.grip_order),
        )
        self.rec.log(E_SCENE if static else E_SCENE_CHANGES, doc, props, static=static)
        if not self.blueprint_sent:
            self._send_blueprint(info)

    def _send_blueprint(self, info: SceneInfo | None) -> None:
        self.rec.send_blueprint(default_blueprint(info), make_active=True, make_default=True)
        self.blueprint_sent = True

    def _handle_targets(self, item: QueueItem) -> None:
        self._pending_targets.append(item)
        self._count_row()

    def _handle_result(self, item: QueueItem) -> None:
        r: ResultSnap = item.payload
        key = (r.status, r.stable)
        if key != self.last_status:
            text = f"{r.status}: {r.message}" + ("" if r.stable is not False else " (unstable)")
            level = "INFO" if r.status == "ok" and r.stable is not False else "WARN"
            self._row(E_STATUS, "TextLog", item, text=[text], level=[level])
            self.last_status = key
        self._pending_results.append(item)
        self._count_row()

    # -- batched, vectorised over the rows of a batch (the per-row Python cost is what the CPU
    # pays)
    def _send(
        self, entity: str, arch: str, items: list[QueueItem], **fields: tuple[Any, list[int]]
    ) -> None:
        """Send ``arch`` rows for ``items``, one send_columns call.

        send_columns of ``arch`` rows for ``items``; fields: name → (concatenated data,
        instances per row).
        """
        try:
            groups: dict[tuple, dict] = {}
            for name, (data, lengths) in fields.items():
                groups.setdefault(tuple(int(n) for n in lengths), {})[name] = data
            self._send_columns(
                entity,
                arch,
                [int(cast(int, it.update)) for it in items],
                [int(it.ros_time_ns) for it in items],
                groups,
            )
        except Exception as exc:  # noqa: BLE001 - reported by _error, never raised
            self._error(f"sending {entity}", exc)

    def _send_columns(
        self,
        entity: str,
        arch: str,
        updates: list[int],
        stamps: list[int],
        groups: dict[tuple, dict],
    ) -> None:
        """Send one send_columns of ``arch`` rows at ``updates`` and ``stamps`` [ns].

        One send_columns of ``arch`` rows at ``updates`` and ``stamps`` [ns]; ``groups``:
        instances per row → {field: concatenated data} (fields with the same instance counts share
        a partition).
        """
        rr = self._rr
        indexes = [
            rr.TimeColumn(TIMELINE_UPDATE, sequence=updates),
            rr.TimeColumn(TIMELINE_ROS, timestamp=np.array(stamps, dtype="datetime64[ns]")),
        ]
        columns: list[Any] = []
        for lengths, fields in groups.items():
            columns.extend(getattr(rr, arch).columns(**fields).partition(list(lengths)))
        self.rec.send_columns(entity, indexes=indexes, columns=columns)

    def _send_targets(self, items: list[QueueItem]) -> None:
        for it in items:
            names = list(it.payload)
            flat = [np.concatenate([pos, quat]) for pos, quat in it.payload.values()]
            self._row(
                E_DATA_TARGETS,
                "AnyValues",
                it,
                grip_names=names,
                poses=np.concatenate(flat) if flat else np.zeros(0),
            )
        length = self.scene.length if self.scene else 1.0
        for columns in target_columns(items, length):
            self._send(columns.entity, columns.arch, columns.items, **columns.fields)

    def _send_results(self, items: list[QueueItem]) -> None:
        snaps: list[ResultSnap] = [it.payload for it in items]
        ones = [1] * len(items)
        self._send(
            E_SOLVE_TIME,
            "Scalars",
            items,
            scalars=(np.array([r.solve_time_ms for r in snaps]), ones),
        )
        self._send(
            E_ITERATIONS,
            "Scalars",
            items,
            scalars=(np.array([float(r.iterations) for r in snaps]), ones),
        )
        shapes: dict[int, list[int]] = {}
        for i, (it, r) in enumerate(zip(items, snaps)):
            data: dict[str, Any] = dict(
                status=r.status,
                message=r.message,
                warm_started=r.warm_started,
                iterations=r.iterations,
            )
            if r.warm_call is not None:
                data["warm"] = bool(r.warm_call)
            if r.targets is not None:
                data["target_names"] = list(r.targets)
                data["target_poses"] = np.concatenate(
                    [np.concatenate(p) for p in r.targets.values()]
                )
            if r.status == "ok" and len(r.points) >= 2:
                shapes.setdefault(len(r.points), []).append(i)
                data.update(
                    s=r.s,
                    points=r.points.ravel(),
                    orientations=r.orientations.ravel(),
                    energy_terms=list(r.energy),
                    energy=np.array(list(r.energy.values()), dtype=float),
                    grip_names=list(r.forces),
                    grip_forces=np.concatenate(list(r.forces.values()))
                    if r.forces
                    else np.zeros(0),
                )
                if r.stable is not None:
                    data["stable"] = bool(r.stable)
                if len(
                    r.self_contacts
                ):  # rows of s_a, s_b, point_a, point_b, force on s_a (flattened)
                    data["self_contacts"] = r.self_contacts.ravel()
            if r.model:  # also for a failed solve: the model it was attempted with
                data["model"] = _json(r.model)
            self._row(E_DATA_RESULT, "AnyValues", it, **data)
        self._send_model_scalars(items, snaps)
        for rows in shapes.values():
            try:
                self._send_shapes([items[i] for i in rows], [snaps[i] for i in rows])
            except Exception as exc:  # noqa: BLE001 - reported by _error, never raised
                self._error("drawing shapes", exc)

    def _send_model_scalars(self, items: list[QueueItem], snaps: list[ResultSnap]) -> None:
        """model/<key>: the numbers of ShapeResult.model (None and non-numbers are skipped)."""
        for key in MODEL_SCALARS:
            have, values = [], []
            for i, r in enumerate(snaps):
                v = r.model.get(key) if r.model else None
                if isinstance(v, (bool, int, float)) and math.isfinite(float(v)):
                    have.append(i)
                    values.append(float(v))
            if have:
                self._send(
                    f"{E_MODEL_SERIES}/{key}",
                    "Scalars",
                    [items[i] for i in have],
                    scalars=(np.array(values), [1] * len(have)),
                )

    def _send_shapes(self, items: list[QueueItem], snaps: list[ResultSnap]) -> None:
        """Draw ok results of N samples each: the columns of ``shape_columns``, sent in order."""
        batch = ShapeBatch.of(snaps, self.scene)
        if self.energy_scale is None:
            self.energy_scale = batch.energy_scale()
            self._log_legend()
        for columns in shape_columns(
            items, snaps, batch, self.scene, self.n_frames, self.energy_scale
        ):
            self._send(columns.entity, columns.arch, columns.items, **columns.fields)

    def _log_legend(self) -> None:
        """Log the legend (markdown) and the names and colours of the time series, once."""
        rr = self._rr
        text = legend_markdown(self.energy_scale or 0.0, self.scene)
        self.rec.log(
            E_LEGEND,
            rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN),
            static=True,
        )
        self.rec.log(
            E_ENERGY, rr.SeriesLines(names=list(ENERGY_TERMS), colors=ENERGY_COLORS), static=True
        )
        self.rec.log(
            E_SOLVE_TIME,
            rr.SeriesLines(names=["solve time [ms]"], colors=[[255, 170, 60]]),
            static=True,
        )
        self.rec.log(
            E_ITERATIONS,
            rr.SeriesLines(names=["iterations"], colors=[[120, 180, 255]]),
            static=True,
        )
        self.rec.log(
            E_EIGEN,
            rr.SeriesLines(names=["min eigenvalue"], colors=[[120, 220, 120]]),
            static=True,
        )
        for key, name in MODEL_SCALARS.items():
            self.rec.log(f"{E_MODEL_SERIES}/{key}", rr.SeriesLines(names=[name]), static=True)

    def _handle_rejected(self, item: QueueItem) -> None:
        self._row(E_REJECTED, "TextLog", item, text=[item.payload], level=["WARN"])

    def _handle_model(self, item: QueueItem) -> None:
        self._row(E_MODEL, "TextLog", item, text=[item.payload], level=["INFO"])

    def _handle_fit(self, item: QueueItem) -> None:
        # optional: only a recording with a fit needs it; not at the top: the writer's process
        # must not import the model (identify imports the solver)
        from ..identify.drawing import draw_observation

        fit: FitSnap = item.payload
        self.send_batches()  # keep the rows of earlier updates before this one
        self.rec.set_time(TIMELINE_UPDATE, sequence=int(cast(int, item.update)))
        self.rec.set_time(TIMELINE_ROS, timestamp=np.datetime64(int(item.ros_time_ns), "ns"))
        draw_observation(
            self.rec, E_FIT, fit.points, fit.shape, fit.feet, fit.sigma, fit.huber, static=False
        )
        level = self._rr.TextLogLevel.INFO if fit.ok else self._rr.TextLogLevel.WARN
        self.rec.log(E_FIT_EVENTS, self._rr.TextLog(fit.text, level=level))


def _json(value: Any) -> str:
    return json.dumps(
        value, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o), sort_keys=True
    )
