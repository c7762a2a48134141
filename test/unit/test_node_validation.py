"""Unit tests (no ROS graph) of the node's target checks, parameter checks and diagnostics content."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties
from dlo_ros.node import params as P
from dlo_ros.node.health import Health
from dlo_ros.node.validation import (
    KINDS,
    QUATERNION_TOLERANCE,
    TargetError,
    check_count,
    check_frame,
    check_pose,
    normalise_frame,
)
from dlo_ros.solver.results.result import ShapeResult

Q = (0.0, 0.0, 0.0, 1.0)


def make_problem(twist: float = 0.015, stretch: float | None = None, bend=None) -> Problem:
    st = StringProperties(
        length=1.0,
        bend_stiffness=bend or Profile.constant(0.02),
        twist_stiffness=Profile.constant(twist),
        weight_per_length=Profile.constant(0.5),
        stretch_stiffness=None if stretch is None else Profile.constant(stretch),
        radius=0.005,
    )
    grips = (
        Grip("left", 0.0, "clamp", GripPose(np.array([0.0, 0.0, 0.4]), np.array(Q))),
        Grip("right", 1.0, "clamp", GripPose(np.array([0.6, 0.0, 0.4]), np.array(Q))),
    )
    return Problem(st, grips)


# ---- poses ---------------------------------------------------------------------------------------------
def test_good_pose_is_returned_normalised():
    pose = check_pose([1, 2, 3], [0, 0, 0, 1], "t")
    assert isinstance(pose, GripPose)
    np.testing.assert_array_equal(pose.position, [1, 2, 3])
    np.testing.assert_array_equal(pose.orientation, [0, 0, 0, 1])


def test_quaternion_within_tolerance_is_normalised():
    q = np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)]) * (1 + 0.8 * QUATERNION_TOLERANCE)
    pose = check_pose([0, 0, 0], q, "t")
    assert np.linalg.norm(pose.orientation) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(pose.orientation, q / np.linalg.norm(q))


@pytest.mark.parametrize(
    "position, orientation, kind, words",
    [
        ([np.nan, 0, 0], Q, "non_finite", "position"),
        ([0, np.inf, 0], Q, "non_finite", "position"),
        ([0, 0, 0], [0, np.nan, 0, 1], "non_finite", "orientation"),
        ([0, 0, 0], [0, 0, 0, -np.inf], "non_finite", "orientation"),
        ([0, 0, 0], [0, 0, 0, 0], "quaternion", "zero quaternion"),
        ([0, 0, 0], [0, 0, 0, 1 + 2 * QUATERNION_TOLERANCE], "quaternion", "norm"),
        ([0, 0, 0], [0, 0, 0.5, 0.5], "quaternion", "norm"),
        ([0, 0], Q, "invalid", "position: needs 3"),
        ([0, 0, 0], [0, 0, 1], "invalid", "orientation: needs 4"),
    ],
)
def test_bad_poses_are_rejected_with_their_kind(position, orientation, kind, words):
    with pytest.raises(TargetError) as err:
        check_pose(position, orientation, "grips/left/target")
    assert err.value.kind == kind
    assert kind in KINDS
    assert "grips/left/target" in str(err.value) and words in str(err.value)


def test_frames():
    check_frame("world", "world", "t")
    check_frame("/world", "world", "t")
    assert normalise_frame("/map") == "map"
    for bad in ("", "map", "world2"):
        with pytest.raises(TargetError) as err:
            check_frame(bad, "world", "grips/targets")
        assert err.value.kind == "frame"
        assert "grips/targets" in str(err.value) and "world" in str(err.value)


def test_pose_array_count():
    check_count(2, ["left", "right"], "grips/targets")
    for n in (0, 1, 3):
        with pytest.raises(TargetError) as err:
            check_count(n, ["left", "right"], "grips/targets")
        assert err.value.kind == "count"
        assert f"{n} poses for 2 grips" in str(err.value) and "['left', 'right']" in str(err.value)


def test_reach():
    """The one reach check (``Problem.farthest_apart``, which ``ShapeSolver.unreachable_reason`` and so
    the node's 'unreachable' rejection use)."""
    base = make_problem()
    mid = Grip("mid", 0.5, "pin", GripPose(np.array([0.3, 0.3, 0.4]), np.array(Q)))
    ok = replace(base, grips=base.grips + (mid,))
    assert ok.farthest_apart() is None
    far = replace(ok, grips=base.grips + (replace(mid, pose=GripPose(np.array([0.3, 0.45, 0.4]), np.array(Q))),))
    a, b, dist, span = far.farthest_apart()  # 0.541 m from either end, 0.5 m of string
    assert (a.name, b.name) == ("left", "mid") and dist == pytest.approx(0.5408, abs=1e-4) and span == 0.5
    assert far.farthest_apart(reach=1.25) is None


# ---- parameters ------------------------------------------------------------------------------------------
def test_parameter_table_is_consistent():
    names = [p.name for p in P.STATIC + P.LIVE]
    assert len(names) == len(set(names))
    assert set(P.STRING_FIELDS) <= {p.name for p in P.LIVE}
    assert all(p.read_only for p in P.STATIC) and not any(p.read_only for p in P.LIVE)
    assert P.SPECS["scene"].default == "default_cable"


def test_compile_mode():
    assert P.compile_mode("blocking") == "blocking" and P.compile_mode("off") == "off"
    assert P.compile_mode(False) == "off" and P.compile_mode(True) == "background"
    for bad in ("fast", 1, None):
        with pytest.raises(ValueError, match="compile: must be one of"):
            P.compile_mode(bad)


def test_scene_values():
    v = P.scene_values(make_problem(stretch=None), 51)
    assert v["grip_names"] == ["left", "right"]
    assert v["string.bend_stiffness"] == 0.02 and v["string.stretch_stiffness"] == 0.0
    assert v["output_points"] == 51


def test_apply_string_changes_only_what_differs():
    st = make_problem().string
    same = P.apply_string(st, {"string.bend_stiffness": 0.02, "string.radius": 0.005})
    assert same is st
    new = P.apply_string(st, {"string.bend_stiffness": 0.05, "string.weight_per_length": 0.0, "string.radius": 0.01})
    assert new.bend_stiffness.values == (0.05,) and new.weight_per_length.values == (0.0,) and new.radius == 0.01


def test_table_profile_is_scaled_by_its_maximum():
    table = Profile.table([[0.0, 0.01], [1.0, 0.04]])
    st = make_problem(bend=table).string
    assert P.scene_values(replace(make_problem(), string=st), 51)["string.bend_stiffness"] == 0.04
    new = P.apply_string(st, {"string.bend_stiffness": 0.08})
    assert new.bend_stiffness.s == (0.0, 1.0)
    np.testing.assert_allclose(new.bend_stiffness.values, (0.02, 0.08))


@pytest.mark.parametrize(
    "name, value, words",
    [
        ("string.bend_stiffness", 0.0, "must be > 0"),
        ("string.bend_stiffness", -1.0, "must be >= 0"),
        ("string.weight_per_length", -0.1, "must be >= 0"),
        ("string.twist_stiffness", 0.0, "cannot switch"),
        ("string.stretch_stiffness", 100.0, "cannot switch"),
        ("string.radius", float("nan"), "finite"),
        ("output_points", 1, ">= 2"),
        ("output_points", 20000, "<= 10000"),
        ("scene", "other", "read-only"),
        ("compile", "off", "read-only"),
        ("frame_id", "map", "read-only"),
        ("solver.model", "full", "read-only"),
    ],
)
def test_refused_parameters(name, value, words):
    reason = P.check_live(name, value, make_problem())
    assert words in reason and (name in reason or "must" in reason)


def test_accepted_parameters():
    pr = make_problem()
    for name, value in [("string.bend_stiffness", 0.1), ("string.twist_stiffness", 0.5), ("string.radius", 0.0),
                        ("string.weight_per_length", 0.0), ("output_points", 11), ("markers.force_scale", 0.5),
                        ("use_sim_time", True)]:
        assert P.check_live(name, value, pr) == "", name
    twistless = make_problem(twist=0.0)
    assert P.check_live("string.twist_stiffness", 0.0, twistless) == ""
    assert "cannot switch" in P.check_live("string.twist_stiffness", 0.1, twistless)
    extensible = make_problem(stretch=100.0)
    assert P.check_live("string.stretch_stiffness", 200.0, extensible) == ""
    assert "cannot switch" in P.check_live("string.stretch_stiffness", 0.0, extensible)


# ---- diagnostics content -----------------------------------------------------------------------------------
class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def ok_result(stable=True) -> ShapeResult:
    return ShapeResult(status="ok", message="converged", stable=stable, min_eigenvalue=1.0 if stable else -0.5,
                       iterations=3, solve_time_ms=4.0, warm_started=True, energy={"total": 0.4})


def test_health_levels_and_counters():
    clock = FakeClock()
    h = Health(scene="s", frame_id="world", grips=("left", "right"), throttle_s=1.0, clock=clock)
    assert h.level_and_message()[0] == "warn" and "no shape yet" in h.level_and_message()[1]
    h.update(ok_result(), "initial")
    assert h.level_and_message()[0] == "ok"
    assert h.error("quaternion", "grips/left/target: quaternion norm is 2", rejected=True) is True
    level, msg = h.level_and_message()
    assert level == "warn" and "input rejected" in msg and "last good shape" in msg
    assert h.error("quaternion", "again", rejected=True) is False  # throttled (same kind)
    assert h.error("frame", "frame", rejected=True) is True       # another kind is not
    clock.t += 1.5
    assert h.error("quaternion", "later", rejected=True) is True
    assert h.error("unreachable", "too far", rejected=False) is True
    assert "solve failed (unreachable)" in h.level_and_message()[1]
    v = h.values()
    assert v["errors.quaternion"] == 3 and v["errors.frame"] == 1 and v["errors.unreachable"] == 1
    assert v["rejected inputs"] == 4 and v["failures"] == 1
    assert v["last error kind"] == "unreachable" and v["last error"] == "too far"
    assert set(f"errors.{k}" for k in KINDS) <= set(v)
    h.update(ok_result(stable=False), "targets")
    assert h.level_and_message()[0] == "warn" and "unstable" in h.level_and_message()[1]
    h.update(ok_result(), "targets")
    assert h.level_and_message()[0] == "ok"
    v = h.values()
    assert v["updates"] == 3 and v["stable updates"] == 2 and v["unstable updates"] == 1
    assert v["update rate hz"] == pytest.approx(3 / 2.0)
    assert h.should_warn("unstable") is True and h.should_warn("unstable") is False
    clock.t += 1.0
    assert h.should_warn("unstable") is True
    h.set_state("failed: boom")
    assert h.level_and_message()[0] == "error"


def test_grip_miss():
    from dlo_ros.node.validation import grip_miss

    s = np.linspace(0.0, 1.0, 11)
    pts = np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1)
    grips = [("left", 0.0, [0.0, 0.0, 0.0]), ("right", 1.0, [1.0, 0.0, 0.0]), ("mid", 0.55, [9.0, 9.0, 9.0])]
    assert grip_miss(pts, s, grips, 1e-6) == ""  # 'mid' sits between samples: not checked
    bad = [("left", 0.0, [0.0, 0.0, 0.0]), ("right", 1.0, [1.0, 0.05, 0.0])]
    assert "misses grip 'right' by 0.05 m" in grip_miss(pts, s, bad, 1e-6)
    pts[3, 0] = np.nan
    assert "misses grip 'a'" in grip_miss(pts, s, [("a", 0.3, [0.3, 0.0, 0.0])], 1e-6)
    assert grip_miss(np.zeros((0, 3)), np.zeros(0), grips, 1e-6) == ""
