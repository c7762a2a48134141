"""The node with ``solver.model: auto``: the model is visible in /diagnostics and in the rerun recording,
and a change of model during a run is logged with its reason (issue 6).

Real parts: the node in a subprocess (``running_node``: its own ROS_DOMAIN_ID, reserved with
``allocate_domain_id``, so these tests run beside the other node tests), targets and diagnostics over
real DDS, the recording written by the recorder's child process and read back from the .rrd.

* default_cable starts planar; moving the right grip 5 cm out of the working plane makes auto switch
  to a 3D model: the diagnostics then say planar false with the reason, the node logs it (INFO), and
  the recording has an events/model entry with the reason at that update, plus model/order,
  model/variables, model/estimated_error_m per update.
* a tolerance auto cannot meet (1e-9 m; it reaches its highest order) makes the diagnostics WARN.

The first solve of auto builds several NLPs (seconds): the DDS tests take about 8 and 15 s here.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from dlo_ros.node.client import running_node
from dlo_ros.node.conversions import diagnostic_status, diagnostic_values
from dlo_ros.node.health import Health, model_text, new_model_changes
from dlo_ros.paths import scene_path
from dlo_ros.solver.result import ShapeResult

Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)
RERUN = str(Path(sys.executable).parent / "rerun")
WARN = b"\x01"


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def auto_model(**kw) -> dict:
    """A ShapeResult.model as AutoShapeSolver reports it."""
    m = {"planar": True, "twist": False, "stretch": False, "gravity": True, "order": 12, "obstacles": 1,
         "estimated_error_m": 4.3e-5, "tolerance_m": 1e-3, "variables": 15, "auto": True,
         "reasons": ["planar: scene lies in one plane"], "changes": [], "changed": []}
    m.update(kw)
    return m


# ---- pure: what the node makes of ShapeResult.model ---------------------------------------------------------
def test_health_shows_the_model_and_its_last_change():
    clock = FakeClock()
    h = Health(scene="default_cable", grips=("left", "right"), clock=clock)
    v = h.values()
    assert v["model.planar"] is None and v["model.changes"] == 0 and v["model.last change"] == ""
    ok = ShapeResult(status="ok", message="converged", stable=True, min_eigenvalue=1.0, solve_time_ms=2.0)
    h.update(ok, "initial")
    h.set_model(auto_model(), ["order 8 error estimate 0.000826 m > 0.0005 m: order 12"], stamp_ns=5_500_000_000,
                update=0)
    assert h.level_and_message()[0] == "ok"
    clock.t += 2.0
    v = h.values()
    assert v["model.auto"] is True and v["model.planar"] is True and v["model.order"] == 12
    assert v["model.variables"] == 15 and v["model.estimated_error_m"] == 4.3e-5 and v["model.tolerance_m"] == 1e-3
    assert v["model.reasons"] == "planar: scene lies in one plane"
    assert v["model.changes"] == 1 and v["model.last change"].startswith("order 8 error estimate")
    assert v["model.last change time"] == "5.500" and v["model.last change update"] == 0
    assert v["model.last change age s"] == pytest.approx(2.0)
    # a solve that changes nothing keeps the last change
    h.set_model(auto_model(planar=False, variables=39), [], stamp_ns=9_000_000_000, update=3)
    v = h.values()
    assert v["model.planar"] is False and v["model.changes"] == 1 and v["model.last change update"] == 0
    # one solve, two changes: both reasons, in order
    h.set_model(auto_model(planar=False, order=16), ["targets left the plane (...): full model",
                                                     "order 12 error estimate 0.00125 m > 0.0005 m: order 16"],
                stamp_ns=12_000_000_000, update=4)
    v = h.values()
    assert v["model.changes"] == 3 and v["model.last change update"] == 4
    assert v["model.last change"] == ("targets left the plane (...): full model; "
                                      "order 12 error estimate 0.00125 m > 0.0005 m: order 16")
    # as the node publishes it: strings
    text = diagnostic_values(diagnostic_status("/dlo: shape", *h.level_and_message(), "default_cable", h.values()))
    assert text["model.planar"] == "false" and text["model.order"] == "16" and text["model.auto"] == "true"
    assert text["model.estimated_error_m"] == "4.3e-05" and text["model.last change time"] == "12.000"


def test_health_warns_when_the_model_misses_its_tolerance():
    h = Health(clock=FakeClock())
    ok = ShapeResult(status="ok", message="converged", stable=True, min_eigenvalue=1.0, solve_time_ms=2.0)
    h.update(ok, "initial")
    h.set_model(auto_model(order=32, estimated_error_m=1.8e-8, tolerance_m=1e-9, tolerance_met=False,
                           reasons=["planar: scene lies in one plane"]))
    level, message = h.level_and_message()
    assert level == "warn" and "tolerance not met" in message and "1.8e-08" in message and "1e-09" in message
    assert h.tolerance_problem() == message
    # the estimate over the tolerance says so even without the flag
    h.set_model(auto_model(estimated_error_m=2e-3))
    level, message = h.level_and_message()
    assert level == "warn" and message.startswith("model: tolerance not met")
    # an unknown estimate (not checked yet), or a fixed model, is no warning
    h.set_model(auto_model(estimated_error_m=None))
    assert h.level_and_message()[0] == "ok" and h.tolerance_problem() == ""
    h.set_model({"planar": False, "twist": True, "stretch": False, "gravity": True, "order": 16, "obstacles": 1,
                 "estimated_error_m": None, "variables": 51})
    assert h.level_and_message()[0] == "ok" and h.values()["model.auto"] is False
    # errors and instability come first
    h.set_model(auto_model(estimated_error_m=2e-3))
    h.error("unreachable", "too far", rejected=False)
    assert "solve failed" in h.level_and_message()[1]


def test_new_model_changes_reports_each_change_once():
    # during a solve: 'changed'
    m = auto_model(changes=["a"], changed=["a"])
    assert new_model_changes(m, 0) == (["a"], 1)
    assert new_model_changes(auto_model(changes=["a"], changed=[]), 1) == ([], 1)
    # a change between solves (set_problem: 'scene changed') shows only in the history: reported first
    m = auto_model(changes=["a", "scene changed", "b"], changed=["b"])
    assert new_model_changes(m, 1) == (["scene changed", "b"], 3)
    # repeated reasons are counted, not merged
    m = auto_model(changes=["x", "x", "x"], changed=["x"])
    assert new_model_changes(m, 1) == (["x", "x"], 3)
    # a note in 'changed' that is not in the history (e.g. a failed background check) is still reported
    assert new_model_changes(auto_model(changes=["a"], changed=["model check failed: boom"]), 1) == (
        ["model check failed: boom"], 1)
    # a new solver (shorter history) starts over; a fixed model has neither key
    assert new_model_changes(auto_model(changes=["c"], changed=["c"]), 5) == (["c"], 1)
    assert new_model_changes({"planar": False, "order": 16}, 0) == ([], 0)


def test_model_text():
    assert model_text({}) == ""
    assert model_text(auto_model()) == ("auto: planar, gravity, order 12, 15 unknowns, 1 obstacle(s), "
                                        "estimated error 4.3e-05 m (tolerance 0.001 m)")
    assert model_text(auto_model(estimated_error_m=None)).endswith("error not estimated yet (tolerance 0.001 m)")
    assert model_text({"planar": False, "twist": True, "gravity": True, "order": 16, "variables": 51}) == (
        "3D, twist, gravity, order 16, 51 unknowns")


# ---- the node over DDS -----------------------------------------------------------------------------------------
def node_args(scene: str, *extra: str) -> tuple[str, ...]:
    return ("--scene", scene, "--ros-args", "-p", "compile:=off", "-p", "solver.model:=auto",
            "-p", "diagnostics_period:=0.2", *extra)


def send(proc, cl, right, timeout: float = 40.0):
    """Publish both targets and wait for the centreline that answers them; its stamp."""
    stamp = cl.publish_targets([LEFT, (right, Q)])
    ev = cl.wait_for_path(timeout, where=lambda e: e.stamp_ns == stamp)
    assert ev is not None, f"no centreline for right={right} within {timeout} s\n{proc.output()}"
    return stamp


def test_leaving_the_plane_is_shown_in_diagnostics_log_and_recording(tmp_path):
    pytest.importorskip("rerun", reason="rerun-sdk needs Python >= 3.11")
    from dlo_ros.recording.replay import read_recording

    rrd, log = tmp_path / "auto.rrd", tmp_path / "node.log"
    with running_node(*node_args("default_cable", "-p", f"record.rrd:={rrd}"), log_path=log,
                      startup_timeout=90.0) as (proc, cl):
        # in the plane: a planar model, its order, size and tolerance in the diagnostics
        send(proc, cl, (0.58, 0.0, 0.42))
        got = cl.wait_for_diagnostics(lambda v, st: v.get("model.auto") == "true" and v.get("model.planar") == "true"
                                      and v.get("model.order") not in (None, ""), 10.0)
        assert got is not None, (cl.diagnostic_values(), proc.output())
        values, _ = got
        assert int(values["model.variables"]) > 0 and float(values["model.tolerance_m"]) == pytest.approx(1e-3)
        assert "planar" in values["model.reasons"]
        planar_changes = int(values["model.changes"])

        # out of the plane: auto switches to 3D during that solve
        stamp_out = send(proc, cl, (0.58, 0.05, 0.42))
        got = cl.wait_for_diagnostics(lambda v, st: v.get("model.planar") == "false", 10.0)
        assert got is not None, (cl.diagnostic_values(), proc.output())
        values, status = got
        assert int(values["model.changes"]) > planar_changes
        assert "plane" in values["model.last change"], values
        assert values["model.last change update"] != "" and float(values["model.last change time"]) == pytest.approx(
            stamp_out / 1e9, abs=1e-3)
        assert float(values["model.last change age s"]) >= 0.0
        # a few more moves out of the plane, until the 3D model's error has been estimated (at once when
        # auto checks inside the solve; a solve or two later when it checks in the background)
        deadline, k, got = time.monotonic() + 30.0, 0, None
        while got is None and time.monotonic() < deadline:
            k += 1
            stamp_last = send(proc, cl, (0.58 - 0.005 * k, 0.05, 0.42))
            got = cl.wait_for_diagnostics(lambda v, st: v.get("model.planar") == "false"
                                          and v.get("model.estimated_error_m") not in (None, ""), 0.5)
        assert got is not None, (cl.diagnostic_values(), proc.output())
        values, status = got
        est, tol = float(values["model.estimated_error_m"]), float(values["model.tolerance_m"])
        assert est >= 0.0
        if est <= tol:
            assert status.level != WARN or "tolerance" not in status.message, status.message
    text = log.read_text()
    assert proc.returncode == 0, text
    assert "Traceback" not in text, text
    changes = [line for line in text.splitlines() if "model change (update" in line and "plane" in line]
    assert changes and "INFO" in changes[0], text

    done = subprocess.run([RERUN, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    rec = read_recording(rrd)
    by_stamp = {r.ros_time_ns: r for r in rec.results}
    out = by_stamp[stamp_out]  # the solve that left the plane
    assert out.model.get("planar") is False and out.model.get("auto") is True
    assert any("plane" in c for c in out.model.get("changed", [])), out.model
    before = [r for r in rec.results if r.update < out.update]
    assert before and all(r.model.get("planar") is True for r in before)
    events = [(u, text) for entity, u, text in rec.events if entity == "events/model"]
    assert any(u == out.update and "model change" in t and "plane" in t for u, t in events), events
    assert any(u == out.update and t.startswith("model now: auto: 3D") for u, t in events), events
    # the model on the timeline: one value per update of order and size, the estimate once measured
    for key in ("order", "variables", "planar", "tolerance_m"):
        series = dict(rec.model_series.get(key, []))
        assert set(series) >= {r.update for r in rec.results}, (key, series)
    assert dict(rec.model_series["planar"])[out.update] == 0.0
    assert dict(rec.model_series["variables"])[out.update] > dict(rec.model_series["variables"])[0]
    estimates = dict(rec.model_series["estimated_error_m"])
    assert estimates and by_stamp[stamp_last].update in estimates
    assert {"model/order", "model/variables", "model/estimated_error_m"} <= rec.entities


def test_a_tolerance_that_cannot_be_met_is_a_warning(tmp_path):
    scene = yaml.safe_load(scene_path("default_cable").read_text())
    scene["name"] = "default_cable_tight"
    scene["solver"] = {**scene.get("solver", {}), "error_tolerance": 1e-9}
    scene["obstacles"] = []  # the table is far below the cable; without its rows order 32 builds faster
    path = tmp_path / "tight.yaml"
    path.write_text(yaml.safe_dump(scene))
    log = tmp_path / "node.log"
    with running_node(*node_args(str(path)), log_path=log, startup_timeout=120.0) as (proc, cl):
        # auto escalates to its highest order (at once when it checks inside the solve; over the next
        # solves when it checks in the background: small moves in the plane give it those)
        deadline, k, got = time.monotonic() + 180.0, 0, None  # order 32 checks take a minute on a loaded 2-core machine
        while True:
            got = cl.wait_for_diagnostics(lambda v, st: v.get("model.order") not in (None, "") and st.level == WARN
                                          and "tolerance not met" in st.message, 1.0)
            if got is not None or time.monotonic() > deadline:
                break
            k += 1
            send(proc, cl, (0.6 - 0.002 * k, 0.0, 0.4))
        assert got is not None, (cl.diagnostic_values(), proc.output())
        values, status = got
        assert "tolerance not met" in status.message, status.message
        assert values["model.tolerance_met"] in ("False", "false")
        assert float(values["model.tolerance_m"]) == pytest.approx(1e-9)
        assert float(values["model.estimated_error_m"]) > float(values["model.tolerance_m"])
        assert int(values["model.changes"]) >= 1 and "order" in values["model.last change"]
        # no shape meets a 1e-9 m tolerance: each is published with a warning, never as a stable equilibrium
        assert values["status"] == "unverified" and values["stable"] in ("None", "none", ""), values
        assert float(values["equilibrium residual m"]) > 1e-9
    text = log.read_text()
    assert proc.returncode == 0, text
    assert "Traceback" not in text, text
    assert any("WARN" in line and "tolerance not met" in line for line in text.splitlines()), text
