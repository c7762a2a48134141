"""Drawing maths of the recording (no rerun): colours and rotation matrices.

The bend-energy density and its colour map are dlo_ros.shading's, shared with the node's markers.
"""

from __future__ import annotations

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
