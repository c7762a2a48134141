"""The capsule chain as messages (dlo_ros/node/planning_scene.py): markers, MoveIt primitives and
the CollisionObject, with moveit_msgs absent (it is not on PyPI) and with a stand-in of it."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
from geometry_msgs.msg import Pose
from rclpy.serialization import deserialize_message, serialize_message
from shape_msgs.msg import SolidPrimitive
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from dlo_ros.model.rotations import quat_to_matrix
from dlo_ros.node import planning_scene as ps
from dlo_ros.node.capsules import CapsuleChain, capsule_chain
from dlo_ros.node.conversions import time_to_ns

STAMP = 1_700_000_000_123_456_789


def chain_of(joints, radius: float = 0.01) -> CapsuleChain:
    """A chain through these joints (built directly: the messages do not care how)."""
    j = np.asarray(joints, dtype=float)
    return CapsuleChain(j, radius, radius / 2, radius, radius / 2, np.arange(len(j)))


#: an L-shaped chain going down at the end: +x, +y, then -z (the cylinder turned upside down)
ELL = chain_of([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, -2]], radius=0.05)


def pose_arrays(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w])


# ---- markers ------------------------------------------------------------------------------------


def test_the_markers_are_a_namespaced_deleteall_then_spheres_and_cylinders():
    array = ps.capsule_markers(ELL, "world", STAMP)
    assert isinstance(array, MarkerArray)
    first, *parts = array.markers
    assert first.action == Marker.DELETEALL and first.ns == ps.CAPSULE_NS
    assert len(parts) == 2 * ELL.count + 1 == 7
    assert [m.id for m in parts] == list(range(7))  # sphere 0, cylinder 0, sphere 1, ...
    for m in array.markers:
        assert m.header.frame_id == "world" and time_to_ns(m.header.stamp) == STAMP
        assert m.ns == ps.CAPSULE_NS
    spheres = [m for m in parts if m.type == Marker.SPHERE]
    cylinders = [m for m in parts if m.type == Marker.CYLINDER]
    assert [m.id for m in spheres] == [0, 2, 4, 6] and [m.id for m in cylinders] == [1, 3, 5]
    assert all(m.action == Marker.ADD for m in parts)
    for k, m in enumerate(spheres):
        position, q = pose_arrays(m.pose)
        np.testing.assert_allclose(position, ELL.joints[k], atol=0)
        np.testing.assert_allclose(q, [0, 0, 0, 1], atol=0)
        assert (m.scale.x, m.scale.y, m.scale.z) == (0.1, 0.1, 0.1)
    for k, m in enumerate(cylinders):
        a, b = ELL.joints[k], ELL.joints[k + 1]
        position, q = pose_arrays(m.pose)
        np.testing.assert_allclose(position, (a + b) / 2, atol=1e-15)
        axis = quat_to_matrix(q)[:, 2]  # the marker's z axis
        np.testing.assert_allclose(axis, (b - a) / np.linalg.norm(b - a), atol=1e-12)
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
        assert (m.scale.x, m.scale.y) == (0.1, 0.1)
        assert m.scale.z == pytest.approx(np.linalg.norm(b - a), abs=1e-15)


def test_the_markers_take_a_namespace_and_colour_and_serialise():
    array = ps.capsule_markers(ELL, "base_link", 5, ns="cable_a", color=(1.0, 0.5, 0.25, 0.75))
    assert {m.ns for m in array.markers} == {"cable_a"}
    for m in array.markers[1:]:
        assert (m.color.r, m.color.g, m.color.b, m.color.a) == (1.0, 0.5, 0.25, 0.75)
    back = deserialize_message(serialize_message(array), MarkerArray)
    assert len(back.markers) == len(array.markers)
    assert back.markers[2].scale.z == pytest.approx(1.0)


def rviz(shown: dict, array: MarkerArray) -> dict:
    """What RViz's marker display keeps after an array (rviz_default_plugins MarkerCommon:
    DELETEALL with a namespace clears that namespace, without one everything)."""
    shown = dict(shown)
    for m in array.markers:
        if m.action == Marker.DELETEALL:
            shown = {key: v for key, v in shown.items() if m.ns and key[0] != m.ns}
        elif m.action == Marker.DELETE:
            shown.pop((m.ns, m.id), None)
        else:
            shown[(m.ns, m.id)] = m.type
    return shown


def test_a_shorter_chain_replaces_a_longer_one_and_other_namespaces_stay():
    a = np.linspace(0.0, 3.0, 200)
    curve = np.stack([np.cos(a), np.sin(a), 0 * a], axis=1)
    long_chain = capsule_chain(curve, 0.005, 0.002)
    short_chain = capsule_chain(curve, 0.005, 0.02)
    assert short_chain.count < long_chain.count
    other = {("string", 0): Marker.LINE_STRIP}
    shown = rviz(other, ps.capsule_markers(long_chain, "world", 1))
    shown = rviz(shown, ps.capsule_markers(short_chain, "world", 2))
    expected = {(ps.CAPSULE_NS, i) for i in range(2 * short_chain.count + 1)}
    assert set(shown) == expected | set(other)


def test_the_cylinder_axis_for_every_direction():
    rng = np.random.default_rng(7)
    near_down = [[1e-9, 0.0, -1.0], [1e-13, -1e-14, -1.0]]  # where 1 + z·u cancels
    for d in [*np.eye(3), *-np.eye(3), *rng.normal(size=(20, 3)), *near_down]:
        q = ps.axis_quaternion(d)
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(quat_to_matrix(q)[:, 2], d / np.linalg.norm(d), atol=1e-14)


def test_a_zero_length_capsule_is_its_spheres():
    """A chord from a point back to itself (a closed loop as one capsule) draws no cylinder."""
    chain = chain_of([[0, 0, 0], [1, 0, 0], [1, 0, 0]])
    kinds = [(part.kind, part.number) for part in ps.capsule_poses(chain)]
    sphere, cylinder = SolidPrimitive.SPHERE, SolidPrimitive.CYLINDER
    assert kinds == [(sphere, 0), (cylinder, 0), (sphere, 1), (sphere, 2)]
    assert [m.id for m in ps.capsule_markers(chain, "w", 0).markers[1:]] == [0, 1, 2, 4]
    assert len(ps.primitives(chain)) == 4


# ---- MoveIt primitives --------------------------------------------------------------------------


def test_the_primitives_are_cylinders_and_spheres_with_their_dimensions():
    shapes = ps.primitives(ELL)
    assert len(shapes) == 7
    markers = ps.capsule_markers(ELL, "world", 0).markers[1:]
    for (shape, pose), m in zip(shapes, markers):
        assert isinstance(shape, SolidPrimitive) and isinstance(pose, Pose)
        assert pose == m.pose  # the same placement as the marker drawn for it
        if m.type == Marker.SPHERE:
            assert shape.type == SolidPrimitive.SPHERE
            assert list(shape.dimensions) == [0.05]
        else:
            assert shape.type == SolidPrimitive.CYLINDER
            height = shape.dimensions[SolidPrimitive.CYLINDER_HEIGHT]
            radius = shape.dimensions[SolidPrimitive.CYLINDER_RADIUS]
            assert (len(shape.dimensions), radius) == (2, 0.05)
            assert height == pytest.approx(m.scale.z, abs=0)
    heights = [s.dimensions[0] for s, _ in shapes if s.type == SolidPrimitive.CYLINDER]
    np.testing.assert_allclose(heights, [1.0, 1.0, 2.0], atol=1e-15)
    back = deserialize_message(serialize_message(shapes[1][0]), SolidPrimitive)
    assert back.type == SolidPrimitive.CYLINDER and list(back.dimensions) == [1.0, 0.05]


# ---- the CollisionObject ------------------------------------------------------------------------


def fake_moveit(with_pose: bool) -> tuple[types.ModuleType, types.ModuleType]:
    """A stand-in for moveit_msgs with MoveIt's CollisionObject fields (and its pose if asked)."""

    class CollisionObject:
        ADD, REMOVE, APPEND, MOVE = 0, 1, 2, 3

        def __init__(self):
            self.header = Header()
            self.id = ""
            self.primitives: list = []
            self.primitive_poses: list = []
            self.operation = 0
            if with_pose:
                self.pose = Pose()

    package = types.ModuleType("moveit_msgs")
    msg = types.ModuleType("moveit_msgs.msg")
    msg.CollisionObject = CollisionObject
    package.msg = msg
    return package, msg


@pytest.mark.parametrize("with_pose", [True, False])
def test_the_collision_object_with_moveit_msgs(monkeypatch, with_pose):
    package, msg = fake_moveit(with_pose)
    monkeypatch.setitem(sys.modules, "moveit_msgs", package)
    monkeypatch.setitem(sys.modules, "moveit_msgs.msg", msg)
    obj = ps.collision_object(ELL, "world", STAMP, object_id="cable_1")
    assert isinstance(obj, msg.CollisionObject)
    assert obj.header.frame_id == "world" and time_to_ns(obj.header.stamp) == STAMP
    assert obj.id == "cable_1" and obj.operation == msg.CollisionObject.ADD
    shapes = ps.primitives(ELL)
    assert obj.primitives == [s for s, _ in shapes]
    assert obj.primitive_poses == [p for _, p in shapes]
    if with_pose:
        position, q = pose_arrays(obj.pose)
        assert list(position) == [0, 0, 0] and list(q) == [0, 0, 0, 1]
    assert ps.collision_object(ELL, "world", STAMP).id == "dlo_cable"


def test_without_moveit_msgs_there_is_no_collision_object(monkeypatch):
    monkeypatch.setitem(sys.modules, "moveit_msgs", None)  # import moveit_msgs raises ImportError
    monkeypatch.setitem(sys.modules, "moveit_msgs.msg", None)
    assert ps.collision_object(ELL, "world", STAMP) is None
