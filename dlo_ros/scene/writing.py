"""A scene written back in the scene-file format (:func:`scene_to_dict`).

Every key is explicit, so the written scene does not depend on the reader's defaults; obstacles
are written by their type's ``to_dict`` (``model.obstacle_types``).
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import numpy as np

from ..model.profile import Profile
from ..solver.options import SolverOptions
from .format import Scene


def profile_to_yaml(p: Profile) -> float | dict:
    """Write a profile as a number (constant) or ``{table: [[s, value], ...]}``."""
    if len(p.s) == 1:
        return float(p.values[0])
    return {"table": [[float(s), float(v)] for s, v in zip(p.s, p.values)]}


def _floats(a: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def scene_to_dict(scene: Scene) -> dict:
    """Return the scene in the scene-file format, every key explicit.

    ``scene_from_dict`` of it gives an equal scene.
    """
    pr, st = scene.problem, scene.problem.string
    out: dict[str, Any] = {"name": scene.name}
    if scene.description:
        out["description"] = scene.description
    out["frame_id"] = scene.frame_id
    out["string"] = {
        "length": float(st.length),
        "bend_stiffness": profile_to_yaml(st.bend_stiffness),
        "twist_stiffness": profile_to_yaml(st.twist_stiffness),
        "stretch_stiffness": None
        if st.stretch_stiffness is None
        else profile_to_yaml(st.stretch_stiffness),
        "weight_per_length": profile_to_yaml(st.weight_per_length),
        "radius": float(st.radius),
    }
    if st.lateral_bend_stiffness is not None:  # absent: an isotropic rod (files stay as they were)
        out["string"]["lateral_bend_stiffness"] = profile_to_yaml(st.lateral_bend_stiffness)
    if scene.uncertainty is not None:  # absent when the scene gives none (files stay as they were)
        out["string"]["uncertainty"] = scene.uncertainty.marginal_sigmas(st)
    out["gravity"] = {"direction": _floats(pr.gravity_unit)}
    out["grips"] = [
        {
            "name": g.name,
            "s": float(g.s),
            "mode": g.mode,
            "position": _floats(g.pose.position),
            "orientation": _floats(g.pose.orientation),
        }
        for g in pr.grips
    ]
    out["loads"] = [
        {"s": float(ld.s), "force": _floats(ld.force), "moment": _floats(ld.moment)}
        for ld in pr.loads
    ]
    out["obstacles"] = [ob.to_dict() for ob in pr.obstacles]
    out["relative_positions"] = [
        {"s_a": float(r.s_a), "s_b": float(r.s_b), "offset": _floats(r.offset)}
        for r in pr.relative_positions
    ]
    out["solver"] = {f.name: getattr(scene.options, f.name) for f in fields(SolverOptions)}
    return out
