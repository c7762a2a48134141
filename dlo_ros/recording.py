"""Rerun recording of what the solver does: shapes, forces, targets, timings, events (no ROS).

One :class:`Recorder` per recording.  It is *off* (every method a cheap no-op) unless one of ``rrd``
(save to an .rrd file), ``spawn`` (start a native viewer and stream to it) or ``connect`` (stream to a
running viewer) is given; any combination works.  Documented in ``msg_docs/recording.md``.

Off the critical path: ``log_targets`` / ``log_result`` / ``log_update`` copy their arguments into a
flat tuple of bytes, pickle it and write it into a non-blocking pipe (tens of µs); a child process
(``backend="process"``, niced) makes every rerun call, in column batches.  If the pipe and the bounded
backlog behind it are full, the oldest waiting message is dropped and counted (:attr:`Recorder.dropped`);
the scene (``log_scene``) and model changes are never dropped.  Every ``log_*`` is thread-safe and keeps
the order of one thread's calls.  ``backend="thread"`` runs the writer in a thread instead.

Entity tree (world frame, right-handed, z up, metres; timelines ``update`` (sequence) and
``ros_time`` (timestamp)):

=============================  ===================================================================
``world``                      ViewCoordinates RIGHT_HAND_Z_UP (static)
``world/obstacles/<i>_<name>`` the scene's obstacles as their own shapes (static)
``world/cable``                centreline: one segment per pair of samples, coloured by bend energy
                               density ½ Rf κ² (viridis; scale in ``scene/legend``)
``world/cable/frames``         material frames at a few samples (x tangent red, y green, z blue)
``world/grips/<name>``         grip pose (axes) at the grip's s on the solved shape
``world/grips/<name>/force``   force the gripper exerts on the string (arrow, label in N)
``world/targets/<name>``       the grip target as received (point + tangent arrow)
``timeseries/solve_time_ms``   wall time of each solve [ms]
``timeseries/iterations``      Newton steps or IPOPT iterations
``timeseries/energy``          bend, twist, stretch, gravity, external_work, total [J]
``timeseries/min_eigenvalue``  smallest reduced Hessian eigenvalue (< 0: unstable)
``model/<key>``                the solver's model per update (``ShapeResult.model``): ``order``,
                               ``variables``, ``planar`` (1/0), ``estimated_error_m``, ``tolerance_m``
``events/status``              status text, logged when it (or stability) changes
``events/rejected``            every rejected input with its reason (WARN)
``events/model``               model events (INFO): changes of the model with their reasons, scene changes
``events/recorder``            the recorder's own warnings (dropped items)
``world/fit/observed``         the node's fits (``log_fit``): observed points, red beyond the robust
``world/fit/fitted``           loss's threshold; the fitted centreline; one segment per point to its
``world/fit/residuals``        nearest point on it (dlo_ros.identify.drawing), at the fit's update
``events/fit``                 each fit's summary line and what it applied (INFO; WARN if not ok)
``scene/yaml``                 the scene file (scene_to_dict as YAML), static; ``scene/changes`` later ones
``scene/legend``               colour and arrow scales (static)
``data/result``                exact float64 copy of each result (for ``dlo replay --resolve``)
``data/targets``               exact float64 copy of each received target set
=============================  ===================================================================
"""
from __future__ import annotations

import collections
import logging
import math
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .model.rotations import quat_z_to

log = logging.getLogger(__name__)

DEFAULT_GRPC_URL = "rerun+http://127.0.0.1:9876/proxy"
DEFAULT_PORT = 9876
ENERGY_TERMS = ("bend", "twist", "stretch", "gravity", "external_work", "total")
ENERGY_COLORS = [[230, 90, 90], [90, 200, 230], [200, 120, 230], [120, 200, 90], [230, 180, 60], [240, 240, 240]]
AXIS_COLORS = [[230, 60, 60], [60, 200, 60], [70, 110, 255]]
TIMELINE_UPDATE = "update"
TIMELINE_ROS = "ros_time"

# Entity paths (also used by dlo_ros.replay to read a recording back).
E_WORLD = "world"
E_CABLE = "world/cable"
E_FRAMES = "world/cable/frames"
E_GRIPS = "world/grips"
E_TARGETS = "world/targets"
E_OBSTACLES = "world/obstacles"
E_SOLVE_TIME = "timeseries/solve_time_ms"
E_ITERATIONS = "timeseries/iterations"
E_ENERGY = "timeseries/energy"
E_EIGEN = "timeseries/min_eigenvalue"
E_MODEL_SERIES = "model"  # model/<key>: scalars of ShapeResult.model, one row per result that has them
#: ShapeResult.model entries recorded as scalars (model/<key>; booleans as 1/0), with their series names.
MODEL_SCALARS = {"order": "basis order", "variables": "unknowns", "planar": "planar (1) / 3D (0)",
                 "estimated_error_m": "estimated error [m]", "tolerance_m": "tolerance [m]"}
E_STATUS = "events/status"
E_REJECTED = "events/rejected"
E_MODEL = "events/model"
E_RECORDER = "events/recorder"
E_FIT = "world/fit"  # world/fit/{observed,fitted,residuals}: the node's newest fit (dlo_ros.identify.drawing)
E_FIT_EVENTS = "events/fit"  # each fit's summary and what it applied (INFO) or why not (WARN)
E_SCENE = "scene/yaml"
E_SCENE_CHANGES = "scene/changes"
E_LEGEND = "scene/legend"
E_DATA_RESULT = "data/result"
E_DATA_TARGETS = "data/targets"

#: viridis at 0, 1/8, …, 1 (8-bit RGB); the centreline's colour map.
_VIRIDIS = np.array([
    [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
    [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]], dtype=float)


class RecordingUnavailable(RuntimeError):
    """Recording was asked for but rerun-sdk cannot be imported (it needs Python >= 3.11)."""


# ---- pure helpers (no rerun) -------------------------------------------------------------------------
def has_display() -> bool:
    """Whether a native window can open here (Linux: $DISPLAY or $WAYLAND_DISPLAY; macOS, Windows: yes)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def grpc_url(address: str | None) -> str:
    """``--connect`` address → rerun gRPC URL.

    ``rerun://…``, ``rerun+http://…``, ``rerun+https://…`` are kept; ``HOST``, ``HOST:PORT`` or ``:PORT``
    become ``rerun+http://HOST:PORT/proxy`` (host 127.0.0.1, port 9876 when omitted); ``""`` is the default
    ``rerun+http://127.0.0.1:9876/proxy``.
    """
    address = (address or "").strip()
    if not address:
        return DEFAULT_GRPC_URL
    if address.startswith(("rerun://", "rerun+http://", "rerun+https://")):
        return address
    if "://" in address:
        raise ValueError(f"--connect: expected HOST[:PORT] or a rerun+http://HOST:PORT/proxy URL, got {address!r}")
    host, _, port = address.rpartition(":") if ":" in address else (address, "", "")
    host = host or "127.0.0.1"
    if port:
        if not port.isdigit() or not (0 < int(port) < 65536):
            raise ValueError(f"--connect: bad port in {address!r}")
    else:
        port = str(DEFAULT_PORT)
    return f"rerun+http://{host}:{port}/proxy"


def bend_energy_density(points: np.ndarray, bend_stiffness: float | np.ndarray) -> np.ndarray:
    """½ Rf κ² per segment [J/m] of a polyline (N points → N−1 values).

    κ at an interior vertex is the turning angle between consecutive tangents divided by the mean of
    the two segment lengths; the end vertices take their neighbour's κ; a segment gets the mean of κ²
    at its two ends.  ``bend_stiffness``: Rf [N·m²], a constant or one value per point.
    """
    p = np.asarray(points, dtype=float)
    n = len(p)
    if n < 2:
        return np.zeros(0)
    e = np.diff(p, axis=0)
    length = np.linalg.norm(e, axis=1)
    t = e / np.maximum(length, 1e-300)[:, None]
    kappa = np.zeros(n)
    if n > 2:
        cross = np.linalg.norm(np.cross(t[:-1], t[1:]), axis=1)
        dot = np.einsum("ij,ij->i", t[:-1], t[1:])
        kappa[1:-1] = np.arctan2(cross, dot) / np.maximum(0.5 * (length[:-1] + length[1:]), 1e-300)
        kappa[0], kappa[-1] = kappa[1], kappa[-2]
    rf = np.asarray(bend_stiffness, dtype=float)
    rf = np.full(n, float(rf)) if rf.ndim == 0 else np.broadcast_to(rf.ravel(), (n,))
    k2 = kappa**2
    return 0.5 * 0.5 * (rf[:-1] * k2[:-1] + rf[1:] * k2[1:])


def bend_energy_density_batch(points: np.ndarray, bend_stiffness: np.ndarray) -> np.ndarray:
    """:func:`bend_energy_density` of m polylines at once: points (m, N, 3), Rf (m, N) → (m, N−1)."""
    p = np.asarray(points, dtype=float)
    e = np.diff(p, axis=1)
    length = np.linalg.norm(e, axis=2)
    t = e / np.maximum(length, 1e-300)[:, :, None]
    kappa = np.zeros(p.shape[:2])
    if p.shape[1] > 2:
        cross = np.linalg.norm(np.cross(t[:, :-1], t[:, 1:]), axis=2)
        dot = np.einsum("mij,mij->mi", t[:, :-1], t[:, 1:])
        kappa[:, 1:-1] = np.arctan2(cross, dot) / np.maximum(0.5 * (length[:, :-1] + length[:, 1:]), 1e-300)
        kappa[:, 0], kappa[:, -1] = kappa[:, 1], kappa[:, -2]
    k2 = np.asarray(bend_stiffness, dtype=float) * kappa**2
    return 0.25 * (k2[:, :-1] + k2[:, 1:])


def viridis(u: np.ndarray) -> np.ndarray:
    """Values in [0, 1] (clipped) → uint8 RGB (…, 3)."""
    u = np.clip(np.nan_to_num(np.asarray(u, dtype=float)), 0.0, 1.0) * (len(_VIRIDIS) - 1)
    i = np.minimum(u.astype(int), len(_VIRIDIS) - 2)
    f = (u - i)[..., None]
    return np.round(_VIRIDIS[i] * (1 - f) + _VIRIDIS[i + 1] * f).astype(np.uint8)


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w) → (N, 3, 3) rotation matrices (columns = pose axes)."""
    q = np.asarray(q, dtype=float).reshape(-1, 4)
    q = q / np.sqrt(np.einsum("ij,ij->i", q, q))[:, None]
    x, y, z, w = q.T
    m = np.empty((len(q), 3, 3))
    m[:, 0, 0] = 1 - 2 * (y * y + z * z)
    m[:, 0, 1] = 2 * (x * y - z * w)
    m[:, 0, 2] = 2 * (x * z + y * w)
    m[:, 1, 0] = 2 * (x * y + z * w)
    m[:, 1, 1] = 1 - 2 * (x * x + z * z)
    m[:, 1, 2] = 2 * (y * z - x * w)
    m[:, 2, 0] = 2 * (x * z - y * w)
    m[:, 2, 1] = 2 * (y * z + x * w)
    m[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def obstacle_shape(ob: Any, centre: np.ndarray, extent: float) -> tuple[str, dict]:
    """(archetype name, keyword arguments) drawing an obstacle (``dlo_ros.model.Obstacle``).

    halfspace → a square slab of side 2·extent, 1 % of that thick, lying just behind the surface,
    centred on the projection of ``centre``; sphere → Ellipsoids3D; capsule → Capsules3D; box → Boxes3D.
    """
    p = np.asarray(ob.params, dtype=float)
    if ob.type == "halfspace":
        point, normal = p[0:3], p[3:6] / np.linalg.norm(p[3:6])
        foot = centre - np.dot(centre - point, normal) * normal
        thick = 0.01 * extent
        return "Boxes3D", dict(centers=[foot - 0.5 * thick * normal], half_sizes=[[extent, extent, 0.5 * thick]],
                               quaternions=[quat_z_to(normal)])
    if ob.type == "sphere":
        return "Ellipsoids3D", dict(centers=[p[0:3]], half_sizes=[[p[3]] * 3])
    if ob.type == "capsule":
        a, b = p[0:3], p[3:6]
        return "Capsules3D", dict(translations=[a], lengths=[float(np.linalg.norm(b - a))], radii=[p[6]],
                                  quaternions=[quat_z_to(b - a)])
    if ob.type == "box":
        rotation = p[3:12].reshape(3, 3).T  # params hold Rᵀ row-major
        from .model.rotations import matrix_to_quat

        return "Boxes3D", dict(centers=[p[0:3]], half_sizes=[p[12:15]], quaternions=[matrix_to_quat(rotation)])
    raise ValueError(f"obstacle type {ob.type!r} has no drawing")


def scene_yaml(scene: Any) -> str:
    """The scene in the scene-file format (``dlo_ros.scene.scene_to_dict``) as YAML text."""
    import yaml

    from .scene import scene_to_dict

    return yaml.safe_dump(scene_to_dict(scene), sort_keys=False, default_flow_style=None, width=120)


# ---- snapshots (what the queue holds: copies, no references into the caller's objects) -------------
@dataclass
class _Item:
    kind: str
    update: int | None
    ros_time_ns: int
    payload: Any = None


@dataclass
class _ResultSnap:
    status: str
    message: str
    stable: bool | None
    min_eigenvalue: float | None
    iterations: int
    solve_time_ms: float
    warm_started: bool
    warm_call: bool | None
    s: np.ndarray
    points: np.ndarray
    orientations: np.ndarray
    energy: dict
    forces: dict
    bend_stiffness: Any
    targets: dict | None = None
    model: dict = field(default_factory=dict)
    # one row per self-contact: s_a, s_b [m], point_a, point_b [m], force on s_a [N] (its opposite acts on s_b)
    self_contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 11)))


@dataclass
class _FitSnap:
    """A fit as the node recorded it: observed points, fitted centreline and each point's nearest point on
    it (m), the stated σ [m] and the robust loss's threshold [σ], the summary text, whether it was ok."""

    points: np.ndarray
    shape: np.ndarray
    feet: np.ndarray
    sigma: float
    huber: float
    text: str
    ok: bool


@dataclass
class _SceneInfo:
    """What the writer needs of a scene (plain data: the writer process never imports the model)."""

    name: str
    frame_id: str
    length: float
    grip_s: dict
    grip_order: tuple
    rf_table: tuple  # (s values, Rf values): Rf(s) piecewise linear, ends held
    force_scale: float  # m per N
    yaml_text: str
    obstacles: list  # (archetype, kwargs, label, type)
    centre: np.ndarray
    gravity: np.ndarray
    solver_kind: str
    radius: float
    grip_positions: np.ndarray
    model: str = ""  # the scene's solver.model ('auto', 'full', 'planar'; '' unknown)

    def bend_stiffness(self, s: np.ndarray) -> np.ndarray:
        xs, vs = self.rf_table
        return np.interp(np.asarray(s, dtype=float), xs, vs) if len(xs) > 1 else np.full(np.shape(s), vs[0])


@dataclass
class _Config:
    rrd: str | None
    spawn: bool
    spawn_port: int
    urls: list
    application_id: str
    recording_id: str | None
    frames: int


def _pose_bytes(pose: Any) -> bytes:
    pos, quat = (pose.position, pose.orientation) if hasattr(pose, "position") else pose
    return np.asarray(pos, dtype=float).tobytes() + np.asarray(quat, dtype=float).tobytes()


def _encode_targets(poses: Mapping[str, Any], update: int, ros_time_ns: int) -> tuple:
    """log_targets' message: a flat tuple of primitives and bytes (a few µs to build and to pickle)."""
    return ("T", update, ros_time_ns, tuple(str(n) for n in poses), b"".join(_pose_bytes(p) for p in poses.values()))


def _decode_poses(names: tuple, data: bytes) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    arr = np.frombuffer(data, dtype=float).reshape(len(names), 7)
    return {n: (arr[i, 0:3], arr[i, 3:7]) for i, n in enumerate(names)}


def _encode_result(result: Any, update: int, ros_time_ns: int, bend_stiffness: Any, targets: Any,
                   warm: bool | None) -> tuple:
    """log_result's message: the result copied into a flat tuple of primitives and bytes."""
    energy, grips = result.energy, result.grips
    return (
        "R", update, ros_time_ns, str(result.status), str(result.message), result.stable,
        None if result.min_eigenvalue is None else float(result.min_eigenvalue), int(result.iterations),
        float(result.solve_time_ms), (bool(result.warm_started), warm),
        tuple(energy), np.fromiter(energy.values(), float, len(energy)).tobytes(),
        tuple(grips), b"".join(np.asarray(w.force, dtype=float).tobytes() for w in grips.values()),
        np.asarray(result.s, dtype=float).tobytes(), np.asarray(result.points, dtype=float).tobytes(),
        np.asarray(result.orientations, dtype=float).tobytes(),
        None if bend_stiffness is None else np.asarray(bend_stiffness, dtype=float).tobytes(),
        None if targets is None else (tuple(str(n) for n in targets), b"".join(_pose_bytes(p) for p in targets.values())),
        result.model_dict(),
        b"".join(np.concatenate([[c.s_a, c.s_b], c.point_a, c.point_b, c.force]).astype(float).tobytes()
                 for c in getattr(result, "self_contacts", ())),
    )


def _decode(message: Any) -> _Item:
    """A queued message (an _Item, or an encoded result / targets tuple) → _Item."""
    if isinstance(message, _Item):
        return message
    if message[0] == "T":
        _, update, t, names, data = message
        return _Item("targets", update, t, _decode_poses(names, data))
    (_, update, t, status, text, stable, eig, iterations, ms, warm, e_names, e_data, g_names, g_data,
     s, points, orientations, rf, targets, model, contacts) = message
    f = np.frombuffer(g_data, dtype=float).reshape(len(g_names), 3)
    bend = None if rf is None else np.frombuffer(rf, dtype=float)
    snap = _ResultSnap(
        status=status, message=text, stable=stable, min_eigenvalue=eig, iterations=iterations, solve_time_ms=ms,
        warm_started=warm[0], warm_call=warm[1], s=np.frombuffer(s, dtype=float), points=np.frombuffer(points, dtype=float).reshape(-1, 3),
        orientations=np.frombuffer(orientations, dtype=float).reshape(-1, 4),
        energy=dict(zip(e_names, np.frombuffer(e_data, dtype=float).tolist())),
        forces={n: f[i] for i, n in enumerate(g_names)},
        bend_stiffness=None if bend is None else (float(bend[0]) if bend.size == 1 else bend),
        targets=None if targets is None else _decode_poses(*targets), model=model,
        self_contacts=np.frombuffer(contacts, dtype=float).reshape(-1, 11),
    )
    return _Item("result", update, t, snap)


def scene_info(scene_or_problem: Any, frame_id: str | None = None, solver: Any = None,
               force_scale: float | None = None) -> _SceneInfo:
    """The writer's view of a Scene (or a bare Problem: then no YAML, not re-solvable)."""
    problem = getattr(scene_or_problem, "problem", scene_or_problem)
    is_scene = problem is not scene_or_problem
    st = problem.string
    L = float(st.length)
    gpos = np.array([g.pose.position for g in problem.grips], dtype=float)
    gu = problem.gravity_unit
    centre = gpos.mean(axis=0) + 0.25 * L * gu
    if force_scale:
        scale = float(force_scale)
    else:
        weight = float(np.mean(st.weight_per_length(np.linspace(0, L, 201)))) * L
        loads = sum(float(np.linalg.norm(ld.force)) for ld in problem.loads)
        f_ref = max(weight, loads, 4 * math.pi**2 * st.bend_stiffness.maximum / L**2, 1e-12)
        scale = 0.15 * L / f_ref
    extent = 0.8 * L
    obstacles = []
    for ob in problem.obstacles:
        kind, kwargs = obstacle_shape(ob, centre, extent)
        obstacles.append((kind, kwargs, ob.name or ob.type, ob.type))
    kind = solver if isinstance(solver, str) else ("" if solver is None else type(solver).__name__)
    return _SceneInfo(
        name=str(getattr(scene_or_problem, "name", "problem")),
        frame_id=str(frame_id or getattr(scene_or_problem, "frame_id", "world")),
        length=L, grip_s={g.name: float(g.s) for g in problem.grips}, grip_order=tuple(g.name for g in problem.grips),
        rf_table=(tuple(st.bend_stiffness.s), tuple(st.bend_stiffness.values)), force_scale=scale,
        yaml_text=scene_yaml(scene_or_problem) if is_scene else "", obstacles=obstacles, centre=centre,
        gravity=gu, solver_kind=kind, radius=float(st.radius), grip_positions=gpos,
        model=str(getattr(getattr(scene_or_problem, "options", None), "model", "") or ""),
    )


# ---- the rerun side ----------------------------------------------------------------------------------
BATCH_SECONDS = 0.1  # rows wait at most this long in the writer before they are sent (live viewers lag this much)
BATCH_ROWS = 512  # ... or until this many rows are buffered


def _instances(value: Any) -> Any:
    """A field value as a batch of instances (leading axis = instances)."""
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


class _Writer:
    """Owns the rerun RecordingStream and turns items into rerun calls, in one thread.

    Static data is logged at once; time-stamped rows are buffered per (entity, archetype) and sent with
    ``send_columns`` at most every BATCH_SECONDS (or BATCH_ROWS rows, or on flush/close): one rerun call
    per entity per batch instead of one per row, which makes a recorded update cost ~10× less CPU.
    """

    def __init__(self, cfg: _Config) -> None:
        try:
            import rerun as rr
        except ImportError as exc:  # Python 3.10, or a broken install
            raise RecordingUnavailable(
                f"recording needs rerun-sdk (Python >= 3.11; see requirements.txt): {exc}") from None
        self._rr = rr
        self.cfg = cfg
        self.rec = rr.RecordingStream(cfg.application_id, recording_id=cfg.recording_id)
        sinks: list[Any] = []
        if cfg.rrd:
            Path(cfg.rrd).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(cfg.rrd)))
        if cfg.spawn:
            # Starts the `rerun` viewer and waits until it listens; it needs a display for its window.
            rr.spawn(port=cfg.spawn_port, connect=False, recording=self.rec)
        for url in dict.fromkeys(cfg.urls):
            sinks.append(rr.GrpcSink(url))
        self.rec.set_sinks(*sinks)
        self.recording_id = self.rec.get_recording_id()
        self.n_frames = max(0, int(cfg.frames))
        self.errors = 0
        self.last_error = ""
        self.scene: _SceneInfo | None = None
        self.blueprint_sent = False
        self.energy_scale: float | None = None
        self.last_status: tuple | None = None
        self.dropped_reported = 0
        self._rows: dict[tuple[str, str], list[tuple[int, int, dict]]] = {}
        self._pending_targets: list[_Item] = []
        self._pending_results: list[_Item] = []
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
        """Log one message (an _Item or an encoded tuple, see :func:`_decode`)."""
        item = _Item("?", None, 0)
        try:
            item = _decode(message)
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
        import pyarrow as pa

        targets, results = self._pending_targets, self._pending_results
        self._pending_targets, self._pending_results = [], []
        if targets:
            self._send_targets(targets)
        if results:
            self._send_results(results)
        rows, self._rows, self._n_rows, self._oldest = self._rows, {}, 0, None
        rr = self._rr
        for (entity, arch), entries in rows.items():
            try:
                indexes = [
                    rr.TimeColumn(TIMELINE_UPDATE, sequence=[u for u, _, _ in entries]),
                    rr.TimeColumn(TIMELINE_ROS, timestamp=np.array([t for _, t, _ in entries], dtype="datetime64[ns]")),
                ]
                names = list(dict.fromkeys(k for _, _, f in entries for k in f))
                groups: dict[tuple, dict] = {}
                for name in names:
                    values = [_instances(f[name]) if name in f else [] for _, _, f in entries]
                    data = _concat(values)
                    if arch == "AnyValues":  # as an Arrow array: rerun's generic path boxes every number
                        data = pa.array(data)
                    groups.setdefault(tuple(len(v) for v in values), {})[name] = data
                columns: list[Any] = []
                for lengths, fields in groups.items():
                    columns.extend(getattr(rr, arch).columns(**fields).partition(list(lengths)))
                self.rec.send_columns(entity, indexes=indexes, columns=columns)
            except Exception as exc:  # noqa: BLE001
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
    def _row(self, entity: str, arch: str, item: _Item, **fields: Any) -> None:
        self._rows.setdefault((entity, arch), []).append((int(item.update), int(item.ros_time_ns), fields))
        self._count_row()

    def _count_row(self) -> None:
        self._n_rows += 1
        if self._oldest is None:
            self._oldest = time.monotonic()

    def _report_drops(self, dropped: int, item: _Item) -> None:
        text = (f"recorder queue full: {dropped - self.dropped_reported} item(s) dropped before this one "
                f"({dropped} in total)")
        if item.update is not None:
            self._row(E_RECORDER, "TextLog", item, text=text, level="WARN")
        else:
            self.rec.log(E_RECORDER, self._rr.TextLog(text, level=self._rr.TextLogLevel.WARN), static=True)
        self.dropped_reported = dropped

    def _handle_scene(self, item: _Item) -> None:
        rr = self._rr
        info: _SceneInfo = item.payload
        first = self.scene is None
        self.scene = info
        static = item.update is None
        if not static:
            self.send_batches()  # rows of earlier updates are drawn with the earlier scene
            self.rec.set_time(TIMELINE_UPDATE, sequence=int(item.update))
            self.rec.set_time(TIMELINE_ROS, timestamp=np.datetime64(int(item.ros_time_ns), "ns"))
        if first or static:
            self.rec.log(E_WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for i, (kind, kwargs, label, ob_type) in enumerate(info.obstacles):
            colour = [70, 72, 80] if ob_type == "halfspace" else [150, 150, 165]
            arch = getattr(rr, kind)(**kwargs, colors=[colour], labels=[label], fill_mode=rr.components.FillMode.Solid)
            self.rec.log(f"{E_OBSTACLES}/{i}_{_part(label)}", arch, static=static)
        doc = rr.TextDocument(info.yaml_text or "# scene not recorded (a Problem was logged)", media_type="text/plain")
        props = rr.AnyValues(scene_name=info.name, frame_id=info.frame_id, solver=info.solver_kind,
                             grip_names=list(info.grip_order))
        self.rec.log(E_SCENE if static else E_SCENE_CHANGES, doc, props, static=static)
        if not self.blueprint_sent:
            self._send_blueprint(info)

    def _send_blueprint(self, info: _SceneInfo | None) -> None:
        self.rec.send_blueprint(default_blueprint(info), make_active=True, make_default=True)
        self.blueprint_sent = True

    def _handle_targets(self, item: _Item) -> None:
        self._pending_targets.append(item)
        self._count_row()

    def _handle_result(self, item: _Item) -> None:
        r: _ResultSnap = item.payload
        key = (r.status, r.stable)
        if key != self.last_status:
            text = f"{r.status}: {r.message}" + ("" if r.stable is not False else " (unstable)")
            level = "INFO" if r.status == "ok" and r.stable is not False else "WARN"
            self._row(E_STATUS, "TextLog", item, text=[text], level=[level])
            self.last_status = key
        self._pending_results.append(item)
        self._count_row()

    # -- batched, vectorised over the rows of a batch (the per-row Python cost is what the CPU pays)
    def _send(self, entity: str, arch: str, items: list[_Item], **fields: tuple[Any, list[int]]) -> None:
        """send_columns of ``arch`` rows for ``items``; fields: name → (concatenated data, instances per row)."""
        rr = self._rr
        try:
            indexes = [rr.TimeColumn(TIMELINE_UPDATE, sequence=[int(it.update) for it in items]),
                       rr.TimeColumn(TIMELINE_ROS, timestamp=np.array([int(it.ros_time_ns) for it in items],
                                                                      dtype="datetime64[ns]"))]
            groups: dict[tuple, dict] = {}
            for name, (data, lengths) in fields.items():
                groups.setdefault(tuple(int(n) for n in lengths), {})[name] = data
            columns: list[Any] = []
            for lengths, group in groups.items():
                columns.extend(getattr(rr, arch).columns(**group).partition(list(lengths)))
            self.rec.send_columns(entity, indexes=indexes, columns=columns)
        except Exception as exc:  # noqa: BLE001
            self._error(f"sending {entity}", exc)

    def _send_targets(self, items: list[_Item]) -> None:
        L = self.scene.length if self.scene else 1.0
        by_grip: dict[str, list[tuple[_Item, np.ndarray, np.ndarray]]] = {}
        for it in items:
            names, flat = [], []
            for name, (pos, quat) in it.payload.items():
                by_grip.setdefault(name, []).append((it, pos, quat))
                names.append(name)
                flat.append(np.concatenate([pos, quat]))
            self._row(E_DATA_TARGETS, "AnyValues", it, grip_names=names, poses=np.concatenate(flat) if flat else
                      np.zeros(0))
        orange = np.array([255, 150, 40], np.uint8)
        for name, rows in by_grip.items():
            m = len(rows)
            its = [r[0] for r in rows]
            pos = np.array([r[1] for r in rows], dtype=float)
            x_axis = quats_to_matrices(np.array([r[2] for r in rows]))[:, :, 0]
            ones = [1] * m
            path = f"{E_TARGETS}/{_part(name)}"
            self._send(path, "Points3D", its, positions=(pos, ones), radii=(np.full(m, 0.012 * L), ones),
                       colors=(np.tile(orange, (m, 1)), ones), labels=([f"{name} target"] * m, ones))
            self._send(path, "Arrows3D", its, origins=(pos, ones), vectors=(0.12 * L * x_axis, ones),
                       colors=(np.tile(orange, (m, 1)), ones), radii=(np.full(m, 0.003 * L), ones))

    def _send_results(self, items: list[_Item]) -> None:
        snaps: list[_ResultSnap] = [it.payload for it in items]
        ones = [1] * len(items)
        self._send(E_SOLVE_TIME, "Scalars", items, scalars=(np.array([r.solve_time_ms for r in snaps]), ones))
        self._send(E_ITERATIONS, "Scalars", items, scalars=(np.array([float(r.iterations) for r in snaps]), ones))
        shapes: dict[int, list[int]] = {}
        for i, (it, r) in enumerate(zip(items, snaps)):
            data: dict[str, Any] = dict(status=r.status, message=r.message, warm_started=r.warm_started,
                                        iterations=r.iterations)
            if r.warm_call is not None:
                data["warm"] = bool(r.warm_call)
            if r.targets is not None:
                data["target_names"] = list(r.targets)
                data["target_poses"] = np.concatenate([np.concatenate(p) for p in r.targets.values()])
            if r.status == "ok" and len(r.points) >= 2:
                shapes.setdefault(len(r.points), []).append(i)
                data.update(s=r.s, points=r.points.ravel(), orientations=r.orientations.ravel(),
                            energy_terms=list(r.energy), energy=np.array(list(r.energy.values()), dtype=float),
                            grip_names=list(r.forces),
                            grip_forces=np.concatenate(list(r.forces.values())) if r.forces else np.zeros(0))
                if r.stable is not None:
                    data["stable"] = bool(r.stable)
                if len(r.self_contacts):  # rows of s_a, s_b, point_a, point_b, force on s_a (flattened)
                    data["self_contacts"] = r.self_contacts.ravel()
            if r.model:  # also for a failed solve: the model it was attempted with
                data["model"] = _json(r.model)
            self._row(E_DATA_RESULT, "AnyValues", it, **data)
        self._send_model_scalars(items, snaps)
        for rows in shapes.values():
            try:
                self._send_shapes([items[i] for i in rows], [snaps[i] for i in rows])
            except Exception as exc:  # noqa: BLE001
                self._error("drawing shapes", exc)

    def _send_model_scalars(self, items: list[_Item], snaps: list[_ResultSnap]) -> None:
        """model/<key>: the numbers of ShapeResult.model (None and non-numbers are skipped)."""
        for key in MODEL_SCALARS:
            have, values = [], []
            for i, r in enumerate(snaps):
                v = r.model.get(key) if r.model else None
                if isinstance(v, (bool, int, float)) and math.isfinite(float(v)):
                    have.append(i)
                    values.append(float(v))
            if have:
                self._send(f"{E_MODEL_SERIES}/{key}", "Scalars", [items[i] for i in have],
                           scalars=(np.array(values), [1] * len(have)))

    def _send_shapes(self, items: list[_Item], snaps: list[_ResultSnap]) -> None:
        """Centrelines, frames, grips, forces, energies, eigenvalues of ok results with N samples each."""
        sc = self.scene
        m = len(snaps)
        P = np.stack([r.points for r in snaps])  # (m, N, 3)
        O = np.stack([r.orientations for r in snaps])  # (m, N, 4)
        S = np.stack([r.s for r in snaps])  # (m, N)
        n = P.shape[1]
        L = sc.length if sc else (float(S[0, -1] - S[0, 0]) or 1.0)
        rf = np.empty((m, n))
        for i, r in enumerate(snaps):
            if r.bend_stiffness is not None:
                rf[i] = r.bend_stiffness
            elif sc is not None:
                rf[i] = sc.bend_stiffness(r.s)
            else:
                rf[i] = 1.0
        density = bend_energy_density_batch(P, rf)  # (m, N-1)
        if self.energy_scale is None:
            self.energy_scale = max(0.5 * float(np.max(rf[0])) * (2 * math.pi / L) ** 2,
                                    1.25 * float(np.max(density[0])))
            self._log_legend()
        rows = [n - 1] * m
        ones = [1] * m
        radius = max(sc.radius if sc else 0.0, 0.004 * L)
        segments = np.stack([P[:, :-1], P[:, 1:]], axis=2).reshape(-1, 2, 3)
        self._send(E_CABLE, "LineStrips3D", items, strips=(segments, rows),
                   colors=(viridis(density / self.energy_scale).reshape(-1, 3), rows),
                   radii=(np.full(m, radius), ones))
        axes = np.array(AXIS_COLORS, dtype=np.uint8)
        if self.n_frames:  # material frames at a few samples
            idx = np.unique(np.round(np.linspace(0, n - 1, self.n_frames)).astype(int))
            k = len(idx)
            rot = quats_to_matrices(O[:, idx].reshape(-1, 4)).reshape(m, k, 3, 3)
            a = 0.05 * L
            vectors = a * np.concatenate([rot[:, :, :, 0], rot[:, :, :, 1], rot[:, :, :, 2]], axis=1)
            origins = np.concatenate([P[:, idx]] * 3, axis=1)
            self._send(E_FRAMES, "Arrows3D", items, vectors=(vectors.reshape(-1, 3), [3 * k] * m),
                       origins=(origins.reshape(-1, 3), [3 * k] * m),
                       colors=(np.tile(np.repeat(axes, k, axis=0), (m, 1)), [3 * k] * m),
                       radii=(np.full(m, 0.002 * L), ones))
        if sc is not None:  # grips: pose on the solved shape (the s of the first row), and the reaction force
            s0 = S[0]
            b = 0.1 * L
            for name, s_g in sc.grip_s.items():
                j1 = int(np.clip(np.searchsorted(s0, s_g), 1, n - 1))
                j0 = j1 - 1
                w = (s_g - s0[j0]) / (s0[j1] - s0[j0]) if s0[j1] > s0[j0] else 0.0
                pos = P[:, j0] * (1 - w) + P[:, j1] * w  # (m, 3)
                rot = quats_to_matrices(O[:, int(np.argmin(np.abs(s0 - s_g)))])  # (m, 3, 3)
                path = f"{E_GRIPS}/{_part(name)}"
                self._send(path, "Arrows3D", items, vectors=((b * rot.transpose(0, 2, 1)).reshape(-1, 3), [3] * m),
                           origins=(np.repeat(pos, 3, axis=0), [3] * m), colors=(np.tile(axes, (m, 1)), [3] * m),
                           radii=(np.full(3 * m, 0.004 * L), [3] * m))
                have = [i for i, r in enumerate(snaps) if name in r.forces]
                if have:
                    f = np.array([snaps[i].forces[name] for i in have])
                    one = [1] * len(have)
                    self._send(path + "/force", "Arrows3D", [items[i] for i in have],
                               vectors=(sc.force_scale * f, one), origins=(pos[have], one),
                               colors=(np.tile(np.array([230, 60, 230], np.uint8), (len(have), 1)), one),
                               radii=(np.full(len(have), 0.005 * L), one),
                               labels=([f"{x:.3g} N" for x in np.linalg.norm(f, axis=1)], one))
        energy = np.array([[float(r.energy.get(t, 0.0)) for t in ENERGY_TERMS] for r in snaps])
        self._send(E_ENERGY, "Scalars", items, scalars=(energy.ravel(), [len(ENERGY_TERMS)] * m))
        eig = [i for i, r in enumerate(snaps) if r.min_eigenvalue is not None and math.isfinite(r.min_eigenvalue)]
        if eig:
            self._send(E_EIGEN, "Scalars", [items[i] for i in eig],
                       scalars=(np.array([snaps[i].min_eigenvalue for i in eig]), [1] * len(eig)))

    def _log_legend(self) -> None:
        rr, sc = self._rr, self.scene
        lines = [
            "# Legend",
            f"* centreline colour: bend energy density ½ Rf κ² from 0 J/m (dark purple) to "
            f"{self.energy_scale:.4g} J/m and above (yellow); κ from consecutive tangents",
            "* axes: x = tangent (red), y (green), z (blue): material frames and grip poses",
        ]
        if sc is not None:
            lines.append(f"* magenta arrows: force each gripper exerts on the string, {sc.force_scale:.4g} m per N")
        lines.append("* orange: grip targets as received (point and tangent)")
        self.rec.log(E_LEGEND, rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
        self.rec.log(E_ENERGY, rr.SeriesLines(names=list(ENERGY_TERMS), colors=ENERGY_COLORS), static=True)
        self.rec.log(E_SOLVE_TIME, rr.SeriesLines(names=["solve time [ms]"], colors=[[255, 170, 60]]), static=True)
        self.rec.log(E_ITERATIONS, rr.SeriesLines(names=["iterations"], colors=[[120, 180, 255]]), static=True)
        self.rec.log(E_EIGEN, rr.SeriesLines(names=["min eigenvalue"], colors=[[120, 220, 120]]), static=True)
        for key, name in MODEL_SCALARS.items():
            self.rec.log(f"{E_MODEL_SERIES}/{key}", rr.SeriesLines(names=[name]), static=True)

    def _handle_rejected(self, item: _Item) -> None:
        self._row(E_REJECTED, "TextLog", item, text=[item.payload], level=["WARN"])

    def _handle_model(self, item: _Item) -> None:
        self._row(E_MODEL, "TextLog", item, text=[item.payload], level=["INFO"])

    def _handle_fit(self, item: _Item) -> None:
        from .identify.drawing import draw_observation  # imported only by a recording that has a fit

        fit: _FitSnap = item.payload
        self.send_batches()  # keep the rows of earlier updates before this one
        self.rec.set_time(TIMELINE_UPDATE, sequence=int(item.update))
        self.rec.set_time(TIMELINE_ROS, timestamp=np.datetime64(int(item.ros_time_ns), "ns"))
        draw_observation(self.rec, E_FIT, fit.points, fit.shape, fit.feet, fit.sigma, fit.huber, static=False)
        level = self._rr.TextLogLevel.INFO if fit.ok else self._rr.TextLogLevel.WARN
        self.rec.log(E_FIT_EVENTS, self._rr.TextLog(fit.text, level=level))


# ---- backends: where the writer runs -------------------------------------------------------------------
def _drop_oldest(queue: collections.deque, limit: int) -> int:
    """Make room in ``queue`` of (payload, keep) by dropping its oldest droppable entry; returns 1 if one
    was dropped."""
    if len(queue) < limit:
        return 0
    for i, (_, keep) in enumerate(queue):
        if not keep:
            del queue[i]
            return 1
    return 0


class _ThreadBackend:
    """The writer in a background thread of this process (``backend="thread"``).  Simple, but rerun's
    Python work shares the GIL with the caller: on a loaded machine it slows the solver thread."""

    def __init__(self, cfg: _Config, timeout: float, queue_size: int) -> None:
        del timeout
        self.writer = _Writer(cfg)
        self.recording_id = self.writer.recording_id
        self.dropped = 0
        self._limit = queue_size
        self._queue: collections.deque = collections.deque()
        self._cond = threading.Condition()
        self._busy = self._stop = False
        self._thread = threading.Thread(target=self._run, name="dlo-recorder", daemon=True)
        self._thread.start()

    @property
    def pending(self) -> int:
        with self._cond:
            return len(self._queue) + int(self._busy)

    def submit(self, message: Any, keep: bool) -> None:
        with self._cond:
            if self._stop:
                return
            self.dropped += _drop_oldest(self._queue, self._limit)
            self._queue.append(((message, self.dropped), keep))
            self._cond.notify_all()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not (self._queue or self._stop):
                    due = self.writer.due()
                    if due == 0.0:
                        break
                    self._cond.wait(due)
                if not self._queue and not self._stop:
                    entry = None  # only a batch to send
                elif not self._queue:
                    return
                else:
                    entry = self._queue.popleft()[0]
                self._busy = True
            try:
                if entry is None:
                    self.writer.send_batches()
                else:
                    self.writer.handle(*entry)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _drain(self, deadline: float) -> bool:
        with self._cond:
            while self._queue or self._busy:
                if not self._cond.wait(max(0.0, deadline - time.monotonic())) and time.monotonic() >= deadline:
                    return False
        return True

    def flush(self, timeout: float) -> tuple[bool, dict]:
        deadline = time.monotonic() + timeout
        done = self._drain(deadline)
        self.writer.flush(max(0.1, deadline - time.monotonic()))
        return done, self.writer.stats()

    def close(self, timeout: float) -> dict:
        deadline = time.monotonic() + timeout
        self._drain(deadline)
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(max(0.1, deadline - time.monotonic()))
        self.writer.close(max(1.0, deadline - time.monotonic()))
        return self.writer.stats()


def _frame(message: Any) -> bytes:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return struct.pack("<I", len(data)) + data


def _write_all(fd: int, data: bytes, deadline: float | None = None) -> None:
    """Write all of ``data`` to a (possibly non-blocking) fd, waiting for room until ``deadline``."""
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(fd, view):]
        except BlockingIOError:
            wait = None if deadline is None else deadline - time.monotonic()
            if wait is not None and wait <= 0:
                raise TimeoutError("the recorder process does not keep up") from None
            select.select([], [fd], [], wait)


def _read_exact(fd: int, n: int, deadline: float | None) -> bytes | None:
    chunks, left = [], n
    while left:
        if deadline is not None:
            wait = deadline - time.monotonic()
            if wait <= 0 or not select.select([fd], [], [], wait)[0]:
                raise TimeoutError("no answer from the recorder process")
        data = os.read(fd, left)
        if not data:
            return None
        chunks.append(data)
        left -= len(data)
    return b"".join(chunks)


def _read_frame(fd: int, deadline: float | None = None) -> Any:
    header = _read_exact(fd, 4, deadline)
    if header is None:
        return None
    body = _read_exact(fd, struct.unpack("<I", header)[0], deadline)
    return None if body is None else pickle.loads(body)  # noqa: S301 - frames from our own process


F_SETPIPE_SZ = 1031  # Linux fcntl: set a pipe's buffer size
CHILD_NICE = 19  # the recorder process runs at the lowest priority: it yields the CPU to the solver
CHILD_POLL_SECONDS = 0.02  # the recorder process reads its pipe at most this often while data flows


class _ProcessBackend:
    """The writer in a child process (``backend="process"``, the default).

    ``submit`` pickles the snapshot and writes it into a non-blocking pipe (enlarged to 1 MiB where
    Linux allows): tens of microseconds in the caller's thread, no background Python thread competing
    for the GIL.  Only when the pipe is full does a frame wait in the bounded backlog (drop-oldest),
    which a small thread writes out as soon as the child has read.  The child
    (``python -c 'from dlo_ros.recording import _child_main; ...'``) makes every rerun call; it ignores
    SIGINT (Ctrl-C stops the parent, which then closes it) and finishes the recording on EOF.
    """

    def __init__(self, cfg: _Config, timeout: float, queue_size: int) -> None:
        env = dict(os.environ)
        package_root = str(Path(__file__).resolve().parent.parent)
        env["PYTHONPATH"] = os.pathsep.join([package_root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
        code = "import sys; from dlo_ros.recording import _child_main; sys.exit(_child_main())"
        self.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     env=env, close_fds=True)
        self._in, self._out = self.proc.stdin.fileno(), self.proc.stdout.fileno()
        self.dead = False
        self.dropped = 0
        self.stats = {"errors": 0, "last_error": ""}
        try:
            _write_all(self._in, _frame(cfg))
            reply = _read_frame(self._out, time.monotonic() + timeout)
        except (OSError, TimeoutError) as exc:
            self._kill()
            raise RuntimeError(f"the recorder process did not start: {exc}") from None
        if not reply or reply[0] != "ready":
            self._kill()
            message = reply[1] if reply else f"it exited with code {self.proc.poll()}"
            if reply and reply[0] == "unavailable":
                raise RecordingUnavailable(message)
            raise RuntimeError(f"recording could not start: {message}")
        self.recording_id = reply[1]
        try:
            import fcntl

            fcntl.fcntl(self._in, F_SETPIPE_SZ, 1 << 20)
        except (ImportError, OSError):
            pass
        os.set_blocking(self._in, False)
        self._limit = queue_size
        self._cond = threading.Condition()
        self._backlog: collections.deque = collections.deque()  # (frame bytes, keep)
        self._partial = b""  # the unwritten tail of a frame (never dropped: the stream must stay framed)
        self._stop = False
        self._request_lock = threading.Lock()
        self._thread = threading.Thread(target=self._drain_loop, name="dlo-recorder-pipe", daemon=True)
        self._thread.start()

    @property
    def pending(self) -> int:
        with self._cond:
            return len(self._backlog) + int(bool(self._partial))

    def submit(self, message: Any, keep: bool) -> None:
        frame = _frame(("item", message, self.dropped))
        with self._cond:
            if self.dead or self._stop:
                return
            if not self._backlog and not self._partial:
                try:
                    n = os.write(self._in, frame)
                except BlockingIOError:
                    n = 0
                except OSError as exc:
                    self._died(exc)
                    return
                if n == len(frame):
                    return
                self._partial = frame[n:]
            else:
                self.dropped += _drop_oldest(self._backlog, self._limit)
                self._backlog.append((frame, keep))
            self._cond.notify_all()

    def _write_some(self) -> bool:
        """Write what is waiting until the pipe is full (lock held); True when nothing is left."""
        while True:
            if not self._partial:
                if not self._backlog:
                    return True
                self._partial = self._backlog.popleft()[0]
            try:
                n = os.write(self._in, self._partial)
            except BlockingIOError:
                return False
            self._partial = self._partial[n:]

    def _drain_loop(self) -> None:
        while True:
            with self._cond:
                while not (self._partial or self._backlog or self._stop):
                    self._cond.wait()
                if self._stop or self.dead:
                    return
            select.select([], [self._in], [], 0.5)  # wait for room, GIL released
            with self._cond:
                if self.dead:
                    return
                try:
                    if self._write_some():
                        self._cond.notify_all()
                except OSError as exc:
                    self._died(exc)
                    return

    def _died(self, exc: BaseException) -> None:
        """The child is gone (lock held): count it once, drop what waits."""
        if not self.dead:
            self.dead = True
            self.stats = {"errors": self.stats["errors"] + 1, "last_error": f"recorder process: {exc}"}
            log.warning("recorder: the recorder process has gone (%s); recording stopped", exc)
        self.dropped += len(self._backlog)
        self._backlog.clear()
        self._partial = b""
        self._cond.notify_all()

    def _request(self, kind: str, timeout: float) -> tuple[bool, dict]:
        """Write everything, then ask the child to ``flush`` or ``close`` and wait for its answer."""
        deadline = time.monotonic() + timeout
        with self._request_lock:
            with self._cond:
                if self.dead:
                    return False, self.stats
                try:
                    while not self._write_some():
                        if time.monotonic() >= deadline:
                            return False, self.stats
                        select.select([], [self._in], [], max(0.0, deadline - time.monotonic()))
                    _write_all(self._in, _frame((kind, max(0.1, deadline - time.monotonic()))), deadline)
                except TimeoutError:
                    return False, self.stats
                except OSError as exc:
                    self._died(exc)
                    return False, self.stats
            try:
                reply = _read_frame(self._out, deadline + 5.0)
            except (OSError, TimeoutError) as exc:
                with self._cond:
                    self._died(exc)
                return False, self.stats
            if reply is None:
                with self._cond:
                    self._died(EOFError("it exited"))
                return False, self.stats
            self.stats = reply[1]
            return True, self.stats

    def flush(self, timeout: float) -> tuple[bool, dict]:
        return self._request("flush", timeout)

    def close(self, timeout: float) -> dict:
        _, stats = self._request("close", timeout)
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(1.0)
        for f in (self.proc.stdin, self.proc.stdout):
            try:
                f.close()
            except OSError:
                pass
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._kill()
        return stats

    def _kill(self) -> None:
        self.dead = True
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def _child_main() -> int:
    """Entry point of the recorder process: read frames from stdin, log them, answer on stdout."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    inp = sys.stdin.buffer.fileno()
    out = os.dup(1)
    os.dup2(2, 1)  # anything printed in here goes to stderr, never into the answer pipe
    cfg = _read_frame(inp)
    if cfg is None:
        return 0
    try:
        writer = _Writer(cfg)
    except RecordingUnavailable as exc:
        _write_all(out, _frame(("unavailable", str(exc))))
        return 1
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
        _write_all(out, _frame(("error", f"{type(exc).__name__}: {exc}")))
        return 1
    _write_all(out, _frame(("ready", writer.recording_id)))
    if hasattr(os, "nice"):
        try:
            os.nice(CHILD_NICE)  # background work: yield the CPU to the solver on a busy machine
        except OSError:
            pass
    os.set_blocking(inp, False)
    buf = bytearray()
    while True:
        due = writer.due()
        if not select.select([inp], [], [], due)[0]:
            writer.send_batches()
            continue
        eof = False
        while True:  # take everything the pipe holds
            try:
                chunk = os.read(inp, 1 << 20)
            except BlockingIOError:
                break
            if not chunk:
                eof = True
                break
            buf += chunk
        while len(buf) >= 4:
            n = struct.unpack_from("<I", buf)[0]
            if len(buf) < 4 + n:
                break
            message = pickle.loads(bytes(buf[4:4 + n]))  # noqa: S301 - frames from our parent
            del buf[:4 + n]
            if message[0] == "item":
                writer.handle(message[1], message[2])
            elif message[0] == "flush":
                writer.flush(message[1])
                _write_all(out, _frame(("flushed", writer.stats())))
            elif message[0] == "close":
                writer.close(message[1])
                _write_all(out, _frame(("closed", writer.stats())))
                return 0
        if eof:  # the parent went away: finish what was logged
            writer.close()
            return 0
        if writer.due() == 0.0:
            writer.send_batches()
        # Sleep while frames accumulate: a write into the pipe of a reader that is not waiting on it
        # wakes nobody, so a stream of updates costs the solver's process no context switches.
        time.sleep(CHILD_POLL_SECONDS)


# ---- the public front end ---------------------------------------------------------------------------
class Recorder:
    """Records solves to rerun (an .rrd file, a spawned viewer, a running viewer, or any of these).

    Off when ``rrd`` is None, ``spawn`` False and ``connect`` None: then every method returns at once.
    ``connect``: a viewer address (see :func:`grpc_url`; ``""`` = the default local viewer).
    ``recording_id``: fixed id (default: a fresh one).  ``queue_size``: items waiting to be logged before
    the oldest is dropped (counted in :attr:`dropped`; scene and model events are never dropped).
    ``force_scale``: arrow length per newton [m/N] (default 0.15·L divided by the largest of the
    string's weight, the loads' total force and 4π²·Rf_max/L², the clamped string's buckling load).
    ``frames``: number of material frames drawn along the string.  ``backend``: ``"process"``
    (default: rerun runs in a child process; the caller only pickles into a pipe) or ``"thread"`` (a
    background thread here; shares the GIL).  Raises RecordingUnavailable without rerun-sdk, ValueError
    for a bad ``connect`` address, RuntimeError when the viewer cannot be spawned or the recorder
    process cannot start.
    """

    def __init__(self, *, rrd: str | Path | None = None, spawn: bool = False, connect: str | None = None,
                 application_id: str = "dlo_ros", recording_id: str | None = None, queue_size: int = 1024,
                 force_scale: float | None = None, frames: int = 9, spawn_port: int = DEFAULT_PORT,
                 backend: str = "process", start_timeout: float = 60.0) -> None:
        self.enabled = bool(rrd) or bool(spawn) or connect is not None
        self.rrd = Path(rrd) if rrd else None
        self.errors = 0
        self.last_error = ""
        self.recording_id: str | None = None
        self.url: str | None = None
        self._force_scale = force_scale
        self._closed = False
        self._backend: Any = None
        if not self.enabled:
            return
        if backend not in ("process", "thread"):
            raise ValueError(f"backend: must be 'process' or 'thread', got {backend!r}")
        if spawn and not has_display():
            raise RuntimeError("no display ($DISPLAY and $WAYLAND_DISPLAY are unset), so a spawned viewer cannot open "
                               "a window; save with --rrd FILE and open it with `dlo replay FILE` where there is a "
                               "display, or stream with --connect to a viewer running elsewhere")
        urls = ([f"rerun+http://127.0.0.1:{spawn_port}/proxy"] if spawn else []) + \
            ([grpc_url(connect)] if connect is not None else [])
        self.url = urls[0] if urls else None
        cfg = _Config(rrd=str(self.rrd.resolve()) if self.rrd else None, spawn=bool(spawn), spawn_port=int(spawn_port),
                      urls=urls, application_id=application_id, recording_id=recording_id, frames=int(frames))
        kind = _ProcessBackend if backend == "process" else _ThreadBackend
        self._backend = kind(cfg, start_timeout, max(1, int(queue_size)))
        self.recording_id = self._backend.recording_id

    # ---- public API (any thread) ------------------------------------------------------------------
    def log_scene(self, scene_or_problem: Any, frame_id: str | None = None, *, solver: Any = None,
                  update: int | None = None, ros_time_ns: int | None = None) -> None:
        """The scene: obstacles, the scene YAML (for ``dlo replay --resolve``), the default blueprint.

        ``scene_or_problem``: a ``dlo_ros.scene.Scene`` (its YAML makes the recording re-solvable) or a
        ``Problem`` (drawn, but not re-solvable).  ``frame_id`` defaults to the scene's.  ``solver``: the
        solver object (or its class name), so that replay builds the same kind.  With ``update`` None
        everything is static (call it once, before the first result); with an ``update`` it is a change
        from that update on (``scene/changes``), e.g. after the node changed the problem.  Not meant for
        the critical path (it writes the scene as YAML in the calling thread, ~ms); never dropped.
        """
        if not self.enabled:
            return
        info = scene_info(scene_or_problem, frame_id, solver, self._force_scale)
        self._put(_Item("scene", update, self._now(ros_time_ns) if update is not None else 0, info), keep=True)

    def log_targets(self, poses: Mapping[str, Any], *, update: int, ros_time_ns: int | None = None) -> None:
        """Grip targets as received: ``{name: (position[3], quaternion xyzw[4])}`` or ``{name: GripPose}``."""
        if not self.enabled:
            return
        self._put(_encode_targets(poses, int(update), self._now(ros_time_ns)))

    def log_result(self, result: Any, *, update: int, ros_time_ns: int | None = None,
                   bend_stiffness: float | np.ndarray | None = None, targets: Mapping[str, Any] | None = None,
                   warm: bool | None = None) -> None:
        """One solve (a committed update, or a failed one).  ``bend_stiffness``: Rf [N·m²] (a constant or
        one value per sample of result.s) for the colouring; None takes it from the scene.  ``targets``:
        the grip poses this solve used (all grips), recorded exactly so that ``dlo replay --resolve``
        repeats the same solve (without it, replay folds the ``log_targets`` of updates ≤ this one).
        ``warm``: the ``warm`` argument the solve was called with (False after a reset / for the first
        solve); replay repeats it (None: replay takes the first update as cold, the others as warm
        unless the result says it was not warm-started)."""
        if not self.enabled:
            return
        self._put(_encode_result(result, int(update), self._now(ros_time_ns), bend_stiffness, targets, warm))

    def log_update(self, result: Any, *, update: int, problem: Any = None, ros_time_ns: int | None = None,
                   warm: bool | None = None) -> None:
        """The node's one call per solve: :meth:`log_result` with the grip poses and the bend stiffness
        taken from ``problem`` (the Problem that was solved; its grip poses are the targets used).

        Call it from the solver's thread right after ``solve`` returns, for every streaming solve (ok or
        not).  ``ros_time_ns``: the header stamp of the newest target folded into the solve (None: now).
        ``warm``: False when the solve started cold (first solve, after a reset, a rebuilt solver).
        """
        if not self.enabled:
            return
        targets = bend = None
        if problem is not None:
            targets = {g.name: g.pose for g in problem.grips}
            if len(result.s):
                bend = problem.string.bend_stiffness(np.asarray(result.s, dtype=float))
        self.log_result(result, update=update, ros_time_ns=ros_time_ns, bend_stiffness=bend, targets=targets,
                        warm=warm)

    def log_rejected(self, reason: str, *, update: int, ros_time_ns: int | None = None) -> None:
        """An input that was rejected (bad pose, unknown grip, wrong frame, ...) and why."""
        if not self.enabled:
            return
        self._put(_Item("rejected", int(update), self._now(ros_time_ns), str(reason)))

    def log_model_change(self, text: str, *, update: int, ros_time_ns: int | None = None,
                         scene: Any = None) -> None:
        """A free-text model event (e.g. the model reduction switched models).  With ``scene`` the new
        scene is recorded too (as :meth:`log_scene` with ``update``).  Never dropped."""
        if not self.enabled:
            return
        t = self._now(ros_time_ns)
        self._put(_Item("model", int(update), t, str(text)), keep=True)
        if scene is not None:
            self.log_scene(scene, update=update, ros_time_ns=t)

    def log_fit(self, points: np.ndarray, shape: np.ndarray, feet: np.ndarray, *, sigma: float, huber: float,
                text: str, ok: bool, update: int, ros_time_ns: int | None = None) -> None:
        """A fit of observed points at ``update``: ``points`` (N, 3), the fitted centreline ``shape`` (S, 3) and
        each point's nearest point on it ``feet`` (N, 3) [m] (empty when the fit failed), drawn under
        ``world/fit`` by ``dlo_ros.identify.drawing``; ``text`` (its summary and what it applied) goes to
        ``events/fit`` (WARN unless ``ok``).  Never dropped."""
        if not self.enabled:
            return
        snap = _FitSnap(np.array(points, dtype=float), np.array(shape, dtype=float).reshape(-1, 3),
                        np.array(feet, dtype=float).reshape(-1, 3), float(sigma), float(huber), str(text), bool(ok))
        self._put(_Item("fit", int(update), self._now(ros_time_ns), snap), keep=True)

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until everything logged so far is in rerun's sinks (False on timeout or a dead writer)."""
        if not self.enabled or self._closed:
            return True
        done, stats = self._backend.flush(timeout)
        self._absorb(stats)
        return done

    def close(self, timeout: float = 10.0) -> None:
        """Log what is queued, flush and close the sinks (the .rrd file is complete afterwards).
        Idempotent; ``with Recorder(...) as rec:`` calls it on exit."""
        if not self.enabled or self._closed:
            return
        self._closed = True
        self._absorb(self._backend.close(timeout))

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def dropped(self) -> int:
        """Items dropped because the writer fell behind by more than ``queue_size`` items."""
        return self._backend.dropped if self._backend is not None else 0

    @property
    def pending(self) -> int:
        """Items accepted and not yet handed to rerun (or to the recorder process)."""
        return self._backend.pending if self._backend is not None and not self._closed else 0

    # ---- internals ----------------------------------------------------------------------------------
    @staticmethod
    def _now(ros_time_ns: int | None) -> int:
        return time.time_ns() if ros_time_ns is None else int(ros_time_ns)

    def _absorb(self, stats: dict) -> None:
        self.errors = max(self.errors, int(stats.get("errors", 0)))
        self.last_error = stats.get("last_error") or self.last_error

    def _put(self, message: Any, keep: bool = False) -> None:
        if self._closed:
            return
        self._backend.submit(message, keep)


def _part(name: str) -> str:
    """A name as one entity-path part."""
    cleaned = "".join(c if c.isalnum() or c in "_-" else "_" for c in str(name))
    return cleaned or "_"


def _json(value: Any) -> str:
    import json

    return json.dumps(value, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o), sort_keys=True)


def auto_model(info: _SceneInfo | None) -> bool:
    """Whether the recorded solver picks its model (solver.model 'auto', not a ShapeSolver of it)."""
    return info is not None and info.model == "auto" and info.solver_kind in ("", "AutoShapeSolver")


def default_blueprint(info: _SceneInfo | None = None) -> Any:
    """3D world view (left) beside the time series and the event log (right); timeline ``update``."""
    import rerun.blueprint as rrb

    world = rrb.Spatial3DView(origin=E_WORLD, name="World (m, z up)", eye_controls=_eye(info) if info else None)
    views = [
        rrb.TimeSeriesView(origin=E_ENERGY, name="Energy [J]"),
        rrb.TimeSeriesView(origin=E_SOLVE_TIME, name="Solve time [ms]"),
        rrb.TimeSeriesView(origin=E_ITERATIONS, name="Iterations (Newton steps or IPOPT)"),
        rrb.TimeSeriesView(origin=E_EIGEN, name="Min reduced eigenvalue (< 0: unstable)"),
    ]
    shares = [3, 2, 2, 2]
    if auto_model(info):  # the model changes: its error estimate beside the tolerance
        views.append(rrb.TimeSeriesView(origin=E_MODEL_SERIES, name="Model: estimated error vs tolerance [m]",
                                        contents=["$origin/estimated_error_m", "$origin/tolerance_m"]))
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


def _eye(info: _SceneInfo) -> Any:
    """Camera looking at the cable from the side: perpendicular to the grips' chord and to gravity."""
    import rerun.blueprint as rrb

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
