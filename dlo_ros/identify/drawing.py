"""Rerun drawing of a fit (``dlo fit --rrd FILE``): observed points, fitted centrelines, residuals.

Entity tree (world frame, z up, metres; everything static):

=================================  ================================================================
``world``                          ViewCoordinates RIGHT_HAND_Z_UP
``world/fit/<i>_<name>/observed``  the observed points: grey, red where the robust loss down-weighted
                                   them (|r| > huber σ)
``world/fit/<i>_<name>/fitted``    the fitted equilibrium's centreline
``world/fit/<i>_<name>/residuals`` one segment per point, from the point to its nearest point on the
                                   centreline (the point-to-curve residual)
``fit/summary``                    the text summary of ``dlo fit``
=================================  ================================================================
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .fit import FitResult, FitSettings
from .observations import ObservationSet

GREY, RED, BLUE, ORANGE = (150, 150, 150), (220, 40, 40), (40, 90, 220), (240, 150, 30)


def entity_name(index: int, name: str) -> str:
    """``<i>_<name>`` with characters rerun treats specially replaced."""
    return f"{index}_{re.sub(r'[^A-Za-z0-9_.-]+', '_', name)}"


def save_fit(path: str | Path, result: FitResult, data: ObservationSet, summary: str,
             settings: FitSettings = FitSettings()) -> None:
    """Write the drawing of ``result`` (fitted to ``data``) to the .rrd file ``path``.  Raises
    RuntimeError when rerun-sdk cannot be imported."""
    try:
        import rerun as rr
    except ImportError as exc:
        raise RuntimeError(f"drawing needs rerun-sdk (see requirements.txt): {exc}") from None
    rec = rr.RecordingStream("dlo_fit")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path))
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for i, (fitted, obs) in enumerate(zip(result.observations, data.observations)):
        base = f"world/fit/{entity_name(i, obs.name)}"
        distance = np.linalg.norm(obs.points - fitted.feet, axis=1) if len(fitted.feet) else np.zeros(len(obs.points))
        colours = np.where((distance > settings.huber * obs.sigma)[:, None], RED, GREY).astype(np.uint8)
        rec.log(f"{base}/observed", rr.Points3D(obs.points, colors=colours, radii=obs.sigma), static=True)
        if len(fitted.shape):
            rec.log(f"{base}/fitted", rr.LineStrips3D([fitted.shape], colors=[BLUE]), static=True)
        if len(fitted.feet):
            segments = np.stack([obs.points, fitted.feet], axis=1)
            rec.log(f"{base}/residuals", rr.LineStrips3D(segments, colors=[ORANGE]), static=True)
    rec.log("fit/summary", rr.TextDocument(summary), static=True)
    rec.flush()
    rec.disconnect()
