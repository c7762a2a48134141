"""What the node makes of ShapeResult.model with ``solver.model: auto`` (no ROS graph): the diagnostics'
model fields and level, the log line of each model change (test/ros/test_node_auto_model.py runs the
node itself)."""
from __future__ import annotations

import pytest

from dlo_ros.node.conversions import diagnostic_status, diagnostic_values
from dlo_ros.node.health import Health, model_text, new_model_changes
from dlo_ros.solver.results.result import ShapeResult

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


class _Logged:
    """A logger that keeps its lines."""

    def __init__(self):
        self.lines: list[tuple[str, str]] = []

    def info(self, text):
        self.lines.append(("info", text))

    def warning(self, text):
        self.lines.append(("warn", text))


class _Solved:
    """What StreamLog.observe_model reads of a result: its model as a dict."""

    def __init__(self, model: dict):
        self.model = model

    def model_dict(self) -> dict:
        return self.model


def test_stream_log_says_met_again_only_once_a_check_says_so():
    # the main job logged "meets its error tolerance again: ... error not estimated yet" at each
    # mesh switch: a model not checked yet is neither met nor not met
    from dlo_ros.node.stream_log import StreamLog
    from dlo_ros.scene import load_scene

    log = _Logged()
    stream = StreamLog(load_scene("default_cable"), Health(scene="s", grips=("left", "right")), log)
    over = auto_model(estimated_error_m=0.176, tolerance_met=False, checked=True)
    switched = auto_model(estimated_error_m=None, tolerance_met=None, checked=False)
    met = auto_model(estimated_error_m=4e-4, tolerance_met=True, checked=True)
    for model in (over, switched, switched, over, switched, met, met):
        stream.observe_model(_Solved(model), 0)
    said = [(kind, text.split(":")[0]) for kind, text in log.lines]
    assert said == [("warn", "model"), ("info", "model meets its error tolerance again")], log.lines
    assert "176 unknowns" not in log.lines[0][1] and "(order 12, 15 unknowns)" in log.lines[0][1]
