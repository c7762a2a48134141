"""Rerun recording of what the solver does: shapes, forces, targets, timings, events (no ROS).

One :class:`Recorder` per recording.  It is *off* (every method a cheap no-op) unless one of
``rrd`` (save to an .rrd file), ``spawn`` (start a native viewer and stream to it) or ``connect``
(stream to a running viewer) is given; any combination works.  Documented in
``msg_docs/recording.md``.

Off the critical path: ``log_targets`` / ``log_result`` / ``log_update`` copy their arguments into
a flat tuple of bytes, pickle it and write it into a non-blocking pipe (tens of µs); a child
process (``backend="process"``, niced) makes every rerun call, in column batches.  If the pipe and
the bounded backlog behind it are full, the oldest waiting message is dropped and counted
(:attr:`Recorder.dropped`); the scene (``log_scene``) and model changes are never dropped.  Every
``log_*`` is thread-safe and keeps the order of one thread's calls.  ``backend="thread"`` runs the
writer in a thread instead.

Modules, one job each: :mod:`.recorder` (the public :class:`Recorder`), :mod:`.paths` (entity paths
and timelines; the entity tree is documented there), :mod:`.codec` (snapshots on the wire),
:mod:`.transport` (child process or thread), :mod:`.writer` (rerun calls), :mod:`.visuals` and
:mod:`.shape_columns` (drawing maths), :mod:`.obstacle_drawing` (obstacles from their primitive),
:mod:`.scene_info`, :mod:`.blueprint` (the default layout), :mod:`.replay` (reading a
recording back and re-solving it) and :mod:`.viewer` (opening or rendering one).  Importing the
package does not import rerun.
"""

from __future__ import annotations

from ..shading import segment_energy_density as bend_energy_density
from .blueprint import auto_model, default_blueprint
from .paths import (
    E_CABLE,
    E_DATA_RESULT,
    E_DATA_TARGETS,
    E_EIGEN,
    E_ENERGY,
    E_FIT,
    E_FIT_EVENTS,
    E_FRAMES,
    E_GRIPS,
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
    E_TARGETS,
    E_WORLD,
    ENERGY_TERMS,
    MODEL_SCALARS,
    TIMELINE_ROS,
    TIMELINE_UPDATE,
)
from .recorder import DEFAULT_GRPC_URL, DEFAULT_PORT, Recorder, grpc_url, has_display
from .scene_info import scene_info, scene_yaml
from .visuals import quats_to_matrices, viridis

from .writer import RecordingUnavailable, Writer

__all__ = [
    "DEFAULT_GRPC_URL",
    "DEFAULT_PORT",
    "Recorder",
    "Writer",
    "RecordingUnavailable",
    "auto_model",
    "bend_energy_density",
    "default_blueprint",
    "grpc_url",
    "has_display",
    "quats_to_matrices",
    "scene_info",
    "scene_yaml",
    "viridis",
    "E_CABLE",
    "E_DATA_RESULT",
    "E_DATA_TARGETS",
    "E_EIGEN",
    "E_ENERGY",
    "E_FIT",
    "E_FIT_EVENTS",
    "E_FRAMES",
    "E_GRIPS",
    "E_ITERATIONS",
    "E_LEGEND",
    "E_MODEL",
    "E_MODEL_SERIES",
    "E_OBSTACLES",
    "E_RECORDER",
    "E_REJECTED",
    "E_SCENE",
    "E_SCENE_CHANGES",
    "E_SOLVE_TIME",
    "E_STATUS",
    "E_TARGETS",
    "E_WORLD",
    "ENERGY_TERMS",
    "MODEL_SCALARS",
    "TIMELINE_ROS",
    "TIMELINE_UPDATE",
]
