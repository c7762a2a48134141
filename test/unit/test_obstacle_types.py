"""Every registered obstacle type implements all its behaviour (dlo_ros.model.obstacle_types).

Each type in the registry must have a sample below; the checks run on every registered type, so a
new type without a sample, or with a missing or wrong behaviour, fails here.  Distances are checked
against hand-computed values, not against the code's own output.
"""
from __future__ import annotations

import inspect
import math

import casadi as ca
import numpy as np
import pytest

from dlo_ros.model.obstacle_types import (OBSTACLE_TYPES, PRIMITIVE_KINDS, Key, ObstacleType,
                                          Primitive, register)
from dlo_ros.model.obstacles import Obstacle
from dlo_ros.scene import SceneError, scene_from_dict, scene_to_dict
from dlo_ros.solver.contact.obstacle_slots import FLAT

S2 = math.sqrt(0.5)

#: per type: a scene mapping, points with their hand-computed exact signed distance h [m]
#: (positive inside; the box's h is the inscribed superellipsoid, exact on the axes through its
#: face centres),
#: a point inside the true obstacle (its distance bound must be ≤ 0 there; for the box a point near
#: a corner, outside the inscribed superellipsoid), a plane (origin, unit normal) the obstacle lies
#: clear of by more than 0.1 m, one it fits in, and one that cuts it away from its centre.
SAMPLES: dict[str, dict] = {
    "halfspace": dict(
        spec={"type": "halfspace", "point": [0, 0, 0.1], "normal": [0, 0, 2]},
        points=[([0.3, -2, 0.4], -0.3), ([1, 1, -0.15], 0.25)],
        inside=[0, 0, 0], clear=([0, 0, 0.5], [0, 0, 1]), fits=([0, 0, 0.5], [0, 1, 0]),
        cuts=([0, 0, 0], [0, 0, 1])),
    "sphere": dict(
        spec={"type": "sphere", "center": [1, 2, 3], "radius": 0.5},
        points=[([1, 2, 3.2], 0.3), ([1, 2 + 0.8 * 3, 3 + 0.6 * 3], -2.5)],
        inside=[1, 2, 3], clear=([0, 0, 0], [1, 0, 0]), fits=([0, 0, 3], [0, 0, 1]),
        cuts=([1, 2, 3.3], [0, 0, 1])),
    "capsule": dict(
        spec={"type": "capsule", "a": [0, 0, 0], "b": [0, 0, 1], "radius": 0.1},
        points=[([0.04, 0.03, 0.5], 0.05), ([0, 0, 1.5], -0.4), ([0, 0.3, -0.4], -0.4)],
        inside=[0, 0, 0.5], clear=([0.5, 0, 0], [1, 0, 0]), fits=([0, 0, 0], [0, 1, 0]),
        cuts=([0, 0, 0.8], [0, 0, 1])),
    "box": dict(
        spec={"type": "box", "center": [0, 0, 1], "half_extents": [0.1, 0.2, 0.3],
              "orientation": [0, 0, S2, S2]},  # 90° about z: the box's x axis is world y
        points=[([0, 0, 1], 0.1), ([0.2, 0, 1], 0.0), ([0, 0.15, 1], -0.05)],
        inside=[-0.198, 0.099, 1.297], clear=([0, 0, 2], [0, 0, 1]), fits=([0, 0, 1], [0, 1, 0]),
        cuts=([0, 0, 1.25], [0, 0, 1])),
}


def test_every_registered_type_has_a_sample_and_every_behaviour():
    assert set(SAMPLES) == set(OBSTACLE_TYPES)
    abstract = ObstacleType.__abstractmethods__
    assert {"parse", "to_dict", "h", "distance_bound", "clear_of_plane", "planarity_violation",
            "primitive"} <= abstract
    for name, kind in OBSTACLE_TYPES.items():
        cls = type(kind)
        assert not inspect.isabstract(cls), f"{name}: {sorted(cls.__abstractmethods__)} missing"
        for method in abstract:  # each implemented by the type itself or a shared base, not absent
            assert getattr(cls, method) is not getattr(ObstacleType, method), (name, method)
        assert kind.name == name
        assert isinstance(kind.size, int) and kind.size > 0
        assert kind.keys
        assert all(isinstance(k, Key) and k.kind in ("vector", "number", "quaternion")
                   for k in kind.keys.values())
        assert isinstance(kind.flat, bool)


def test_a_type_missing_a_behaviour_cannot_be_registered():
    class Partial(ObstacleType):  # no primitive, no planarity test, ...
        name, size, keys, fields = "partial", 1, {"r": Key("number", True)}, {"r": 0}

        def parse(self, d, where):
            return np.array([1.0])

    with pytest.raises(TypeError):
        register(Partial)
    assert "partial" not in OBSTACLE_TYPES
    with pytest.raises(ValueError, match="registered twice"):
        register(type(OBSTACLE_TYPES["sphere"]))


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_parse_to_dict_round_trip(name):
    sample = SAMPLES[name]
    ob = Obstacle.from_dict(dict(sample["spec"], name="it"))
    assert ob.params.shape == (OBSTACLE_TYPES[name].size,)
    d = ob.to_dict()
    assert d["type"] == name and d["name"] == "it"
    assert set(d) - {"type", "name"} == set(OBSTACLE_TYPES[name].keys)
    again = Obstacle.from_dict(d)
    np.testing.assert_allclose(again.params, ob.params, atol=1e-12)
    # and through a whole scene written and read back (the former _obstacle_to_dict switch)
    scene = {"string": {"length": 1.0, "bend_stiffness": 0.02, "weight_per_length": 0.5},
             "grips": [{"name": "g", "s": 0.0, "mode": "clamp", "position": [5, 5, 5]}],
             "obstacles": [d]}
    back = scene_from_dict(scene_to_dict(scene_from_dict(scene))).problem.obstacles[0]
    np.testing.assert_allclose(back.params, ob.params, atol=1e-12)


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_parse_errors_name_the_key(name):
    kind = OBSTACLE_TYPES[name]
    spec = SAMPLES[name]["spec"]
    for key in kind.keys:
        bad = dict(spec, **{key: [float("nan")] * 5})
        with pytest.raises(ValueError, match=rf"obstacles\[3\]\.{key}"):
            kind.parse(bad, "obstacles[3]")
        with pytest.raises(SceneError, match=rf"obstacles\[0\]\.{key}"):
            scene_from_dict({"string": {"length": 1.0, "bend_stiffness": 0.02},
                             "grips": [{"name": "g", "s": 0.0, "mode": "clamp",
                                        "position": [0, 0, 0]}],
                             "obstacles": [dict(spec, **{key: "x"})]})


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_h_against_hand_computed_distances(name):
    sample = SAMPLES[name]
    ob = Obstacle.from_dict(sample["spec"])
    kind = ob.obstacle_type
    xs = ca.SX.sym("x", 3)
    symbolic = ca.Function("h", [xs], [kind.h(xs, ca.DM(ob.params))])
    points = np.array([p for p, _ in sample["points"]], dtype=float)
    for x, want in sample["points"]:
        assert ob.h(x) == pytest.approx(want, abs=1e-12), (name, x)
        assert float(symbolic(x)) == pytest.approx(want, abs=1e-12), (name, x)
        bound = kind.distance_bound(np.asarray(x, float), ob.params)
        assert bound <= -want + 1e-12  # a lower bound of the distance (−h outside)
    np.testing.assert_allclose(ob.h_many(points), [w for _, w in sample["points"]], atol=1e-12)
    assert kind.distance_bound(np.array(sample["inside"], float), ob.params) <= 0.0


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_plane_tests(name):
    sample = SAMPLES[name]
    ob = Obstacle.from_dict(sample["spec"])
    kind, p = ob.obstacle_type, ob.params
    origin, normal = (np.array(v, float) for v in sample["clear"])
    assert kind.clear_of_plane(p, origin, normal, 0.1)
    assert kind.planarity_violation(p, origin, normal, 1e-6, 1.0) != ""
    origin, normal = (np.array(v, float) for v in sample["fits"])
    assert not kind.clear_of_plane(p, origin, normal, 0.0)
    assert kind.planarity_violation(p, origin, normal, 1e-6, 1.0) == ""
    origin, normal = (np.array(v, float) for v in sample["cuts"])
    assert not kind.clear_of_plane(p, origin, normal, 0.0)


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_primitive_describes_the_shape(name):
    ob = Obstacle.from_dict(SAMPLES[name]["spec"])
    pr = ob.primitive()
    assert isinstance(pr, Primitive) and pr.kind in PRIMITIVE_KINDS
    assert pr.centre.shape == (3,) and pr.orientation.shape == (4,) and pr.half_sizes.shape == (3,)
    assert np.linalg.norm(pr.axis) == pytest.approx(1.0)
    assert len(pr.colour) == 3 and all(0 <= c <= 255 for c in pr.colour)
    # the surface of the drawn shape is where h = 0 (a point on it, along the frame's z axis)
    if pr.kind == "plane":
        surface = pr.centre
    elif pr.kind == "capsule":
        a, b = pr.ends()
        np.testing.assert_allclose([a, b], [ob.a, ob.b], atol=1e-12)
        surface = pr.centre + pr.radius * np.cross(pr.axis, [1.0, 0.0, 0.0]) / np.linalg.norm(
            np.cross(pr.axis, [1.0, 0.0, 0.0]))
    else:  # sphere, box: the face centre along the frame's z axis
        surface = pr.centre + pr.half_sizes[2] * pr.axis
    assert ob.h(surface) == pytest.approx(0.0, abs=1e-12)


def test_only_the_half_space_is_flat():
    assert FLAT == tuple(n for n, k in OBSTACLE_TYPES.items() if k.flat) == ("halfspace",)
