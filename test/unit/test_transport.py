"""Twist-free frames (``model/transport.py``) against the helix's rotation-minimising frame in
closed form, and against the step-by-step transport written out here (one Rodrigues rotation per
pair of neighbouring tangents, a loop)."""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.transport import transported_frames

A, B = 0.3, 0.1  # helix radius and pitch / 2π [m]
C = np.hypot(A, B)
TORSION = B / C**2


def helix(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit tangent, normal and binormal (each (K, 3)) of (A cos φ, A sin φ, B φ), φ = s/C."""
    phi = s / C
    t = np.stack([-A * np.sin(phi), A * np.cos(phi), np.full_like(phi, B)], axis=1) / C
    n = np.stack([-np.cos(phi), -np.sin(phi), np.zeros_like(phi)], axis=1)
    return t, n, np.cross(t, n)


def stepwise(t: np.ndarray, k0: int, hint: np.ndarray) -> np.ndarray:
    """d1 (K, 3) carried from k0 both ways, one smallest rotation (Rodrigues) per step."""
    d1 = np.empty_like(t)
    d1[k0] = hint - hint @ t[k0] * t[k0]
    d1[k0] /= np.linalg.norm(d1[k0])
    for order in (range(k0 + 1, len(t)), range(k0 - 1, -1, -1)):
        prev = k0
        for k in order:
            c, axis = t[prev] @ t[k], np.cross(t[prev], t[k])
            v = d1[prev]
            d1[k] = v if c < -0.999999 else v * c + np.cross(axis, v) + axis * (axis @ v) / (1 + c)
            d1[k] /= np.linalg.norm(d1[k])
            prev = k
    return d1


@pytest.mark.parametrize("k0", [0, 700, 2000])
def test_the_helix_frame_turns_against_its_torsion(k0):
    """Rotation-minimising: d1 = cos θ N + sin θ B with θ' = −τ (d1' has no d2 part); on 2001
    samples within 1e-5, and the error falls about 4x when the samples double (second order)."""
    errors = []
    for k in (2001, 4001):
        s = np.linspace(0.0, 3.0, k)
        t, n, b = helix(s)
        j = k0 * (k - 1) // 2000
        frames = transported_frames(t, j, n[j])
        theta = -TORSION * (s - s[j])
        exact = np.cos(theta)[:, None] * n + np.sin(theta)[:, None] * b
        np.testing.assert_allclose(frames[:, :, 0], t, atol=1e-15)
        np.testing.assert_allclose(frames[:, :, 2], np.cross(t, frames[:, :, 1]), atol=1e-15)
        errors.append(np.abs(frames[:, :, 1] - exact).max())
    assert errors[0] < 1e-5, errors
    assert 3.0 < errors[0] / errors[1] < 5.0, errors


def test_equal_to_the_step_by_step_transport():
    """Random smooth curves, any start, a half turn between neighbours (no axis: carried as is)."""
    rng = np.random.default_rng(4)
    for case in range(60):
        k = int(rng.integers(2, 300))
        s = np.linspace(0.0, 1.0, k)[:, None]
        w, phase, size = rng.normal(size=(3, 3))
        v = np.cos(4 * s * w + phase) * size + rng.normal(size=3)
        if case % 6 == 0:
            v[k // 2:] *= -1.0
        t = v / np.linalg.norm(v, axis=1)[:, None]
        k0, hint = int(rng.integers(0, k)), rng.normal(size=3)
        frames = transported_frames(t, k0, hint)
        np.testing.assert_allclose(frames[:, :, 1], stepwise(t, k0, hint), atol=1e-12)
        if case % 6:  # a frame carried across a half turn is not perpendicular to the new tangent
            gram = np.einsum("kij,kil->kjl", frames, frames)
            np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-13)
