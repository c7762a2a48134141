"""The cable's capsule chain as ROS messages: RViz markers and a MoveIt collision object.

Pure functions (no node, context or graph), like ``markers.py``.  A capsule is a cylinder along
its chord plus a sphere at each end; consecutive capsules share their end spheres, so a chain of K
capsules is K cylinders and K + 1 spheres.  ``shape_msgs`` comes with the pinned wheels;
``moveit_msgs`` does not (apt only), so ``collision_object`` returns None without it and
``primitives`` builds everything it would hold.  msg_docs/planning_scene.md: how to use them.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from geometry_msgs.msg import Pose, Vector3
from shape_msgs.msg import SolidPrimitive
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from .capsules import CapsuleChain
from .conversions import arrays_to_pose, header
from .validation import Vector

#: the markers' namespace: DELETEALL is scoped to it, so other markers on the topic stay
CAPSULE_NS = "dlo_cable"
#: translucent, so the predicted string inside stays visible
CAPSULE_RGBA = (0.2, 0.6, 1.0, 0.35)
#: a cylinder shorter than this [m] is left out: its end spheres already cover it
MIN_CYLINDER = 1e-9


def axis_quaternion(direction: Vector) -> np.ndarray:
    """Return the quaternion (x, y, z, w) of the shortest rotation taking +z onto ``direction``.

    A cylinder's axis in both ``Marker.CYLINDER`` and ``SolidPrimitive.CYLINDER`` is its local z.
    """
    u = np.asarray(direction, dtype=float)
    u = u / np.linalg.norm(u)
    # (z × u, 1 + z·u) is the half-angle quaternion, unnormalised; near u = -z, 1 + z·u is
    # computed as (ux² + uy²) / (1 - uz) (the same for a unit u) so it does not cancel to 0
    across = u[0] ** 2 + u[1] ** 2
    w = 1.0 + u[2] if u[2] >= 0.0 else across / (1.0 - u[2])
    if across == 0.0 and w == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])  # u = -z exactly: half a turn about x
    q = np.array([-u[1], u[0], 0.0, w])
    return q / np.linalg.norm(q)


class CapsulePart(NamedTuple):
    """One part of a drawn chain: its kind, its pose in the chain's frame, its number.

    kind: SolidPrimitive.SPHERE (at joint ``number``, identity orientation) or
    SolidPrimitive.CYLINDER (at the middle of capsule ``number``, z along it).
    """

    kind: int
    pose: Pose
    number: int


def capsule_poses(chain: CapsuleChain) -> list[CapsulePart]:
    """Return the chain's parts in order along the cable.

    Spheres and cylinders alternate: sphere 0, cylinder 0, sphere 1, ..., sphere K; a cylinder
    shorter than MIN_CYLINDER is left out.
    """
    parts: list[CapsulePart] = []
    identity = (0.0, 0.0, 0.0, 1.0)
    for k, joint in enumerate(chain.joints):
        parts.append(CapsulePart(SolidPrimitive.SPHERE, arrays_to_pose(joint, identity), k))
        if k == chain.count:
            break
        a, b = joint, chain.joints[k + 1]
        if np.linalg.norm(b - a) >= MIN_CYLINDER:
            middle = arrays_to_pose((a + b) / 2, axis_quaternion(b - a))
            parts.append(CapsulePart(SolidPrimitive.CYLINDER, middle, k))
    return parts


def capsule_markers(
    chain: CapsuleChain,
    frame_id: str,
    stamp_ns: int,
    *,
    ns: str = CAPSULE_NS,
    color: tuple[float, float, float, float] = CAPSULE_RGBA,
) -> MarkerArray:
    """Build the MarkerArray of the capsules: a DELETEALL of ``ns``, then a marker per part.

    Sphere at joint k: id 2k, diameter 2R.  Cylinder of capsule k: id 2k + 1, pose at its middle
    with z along it, scale (2R, 2R, length).  The DELETEALL carries ``ns``: RViz 2 (Galactic and
    later, ros2/rviz#685) then clears only that namespace, so a shorter chain replaces a longer one
    and other namespaces on the topic stay.  color: (r, g, b, a) in [0, 1].
    """
    h = header(frame_id, stamp_ns)
    markers = [Marker(header=h, ns=ns, action=Marker.DELETEALL)]
    diameter = 2.0 * chain.radius
    lengths = chain.lengths
    rgba = ColorRGBA(r=float(color[0]), g=float(color[1]), b=float(color[2]), a=float(color[3]))
    for kind, pose, k in capsule_poses(chain):
        m = Marker(header=h, ns=ns, action=Marker.ADD, pose=pose)
        if kind == SolidPrimitive.SPHERE:
            m.id, m.type = 2 * k, Marker.SPHERE
            m.scale = Vector3(x=diameter, y=diameter, z=diameter)
        else:
            m.id, m.type = 2 * k + 1, Marker.CYLINDER
            m.scale = Vector3(x=diameter, y=diameter, z=float(lengths[k]))
        m.color = rgba
        m.frame_locked = False
        markers.append(m)
    return MarkerArray(markers=markers)


def primitives(chain: CapsuleChain) -> list[tuple[SolidPrimitive, Pose]]:
    """Return the chain as MoveIt shapes: (SolidPrimitive, pose in the chain's frame) per part.

    In the order of ``capsule_poses``.  A sphere's dimensions are [R]; a cylinder's are
    [height, radius] = [|b - a|, R] (SolidPrimitive.CYLINDER_HEIGHT, CYLINDER_RADIUS), its axis
    the pose's z.
    """
    out: list[tuple[SolidPrimitive, Pose]] = []
    radius = float(chain.radius)
    lengths = chain.lengths
    for kind, pose, k in capsule_poses(chain):
        if kind == SolidPrimitive.SPHERE:
            shape = SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[radius])
        else:
            dims = [0.0, 0.0]
            dims[SolidPrimitive.CYLINDER_HEIGHT] = float(lengths[k])
            dims[SolidPrimitive.CYLINDER_RADIUS] = radius
            shape = SolidPrimitive(type=SolidPrimitive.CYLINDER, dimensions=dims)
        out.append((shape, pose))
    return out


def moveit_collision_object_type() -> Any | None:
    """Return moveit_msgs' CollisionObject class, or None where moveit_msgs is not installed."""
    try:
        # optional: moveit_msgs comes from apt (ros-jazzy-moveit-msgs), not from the wheels
        from moveit_msgs.msg import CollisionObject
    except ImportError:
        return None
    return CollisionObject


def collision_object(
    chain: CapsuleChain, frame_id: str, stamp_ns: int, object_id: str = "dlo_cable"
) -> Any | None:
    """Return a moveit_msgs/CollisionObject ADD of the chain's primitives, None without MoveIt.

    The object's pose (MoveIt 2) is the identity, so the primitive poses are in ``frame_id``.
    Publishing it again with the same ``object_id`` replaces the earlier shape in the scene.
    Typed Any: moveit_msgs has no wheel to type-check against.
    """
    obj = _empty_object(frame_id, stamp_ns, object_id)
    if obj is None:
        return None
    if hasattr(obj, "pose"):  # MoveIt 2's object pose; MoveIt warns on its all-zero quaternion
        obj.pose = arrays_to_pose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    shapes = primitives(chain)
    obj.primitives = [shape for shape, _ in shapes]
    obj.primitive_poses = [pose for _, pose in shapes]
    obj.operation = type(obj).ADD
    return obj


def removal_markers(frame_id: str, stamp_ns: int, ns: str = CAPSULE_NS) -> MarkerArray:
    """Return a MarkerArray that clears the capsules (a DELETEALL of ``ns``)."""
    return MarkerArray(
        markers=[Marker(header=header(frame_id, stamp_ns), ns=ns, action=Marker.DELETEALL)]
    )


def collision_removal(frame_id: str, stamp_ns: int, object_id: str = "dlo_cable") -> Any | None:
    """Return a moveit_msgs/CollisionObject REMOVE of ``object_id``, None without MoveIt."""
    obj = _empty_object(frame_id, stamp_ns, object_id)
    if obj is not None:
        obj.operation = type(obj).REMOVE
    return obj


def _empty_object(frame_id: str, stamp_ns: int, object_id: str) -> Any | None:
    """Return a CollisionObject with its header and id only, None without moveit_msgs."""
    CollisionObject = moveit_collision_object_type()
    if CollisionObject is None:
        return None
    obj = CollisionObject()
    obj.header = header(frame_id, stamp_ns)
    obj.id = object_id
    return obj
