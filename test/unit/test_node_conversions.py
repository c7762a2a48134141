"""Unit tests (no ROS graph) of dlo_ros.node.conversions: messages <-> numpy and the output messages."""
from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Pose, PoseStamped
from visualization_msgs.msg import Marker

from dlo_ros.model import Grip, GripPose, Obstacle, Problem, Profile, StringProperties
from dlo_ros.model.rotations import matrix_to_quat, quat_to_matrix
from dlo_ros.node import conversions as conv
from dlo_ros.node import markers
from dlo_ros.shading import frame_tangents as tangents
from dlo_ros.solver.results.result import GripWrench, ShapeResult

FRAMES = ["", "w", "ab", "abc", "abcd", "world", "abcdef", "abcdefg", "abcdefgh", "a_longer_frame_7"]  # every length mod 8


def arc_result(radius: float = 0.5, n: int = 41, angle: float = math.pi / 2) -> ShapeResult:
    """A circular arc in the x-z plane, poses with x along the tangent (curvature 1/radius)."""
    s = np.linspace(0.0, radius * angle, n)
    a = s / radius
    points = np.stack([radius * np.sin(a), np.zeros(n), radius * (1 - np.cos(a))], axis=1)
    tangent = np.stack([np.cos(a), np.zeros(n), np.sin(a)], axis=1)
    frames = np.stack([tangent, np.tile([0.0, 1.0, 0.0], (n, 1)), np.cross(tangent, [0.0, 1.0, 0.0])], axis=2)
    quats = matrix_to_quat(frames)
    grips = {"left": GripWrench(np.array([1.0, 0.0, -0.5]), np.array([0.0, 0.1, 0.0])),
             "right": GripWrench(np.array([-1.0, 0.0, -0.5]), np.array([0.0, -0.1, 0.0]))}
    return ShapeResult(status="ok", message="converged", s=s, points=points, orientations=quats, grips=grips,
                       stable=True, energy={"total": 1.0})


def problem_for(result: ShapeResult, obstacles=()) -> Problem:
    st = StringProperties(length=float(result.s[-1]), bend_stiffness=Profile.constant(0.02),
                          twist_stiffness=Profile.constant(0.01), weight_per_length=Profile.constant(0.5), radius=0.005)
    grips = (Grip("left", 0.0, "clamp", GripPose(result.points[0], result.orientations[0])),
             Grip("right", float(result.s[-1]), "pin", GripPose(result.points[-1], result.orientations[-1])))
    return Problem(st, grips, obstacles=tuple(obstacles))


def test_time_round_trip():
    for ns in (0, 1, 999_999_999, 1_000_000_000, 1_795_314_550_643_126_142):
        assert conv.time_to_ns(conv.ns_to_time(ns)) == ns
    h = conv.header("world", 1_500_000_001)
    assert h.frame_id == "world" and h.stamp.sec == 1 and h.stamp.nanosec == 500_000_001


def test_pose_round_trip():
    p, q = np.array([0.1, -2.0, 3.5]), np.array([0.1, 0.2, 0.3, 0.9])
    pose = conv.arrays_to_pose(p, q)
    assert isinstance(pose, Pose)
    p2, q2 = conv.pose_to_arrays(pose)
    np.testing.assert_array_equal(p2, p)
    np.testing.assert_array_equal(q2, q)
    ps = conv.pose_stamped(p, q, "world", 5)
    assert ps.header.frame_id == "world" and conv.time_to_ns(ps.header.stamp) == 5


def test_quaternion_product_and_transform():
    rng = np.random.default_rng(1)
    for _ in range(10):
        a, b = rng.normal(size=4), rng.normal(size=4)
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        np.testing.assert_allclose(quat_to_matrix(conv.quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b),
                                   atol=1e-12)
    # a frame rotated by 90 deg about z and shifted by (1, 0, 0): the point (1, 0, 0) there is (1, 1, 0) here
    rot = np.array([0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)])
    p, q = conv.transform_pose(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]), (1.0, 0.0, 0.0), rot)
    np.testing.assert_allclose(p, [1.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(q, rot, atol=1e-12)


def test_result_to_path_and_back():
    r = arc_result()
    path = conv.result_to_path(r, "world", 123)
    assert path.header.frame_id == "world" and conv.time_to_ns(path.header.stamp) == 123
    assert len(path.poses) == len(r.s)
    assert all(ps.header.frame_id == "world" and conv.time_to_ns(ps.header.stamp) == 123 for ps in path.poses)
    pts, qs = conv.path_to_arrays(path)
    np.testing.assert_array_equal(pts, r.points)
    np.testing.assert_array_equal(qs, r.orientations)
    # x-axis along the tangent
    np.testing.assert_allclose(tangents(qs)[1:-1], np.diff(pts, axis=0)[1:] / np.linalg.norm(
        np.diff(pts, axis=0)[1:], axis=1, keepdims=True), atol=0.05)
    empty = conv.path_to_arrays(conv.result_to_path(ShapeResult(status="failed", message=""), "world", 0))
    assert empty[0].shape == (0, 3) and empty[1].shape == (0, 4)


def test_wrench():
    w = GripWrench(np.array([1.0, -2.0, 3.0]), np.array([0.1, 0.2, -0.3]))
    msg = conv.wrench_stamped(w, "world", 7)
    assert msg.header.frame_id == "world"
    f, t = conv.wrench_to_arrays(msg)
    np.testing.assert_array_equal(f, w.force)
    np.testing.assert_array_equal(t, w.torque)


@pytest.mark.parametrize("frame", FRAMES)
def test_the_serialised_wrench_reads_back_as_the_message(frame):
    """The node publishes the wrenches as CDR bytes: deserialised, they are what wrench_stamped builds."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message, serialize_message

    w = GripWrench(np.array([1.0, -2.0, 3.5e-9]), np.array([0.1, 0.2, -0.3]))
    stamp = 1_796_154_177_018_047_479
    data = conv.wrench_cdr(w, frame, stamp)
    expected = conv.wrench_stamped(w, frame, stamp)
    assert deserialize_message(data, WrenchStamped) == expected
    assert len(data) == len(serialize_message(expected))  # its padding bytes are not zeroed: compare sizes


def test_curvature_of_an_arc_is_exact():
    r = arc_result(radius=0.5)
    np.testing.assert_allclose(markers.curvature(r.s, r.orientations), 2.0, rtol=1e-9)
    density = markers.bending_energy_density(r.s, r.orientations, Profile.constant(0.02))
    np.testing.assert_allclose(density, 0.5 * 0.02 * 4.0, rtol=1e-9)
    np.testing.assert_allclose(markers.bending_energy_density(r.s, r.orientations, 0.02), density)
    straight = np.tile([0.0, 0.0, 0.0, 1.0], (5, 1))
    np.testing.assert_array_equal(markers.curvature(np.linspace(0, 1, 5), straight), 0.0)
    assert markers.curvature(np.array([0.0]), straight[:1]).shape == (1,)


def test_colour_map():
    c = markers.colour_map(np.array([-1.0, 0.0, 0.5, 1.0, 2.0]))
    assert c.shape == (5, 3) and np.all((c >= 0) & (c <= 1))
    np.testing.assert_array_equal(c[0], c[1])
    np.testing.assert_array_equal(c[3], c[4])
    assert c[1][2] > c[1][0] and c[3][0] > c[3][2]  # blue at 0, red at 1


def test_markers():
    r = arc_result()
    obstacles = [
        Obstacle.from_dict({"type": "sphere", "name": "ball", "center": [0, 0, 1], "radius": 0.1}),
        Obstacle.from_dict({"type": "box", "center": [0, 1, 0], "half_extents": [0.1, 0.2, 0.3],
                            "orientation": [0, 0, math.sin(0.2), math.cos(0.2)]}),
        Obstacle.from_dict({"type": "capsule", "a": [0, 0, 0], "b": [0, 0, 1], "radius": 0.05}),
        Obstacle.from_dict({"type": "halfspace", "point": [0, 0, -1], "normal": [0, 0, 1]}),
    ]
    pr = problem_for(r, obstacles)
    arr = markers.result_markers(r, pr, "world", 42, force_scale=0.1)
    ms = arr.markers
    assert ms[0].action == Marker.DELETEALL
    by_ns: dict[str, list[Marker]] = {}
    for m in ms[1:]:
        by_ns.setdefault(m.ns, []).append(m)
        assert m.header.frame_id == "world" and conv.time_to_ns(m.header.stamp) == 42
    line = by_ns["string"][0]
    assert line.type == Marker.LINE_STRIP and len(line.points) == len(r.s) == len(line.colors)
    assert line.scale.x == pytest.approx(0.01)
    assert len(by_ns["grips"]) == 2 and all(m.type == Marker.ARROW for m in by_ns["grips"])
    forces = by_ns["forces"]
    assert len(forces) == 2
    tip = np.array([forces[0].points[1].x, forces[0].points[1].y, forces[0].points[1].z])
    np.testing.assert_allclose(tip, r.points[0] + 0.1 * r.grips["left"].force)
    types = sorted(m.type for m in by_ns["obstacles"])
    assert types == sorted([Marker.SPHERE, Marker.CUBE, Marker.CYLINDER, Marker.SPHERE, Marker.SPHERE, Marker.CUBE])
    ids = [(m.ns, m.id) for m in ms[1:]]
    assert len(ids) == len(set(ids))
    sphere = next(m for m in by_ns["obstacles"] if m.text == "ball")
    assert sphere.scale.x == pytest.approx(0.2) and sphere.pose.position.z == pytest.approx(1.0)
    box = next(m for m in by_ns["obstacles"] if m.type == Marker.CUBE and m.scale.z == pytest.approx(0.6))
    np.testing.assert_allclose([box.pose.orientation.z, box.pose.orientation.w], [math.sin(0.2), math.cos(0.2)])
    cyl = next(m for m in by_ns["obstacles"] if m.type == Marker.CYLINDER)
    assert cyl.scale.z == pytest.approx(1.0) and cyl.pose.position.z == pytest.approx(0.5)
    # uniform curvature -> uniform colour; a fixed scale maps the density 0.04 J/m to the middle of the map
    colours = np.array([(c.r, c.g, c.b) for c in line.colors])
    np.testing.assert_allclose(colours, np.tile(colours[0], (len(colours), 1)), atol=1e-6)
    half = markers.result_markers(r, pr, "world", 42, energy_scale=0.08).markers[1]
    mid = markers.colour_map(np.array([0.5]))[0]
    np.testing.assert_allclose([half.colors[3].r, half.colors[3].g, half.colors[3].b], mid, atol=1e-6)


def test_diagnostic_status():
    st = conv.diagnostic_status("/dlo: shape", "warn", "input rejected", "default_cable",
                                {"stable": True, "solve time ms": 1.23456789, "last error": None, "updates": 3})
    assert isinstance(st, DiagnosticStatus) and st.level == DiagnosticStatus.WARN
    assert conv.diagnostic_values(st) == {"stable": "true", "solve time ms": "1.23457", "last error": "",
                                          "updates": "3"}
    with pytest.raises(KeyError):
        conv.diagnostic_status("x", "bad", "", "", {})


def test_in_frame_with_and_without_a_transform_lookup():
    from dlo_ros.node.validation import TargetError

    p, q = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])
    same = conv.in_frame("/world", "world", p, q, "t")
    assert same[0] is p and same[1] is q
    with pytest.raises(TargetError, match="'map', not 'world'") as err:
        conv.in_frame("map", "world", p, q, "grips/left/target")
    assert err.value.kind == "frame"
    rot = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    calls = []

    def lookup(target, source):
        calls.append((target, source))
        if source != "map":
            raise LookupError(f'"{source}" passed to lookupTransform argument source_frame does not exist')
        return (1.0, 0.0, 0.0), rot

    p2, q2 = conv.in_frame("/map", "world", p, q, "t", lookup)
    assert calls == [("world", "map")]
    np.testing.assert_allclose(p2, [1.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(q2, rot, atol=1e-12)
    with pytest.raises(TargetError, match="no transform from 'odom' to 'world'.*does not exist") as err:
        conv.in_frame("odom", "world", p, q, "t", lookup)
    assert err.value.kind == "frame"
    with pytest.raises(TargetError, match="frame_id is empty"):
        conv.in_frame("", "world", p, q, "t", lookup)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("n", [0, 1, 2, 51])
def test_the_serialised_centreline_reads_back_as_the_message(frame, n):
    """The node publishes the Path as CDR bytes built from the arrays (#14's lean path): deserialised,
    they are the message result_to_path builds (every alignment case of the frame id's length)."""
    from nav_msgs.msg import Path
    from rclpy.serialization import deserialize_message, serialize_message

    rng = np.random.default_rng(n)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None] if n else 1.0
    result = ShapeResult(status="ok", message="", points=rng.normal(size=(n, 3)), orientations=q)
    stamp = 1_796_154_177_018_047_479
    data = conv.result_path_cdr(result, frame, stamp)
    expected = conv.result_to_path(result, frame, stamp)
    assert deserialize_message(data, Path) == expected
    assert len(data) == len(serialize_message(expected))


@pytest.mark.parametrize("count", [0, 1, 51])
def test_path_from_cdr_reads_what_rclpy_serialises(count):
    """Any nav_msgs/Path, poses with headers of their own (frame_ids of different lengths, so every
    alignment case occurs), read from rclpy's own serialisation."""
    from nav_msgs.msg import Path
    from rclpy.serialization import serialize_message

    rng = np.random.default_rng(count)
    msg = Path()
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 1_700_000_000, 123_456_789, "world"
    for k in range(count):
        ps = PoseStamped()
        ps.header.frame_id = "f" * (k % 9)
        ps.header.stamp.sec = k
        p, q = rng.normal(size=3), rng.normal(size=4)
        ps.pose = conv.arrays_to_pose(p, q / np.linalg.norm(q))
        msg.poses.append(ps)
    stamp, frame, points, quats = conv.path_from_cdr(serialize_message(msg))
    assert stamp == 1_700_000_000_123_456_789 and frame == "world"
    want_points, want_quats = conv.path_to_arrays(msg)
    assert points.shape == (count, 3) and quats.shape == (count, 4)
    np.testing.assert_array_equal(points, want_points.reshape(count, 3))
    np.testing.assert_array_equal(quats, want_quats.reshape(count, 4))


def test_path_from_cdr_inverts_path_cdr_and_refuses_bad_bytes():
    rng = np.random.default_rng(0)
    points, quats = rng.normal(size=(51, 3)), rng.normal(size=(51, 4))
    data = conv.path_cdr(points, quats, "map", 5_000_000_007)
    stamp, frame, p, q = conv.path_from_cdr(data)
    assert (stamp, frame) == (5_000_000_007, "map")
    np.testing.assert_array_equal(p, points)
    np.testing.assert_array_equal(q, quats)
    for bad in (data[:-8], data[:30], b"\x00\x00" + data[2:], b""):
        with pytest.raises(conv.CdrError):
            conv.path_from_cdr(bad)
    lying = bytearray(data)
    lying[4 + 12 + 4:4 + 12 + 4 + 4] = (10**6).to_bytes(4, "little")  # the pose count, after the header
    with pytest.raises(conv.CdrError):
        conv.path_from_cdr(bytes(lying))


def test_every_primitive_kind_is_drawn_from_its_description():
    """The node draws obstacles from their Primitive, whatever their type: each kind the model can
    describe (obstacle_types.PRIMITIVE_KINDS) has a drawing, and the drawing's geometry is the
    primitive's (hand-made primitives, independent of any obstacle type)."""
    from dlo_ros.model.obstacle_types import PRIMITIVE_KINDS, Primitive

    assert set(markers.PRIMITIVE_MARKERS) == set(PRIMITIVE_KINDS)
    h = conv.header("world", 7)
    q = np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)])
    z = np.array([0.0, 0.0, 1.0])
    sphere = markers.primitive_markers(
        Primitive("sphere", np.array([1.0, 2.0, 3.0]), q, z, np.full(3, 0.25), 0.25), h, 10)
    assert [(m.type, m.id) for m in sphere] == [(Marker.SPHERE, 10)]
    assert (sphere[0].scale.x, sphere[0].pose.position.y) == (0.5, 2.0)
    box = markers.primitive_markers(
        Primitive("box", np.array([0.0, 1.0, 0.0]), q, z, np.array([0.1, 0.2, 0.3])), h, 0)
    assert [m.type for m in box] == [Marker.CUBE]
    assert (box[0].scale.x, box[0].scale.y, box[0].scale.z) == (0.2, 0.4, 0.6)
    assert (box[0].pose.orientation.z, box[0].pose.orientation.w) == (q[2], q[3])
    capsule = markers.primitive_markers(
        Primitive("capsule", np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, 1.0]), z,
                  np.array([0.05, 0.05, 0.5]), 0.05), h, 3)
    assert [(m.type, m.id) for m in capsule] == [
        (Marker.CYLINDER, 3), (Marker.SPHERE, 4), (Marker.SPHERE, 5)]
    assert capsule[0].scale.z == 1.0
    assert sorted(m.pose.position.z for m in capsule[1:]) == [0.5, 1.5]
    plane = markers.primitive_markers(
        Primitive("plane", np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 0.0, 1.0]), z,
                  np.zeros(3)), h, 0)
    assert [m.type for m in plane] == [Marker.CUBE]
    assert plane[0].pose.position.z < -1.0 and plane[0].scale.x == markers.HALFSPACE_SIZE
    with pytest.raises(ValueError, match="cone"):
        markers.primitive_markers(
            Primitive("cone", np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), z, np.zeros(3)), h, 0)
