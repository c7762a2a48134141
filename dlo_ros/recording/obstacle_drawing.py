"""Obstacles drawn from their ``Primitive``, whatever their type (no rerun: archetype names).

Each obstacle type describes itself as a ``Primitive`` (``model.obstacle_types``); here each
primitive kind has one drawing (:data:`DRAWINGS`), so a new obstacle type needs nothing here, and
a new primitive kind one function.  The recorder calls this in the caller's process
(``scene_info``); the writer's process never imports this module, because it imports the model
(CasADi).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..model.obstacle_types import Primitive, PrimitiveKind

#: an obstacle's drawing: (primitive, centre of the scene [m], extent [m]) -> (archetype, kwargs)
Drawing = Callable[[Primitive, np.ndarray, float], tuple[str, dict]]


def _plane(pr: Primitive, centre: np.ndarray, extent: float) -> tuple[str, dict]:
    """Draw a plane as a square slab of side 2·extent, 1 % of that thick, just behind the surface.

    The slab is centred on the projection of ``centre`` onto the plane.
    """
    normal = pr.axis / np.linalg.norm(pr.axis)
    foot = centre - np.dot(centre - pr.centre, normal) * normal
    thick = 0.01 * extent
    return "Boxes3D", dict(
        centers=[foot - 0.5 * thick * normal],
        half_sizes=[[extent, extent, 0.5 * thick]],
        quaternions=[pr.orientation],
    )


def _sphere(pr: Primitive, centre: np.ndarray, extent: float) -> tuple[str, dict]:
    """Draw a sphere as an Ellipsoids3D of equal half sizes."""
    return "Ellipsoids3D", dict(centers=[pr.centre], half_sizes=[pr.half_sizes])


def _capsule(pr: Primitive, centre: np.ndarray, extent: float) -> tuple[str, dict]:
    """Draw a capsule as a Capsules3D from its first end along its axis."""
    return "Capsules3D", dict(
        translations=[pr.ends()[0]],
        lengths=[pr.length],
        radii=[pr.radius],
        quaternions=[pr.orientation],
    )


def _box(pr: Primitive, centre: np.ndarray, extent: float) -> tuple[str, dict]:
    """Draw a box as a Boxes3D."""
    return "Boxes3D", dict(
        centers=[pr.centre], half_sizes=[pr.half_sizes], quaternions=[pr.orientation]
    )


#: the drawing of each primitive kind: a new kind needs one here (test_recording checks)
DRAWINGS: dict[PrimitiveKind, Drawing] = {
    PrimitiveKind.PLANE: _plane,
    PrimitiveKind.SPHERE: _sphere,
    PrimitiveKind.CAPSULE: _capsule,
    PrimitiveKind.BOX: _box,
}


def obstacle_shape(ob: Any, centre: np.ndarray, extent: float) -> tuple[str, dict]:
    """Return (archetype name, keyword arguments) drawing an obstacle from its ``primitive()``.

    ``ob`` is a ``dlo_ros.model.Obstacle``; the drawing is the primitive kind's in
    :data:`DRAWINGS`, whatever the obstacle's type.  ``centre`` and ``extent`` [m] place and size
    an unbounded plane.
    """
    pr = ob.primitive()
    drawing = DRAWINGS.get(pr.kind)
    if drawing is None:
        raise ValueError(f"obstacle primitive {str(pr.kind)!r} has no drawing")
    return drawing(pr, centre, extent)
