"""Drawing maths of the recording (no rerun): colours, rotation matrices, obstacle shapes.

The bend-energy density and its colour map are dlo_ros.shading's, shared with the node's markers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..shading import VIRIDIS_STOPS, colour_map

ENERGY_COLORS = [
    [230, 90, 90],
    [90, 200, 230],
    [200, 120, 230],
    [120, 200, 90],
    [230, 180, 60],
    [240, 240, 240],
]
AXIS_COLORS = [[230, 60, 60], [60, 200, 60], [70, 110, 255]]


def viridis(u: np.ndarray) -> np.ndarray:
    """Values in [0, 1] (clipped; NaN as 0) → uint8 RGB (…, 3) on the viridis map."""
    return np.round(colour_map(u, VIRIDIS_STOPS)).astype(np.uint8)


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
    """(archetype name, keyword arguments) drawing an obstacle (``dlo_ros.model.Obstacle``) from
    its ``primitive()``.

    plane → a square slab of side 2·extent, 1 % of that thick, lying just behind the surface,
    centred on the projection of ``centre``; sphere → Ellipsoids3D; capsule → Capsules3D; box →
    Boxes3D.
    """
    pr = ob.primitive()
    if pr.kind == "plane":
        normal = pr.axis / np.linalg.norm(pr.axis)
        foot = centre - np.dot(centre - pr.centre, normal) * normal
        thick = 0.01 * extent
        return "Boxes3D", dict(
            centers=[foot - 0.5 * thick * normal],
            half_sizes=[[extent, extent, 0.5 * thick]],
            quaternions=[pr.orientation],
        )
    if pr.kind == "sphere":
        return "Ellipsoids3D", dict(centers=[pr.centre], half_sizes=[pr.half_sizes])
    if pr.kind == "capsule":
        return "Capsules3D", dict(
            translations=[pr.ends()[0]],
            lengths=[pr.length],
            radii=[pr.radius],
            quaternions=[pr.orientation],
        )
    if pr.kind == "box":
        return "Boxes3D", dict(
            centers=[pr.centre], half_sizes=[pr.half_sizes], quaternions=[pr.orientation]
        )
    raise ValueError(f"obstacle primitive {pr.kind!r} has no drawing")
