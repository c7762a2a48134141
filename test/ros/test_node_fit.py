"""Identification in the node (fit.enabled): ~/observed, ~/fit, the diagnostics '<node>: fit', applying an
estimate through the node's parameters, and the recording (msg_docs/node.md "Fitting").

The observed shape is config/observations/default_cable_hanging.npy: an independent Kirchhoff shooting
reference (test/reference/kirchhoff.py via bench/suite/example_observation.py) of a cable with Rf = 0.03 N·m²,
D = 0.7 N/m (the scene says 0.02 and 0.5) held by default_cable's two clamps at the scene's poses (which
the node holds until targets arrive), 1.5 mm noise, 30 % occluded, shuffled.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.node.cloud import cloud_points
from dlo_ros.node.fitting import Application, plan_application
from dlo_ros.node.validation import TargetError
from support.node import TEST_MODEL, TEST_SCENE, clean_node

ROOT = Path(__file__).resolve().parents[2]
POINTS = ROOT / "config" / "observations" / "default_cable_hanging.npy"
RF, D, SIGMA = 0.03, 0.7, 0.0015  # the reference cable and its noise (bench/suite/example_observation.py)
Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)


# ---- PointCloud2 → points (no ROS graph) -----------------------------------------------------------------
@dataclass
class _Field:
    name: str
    offset: int
    datatype: int
    count: int = 1


@dataclass
class _Header:
    frame_id: str = "world"


@dataclass
class _Cloud:
    """Duck-typed sensor_msgs/PointCloud2."""

    width: int
    height: int
    fields: list
    point_step: int
    row_step: int
    data: bytes
    is_bigendian: bool = False
    header: _Header = field(default_factory=_Header)


def organised(points: np.ndarray, width: int, *, big: bool = False) -> _Cloud:
    """An organised cloud of float64 z, y, x (reordered), an int field and row padding."""
    height = len(points) // width
    step, pad = 32, 8
    order = ">" if big else "<"
    rows = []
    for r in range(height):
        row = bytearray()
        for p in points[r * width:(r + 1) * width]:
            row += np.array([p[2], p[1], p[0]], dtype=order + "f8").tobytes() + np.array([7, 0], order + "i4").tobytes()
        rows.append(bytes(row) + bytes(pad))
    fields = [_Field("z", 0, 8), _Field("y", 8, 8), _Field("x", 16, 8), _Field("ring", 24, 5)]
    return _Cloud(width, height, fields, step, width * step + pad, b"".join(rows), big)


def test_cloud_points_reads_any_layout_and_names_bad_fields():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(12, 3))
    for big in (False, True):
        np.testing.assert_array_equal(cloud_points(organised(pts, 4, big=big), "world", 100), pts)
    cases = {
        "header.frame_id is 'camera'": lambda c: setattr(c.header, "frame_id", "camera"),
        "no field 'x'": lambda c: c.fields.pop(2),
        "fields['y'].datatype is INT32": lambda c: setattr(c.fields[1], "datatype", 5),
        "fields['z'].count is 3": lambda c: setattr(c.fields[0], "count", 3),
        "outside point_step": lambda c: setattr(c.fields[2], "offset", 28),
        "less than height": lambda c: setattr(c, "data", c.data[:-40]),
        "over fit.max_points = 10": lambda c: None,
    }
    for expected, spoil in cases.items():
        cloud = organised(pts, 4)
        spoil(cloud)
        with pytest.raises(TargetError, match=expected.replace("[", r"\[").replace("]", r"\]")):
            cloud_points(cloud, "world", 10 if "max_points" in expected else 100)
    bad = pts.copy()
    bad[6, 1] = np.nan
    with pytest.raises(TargetError, match=r"point 6 \(row 1, column 2\): field 'y' is nan") as info:
        cloud_points(organised(bad, 4), "world", 100)
    assert info.value.kind == "non_finite"
    with pytest.raises(TargetError, match="0 points"):
        cloud_points(_Cloud(0, 1, [], 12, 0, b""), "world", 100)


def test_fit_parameters_are_in_the_table_the_docs_and_the_shipped_file():
    from dlo_ros.node import params as P

    docs = (ROOT / "msg_docs" / "node.md").read_text()
    shipped = P.read_params_file(str(ROOT / "config" / "dlo_node.yaml"))  # checked against the table
    for spec in P.FIT:
        assert P.SPECS[spec.name] is spec and f"| `{spec.name}` |" in docs, spec.name
        assert shipped[spec.name][0] == spec.default, spec.name
        assert P.check_value(spec.name, spec.default) == ""
    assert [s.name for s in P.FIT if s.read_only] == ["fit.enabled", "fit.period_s", "fit.max_points"]
    problem = None  # check_live never needs the problem for fit.*
    assert P.check_live("fit.parameters", ["D", "Rf"], problem) == ""
    assert "names a parameter twice" in P.check_live("fit.parameters", ["D", "D"], problem)
    assert "at least one" in P.check_live("fit.parameters", [], problem)
    assert "must be >= 1e-06" in P.check_live("fit.point_sigma", 0.0, problem)
    assert "read-only" in P.check_live("fit.period_s", 1.0, problem)


# ---- when an estimate is applied --------------------------------------------------------------------------
def _fit_result(status="ok", **kw):
    from dlo_ros.identify.fit import Estimate, FitResult
    from dlo_ros.model import Profile
    from dlo_ros.scene import load_scene

    string = load_scene("default_cable").problem.string
    from dataclasses import replace

    string = replace(string, weight_per_length=Profile.constant(0.48))
    ratio = {"D/Rf": Estimate("D/Rf", 24.0, 1.0, "1/m³")}
    return FitResult(status, "converged", ratios=kw.get("ratios", ratio), names=("Rf", "D"), string=string,
                     not_identifiable={"Rf": "ratios only", "D": "ratios only"})


CURRENT = {"string.bend_stiffness": 0.02, "string.twist_stiffness": 0.015, "string.weight_per_length": 0.5,
           "string.stretch_stiffness": 0.0, "string.radius": 0.005}


def test_plan_application():
    a = plan_application(_fit_result(), CURRENT, 0.05)
    assert a.values == {"string.weight_per_length": 0.48} and "D/Rf = 24 ± 1" in a.reason  # rel σ 1/24 < 0.05
    refused = plan_application(_fit_result(), CURRENT, 0.04)
    assert refused == Application({}, refused.reason) and "relative σ of D/Rf is 0.0417 > " in refused.reason
    assert not plan_application(_fit_result(), CURRENT, 0.0).applied
    assert "not_converged" in plan_application(_fit_result("not_converged"), CURRENT, 1.0).reason
    undetermined = plan_application(_fit_result(ratios={}), CURRENT, 1.0)
    assert not undetermined.applied and "do not determine it: ratios only" in undetermined.reason
    same = plan_application(_fit_result(), {**CURRENT, "string.weight_per_length": 0.48}, 1.0)
    assert not same.applied and "equals the current values" in same.reason


def test_worker_fits_reuse_their_solvers_with_the_same_result():
    """run_fit keeps its solvers (SolverCache): a later fit, also of a shape in another plane (a kept planar
    solver is not reused there), gives what a fit with new solvers gives."""
    from dlo_ros.identify.fit import fit
    from dlo_ros.identify.objective import FitSettings
    from dlo_ros.model.problem import GripPose
    from dlo_ros.node.fitting import CloudSnapshot, FitConfig, fit_payload, observation_set, run_fit
    from dlo_ros.scene import load_scene

    scene = load_scene("default_cable")
    problem, options = scene.problem, scene.options  # solver.model auto: a planar solver per plane
    points = np.load(POINTS)
    c, s = math.cos(0.6), math.sin(0.6)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    q = (0.0, 0.0, math.sin(0.3), math.cos(0.3))
    turned = {"left": GripPose(np.array([0.0, 0.0, 0.4]), np.array(q)),
              "right": GripPose(turn @ np.array([0.6, 0.0, 0.0]) + [0.0, 0.0, 0.4], np.array(q))}
    config = FitConfig(point_sigma=SIGMA)
    hanging = CloudSnapshot(points, {g.name: g.pose for g in problem.grips}, 0, 1)
    other_plane = CloudSnapshot(points @ turn.T, turned, 0, 2)
    new_solvers = {1: fit(problem, options, observation_set(hanging, config), FitSettings()),
                   2: fit(problem, options, observation_set(other_plane, config), FitSettings())}
    for snap in (hanging, hanging, other_plane):  # built, reused, another plane
        kept = run_fit(fit_payload(problem, options, snap, config))
        new = new_solvers[snap.number]
        assert kept.ok and new.ok
        assert kept.ratios["D/Rf"].value == pytest.approx(new.ratios["D/Rf"].value, rel=1e-9)
        assert kept.ratios["D/Rf"].std == pytest.approx(new.ratios["D/Rf"].std, rel=1e-9)
        assert kept.equilibrium_solves == new.equilibrium_solves
    within({"estimate.D/Rf": kept.ratios["D/Rf"].value, "estimate.D/Rf.sigma": kept.ratios["D/Rf"].std}, "D/Rf",
           D / RF)


# ---- the node over DDS --------------------------------------------------------------------------------------
def within(values: dict, name: str, truth: float, k: float = 3.0) -> tuple[float, float]:
    value, std = float(values[f"estimate.{name}"]), float(values[f"estimate.{name}.sigma"])
    assert abs(value - truth) <= k * std, f"{name} = {value} ± {std}, truth {truth}"
    return value, std


@pytest.mark.skipif(TEST_SCENE != "default_cable", reason="the observation is of default_cable's poses")
def test_fit_over_dds(tmp_path):
    from dlo_ros.recording import paths as R
    from dlo_ros.recording.replay import rows_of

    rrd = tmp_path / "fit.rrd"
    args = ("--scene", TEST_SCENE, "--ros-args", "-p", "compile:=off", "-p", f"solver.model:={TEST_MODEL}",
            "-p", "diagnostics_period:=0.2", "-p", "query_workers:=0", "-p", "fit.enabled:=true",
            "-p", f"fit.point_sigma:={SIGMA}", "-p", "fit.apply_max_rel_sigma:=0.01", "-p", "fit.max_points:=1000",
            "-p", f"record.rrd:={rrd}")
    points = np.load(POINTS)
    with clean_node(*args, log_path=tmp_path / "node.log") as (proc, cl):
        assert cl.wait_for_cloud_subscriber(10.0)
        ok, message = cl.fit()
        assert not ok and "no cloud" in message

        # bad clouds: each rejected, named, and the stream does not notice
        nan = points.copy()
        nan[17, 2] = np.nan
        bad = [(lambda: cl.publish_cloud(nan), "point 17 (row 0, column 17): field 'z' is nan"),
               (lambda: cl.publish_cloud(points, frame_id="camera"), "header.frame_id is 'camera'"),
               (lambda: cl.publish_cloud(np.zeros((0, 3))), "0 points"),
               (lambda: cl.publish_cloud(np.zeros((1001, 3))), "1001 points, over fit.max_points = 1000"),
               (lambda: cl.publish_cloud_msg(_renamed(points)), "fields: no field 'x' (fields: a, y, z)")]
        for i, (publish, expected) in enumerate(bad, start=1):
            publish()
            values, st = cl.wait_for_fit_diagnostics(lambda v, s, i=i: v.get("clouds rejected") == str(i), 10.0) \
                or (None, None)
            assert values is not None, f"cloud {i} not rejected: {proc.output()}"
            assert expected in values["last cloud error"] and st.level == b"\x01", values["last cloud error"]
        assert values["clouds received"] == "0"
        ok, message = cl.fit()
        assert not ok and "no cloud" in message
        stamp = cl.publish_targets([LEFT, ((0.6, 0.0, 0.4), Q)])  # the scene's poses: the shape stays
        assert cl.wait_for_path(10.0, where=lambda e: e.stamp_ns == stamp) is not None
        values, st = cl.wait_for_diagnostics(lambda v, s: v.get("trigger") == "targets", 5.0)
        assert st.level == b"\x00" and values["rejected inputs"] == "0", values

        # a good cloud; the first fit is not precise enough for the bound 0.01 (σ(D/Rf) ≈ 4 %)
        cl.publish_cloud(points)
        assert cl.wait_for_fit_diagnostics(lambda v, s: v.get("clouds received") == "1", 10.0), proc.output()
        during = stream_while_fitting(cl, lambda: cl.fit(), finished=1)
        values, st = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == "1", 60.0)
        assert during >= 1, "no centreline was published while the fit ran"
        print(f"centrelines answered while the first fit ran: {during}")
        assert values["last fit status"] == "ok", values
        ratio, std = within(values, "D/Rf", D / RF)
        assert values["applied"] == "false" and "relative σ of D/Rf" in values["apply reason"]
        assert "Rf" in values["last fit not identifiable"] and "estimate.Rf" not in values
        assert cl.get_parameters(["string.weight_per_length"])["string.weight_per_length"] == 0.5

        # with a looser bound the same cloud's estimate is applied: D moves, Rf is held (shapes give D/Rf)
        assert cl.set_parameters({"fit.apply_max_rel_sigma": 0.1}) == [(True, "")]
        ok, message = cl.fit()
        assert ok, message
        values, _ = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == "2", 60.0)
        assert values["applied"] == "true" and values["applications"] == "1", values
        got = cl.get_parameters(["string.bend_stiffness", "string.weight_per_length"])
        assert got["string.bend_stiffness"] == 0.02
        assert abs(got["string.weight_per_length"] / 0.02 - D / RF) <= 3 * std
        assert got["string.weight_per_length"] == pytest.approx(0.02 * float(values["estimate.D/Rf"]), rel=1e-5)
        # the applied fit's covariance becomes the envelope's uncertainty (the scene has none)
        envelope = cl.wait_for(lambda: (lambda st: st if st is not None and any(
            kv.key == "available" and kv.value == "true" for kv in st.values) else None)(
                cl.other_diagnostics.get("/dlo: envelope")), 15.0)
        assert envelope is not None, cl.other_diagnostics.get("/dlo: envelope")
        parameters = {kv.key: kv.value for kv in envelope.values}["parameters"]
        assert parameters and set(parameters.split(",")) <= {"bend_stiffness", "weight_per_length"}

        # a known total mass makes Rf and D absolute
        assert cl.set_parameters({"fit.total_mass": D / 9.80665}) == [(True, "")]
        ok, message = cl.fit()
        assert ok, message
        values, _ = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == "3", 60.0)
        rf, rf_std = within(values, "Rf", RF)
        within(values, "D", D)
        assert values["applied"] == "true", values
        got = cl.get_parameters(["string.bend_stiffness", "string.weight_per_length"])
        assert got["string.bend_stiffness"] == pytest.approx(rf, rel=1e-5)  # diagnostics: 6 digits
        fit_values = values

        # the fit parameters are checked like every other
        [(ok, reason)] = cl.set_parameters({"fit.parameters": ["Rf", "X"]})
        assert not ok and "'X' is not one of Rf, Rt, D, Re" in reason
        [(ok, reason)] = cl.set_parameters({"fit.enabled": False})
        assert not ok
        assert proc.alive()
    text = (tmp_path / "node.log").read_text()
    assert "fit of cloud 1 (300 points): ok" in text and "applied: string.bend_stiffness 0.02 -> " in text
    assert "string properties changed: string.bend_stiffness=" in text  # the parameter path logged it too

    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    chunks: dict[str, list] = {}
    for chunk in reader.stream(store=reader.recordings()[0]):
        chunks.setdefault(chunk.entity_path.lstrip("/"), []).append(chunk)
    assert {"world/fit/observed", "world/fit/fitted", "world/fit/residuals"} <= set(chunks)
    fit_events = [r["TextLog:text"][0] for r in rows_of(chunks["events/fit"])]
    assert len(fit_events) == 3 and "not applied" in fit_events[0] and "applied: string.weight" in fit_events[1]
    model_events = " ".join(r["TextLog:text"][0] for r in rows_of(chunks[R.E_MODEL]))
    assert "string.weight_per_length=" in model_events and "string.bend_stiffness=" in model_events
    rejected = " ".join(r["TextLog:text"][0] for r in rows_of(chunks[R.E_REJECTED]))
    assert "field 'z' is nan" in rejected
    print(f"fit over DDS: Rf = {rf:.5g} ± {rf_std:.2g}, D/Rf = {ratio:.4g} ± {std:.2g}, "
          f"time {fit_values['last fit time s']} s, {fit_values['last fit solves']} solves")


def _renamed(points: np.ndarray):
    from dlo_ros.node.cloud import points_to_cloud

    msg = points_to_cloud(points, "world", 0)
    msg.fields[0].name = "a"
    return msg


def stream_while_fitting(cl, start, finished: int) -> int:
    """Start a fit with ``start()`` and keep sending targets (each answered before the next) until the fit
    diagnostics report ``finished`` fits; returns how many centrelines arrived while the fit was still
    running: the node's next diagnostics after the centreline still counted fewer finished fits (the
    node's own report, not a clock)."""
    ok, message = start()
    assert ok, message
    answered = 0
    for k in range(10_000):
        angle = 0.05 * math.sin(k / 5)
        stamp = cl.publish_targets([LEFT, ((0.6, 0.0, 0.4), (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)))])
        ev = cl.wait_for_path(10.0, where=lambda e: e.stamp_ns == stamp)
        assert ev is not None, "the stream stopped answering targets during the fit"
        n = cl.diagnostics_count
        assert cl.wait_for(lambda: cl.diagnostics_count > n, 5.0)
        values, _ = cl.wait_for_fit_diagnostics(lambda v, s: True, 5.0)
        if values.get("fits finished") == str(finished):
            return answered
        answered += 1
    return answered


def spawned_workers(pid: int) -> list[int]:
    """Pids of the multiprocessing workers (spawn_main) that are children of process ``pid`` (Linux /proc)."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if int(stat[stat.rindex(")") + 2:].split()[1]) == pid and b"spawn_main" in cmdline:
            out.append(int(entry.name))
    return out


@pytest.mark.skipif(TEST_SCENE != "default_cable", reason="the observation is of default_cable's poses")
def test_continuous_fit_survives_a_failed_fit_and_a_dead_worker(tmp_path):
    import os
    import signal

    # planar: this test compares no shapes with another solver, and the planar model builds fastest
    args = ("--scene", TEST_SCENE, "--ros-args", "-p", "compile:=off", "-p", "solver.model:=planar",
            "-p", "diagnostics_period:=0.2", "-p", "query_workers:=0", "-p", "fit.enabled:=true",
            "-p", "fit.period_s:=0.2", "-p", f"fit.point_sigma:={SIGMA}")
    points = np.load(POINTS)
    with clean_node(*args, log_path=tmp_path / "node.log") as (proc, cl):
        assert cl.wait_for_cloud_subscriber(10.0)
        # a request the scene cannot fit (Re of an inextensible string) fails in the worker: reported, WARN
        assert cl.set_parameters({"fit.parameters": ["Re"]}) == [(True, "")]
        cl.publish_cloud(points)  # no ~/fit call: the timer fits every new cloud
        values, st = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == "1", 60.0) or (None, None)
        assert values is not None, proc.output()
        assert values["last fit status"] == "failed" and "inextensible" in values["last fit message"], values
        assert st.level == b"\x01" and values["fits started"] == "1"  # the same cloud is not fitted again

        # the fit worker dies (as after a crash in IPOPT): the next fit runs in a new one
        workers = spawned_workers(proc.pid)
        assert len(workers) == 1, workers
        os.kill(workers[0], signal.SIGKILL)
        assert cl.set_parameters({"fit.parameters": ["Rf", "D"]}) == [(True, "")]
        finished = 1
        for attempt in range(2):  # the first may still reach the dead worker, and is then reported failed
            cl.publish_cloud(points)
            finished += 1
            values, _ = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == str(finished), 60.0) \
                or (None, None)
            assert values is not None, proc.output()
            if values["last fit status"] == "ok":
                break
            assert "worker process died" in values["last fit message"], values
        within(values, "D/Rf", D / RF)
        assert values["applied"] == "true"  # the default bound 0.1 lets σ(D/Rf) ≈ 4 % through
        assert spawned_workers(proc.pid) != workers
        stamp = cl.publish_targets([LEFT, ((0.55, 0.0, 0.4), Q)])
        assert cl.wait_for_path(10.0, where=lambda e: e.stamp_ns == stamp) is not None
        assert proc.alive()


@pytest.mark.skipif(TEST_SCENE != "default_cable", reason="the observation is of default_cable's poses")
def test_a_misfit_is_not_applied(tmp_path):
    """A cloud the scene's string cannot form (the shipped hanging cable stretched 1.25× downwards from the
    grips' height: longer than the 1 m cable held by these grips), with the default settings (the apply
    bound 0.1 that lets a good fit's σ through): status misfit with the reason, WARN, nothing applied, the
    live D unchanged.  The unchanged string then still fits the shipped cloud."""
    args = ("--scene", TEST_SCENE, "--ros-args", "-p", "compile:=off", "-p", "solver.model:=planar",
            "-p", "diagnostics_period:=0.2", "-p", "query_workers:=0", "-p", "fit.enabled:=true",
            "-p", f"fit.point_sigma:={SIGMA}")
    points = np.load(POINTS)
    stretched = points.copy()
    stretched[:, 2] = 0.4 + 1.25 * (points[:, 2] - 0.4)
    with clean_node(*args, log_path=tmp_path / "node.log") as (proc, cl):
        assert cl.wait_for_cloud_subscriber(10.0)
        cl.publish_cloud(stretched)
        assert cl.wait_for_fit_diagnostics(lambda v, s: v.get("clouds received") == "1", 10.0), proc.output()
        ok, message = cl.fit()
        assert ok, message
        values, st = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == "1", 90.0) or (None, None)
        assert values is not None, proc.output()
        assert values["last fit status"] == "misfit", values
        assert values["last fit message"].startswith("misfit: reduced chi2 "), values
        assert "the fitted shape does not explain the points" in values["last fit message"], values
        assert values["applied"] == "false" and "not applied: the fit is misfit" in values["apply reason"]
        assert st.level == b"\x01" and values["applications"] == "0", values
        assert cl.get_parameters(["string.weight_per_length"])["string.weight_per_length"] == 0.5
        cl.publish_cloud(points)
        assert cl.wait_for_fit_diagnostics(lambda v, s: v.get("clouds received") == "2", 10.0), proc.output()
        ok, message = cl.fit()
        assert ok, message
        values, _ = cl.wait_for_fit_diagnostics(lambda v, s: v.get("fits finished") == "2", 90.0) or (None, None)
        assert values is not None and values["last fit status"] == "ok", values
        within(values, "D/Rf", D / RF)
    assert "not applied: the fit is misfit (misfit: " in (tmp_path / "node.log").read_text()
