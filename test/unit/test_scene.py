"""Tests for dlo_ros.scene: shipped scenes, round trips, and the error messages of malformed input."""
from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from dlo_ros.model.problem import Problem
from dlo_ros.model.profile import Profile
from dlo_ros.paths import available_scenes
from dlo_ros.scene import (
    DEFAULT_SCENE,
    Scene,
    SceneError,
    load_scene,
    scene_from_dict,
    scene_to_dict,
)

REPO = Path(__file__).resolve().parents[2]
GW = 9.80665e-3  # N per gram-weight
REQUIRED_SCENES = {
    "default_cable", "paper_fig2_transition", "paper_fig3_gravity", "paper_fig5_force",
    "paper_rect_paper", "paper_trapezoid_paper", "elastica_clamped",
}


def minimal() -> dict:
    return {
        "name": "t",
        "string": {"length": 1.0, "bend_stiffness": 0.02, "twist_stiffness": 0.01, "weight_per_length": 0.5},
        "grips": [
            {"name": "left", "s": 0.0, "mode": "clamp", "position": [0, 0, 0.4], "orientation": [0, 0, 0, 1]},
            {"name": "right", "s": 1.0, "mode": "clamp", "position": [0.6, 0, 0.4], "orientation": [0, 0, 0, 1]},
        ],
    }


def full() -> dict:
    """Every feature of the format at once."""
    h = math.sqrt(0.5)
    return {
        "name": "everything",
        "description": "all keys\nsecond line",
        "frame_id": "table",
        "string": {
            "length": 1.2,
            "bend_stiffness": {"table": [[0.0, 0.02], [0.6, 0.03], [1.2, 0.025]]},
            "twist_stiffness": 0.01,
            "stretch_stiffness": {"table": [[0.0, 500.0], [1.2, 800.0]]},
            "weight_per_length": {"table": [[0.0, 0.3], [1.2, 0.6]]},
            "radius": 0.004,
        },
        "gravity": {"direction": [0.0, 0.0, -2.0]},
        "grips": [
            {"name": "a", "s": 0.0, "mode": "clamp", "position": [0, 0, 0.5], "orientation": [0, 0, 0, 1]},
            {"name": "mid", "s": 0.6, "mode": "pin", "position": [0.3, 0.0, 0.3]},
            {"name": "b", "s": 1.2, "mode": "tangent", "position": [0.7, 0, 0.5], "orientation": [0, 0, h, h]},
        ],
        "loads": [{"s": 0.3, "force": [0.0, 0.0, -0.1]}, {"s": 0.9, "moment": [0.0, 0.02, 0.0]}, {"s": 1.0}],
        "obstacles": [
            {"type": "halfspace", "name": "table", "point": [0, 0, 0], "normal": [0, 0, 2]},
            {"type": "sphere", "name": "ball", "center": [0.3, 0.3, 0.1], "radius": 0.05},
            {"type": "capsule", "a": [0.0, -0.3, 0.1], "b": [0.5, -0.3, 0.1], "radius": 0.02},
            {"type": "box", "name": "block", "center": [0.5, 0.2, 0.05], "orientation": [0, 0, 0.3826834323650898,
             0.9238795325112867], "half_extents": [0.05, 0.1, 0.05]},
        ],
        "relative_positions": [{"s_a": 0.2, "s_b": 0.4, "offset": [0.1, 0.0, 0.0]}],
        "solver": {"basis": "fourier", "order": 10, "quadrature_nodes": 36, "obstacle_samples": 61,
                   "output_points": 21, "tolerance": 1e-9},
    }


def assert_problems_equal(a: Problem, b: Problem, tol: float = 1e-12) -> None:
    def close(x, y, what):
        assert np.allclose(np.asarray(x, float), np.asarray(y, float), rtol=tol, atol=tol), what

    def same_profile(p: Profile | None, q: Profile | None, what):
        assert (p is None) == (q is None), what
        if p is not None:
            close(p.s, q.s, what + ".s")
            close(p.values, q.values, what + ".values")

    sa, sb = a.string, b.string
    close(sa.length, sb.length, "length")
    close(sa.radius, sb.radius, "radius")
    for name in ("bend_stiffness", "twist_stiffness", "weight_per_length", "stretch_stiffness"):
        same_profile(getattr(sa, name), getattr(sb, name), name)
    close(a.gravity, b.gravity, "gravity")
    assert [(g.name, g.s, g.mode) for g in a.grips] == [(g.name, g.s, g.mode) for g in b.grips]
    for ga, gb in zip(a.grips, b.grips):
        close(ga.pose.position, gb.pose.position, f"{ga.name}.position")
        close(ga.pose.orientation, gb.pose.orientation, f"{ga.name}.orientation")
    assert len(a.loads) == len(b.loads)
    for la, lb in zip(a.loads, b.loads):
        close([la.s, *la.force, *la.moment], [lb.s, *lb.force, *lb.moment], "load")
    assert [(o.type, o.name) for o in a.obstacles] == [(o.type, o.name) for o in b.obstacles]
    for oa, ob in zip(a.obstacles, b.obstacles):
        close(oa.params, ob.params, f"obstacle {oa.type}")
    assert len(a.relative_positions) == len(b.relative_positions)
    for ra, rb in zip(a.relative_positions, b.relative_positions):
        close([ra.s_a, ra.s_b, *ra.offset], [rb.s_a, rb.s_b, *rb.offset], "relative")


# ---- shipped scenes -----------------------------------------------------------------------------------
def test_required_scenes_are_shipped():
    assert REQUIRED_SCENES <= set(available_scenes())
    assert DEFAULT_SCENE in available_scenes()


@pytest.mark.parametrize("name", available_scenes())
def test_shipped_scene_loads_and_solves(name):
    from dlo_ros.solver import make_solver

    scene = load_scene(name)
    assert isinstance(scene, Scene)
    assert scene.name == name
    assert scene.description, "every shipped scene says what it reproduces"
    assert scene.source.endswith(f"{name}.yaml")
    result = make_solver(scene.problem, scene.options, checks="sync").solve()  # as `dlo solve` does
    # every shipped scene solves (bench_fig3_floor, the heavy strip on its floor, with
    # solver.plane keep: test_plane_keep.py against the floor reference)
    assert result.status == "ok", result.message
    assert result.points.shape == (scene.options.output_points, 3)
    assert np.all(np.isfinite(result.points))
    for g in scene.problem.grips:  # the string goes through every grip
        k = int(np.argmin(np.abs(result.s - g.s)))
        if abs(result.s[k] - g.s) < 1e-12:
            assert np.allclose(result.points[k], g.pose.position, atol=1e-6)


@pytest.mark.parametrize("name", available_scenes())
def test_shipped_scene_round_trips(name):
    scene = load_scene(name)
    again = scene_from_dict(scene_to_dict(scene), source=scene.source)
    assert_problems_equal(scene.problem, again.problem)
    assert again.options == scene.options
    assert (again.name, again.frame_id, again.description) == (scene.name, scene.frame_id, scene.description)


def test_default_cable_matches_the_spec():
    scene = load_scene(DEFAULT_SCENE)
    st, pr = scene.problem.string, scene.problem
    assert (st.length, st.bend_stiffness.values, st.twist_stiffness.values, st.weight_per_length.values,
            st.radius, st.stretch_stiffness) == (1.0, (0.02,), (0.015,), (0.5,), 0.005, None)
    left, right = sorted(pr.grips, key=lambda g: g.s)
    assert (left.s, right.s, left.mode, right.mode) == (0.0, 1.0, "clamp", "clamp")
    assert np.isclose(np.linalg.norm(right.pose.position - left.pose.position), 0.6)
    assert left.pose.position[2] == right.pose.position[2] == 0.4
    for g in (left, right):  # pose x-axis (the tangent) along +x
        assert np.allclose(g.pose.orientation, [0, 0, 0, 1])
    (table,) = pr.obstacles
    assert table.type == "halfspace" and np.allclose(table.params, [0, 0, 0, 0, 0, 1])
    assert scene.frame_id == "world"


def test_paper_scenes_parameters():
    fig2 = load_scene("paper_fig2_transition").problem
    assert fig2.string.bend_stiffness.values[0] / fig2.string.twist_stiffness.values[0] == pytest.approx(100)
    assert [g.mode for g in sorted(fig2.grips, key=lambda g: g.s)] == ["clamp", "tangent"]
    assert np.linalg.norm(fig2.grips[1].pose.position - fig2.grips[0].pose.position) == pytest.approx(0.6)
    assert fig2.string.weight_per_length.is_zero

    fig3 = load_scene("paper_fig3_gravity").problem
    st = fig3.string
    assert st.weight_per_length.values[0] * st.length**3 / st.bend_stiffness.values[0] == pytest.approx(3000)
    assert np.linalg.norm(fig3.grips[1].pose.position - fig3.grips[0].pose.position) == pytest.approx(0.7)
    (floor,) = fig3.obstacles
    assert floor.h(np.array([0.35, 0.0, -0.5])) < 0  # L/2 below the ends is still outside the floor

    fig5 = load_scene("paper_fig5_force").problem
    assert [g.mode for g in fig5.grips] == ["pin", "pin"]
    (load,) = fig5.loads
    assert load.s == pytest.approx(0.5)
    assert np.linalg.norm(load.force) == pytest.approx(0.1)  # 0.1 Rf / L^2
    assert math.atan2(load.force[2], load.force[0]) == pytest.approx(3 * math.pi / 4)
    assert load.force[1] == 0
    (floor,) = fig5.obstacles
    assert floor.h(fig5.grips[0].pose.position) == pytest.approx(0.0)  # the floor at the ends' height

    elastica = load_scene("elastica_clamped").problem
    assert np.linalg.norm(elastica.grips[1].pose.position - elastica.grips[0].pose.position) == pytest.approx(0.5)
    assert elastica.string.twist_stiffness.values == (1.0,)


def test_paper_sheets_are_converted_to_si():
    rect = load_scene("paper_rect_paper").problem.string
    assert rect.length == pytest.approx(0.2)
    assert rect.bend_stiffness(np.array([0.1]))[0] == pytest.approx(1e4 * GW * 1e-6)   # gw mm^2 -> N m^2
    assert rect.weight_per_length(np.array([0.1]))[0] == pytest.approx(2e-3 * GW / 1e-3)  # gw/mm -> N/m

    trap = load_scene("paper_trapezoid_paper")
    st = trap.problem.string
    s = np.linspace(0.0, 0.2, 9)
    b = 50.0 + (s * 1e3) / 4.0  # width in mm, s in mm
    assert np.allclose(st.bend_stiffness(s), 330.0 * b * GW * 1e-6, rtol=1e-12)
    assert np.allclose(st.weight_per_length(s), 7.0 * b * 1e-5 * GW / 1e-3, rtol=1e-12)
    assert len(st.bend_stiffness.s) == len(st.weight_per_length.s) == 2
    assert np.linalg.norm(trap.problem.grips[1].pose.position - trap.problem.grips[0].pose.position) == pytest.approx(0.16)


def test_elastica_scene_energy_matches_closed_form():
    from dlo_ros.model.elastica import clamped_clamped_elastica
    from dlo_ros.solver import ShapeSolver

    scene = load_scene("elastica_clamped")
    result = ShapeSolver(scene.problem, scene.options).solve()
    reference = clamped_clamped_elastica(1.0, 1.0, 0.5)
    assert result.energy["total"] == pytest.approx(reference.energy, rel=5e-3)


# ---- round trip and format details ---------------------------------------------------------------------
def test_full_scene_round_trip_and_values():
    scene = scene_from_dict(full())
    pr = scene.problem
    assert np.allclose(pr.gravity, [0, 0, -1])  # normalised
    assert pr.string.stretch_stiffness is not None
    assert pr.grips[2].pose.orientation == pytest.approx([0, 0, math.sqrt(0.5), math.sqrt(0.5)])
    assert np.allclose(pr.obstacles[0].params[3:], [0, 0, 1])
    assert scene.options.basis == "fourier" and scene.options.order == 10
    assert scene.description == "all keys\nsecond line"
    assert scene.frame_id == "table"
    d = scene_to_dict(scene)
    again = scene_from_dict(d)
    assert_problems_equal(pr, again.problem)
    assert again.options == scene.options
    assert set(d) == {"name", "description", "frame_id", "string", "gravity", "grips", "loads", "obstacles",
                      "relative_positions", "solver"}
    # through YAML text as well
    text = yaml.safe_dump(d, sort_keys=False)
    assert_problems_equal(pr, scene_from_dict(yaml.safe_load(text)).problem)


def test_round_trip_through_a_file(tmp_path):
    scene = scene_from_dict(full())
    path = tmp_path / "everything.yaml"
    path.write_text(yaml.safe_dump(scene_to_dict(scene), sort_keys=False))
    loaded = load_scene(path)
    assert_problems_equal(scene.problem, loaded.problem)
    assert loaded.source == str(path)


def test_defaults():
    d = {"string": {"length": 2.0, "bend_stiffness": 1.0}, "grips": [{"s": 0.0, "position": [0, 0, 0]}]}
    scene = scene_from_dict(d)
    st = scene.problem.string
    assert (scene.name, scene.frame_id, scene.description) == ("scene", "world", "")
    assert st.twist_stiffness.is_zero and st.weight_per_length.is_zero
    assert st.stretch_stiffness is None and st.radius == 0.0
    (g,) = scene.problem.grips
    assert (g.name, g.mode) == ("grip0", "clamp")
    assert np.allclose(g.pose.orientation, [0, 0, 0, 1])
    assert np.allclose(scene.problem.gravity, [0, 0, -1])
    assert scene.problem.loads == () and scene.problem.obstacles == () and scene.problem.relative_positions == ()


def test_name_defaults_to_file_stem_and_yaml12_floats(tmp_path):
    path = tmp_path / "my_rope.yaml"
    path.write_text("string: {length: 1, bend_stiffness: 2e-2, radius: 5e-3}\ngrips: [{s: 0, position: [0, 0, 1e0]}]\n")
    scene = load_scene(path)
    assert scene.name == "my_rope"
    assert scene.problem.string.bend_stiffness.values == (0.02,)
    assert scene.problem.string.radius == 0.005


def test_load_by_name_with_suffix_and_unknown_name():
    assert load_scene("default_cable.yaml").name == "default_cable"
    with pytest.raises(FileNotFoundError, match="available"):
        load_scene("no_such_scene")


def test_scene_format_doc_example_loads():
    doc = (REPO / "msg_docs" / "scene_format.md").read_text()
    blocks = re.findall(r"```yaml\n(.*?)```", doc, flags=re.S)
    assert blocks, "scene_format.md has a yaml example"
    for block in blocks:
        scene_from_dict(yaml.safe_load(block))


def test_scene_format_doc_lists_every_solver_option():
    from dataclasses import fields

    from dlo_ros.solver import SolverOptions

    doc = (REPO / "msg_docs" / "scene_format.md").read_text()
    section = doc.split("## `solver`", 1)[1].split("\n## ", 1)[0]
    for f in fields(SolverOptions):
        assert f"| `{f.name}` |" in section, f"msg_docs/scene_format.md: solver table lacks {f.name}"


# ---- malformed input -------------------------------------------------------------------------------------
def _set(d: dict, path: str, value) -> dict:
    """Return a copy of d with the value at a dotted/indexed path replaced (value DELETE removes it)."""
    d = copy.deepcopy(d)
    parts = re.findall(r"[^.\[\]]+|\[\d+\]", path)
    node = d
    for p in parts[:-1]:
        node = node[int(p[1:-1])] if p.startswith("[") else node[p]
    last = parts[-1]
    key = int(last[1:-1]) if last.startswith("[") else last
    if value is DELETE:
        del node[key]
    else:
        node[key] = value
    return d


DELETE = object()

MALFORMED = [
    # (description, path to change, new value, expected start of the message)
    ("unknown top-level key", "colour", "red", "colour:"),
    ("unknown string key", "string.lenght", 1.0, "string.lenght:"),
    ("unknown grip key", "grips[1].positon", [0, 0, 0], "grips[1].positon:"),
    ("missing string", "string", DELETE, "string:"),
    ("missing length", "string.length", DELETE, "string.length:"),
    ("length is a string", "string.length", "one", "string.length:"),
    ("length is a bool", "string.length", True, "string.length:"),
    ("zero length", "string.length", 0.0, "string.length:"),
    ("negative bend stiffness", "string.bend_stiffness", -0.02, "string.bend_stiffness:"),
    ("negative twist stiffness", "string.twist_stiffness", -1.0, "string.twist_stiffness:"),
    ("negative weight in a table", "string.weight_per_length", {"table": [[0, 0.1], [1, -0.1]]},
     "string.weight_per_length.table[1][1]:"),
    ("table s not increasing", "string.bend_stiffness", {"table": [[0.5, 0.1], [0.2, 0.1]]},
     "string.bend_stiffness.table[1][0]:"),
    ("table s beyond L", "string.bend_stiffness", {"table": [[0, 0.1], [2, 0.1]]},
     "string.bend_stiffness.table[1][0]:"),
    ("table row too short", "string.bend_stiffness", {"table": [[0, 0.1], [1]]}, "string.bend_stiffness.table[1]:"),
    ("zero stretch stiffness", "string.stretch_stiffness", 0.0, "string.stretch_stiffness:"),
    ("negative radius", "string.radius", -0.001, "string.radius:"),
    ("NaN stiffness", "string.bend_stiffness", float("nan"), "string.bend_stiffness:"),
    ("missing grips", "grips", DELETE, "grips:"),
    ("empty grips", "grips", [], "grips:"),
    ("grips not a list", "grips", {"s": 0}, "grips:"),
    ("grip not a mapping", "grips[0]", [0, 0, 0], "grips[0]:"),
    ("NaN position", "grips[1].position", [float("nan"), 0.0, 0.4], "grips[1].position[0]:"),
    ("infinite position", "grips[0].position", [0.0, float("inf"), 0.4], "grips[0].position[1]:"),
    ("position too short", "grips[0].position", [0.0, 0.4], "grips[0].position:"),
    ("unnormalised quaternion", "grips[1].orientation", [0, 0, 0, 1.3], "grips[1].orientation: quaternion norm is 1.3"),
    ("zero quaternion", "grips[0].orientation", [0, 0, 0, 0], "grips[0].orientation:"),
    ("quaternion with 3 numbers", "grips[0].orientation", [0, 0, 1], "grips[0].orientation:"),
    ("mode typo", "grips[0].mode", "clmap", "grips[0].mode:"),
    ("grip s above L", "grips[1].s", 1.5, "grips[1].s:"),
    ("grip s negative", "grips[0].s", -0.1, "grips[0].s:"),
    ("grip s missing", "grips[0].s", DELETE, "grips[0].s:"),
    ("two grips at one s", "grips[1].s", 0.0, "grips[1].s:"),
    ("duplicate grip names", "grips[1].name", "left", "grips[1].name:"),
    ("empty grip name", "grips[0].name", "", "grips[0].name:"),
    ("zero gravity", "gravity", {"direction": [0, 0, 0]}, "gravity.direction:"),
    ("unknown gravity key", "gravity", {"dir": [0, 0, -1]}, "gravity.dir:"),
    ("load s out of range", "loads", [{"s": 1.2, "force": [0, 0, -1]}], "loads[0].s:"),
    ("unknown load key", "loads", [{"s": 0.5, "torque": [0, 0, 1]}], "loads[0].torque:"),
    ("NaN load force", "loads", [{"s": 0.5, "force": [0, float("nan"), 0]}], "loads[0].force[1]:"),
    ("obstacle without type", "obstacles", [{"center": [0, 0, 0], "radius": 1}], "obstacles[0].type:"),
    ("unknown obstacle type", "obstacles", [{"type": "cone"}], "obstacles[0].type:"),
    ("unknown obstacle key", "obstacles", [{"type": "sphere", "center": [0, 0, 0], "radius": 0.1, "colour": 1}],
     "obstacles[0].colour:"),
    ("sphere without radius", "obstacles", [{"type": "sphere", "center": [0, 0, 0]}], "obstacles[0].radius:"),
    ("negative sphere radius", "obstacles", [{"type": "sphere", "center": [0, 0, 0], "radius": -1}],
     "obstacles[0].radius:"),
    ("zero halfspace normal", "obstacles", [{"type": "halfspace", "normal": [0, 0, 0]}], "obstacles[0].normal:"),
    ("degenerate capsule", "obstacles", [{"type": "capsule", "a": [0, 0, 0], "b": [0, 0, 0], "radius": 0.1}],
     "obstacles[0]:"),
    ("box with a bad quaternion", "obstacles",
     [{"type": "box", "center": [0, 0, 0], "orientation": [1, 1, 0, 0], "half_extents": [1, 1, 1]}],
     "obstacles[0].orientation:"),
    ("box with a zero extent", "obstacles", [{"type": "box", "center": [0, 0, 0], "half_extents": [1, 0, 1]}],
     "obstacles[0].half_extents:"),
    ("relative position without offset", "relative_positions", [{"s_a": 0.1, "s_b": 0.2}],
     "relative_positions[0].offset:"),
    ("relative position s_b out of range", "relative_positions", [{"s_a": 0.1, "s_b": 3, "offset": [0, 0, 0]}],
     "relative_positions[0].s_b:"),
    ("unknown solver option", "solver", {"ordr": 12}, "solver.ordr:"),
    ("solver order out of range", "solver", {"order": 1}, "solver.order:"),
    ("solver order not an integer", "solver", {"order": 12.5}, "solver.order:"),
    ("solver order a string", "solver", {"order": "twelve"}, "solver.order:"),
    ("solver basis typo", "solver", {"basis": "chebychev"}, "solver.basis:"),
    ("solver basis a number", "solver", {"basis": 5}, "solver.basis:"),
    ("solver tolerance NaN", "solver", {"tolerance": float("nan")}, "solver.tolerance:"),
    ("Fourier basis on the 3D director model", "solver", {"model": "full", "basis": "fourier"}, "solver.basis:"),
    ("paper frame on the 3D director model", "solver", {"model": "full", "frame": "paper"}, "solver.frame:"),
    ("quadrature too coarse for the order", "solver", {"order": 50}, "solver.quadrature_nodes:"),
    ("solver not a mapping", "solver", [1, 2], "solver:"),
    ("name not a string", "name", 3, "name:"),
    ("frame_id empty", "frame_id", "", "frame_id:"),
]


@pytest.mark.parametrize("what,path,value,prefix", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_scene_names_the_key(what, path, value, prefix):
    with pytest.raises(SceneError) as info:
        scene_from_dict(_set(minimal(), path, value))
    message = str(info.value)
    assert message.startswith(prefix), f"{what}: {message!r} should start with {prefix!r}"
    assert info.value.key and prefix.startswith(info.value.key), (info.value.key, prefix)


def test_scene_error_is_a_value_error():
    assert issubclass(SceneError, ValueError)
    with pytest.raises(ValueError):
        scene_from_dict({"string": {}})


def test_not_a_mapping():
    with pytest.raises(SceneError):
        scene_from_dict([1, 2, 3])  # type: ignore[arg-type]


def test_minimal_is_valid():
    scene_from_dict(minimal())


# ---- file errors -----------------------------------------------------------------------------------------
GOOD_FILE = """\
name: good
string:
  length: 1.0
  bend_stiffness: 0.02
grips:
  - {name: left, s: 0.0, position: [0, 0, 0]}
  - {name: right, s: 1.0, position: [0.5, 0, 0], orientation: [0, 0, 0, 1.3]}
"""


def test_semantic_error_in_a_file_names_key_file_and_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(GOOD_FILE)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith("grips[1].orientation: quaternion norm is 1.3")
    assert f"{path}:7" in message
    assert info.value.line == 7 and info.value.source == str(path)


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nstring: {length: 1, bend_stiffness: 1\ngrips: []\n")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}:3:")
    assert "YAML syntax error" in message and "line 2" in message
    assert info.value.line == 3


def test_bad_indentation_is_a_syntax_error(tmp_path):
    path = tmp_path / "indent.yaml"
    path.write_text("string:\n  length: 1\n   bend_stiffness: 1\n")
    with pytest.raises(SceneError, match=re.escape(str(path)) + r":\d+:\d+: YAML syntax error"):
        load_scene(path)


def test_duplicate_yaml_key_is_an_error(tmp_path):
    path = tmp_path / "dup.yaml"
    path.write_text("string: {length: 1, bend_stiffness: 1}\ngrips: [{s: 0, position: [0, 0, 0]}]\nstring: {length: 2}\n")
    with pytest.raises(SceneError, match=r"dup.yaml:3:1: YAML syntax error.*duplicate key 'string' \(first at line 1\)"):
        load_scene(path)


@pytest.mark.parametrize("text,needle", [("", "empty"), ("- 1\n- 2\n", "mapping"), ("just a string\n", "mapping")])
def test_file_that_is_not_a_scene(tmp_path, text, needle):
    path = tmp_path / "odd.yaml"
    path.write_text(text)
    with pytest.raises(SceneError, match=needle) as info:
        load_scene(path)
    assert str(info.value).startswith(str(path))


def test_unknown_key_in_file_reports_its_line(tmp_path):
    path = tmp_path / "unknown.yaml"
    path.write_text(GOOD_FILE.replace("  bend_stiffness: 0.02\n", "  bend_stiffness: 0.02\n  stiffnes: 3\n"))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(info.value).startswith("string.stiffnes: unknown key")
    assert info.value.line == 5


def test_euler_options_are_accepted_with_the_euler_model_and_where_a_planar_model_may_use_them():
    """basis and frame belong to the Euler-angle (and planar) models: accepted with rotation 'euler' and with
    model 'auto' (which may stream its planar model); refused only where nothing could use them."""
    scene_from_dict(_set(minimal(), "solver", {"model": "full", "rotation": "euler", "basis": "fourier", "frame": "paper"}))
    scene_from_dict(_set(minimal(), "solver", {"model": "auto", "basis": "fourier"}))
