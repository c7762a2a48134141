"""Rerun drawing of a fit (``dlo fit --rrd FILE``): observed points, fitted centrelines, residuals.

Entity tree (world frame, z up, metres; everything static):

=================================  ================================================================
``world``                          ViewCoordinates RIGHT_HAND_Z_UP
``world/fit/<i>_<name>/observed``  the observed points: grey, red where the robust loss
down-weighted
                                   them (|r| > huber σ)
``world/fit/<i>_<name>/fitted``    the fitted equilibrium's centreline
``world/fit/<i>_<name>/residuals`` one segment per point, from the point to its nearest point on
the
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


def draw_observation(
    rec,
    base: str,
    points: np.ndarray,
    shape: np.ndarray,
    feet: np.ndarray,
    sigma: float,
    huber: float,
    *,
    static: bool = True,
) -> None:
    """Log one observation's points, fitted centreline and residuals to rerun.

    Log one observation's drawing under ``base`` into the rerun RecordingStream ``rec``:
    ``observed`` (``points`` (N, 3) [m], red beyond ``huber`` σ of the centreline), ``fitted``
    (``shape`` (S, 3) [m]) and ``residuals`` (point → its nearest point ``feet`` (N, 3) on the
    centreline; empty arrays skip a part). ``static``: timeless (``dlo fit --rrd``), or at the
    stream's current time (the node's recording).
    """
    import rerun as rr  # optional: rerun-sdk (Python >= 3.11), with pyarrow

    distance = np.linalg.norm(points - feet, axis=1) if len(feet) else np.zeros(len(points))
    colours = np.where((distance > huber * sigma)[:, None], RED, GREY).astype(np.uint8)
    rec.log(f"{base}/observed", rr.Points3D(points, colors=colours, radii=sigma), static=static)
    if len(shape):
        rec.log(f"{base}/fitted", rr.LineStrips3D([shape], colors=[BLUE]), static=static)
    if len(feet):
        rec.log(
            f"{base}/residuals",
            rr.LineStrips3D(np.stack([points, feet], axis=1), colors=[ORANGE]),
            static=static,
        )


def save_fit(
    path: str | Path,
    result: FitResult,
    data: ObservationSet,
    summary: str,
    settings: FitSettings = FitSettings(),
) -> None:
    """Write the drawing of a fit to an .rrd file.

    Write the drawing of ``result`` (fitted to ``data``) to the .rrd file ``path``.  Raises
    RuntimeError when rerun-sdk cannot be imported.
    """
    try:
        import rerun as rr  # optional: rerun-sdk (Python >= 3.11), with pyarrow
    except ImportError as exc:
        raise RuntimeError(f"drawing needs rerun-sdk (see requirements.txt): {exc}") from None
    rec = rr.RecordingStream("dlo_fit")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path))
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for i, (fitted, obs) in enumerate(zip(result.observations, data.observations)):
        draw_observation(
            rec,
            f"world/fit/{entity_name(i, obs.name)}",
            obs.points,
            fitted.shape,
            fitted.feet,
            obs.sigma,
            settings.huber,
        )
    rec.log("fit/summary", rr.TextDocument(summary), static=True)
    rec.flush()
    rec.disconnect()
