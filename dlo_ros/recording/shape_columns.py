"""The columns that draw a batch of solved shapes (centrelines, frames, grips) and of targets.

Pure numpy, no rerun: :func:`shape_columns` yields one :class:`ColumnsCall` per rerun
``send_columns`` call, in the order the writer sends them, for a batch of ok results that share a
sample count; :func:`target_columns` does the same for a batch of grip targets.  The writer
(``recording.writer``) only sends them, so what is drawn can be read here without the writer's
queueing and batching.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..shading import segment_energy_density
from .codec import QueueItem, ResultSnap
from .paths import (
    E_CABLE,
    E_EIGEN,
    E_ENERGY,
    E_FRAMES,
    E_GRIPS,
    E_TARGETS,
    ENERGY_TERMS,
    path_part,
)
from .scene_info import SceneInfo
from .visuals import AXIS_COLORS, quats_to_matrices, viridis

#: colour (RGB) of the arrows of the force each gripper exerts on the string
FORCE_COLOUR = (230, 60, 230)


class ColumnsCall(NamedTuple):
    """One ``send_columns`` call: rows of ``arch`` on ``entity``, one row per item.

    ``fields``: name → (the rows' data concatenated, instances per row).
    """

    entity: str
    arch: str
    items: list[QueueItem]
    fields: dict[str, tuple[Any, list[int]]]


@dataclass(frozen=True)
class ShapeBatch:
    """m ok results of N samples each, stacked, with their bend-energy density.

    points (m, N, 3) [m], orientations (m, N, 4), s (m, N) [m], length [m] (the scene's, else the
    first result's arc length), rf (m, N) the bend stiffness [N m²] at the samples, density
    (m, N-1) the bend energy per length [J/m] of each segment.
    """

    points: np.ndarray
    orientations: np.ndarray
    s: np.ndarray
    length: float
    rf: np.ndarray
    density: np.ndarray

    @classmethod
    def of(cls, snaps: list[ResultSnap], scene: SceneInfo | None) -> ShapeBatch:
        """Stack ``snaps``; Rf is each result's own, else the scene's Rf(s), else 1."""
        points = np.stack([r.points for r in snaps])
        s = np.stack([r.s for r in snaps])
        length = scene.length if scene else (float(s[0, -1] - s[0, 0]) or 1.0)
        rf = np.empty(s.shape)
        for i, r in enumerate(snaps):
            if r.bend_stiffness is not None:
                rf[i] = r.bend_stiffness
            elif scene is not None:
                rf[i] = scene.bend_stiffness(r.s)
            else:
                rf[i] = 1.0
        orientations = np.stack([r.orientations for r in snaps])
        density = segment_energy_density(points, rf)
        return cls(points, orientations, s, length, rf, density)

    def energy_scale(self) -> float:
        """Return the density [J/m] the colour map tops out at, chosen from the first result.

        The larger of a full circle's density ½ Rf (2π / L)² and 1.25 × the first shape's largest.
        """
        return max(
            0.5 * float(np.max(self.rf[0])) * (2 * math.pi / self.length) ** 2,
            1.25 * float(np.max(self.density[0])),
        )


def shape_columns(
    items: list[QueueItem],
    snaps: list[ResultSnap],
    batch: ShapeBatch,
    scene: SceneInfo | None,
    n_frames: int,
    energy_scale: float,
) -> Iterator[ColumnsCall]:
    """Yield the columns drawing ``batch`` (the shapes of ``snaps``, logged at ``items``).

    In order: the centreline coloured by bend energy, ``n_frames`` material frames, each grip's
    pose and force (when the scene is known), the energy terms and the smallest eigenvalue.
    """
    m, n = batch.points.shape[:2]
    ones = [1] * m
    radius = max(scene.radius if scene else 0.0, 0.004 * batch.length)
    segments = np.stack([batch.points[:, :-1], batch.points[:, 1:]], axis=2).reshape(-1, 2, 3)
    rows = [n - 1] * m
    yield ColumnsCall(
        E_CABLE,
        "LineStrips3D",
        items,
        dict(
            strips=(segments, rows),
            colors=(viridis(batch.density / energy_scale).reshape(-1, 3), rows),
            radii=(np.full(m, radius), ones),
        ),
    )
    if n_frames:
        yield _frame_columns(items, batch, n_frames)
    if scene is not None:
        yield from _grip_columns(items, snaps, batch, scene)
    # None (a dead moment without a potential) is a gap in the series: NaN
    energy = np.array([[r.energy.get(t, 0.0) for t in ENERGY_TERMS] for r in snaps], dtype=float)
    yield ColumnsCall(
        E_ENERGY, "Scalars", items, dict(scalars=(energy.ravel(), [len(ENERGY_TERMS)] * m))
    )
    eig = [
        i
        for i, r in enumerate(snaps)
        if r.min_eigenvalue is not None and math.isfinite(r.min_eigenvalue)
    ]
    if eig:
        yield ColumnsCall(
            E_EIGEN,
            "Scalars",
            [items[i] for i in eig],
            dict(scalars=(np.array([snaps[i].min_eigenvalue for i in eig]), [1] * len(eig))),
        )


def _frame_columns(items: list[QueueItem], batch: ShapeBatch, n_frames: int) -> ColumnsCall:
    """Return the material frames (x, y, z arrows) at ``n_frames`` evenly spaced samples."""
    m, n = batch.points.shape[:2]
    axes = np.array(AXIS_COLORS, dtype=np.uint8)
    idx = np.unique(np.round(np.linspace(0, n - 1, n_frames)).astype(int))
    k = len(idx)
    rot = quats_to_matrices(batch.orientations[:, idx].reshape(-1, 4)).reshape(m, k, 3, 3)
    a = 0.05 * batch.length
    vectors = a * np.concatenate([rot[:, :, :, 0], rot[:, :, :, 1], rot[:, :, :, 2]], axis=1)
    origins = np.concatenate([batch.points[:, idx]] * 3, axis=1)
    return ColumnsCall(
        E_FRAMES,
        "Arrows3D",
        items,
        dict(
            vectors=(vectors.reshape(-1, 3), [3 * k] * m),
            origins=(origins.reshape(-1, 3), [3 * k] * m),
            colors=(np.tile(np.repeat(axes, k, axis=0), (m, 1)), [3 * k] * m),
            radii=(np.full(m, 0.002 * batch.length), [1] * m),
        ),
    )


def _grip_columns(
    items: list[QueueItem], snaps: list[ResultSnap], batch: ShapeBatch, scene: SceneInfo
) -> Iterator[ColumnsCall]:
    """Yield each grip's pose on the solved shape and the force it exerts on the string.

    The pose is read at the grip's s on the first row's samples.
    """
    m, n = batch.points.shape[:2]
    P, Q, s0 = batch.points, batch.orientations, batch.s[0]
    L = batch.length
    b = 0.1 * L
    axes = np.array(AXIS_COLORS, dtype=np.uint8)
    for name, s_g in scene.grip_s.items():
        j1 = int(np.clip(np.searchsorted(s0, s_g), 1, n - 1))
        j0 = j1 - 1
        w = (s_g - s0[j0]) / (s0[j1] - s0[j0]) if s0[j1] > s0[j0] else 0.0
        pos = P[:, j0] * (1 - w) + P[:, j1] * w  # (m, 3)
        rot = quats_to_matrices(Q[:, int(np.argmin(np.abs(s0 - s_g)))])  # (m, 3, 3)
        path = f"{E_GRIPS}/{path_part(name)}"
        yield ColumnsCall(
            path,
            "Arrows3D",
            items,
            dict(
                vectors=((b * rot.transpose(0, 2, 1)).reshape(-1, 3), [3] * m),
                origins=(np.repeat(pos, 3, axis=0), [3] * m),
                colors=(np.tile(axes, (m, 1)), [3] * m),
                radii=(np.full(3 * m, 0.004 * L), [3] * m),
            ),
        )
        have = [i for i, r in enumerate(snaps) if name in r.forces]
        if have:
            f = np.array([snaps[i].forces[name] for i in have])
            one = [1] * len(have)
            yield ColumnsCall(
                path + "/force",
                "Arrows3D",
                [items[i] for i in have],
                dict(
                    vectors=(scene.force_scale * f, one),
                    origins=(pos[have], one),
                    colors=(np.tile(np.array(FORCE_COLOUR, np.uint8), (len(have), 1)), one),
                    radii=(np.full(len(have), 0.005 * L), one),
                    labels=([f"{x:.3g} N" for x in np.linalg.norm(f, axis=1)], one),
                ),
            )


#: colour (RGB) of the grip targets as received
TARGET_COLOUR = (255, 150, 40)


def target_columns(items: list[QueueItem], length: float) -> Iterator[ColumnsCall]:
    """Yield each grip's targets as received: a point and an arrow along its tangent.

    ``items`` carry {grip name: (position, quaternion)}; ``length`` [m] scales the marks.
    """
    by_grip: dict[str, list[tuple[QueueItem, np.ndarray, np.ndarray]]] = {}
    for it in items:
        for name, (pos, quat) in it.payload.items():
            by_grip.setdefault(name, []).append((it, pos, quat))
    orange = np.array(TARGET_COLOUR, np.uint8)
    for name, rows in by_grip.items():
        m = len(rows)
        its = [r[0] for r in rows]
        pos = np.array([r[1] for r in rows], dtype=float)
        x_axis = quats_to_matrices(np.array([r[2] for r in rows]))[:, :, 0]
        ones = [1] * m
        path = f"{E_TARGETS}/{path_part(name)}"
        yield ColumnsCall(
            path,
            "Points3D",
            its,
            dict(
                positions=(pos, ones),
                radii=(np.full(m, 0.012 * length), ones),
                colors=(np.tile(orange, (m, 1)), ones),
                labels=([f"{name} target"] * m, ones),
            ),
        )
        yield ColumnsCall(
            path,
            "Arrows3D",
            its,
            dict(
                origins=(pos, ones),
                vectors=(0.12 * length * x_axis, ones),
                colors=(np.tile(orange, (m, 1)), ones),
                radii=(np.full(m, 0.003 * length), ones),
            ),
        )


def legend_markdown(energy_scale: float, scene: SceneInfo | None) -> str:
    """Return the legend of the drawing (markdown): what each colour and arrow means."""
    lines = [
        "# Legend",
        f"* centreline colour: bend energy density ½ Rf κ² from 0 J/m (dark purple) to "
        f"{energy_scale:.4g} J/m and above (yellow); κ from consecutive tangents",
        "* axes: x = tangent (red), y (green), z (blue): material frames and grip poses",
    ]
    if scene is not None:
        lines.append(
            "* magenta arrows: force each gripper exerts on the string, "
            f"{scene.force_scale:.4g} m per N"
        )
    lines.append("* orange: grip targets as received (point and tangent)")
    return "\n".join(lines)
