"""Bend-energy shading of a centreline: density ½ Rf κ² and colour maps (numpy only).

Bend-energy shading of a centreline: the density ½ Rf κ² and the colour maps that draw it (numpy
only).

One implementation for the two drawings of a shape: the recording's centreline (dlo_ros.recording,
per segment of the polyline, viridis) and the node's line-strip marker (dlo_ros.node.conversions,
per sample, :data:`HEAT_STOPS`).  They differ only in where κ comes from: the recording has the
points of the polyline, the node the material frames at arc lengths s.  Both estimate κ as the
turning angle between two tangents over the length between them (:func:`turning_angle`), exact for
a circular arc.
"""

from __future__ import annotations

import numpy as np

#: viridis at 0, 1/8, …, 1 (8-bit RGB); the recording's centreline colours.
VIRIDIS_STOPS = np.array(
    [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ],
    dtype=float,
)
#: blue (low) → cyan → green → yellow → red (high), RGB in [0, 1]; the node's marker colours.
HEAT_STOPS = np.array(
    [[0.0, 0.2, 1.0], [0.0, 0.9, 1.0], [0.1, 0.9, 0.1], [1.0, 0.9, 0.0], [1.0, 0.1, 0.0]]
)


def turning_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the angle [rad] between unit vectors ``a`` and ``b``, in [0, π].

    Angle [rad] between unit vectors ``a`` and ``b`` (…, 3), in [0, π]; atan2 keeps it accurate
    near 0.
    """
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...i,...i->...", a, b))


def energy_density(kappa: np.ndarray, bend_stiffness: float | np.ndarray) -> np.ndarray:
    """½ Rf κ² [J/m] (Rf [N·m²] a constant or one value per κ)."""
    return 0.5 * np.asarray(bend_stiffness, dtype=float) * np.asarray(kappa, dtype=float) ** 2


def polyline_curvature(points: np.ndarray) -> np.ndarray:
    """κ [1/m] at the vertices of polylines (…, N, 3) → (…, N).

    At an interior vertex: the turning angle between consecutive segments over the mean of their
    two lengths; the end vertices take their neighbour's κ (0 with fewer than 3 points).
    """
    p = np.asarray(points, dtype=float)
    kappa = np.zeros(p.shape[:-1])
    if p.shape[-2] > 2:
        e = np.diff(p, axis=-2)
        length = np.linalg.norm(e, axis=-1)
        t = e / np.maximum(length, 1e-300)[..., None]
        mean_length = np.maximum(0.5 * (length[..., :-1] + length[..., 1:]), 1e-300)
        kappa[..., 1:-1] = turning_angle(t[..., :-1, :], t[..., 1:, :]) / mean_length
        kappa[..., 0], kappa[..., -1] = kappa[..., 1], kappa[..., -2]
    return kappa


def segment_energy_density(points: np.ndarray, bend_stiffness: float | np.ndarray) -> np.ndarray:
    """½ Rf κ² [J/m] per segment of polylines: points (…, N, 3) → (…, N−1).

    κ from :func:`polyline_curvature`; a segment gets the mean of the density at its two ends.
    ``bend_stiffness``: Rf [N·m²], a constant or one value per point (…, N).
    """
    p = np.asarray(points, dtype=float)
    if p.shape[-2] < 2:
        return np.zeros(p.shape[:-2] + (0,))
    rf = np.asarray(bend_stiffness, dtype=float)
    rf = rf if rf.ndim == 0 else rf.reshape(p.shape[:-1])
    density = energy_density(polyline_curvature(p), rf)
    return 0.5 * (density[..., :-1] + density[..., 1:])


def frame_tangents(orientations: np.ndarray) -> np.ndarray:
    """Return the unit tangents (the x-axes) of quaternions (N, 4) x, y, z, w."""
    q = np.asarray(orientations, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)], axis=1)


def frame_curvature(s: np.ndarray, orientations: np.ndarray) -> np.ndarray:
    """Return the curvature κ(s) [1/m] at samples with material frames.

    κ(s) [1/m] at samples s with material frames ``orientations`` (N, 4): the turning angle
    between neighbouring tangents over their Δs, central differences inside, one-sided at the ends
    (0 where Δs is 0).  Exact for a circular arc sampled uniformly.
    """
    s = np.asarray(s, dtype=float)
    n = s.size
    if n < 2:
        return np.zeros(n)
    t = frame_tangents(orientations)
    lo = np.r_[0, np.arange(n - 2), n - 2]
    hi = np.r_[1, np.arange(2, n), n - 1]
    ds = s[hi] - s[lo]
    return np.where(ds > 0, turning_angle(t[lo], t[hi]) / np.where(ds > 0, ds, 1.0), 0.0)


def colour_map(values: np.ndarray, stops: np.ndarray = HEAT_STOPS) -> np.ndarray:
    """Return the colours of ``values`` in [0, 1] on a linear colour map.

    Colours (…, C) of ``values`` in [0, 1] (clipped; NaN as 0), linear between equally spaced
    ``stops`` (K, C): 0 is ``stops[0]``, 1 is ``stops[-1]``.
    """
    v = np.clip(np.nan_to_num(np.asarray(values, dtype=float)), 0.0, 1.0) * (len(stops) - 1)
    i = np.minimum(v.astype(int), len(stops) - 2)
    f = (v - i)[..., None]
    return stops[i] * (1 - f) + stops[i + 1] * f
