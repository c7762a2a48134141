"""Point-to-curve residuals of observed points against a predicted centreline.

Point-to-curve residuals: each observed point against the nearest point of the predicted
centreline.

The centreline is given as a dense polyline x_i = x(s_i) with derivatives dx_i/dθ.  For an observed
point y the foot is the nearest point of the polyline, f = (1 − τ) x_i + τ x_{i+1}, τ ∈ [0, 1], and
the residual is its component normal to the segment,

    r = P (y − f),   P = I − u uᵀ (u the segment's unit direction; P = I at a clamped end of the
    curve),

with dr/dθ = −P df/dθ (the foot's own motion along the curve does not change r to first order).  No
order, correspondence or completeness of the points is assumed.  The polyline's chord error is
h² κ / 8 for spacing h and curvature κ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: points projected at once (memory: CHUNK × segments × 3 floats)
CHUNK = 2048


@dataclass
class CurveResiduals:
    """The residuals of observed points against a curve, and their derivatives.

    residuals (N, 3) [m] = P (y − f); jacobian (N, 3, k) [m] = dr/dθ; s (N,) [m] the feet's arc
    lengths.
    """

    residuals: np.ndarray
    jacobian: np.ndarray
    s: np.ndarray

    @property
    def distances(self) -> np.ndarray:
        """|r| per point [m]."""
        return np.linalg.norm(self.residuals, axis=1)


def point_to_curve(
    points: np.ndarray, s: np.ndarray, curve: np.ndarray, d_curve: np.ndarray
) -> CurveResiduals:
    """Return the residuals of points against a polyline with known derivatives.

    Residuals of ``points`` (N, 3) against the polyline ``curve`` (S, 3) at arc lengths ``s``
    (S,), with ``d_curve`` (S, 3, k) its derivatives (module docstring).
    """
    a, d = curve[:-1], np.diff(curve, axis=0)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    n = points.shape[0]
    seg, tau = np.empty(n, dtype=int), np.empty(n)
    for start in range(0, n, CHUNK):
        y = points[start : start + CHUNK]
        rel = y[:, None, :] - a[None, :, :]
        t = np.clip(np.einsum("nsj,sj->ns", rel, d) / dd, 0.0, 1.0)
        dist2 = np.sum((rel - t[..., None] * d[None]) ** 2, axis=2)
        best = np.argmin(dist2, axis=1)
        seg[start : start + CHUNK] = best
        tau[start : start + CHUNK] = t[np.arange(len(y)), best]
    foot = a[seg] + tau[:, None] * d[seg]
    d_foot = (1.0 - tau)[:, None, None] * d_curve[seg] + tau[:, None, None] * d_curve[seg + 1]
    u = d[seg] / np.sqrt(dd[seg])[:, None]
    at_end = ((seg == 0) & (tau == 0.0)) | ((seg == len(d) - 1) & (tau == 1.0))
    proj = np.eye(3)[None] - np.einsum("ni,nj->nij", u, u)
    proj[at_end] = np.eye(3)
    residuals = np.einsum("nij,nj->ni", proj, points - foot)
    jacobian = -np.einsum("nij,njk->nik", proj, d_foot)
    return CurveResiduals(residuals, jacobian, s[seg] + tau * np.diff(s)[seg])
