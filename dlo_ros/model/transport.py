"""Twist-free frames along a curve: the tangent director model's frames (no roll of its own)."""

from __future__ import annotations

import numpy as np

from .rotations import cross3


def transported_frames(t: np.ndarray, k0: int, hint: np.ndarray) -> np.ndarray:
    """Return twist-free frames transported along unit tangents.

    Frames (K, 3, 3) (columns t, d1, d2) along unit tangents t (K, 3) without twist: d1 at k0 is
    ``hint`` made perpendicular to t[k0], and is carried to its neighbours, both ways, by the
    smallest rotation between consecutive tangents (a discrete d1' = −(t'·d1) t).
    """
    d1s = np.empty_like(t)
    d1 = hint - np.dot(hint, t[k0]) * t[k0]
    d1s[k0] = d1 / np.linalg.norm(d1)
    for rng in (range(k0 + 1, len(t)), range(k0 - 1, -1, -1)):
        prev = k0
        for k in rng:
            d1s[k] = _transport(d1s[prev], t[prev], t[k])
            d1s[k] /= np.linalg.norm(d1s[k])
            prev = k
    return np.stack([t, d1s, cross3(t, d1s)], axis=-1)


def _transport(d1: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """d1 carried from tangent t0 to t1 by the smallest rotation taking t0 to t1."""
    c = float(np.dot(t0, t1))
    axis = cross3(t0, t1)
    if c < -0.999999:
        return d1
    # Rodrigues with k = axis/|axis|, |axis| = sin a: R v = v c + (axis × v) + axis (axis·v) / (1
    # + c)
    return d1 * c + cross3(axis, d1) + axis * np.dot(axis, d1) / (1.0 + c)
