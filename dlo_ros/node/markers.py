"""The node's ``~/markers``: the string coloured by bending energy, grips, obstacles and forces.

Pure functions (no node, context or graph).  Obstacles are drawn from their ``Primitive``
(dlo_ros.model.obstacle_types): the node knows the few primitive kinds, not the obstacle types, so
a new obstacle type needs no edit here.
"""

from __future__ import annotations

from typing import Callable, Iterable

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from ..model.obstacle_types import PrimitiveKind
from ..model.obstacles import Obstacle, Primitive
from ..model.problem import Problem
from ..shading import colour_map as colour_map
from ..shading import energy_density
from ..shading import frame_curvature as curvature
from ..solver.results.result import ShapeResult
from .conversions import arrays_to_pose, header
from .validation import Vector


# ---- bending energy density (dlo_ros.shading, shared with the recording) ------------------------


def bending_energy_density(s: np.ndarray, orientations: np.ndarray, bend_stiffness) -> np.ndarray:
    """Return ½ Rf(s) κ(s)² [J/m] per sample.

    ``bend_stiffness`` is a Profile (callable on s) or a number.
    """
    rf = (
        bend_stiffness(np.asarray(s, dtype=float))
        if callable(bend_stiffness)
        else float(bend_stiffness)
    )
    return energy_density(curvature(s, orientations), rf)


def _rgba(rgb: Vector, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(a))


def _point(p: Vector) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


# ---- markers ------------------------------------------------------------------------------------

GRIP_COLOURS = {"clamp": (0.9, 0.5, 0.1), "pin": (0.6, 0.2, 0.9), "tangent": (0.2, 0.7, 0.9)}
OBSTACLE_RGBA = (0.55, 0.55, 0.6, 0.5)
FORCE_RGB = (0.9, 0.1, 0.6)
SELF_CONTACT_RGB = (1.0, 0.55, 0.0)
HALFSPACE_SIZE = 2.0  # [m] edge of the plate drawn for a half-space
MARKER_NAMESPACES = ("string", "grips", "obstacles", "forces", "self_contacts")


def _marker(h: Header, ns: str, mid: int, kind: int) -> Marker:
    m = Marker(header=h, ns=ns, id=mid, type=kind, action=Marker.ADD)
    m.pose.orientation.w = 1.0
    m.frame_locked = False
    m.lifetime = Duration(sec=0, nanosec=0)
    return m


def _sphere_markers(pr: Primitive, h: Header, mid: int) -> list[Marker]:
    """Draw a sphere primitive: one SPHERE marker."""
    m = _marker(h, "obstacles", mid, Marker.SPHERE)
    m.pose.position = _point(pr.centre)
    m.scale = Vector3(x=2 * pr.radius, y=2 * pr.radius, z=2 * pr.radius)
    return [m]


def _box_markers(pr: Primitive, h: Header, mid: int) -> list[Marker]:
    """Draw a box primitive: one CUBE marker of its extents, in its orientation."""
    m = _marker(h, "obstacles", mid, Marker.CUBE)
    e = pr.half_sizes
    m.pose = arrays_to_pose(pr.centre, pr.orientation)
    m.scale = Vector3(x=2 * e[0], y=2 * e[1], z=2 * e[2])
    return [m]


def _capsule_markers(pr: Primitive, h: Header, mid: int) -> list[Marker]:
    """Draw a capsule primitive: a CYLINDER along its axis plus two end SPHEREs."""
    r = pr.radius
    m = _marker(h, "obstacles", mid, Marker.CYLINDER)
    m.pose = arrays_to_pose(pr.centre, pr.orientation)
    m.scale = Vector3(x=2 * r, y=2 * r, z=pr.length)
    parts = [m]
    for k, end in enumerate(pr.ends()):
        e = _marker(h, "obstacles", mid + 1 + k, Marker.SPHERE)
        e.pose.position = _point(end)
        e.scale = Vector3(x=2 * r, y=2 * r, z=2 * r)
        parts.append(e)
    return parts


def _plane_markers(pr: Primitive, h: Header, mid: int) -> list[Marker]:
    """Draw a plane primitive: a thin plate of HALFSPACE_SIZE just behind the surface."""
    thick = 0.01
    m = _marker(h, "obstacles", mid, Marker.CUBE)
    m.pose = arrays_to_pose(pr.centre - pr.axis * thick / 2, pr.orientation)
    m.scale = Vector3(x=HALFSPACE_SIZE, y=HALFSPACE_SIZE, z=thick)
    return [m]


#: how each kind of ``Primitive`` (model.obstacle_types.PRIMITIVE_KINDS) is drawn: at most three
#: markers, ids mid, mid + 1, mid + 2, colour not yet set.  The node knows primitives, not
#: obstacle types: a new type describes itself as one of these kinds and needs no edit here.
PRIMITIVE_MARKERS: dict[str, Callable[[Primitive, Header, int], list[Marker]]] = {
    PrimitiveKind.PLANE: _plane_markers,
    PrimitiveKind.SPHERE: _sphere_markers,
    PrimitiveKind.CAPSULE: _capsule_markers,
    PrimitiveKind.BOX: _box_markers,
}


def primitive_markers(pr: Primitive, h: Header, mid: int) -> list[Marker]:
    """Build the markers of one drawing primitive (ids mid, mid + 1, mid + 2), colour not set.

    Raises ValueError for a kind :data:`PRIMITIVE_MARKERS` cannot draw.
    """
    draw = PRIMITIVE_MARKERS.get(pr.kind)
    if draw is None:
        raise ValueError(f"primitive kind {pr.kind!r}: no marker drawing for it")
    return draw(pr, h, mid)


def obstacle_markers(obstacles: Iterable[Obstacle], h: Header, start_id: int = 0) -> list[Marker]:
    """Build the markers of the obstacles, drawn from each one's primitive.

    A capsule is a cylinder plus two end spheres, a half-space a plate.
    """
    out: list[Marker] = []
    mid = start_id
    rgba = _rgba(OBSTACLE_RGBA[:3], OBSTACLE_RGBA[3])
    for ob in obstacles:
        parts = primitive_markers(ob.primitive(), h, mid)
        for m in parts:
            m.color = rgba
            m.text = ob.name
        out.extend(parts)
        mid += 3
    return out


def result_markers(
    result: ShapeResult,
    problem: Problem,
    frame_id: str,
    stamp_ns: int,
    *,
    force_scale: float = 0.1,
    energy_scale: float = 0.0,
) -> MarkerArray:
    """Build the MarkerArray of a shape: string, grips, obstacles, grip and self-contact forces.

    The string is a line strip coloured by bending energy density; each self-contact's force is
    drawn on both strands (namespace 'self_contacts').  energy_scale [J/m]: density shown in full
    red (0: the shape's maximum).  Starts with DELETEALL so a consumer never keeps markers of an
    earlier, larger scene.
    """
    h = header(frame_id, stamp_ns)
    markers: list[Marker] = [Marker(header=h, action=Marker.DELETEALL)]
    radius = float(problem.string.radius)
    width = max(2 * radius, 0.004)

    line = _marker(h, "string", 0, Marker.LINE_STRIP)
    line.scale.x = width
    line.points = [_point(p) for p in result.points.tolist()]
    density = bending_energy_density(result.s, result.orientations, problem.string.bend_stiffness)
    top = energy_scale if energy_scale > 0 else float(np.max(density, initial=0.0))
    rgb = colour_map(density / top if top > 0 else np.zeros_like(density))
    line.colors = [_rgba(c) for c in rgb.tolist()]
    line.color = _rgba((1.0, 1.0, 1.0))
    line.text = f"max bending energy density {float(np.max(density, initial=0.0)):.4g} J/m"
    markers.append(line)

    for i, g in enumerate(problem.grips):
        m = _marker(h, "grips", i, Marker.ARROW)  # along the pose's x-axis = the held tangent
        m.pose = arrays_to_pose(g.pose.position, g.pose.orientation)
        m.scale = Vector3(x=0.08, y=0.015, z=0.015)
        m.color = _rgba(GRIP_COLOURS.get(g.mode, (0.8, 0.8, 0.8)))
        m.text = f"{g.name} ({g.mode})"
        markers.append(m)
        wrench = result.grips.get(g.name)
        if wrench is not None:
            f = _marker(h, "forces", i, Marker.ARROW)
            start = np.asarray(g.pose.position, dtype=float)
            f.points = [
                _point(start),
                _point(start + force_scale * np.asarray(wrench.force, dtype=float)),
            ]
            f.scale = Vector3(x=0.006, y=0.012, z=0.0)
            f.color = _rgba(FORCE_RGB)
            f.text = f"{g.name}: {np.linalg.norm(wrench.force):.3g} N on the string"
            markers.append(f)

    # self-contacts: the force on each strand at its contact point (equal and opposite)
    for k, c in enumerate(result.self_contacts):
        for side, (point, force) in enumerate(((c.point_a, c.force), (c.point_b, -c.force))):
            m = _marker(h, "self_contacts", 2 * k + side, Marker.ARROW)
            start = np.asarray(point, dtype=float)
            m.points = [
                _point(start),
                _point(start + force_scale * np.asarray(force, dtype=float)),
            ]
            m.scale = Vector3(x=0.004, y=0.008, z=0.0)
            m.color = _rgba(SELF_CONTACT_RGB)
            s_side = c.s_a if side == 0 else c.s_b
            m.text = f"self-contact s = {s_side:.4g} m: {np.linalg.norm(c.force):.3g} N"
            markers.append(m)

    markers.extend(obstacle_markers(problem.obstacles, h))
    return MarkerArray(markers=markers)
