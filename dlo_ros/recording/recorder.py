"""The public front end of a recording: the Recorder, the viewer address, display checks.

The public front end of a recording: :class:`Recorder`, plus the viewer address and display
checks.

A Recorder snapshots what it is given (dlo_ros.recording.codec) and hands it to a backend
(dlo_ros.recording.transport) without waiting; how it stays off the critical path is described in
the package's docstring (dlo_ros.recording).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .codec import encode_result, encode_targets, EnvelopeSnap, FitSnap, QueueItem
from .scene_info import scene_info
from .transport import ProcessBackend, ThreadBackend
from .writer import WriterConfig

DEFAULT_GRPC_URL = "rerun+http://127.0.0.1:9876/proxy"
DEFAULT_PORT = 9876


def has_display() -> bool:
    """Say whether a native window can open here.

    Whether a native window can open here (Linux: $DISPLAY or $WAYLAND_DISPLAY; macOS, Windows:
    yes).
    """
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def grpc_url(address: str | None) -> str:
    """``--connect`` address → rerun gRPC URL.

    ``rerun://…``, ``rerun+http://…``, ``rerun+https://…`` are kept; ``HOST``, ``HOST:PORT`` or
    ``:PORT`` become ``rerun+http://HOST:PORT/proxy`` (host 127.0.0.1, port 9876 when omitted);
    ``""`` is the default ``rerun+http://127.0.0.1:9876/proxy``.
    """
    address = (address or "").strip()
    if not address:
        return DEFAULT_GRPC_URL
    if address.startswith(("rerun://", "rerun+http://", "rerun+https://")):
        return address
    if "://" in address:
        raise ValueError(
            f"--connect: expected HOST[:PORT] or a rerun+http://HOST:PORT/proxy URL, got "
            f"{address!r}"
        )
    host, _, port = address.rpartition(":") if ":" in address else (address, "", "")
    host = host or "127.0.0.1"
    if port:
        if not port.isdigit() or not (0 < int(port) < 65536):
            raise ValueError(f"--connect: bad port in {address!r}")
    else:
        port = str(DEFAULT_PORT)
    return f"rerun+http://{host}:{port}/proxy"


#: log_result records ``min_eigenvalue`` where a solve left it unread at most once per this many
#: seconds [s] (where the solve computed it anyway, every time)
EIGEN_PERIOD_S = 1.0


class Recorder:
    """Records solves to rerun (an .rrd file, a spawned viewer, a running viewer, or any of these).

    Off when ``rrd`` is None, ``spawn`` False and ``connect`` None: then every method returns at
    once. ``connect``: a viewer address (see :func:`grpc_url`; ``""`` = the default local viewer).
    ``recording_id``: fixed id (default: a fresh one).  ``queue_size``: items waiting to be logged
    before the oldest is dropped (counted in :attr:`dropped`; scene and model events are never
    dropped). ``force_scale``: arrow length per newton [m/N] (default 0.15·L divided by the largest
    of the string's weight, the loads' total force and 4π²·Rf_max/L², the clamped string's buckling
    load). ``frames``: number of material frames drawn along the string.  ``backend``:
    ``"process"`` (default: rerun runs in a child process; the caller only pickles into a pipe) or
    ``"thread"`` (a background thread here; shares the GIL).  Raises RecordingUnavailable without
    rerun-sdk, ValueError for a bad ``connect`` address, RuntimeError when the viewer cannot be
    spawned or the recorder process cannot start.
    """

    def __init__(
        self,
        *,
        rrd: str | Path | None = None,
        spawn: bool = False,
        connect: str | None = None,
        application_id: str = "dlo_ros",
        recording_id: str | None = None,
        queue_size: int = 1024,
        force_scale: float | None = None,
        frames: int = 9,
        spawn_port: int = DEFAULT_PORT,
        backend: str = "process",
        start_timeout: float = 60.0,
    ) -> None:
        self.enabled = bool(rrd) or bool(spawn) or connect is not None
        self.rrd = Path(rrd) if rrd else None
        self.errors = 0
        self.last_error = ""
        self.recording_id: str | None = None
        self.url: str | None = None
        self._force_scale = force_scale
        self._eigen_at = -np.inf  # when log_result last had the eigenvalue worked out
        self._closed = False
        self._backend: Any = None
        if not self.enabled:
            return
        if backend not in ("process", "thread"):
            raise ValueError(f"backend: must be 'process' or 'thread', got {backend!r}")
        if spawn and not has_display():
            raise RuntimeError(
                "no display ($DISPLAY and $WAYLAND_DISPLAY are unset), so a spawned viewer cannot "
                "open "
                "a window; save with --rrd FILE and open it with `dlo replay FILE` where there is "
                "a "
                "display, or stream with --connect to a viewer running elsewhere"
            )
        urls = ([f"rerun+http://127.0.0.1:{spawn_port}/proxy"] if spawn else []) + (
            [grpc_url(connect)] if connect is not None else []
        )
        self.url = urls[0] if urls else None
        cfg = WriterConfig(
            rrd=str(self.rrd.resolve()) if self.rrd else None,
            spawn=bool(spawn),
            spawn_port=int(spawn_port),
            urls=urls,
            application_id=application_id,
            recording_id=recording_id,
            frames=int(frames),
        )
        kind = ProcessBackend if backend == "process" else ThreadBackend
        self._backend = kind(cfg, start_timeout, max(1, int(queue_size)))
        self.recording_id = self._backend.recording_id

    # ---- public API (any thread) ----------------------------------------------------------------
    def log_scene(
        self,
        scene_or_problem: Any,
        frame_id: str | None = None,
        *,
        solver: Any = None,
        update: int | None = None,
        ros_time_ns: int | None = None,
    ) -> None:
        """Log the scene: obstacles, the scene YAML and the default blueprint.

        The scene: obstacles, the scene YAML (for ``dlo replay --resolve``), the default
        blueprint.

        ``scene_or_problem``: a ``dlo_ros.scene.Scene`` (its YAML makes the recording re-solvable)
        or a ``Problem`` (drawn, but not re-solvable).  ``frame_id`` defaults to the scene's.
        ``solver``: the solver object (or its class name), so that replay builds the same kind.
        With ``update`` None everything is static (call it once, before the first result); with an
        ``update`` it is a change from that update on (``scene/changes``), e.g. after the node
        changed the problem.  Not meant for the critical path (it writes the scene as YAML in the
        calling thread, ~ms); never dropped.
        """
        if not self.enabled:
            return
        info = scene_info(scene_or_problem, frame_id, solver, self._force_scale)
        self._put(
            QueueItem("scene", update, self._now(ros_time_ns) if update is not None else 0, info),
            keep=True,
        )

    def log_targets(
        self, poses: Mapping[str, Any], *, update: int, ros_time_ns: int | None = None
    ) -> None:
        """Log grip targets as received.

        Grip targets as received: ``{name: (position[3], quaternion xyzw[4])}`` or ``{name:
        GripPose}``.
        """
        if not self.enabled:
            return
        self._put(encode_targets(poses, int(update), self._now(ros_time_ns)))

    def log_result(
        self,
        result: Any,
        *,
        update: int,
        ros_time_ns: int | None = None,
        bend_stiffness: float | np.ndarray | None = None,
        targets: Mapping[str, Any] | None = None,
        warm: bool | None = None,
    ) -> None:
        """Log one solve: a committed update, or a failed one.

        One solve (a committed update, or a failed one).  ``bend_stiffness``: Rf [N·m²] (a
        constant or one value per sample of result.s) for the colouring; None takes it from the
        scene.  ``targets``: the grip poses this solve used (all grips), recorded exactly so that
        ``dlo replay --resolve`` repeats the same solve (without it, replay folds the
        ``log_targets`` of updates ≤ this one). ``warm``: the ``warm`` argument the solve was
        called with (False after a reset / for the first solve); replay repeats it (None: replay
        takes the first update as cold, the others as warm unless the result says it was not
        warm-started).
        """
        if not self.enabled:
            return
        # the smallest eigenvalue costs a solve that decided by the inertia an eigendecomposition
        # (~0.17 ms compiled on default_cable, 13 % of the update): read at most once a period
        now = time.monotonic()
        eigenvalue = now - self._eigen_at >= EIGEN_PERIOD_S
        if eigenvalue:
            self._eigen_at = now
        self._put(
            encode_result(
                result,
                int(update),
                self._now(ros_time_ns),
                bend_stiffness,
                targets,
                warm,
                eigenvalue,
            )
        )

    def log_update(
        self,
        result: Any,
        *,
        update: int,
        problem: Any = None,
        ros_time_ns: int | None = None,
        warm: bool | None = None,
    ) -> None:
        """Log the node's one call per solve: the result with its problem's poses and stiffness.

        The node's one call per solve: :meth:`log_result` with the grip poses and the bend
        stiffness taken from ``problem`` (the Problem that was solved; its grip poses are the
        targets used).

        Call it from the solver's thread right after ``solve`` returns, for every streaming solve
        (ok or not).  ``ros_time_ns``: the header stamp of the newest target folded into the solve
        (None: now). ``warm``: False when the solve started cold (first solve, after a reset, a
        rebuilt solver).
        """
        if not self.enabled:
            return
        targets = bend = None
        if problem is not None:
            targets = {g.name: g.pose for g in problem.grips}
            if len(result.s):
                bend = problem.string.bend_stiffness(np.asarray(result.s, dtype=float))
        self.log_result(
            result,
            update=update,
            ros_time_ns=ros_time_ns,
            bend_stiffness=bend,
            targets=targets,
            warm=warm,
        )

    def log_rejected(self, reason: str, *, update: int, ros_time_ns: int | None = None) -> None:
        """Log an input that was rejected (bad pose, unknown grip, wrong frame, ...) and why."""
        if not self.enabled:
            return
        self._put(QueueItem("rejected", int(update), self._now(ros_time_ns), str(reason)))

    def log_model_change(
        self, text: str, *, update: int, ros_time_ns: int | None = None, scene: Any = None
    ) -> None:
        """Log a free-text model event, and the new scene if one is given.

        A free-text model event (e.g. the model reduction switched models).  With ``scene`` the
        new scene is recorded too (as :meth:`log_scene` with ``update``).  Never dropped.
        """
        if not self.enabled:
            return
        t = self._now(ros_time_ns)
        self._put(QueueItem("model", int(update), t, str(text)), keep=True)
        if scene is not None:
            self.log_scene(scene, update=update, ros_time_ns=t)

    def log_fit(
        self,
        points: np.ndarray,
        shape: np.ndarray,
        feet: np.ndarray,
        *,
        sigma: float,
        huber: float,
        text: str,
        ok: bool,
        update: int,
        ros_time_ns: int | None = None,
    ) -> None:
        """Log a fit of observed points at ``update``.

        A fit of observed points at ``update``: ``points`` (N, 3), the fitted centreline
        ``shape`` (S, 3) and each point's nearest point on it ``feet`` (N, 3) [m] (empty when the
        fit failed), drawn under ``world/fit`` by ``dlo_ros.identify.drawing``; ``text`` (its
        summary and what it applied) goes to ``events/fit`` (WARN unless ``ok``).  Never
        dropped.
        """
        if not self.enabled:
            return
        snap = FitSnap(
            np.array(points, dtype=float),
            np.array(shape, dtype=float).reshape(-1, 3),
            np.array(feet, dtype=float).reshape(-1, 3),
            float(sigma),
            float(huber),
            str(text),
            bool(ok),
        )
        self._put(QueueItem("fit", int(update), self._now(ros_time_ns), snap), keep=True)

    def log_envelope(
        self,
        points: np.ndarray,
        radii: np.ndarray,
        *,
        text: str,
        update: int,
        ros_time_ns: int | None = None,
    ) -> None:
        """Log an envelope's tube at ``update``: a ball of radius ``radii`` [m] per point [m].

        Drawn under ``world/envelope``; ``text`` (its summary) goes to ``events/envelope``.
        """
        if not self.enabled:
            return
        snap = EnvelopeSnap(
            np.array(points, dtype=float).reshape(-1, 3),
            np.array(radii, dtype=float).ravel(),
            str(text),
        )
        self._put(QueueItem("envelope", int(update), self._now(ros_time_ns), snap), keep=True)

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until everything logged so far is in rerun's sinks.

        Wait until everything logged so far is in rerun's sinks (False on timeout or a dead
        writer).
        """
        if not self.enabled or self._closed:
            return True
        done, stats = self._backend.flush(timeout)
        self._absorb(stats)
        return done

    def close(self, timeout: float = 10.0) -> None:
        """Log what is queued, flush and close the sinks.

        Log what is queued, flush and close the sinks (the .rrd file is complete afterwards).
        Idempotent; ``with Recorder(...) as rec:`` calls it on exit.
        """
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

    # ---- internals ------------------------------------------------------------------------------
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
