"""Rerun recording and replay (dlo_ros/recording.py, dlo_ros/replay.py, `dlo ... --rrd`, `dlo replay`).

Recordings are written for real (rerun-sdk 0.41, the recorder's child process), checked with the
`rerun rrd verify` / `rerun rrd compare` tools that ship in the wheel, and read back with rerun's chunk
API.  The headless screenshot test is opt-in (DLO_TEST_SCREENSHOT=1; it needs a Vulkan driver).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun", reason="rerun-sdk needs Python >= 3.11")

from dlo_ros import recording as R  # noqa: E402
from dlo_ros.model.rotations import quat_to_matrix  # noqa: E402
from dlo_ros.model.obstacles import Obstacle  # noqa: E402
from dlo_ros.model.obstacle_types import OBSTACLE_TYPES, PrimitiveKind  # noqa: E402
from dlo_ros.recording.obstacle_drawing import DRAWINGS, obstacle_shape  # noqa: E402
from dlo_ros.recording.replay import read_recording, resolve  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import ShapeSolver  # noqa: E402
from dlo_ros.solver.results.result import ShapeResult  # noqa: E402
from dlo_ros.solver.results.summary import ModelSummary  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
RERUN = str(Path(sys.executable).parent / "rerun")
UPDATES = 8  # warm updates after the cold solve in the in-process recordings


def run_cli(*args: str, env: dict | None = None, timeout: float = 600) -> subprocess.CompletedProcess:
    full = dict(os.environ)
    full.setdefault("DLO_NO_COMPILE", "1")
    full.update(env or {})
    return subprocess.run([sys.executable, "-m", "dlo_ros.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO, env=full)


def rerun_tool(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([RERUN, *args], capture_output=True, text=True, timeout=120)


def verified(path: Path) -> None:
    done = rerun_tool("rrd", "verify", str(path))
    assert done.returncode == 0, done.stdout + done.stderr


def same_recordings(a: Path, b: Path, tmp: Path) -> bool:
    """`rerun rrd compare` after dropping what depends on the wall clock — the ros_time timeline (the CLI
    stamps updates with the wall time) and the solve-time series; compare ignores log_time — and after
    `rerun rrd optimize`, which compacts both into the same chunks (compare matches whole chunks, and
    how rows were batched while recording depends on timing)."""
    ready = []
    for path in (a, b):
        filtered, optimized = tmp / f"{path.stem}.filtered.rrd", tmp / f"{path.stem}.optimized.rrd"
        done = rerun_tool("rrd", "filter", "--drop-timeline", R.TIMELINE_ROS, "--drop-entity", "/" + R.E_SOLVE_TIME,
                          str(path), "-o", str(filtered))
        assert done.returncode == 0, done.stderr[-2000:]
        done = rerun_tool("rrd", "optimize", str(filtered), "-o", str(optimized))
        assert done.returncode == 0, done.stderr[-2000:]
        ready.append(optimized)
    return rerun_tool("rrd", "compare", "--unordered", *map(str, ready)).returncode == 0


# ---- in-process recordings of default_cable ------------------------------------------------------------
@pytest.fixture(scope="module")
def scene():
    return load_scene("default_cable")


@pytest.fixture(scope="module")
def solver(scene):
    return ShapeSolver(scene.problem, scene.options, compile="off")


def record(path: Path, scene, solver, *, backend: str = "process", step: float = 0.01, perturb: float = 0.0,
           recorder_kw: dict | None = None):
    """Cold solve + UPDATES warm moves of the right grip, recorded; returns the results (as solved)."""
    solver.reset()
    q = scene.problem.grip("right").pose.orientation
    start = scene.problem.grip("right").pose.position
    results = []
    with R.Recorder(rrd=path, backend=backend, **(recorder_kw or {})) as rec:
        rec.log_scene(scene, solver=solver)
        current = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}
        rec.log_targets(current, update=0, ros_time_ns=1_000_000_000)
        for k in range(UPDATES + 1):
            if k:
                current = {**current, "right": (start - np.array([step * k, 0.0, 0.0]), q)}
                rec.log_targets({"right": current["right"]}, update=k)
            r = solver.solve({"right": current["right"]}, warm=k > 0)
            assert r.ok, r.message
            results.append(r)
            logged = replace(r, points=r.points + perturb) if perturb and k == UPDATES // 2 else r
            rec.log_result(logged, update=k, targets=current, warm=k > 0)
        rec.log_rejected("grip 'middle': unknown (configured grips: ['left', 'right'])", update=UPDATES)
        rec.log_model_change("switched to the planar model (test)", update=UPDATES)
    assert rec.errors == 0, rec.last_error
    assert rec.dropped == 0
    return results


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, scene, solver):
    path = tmp_path_factory.mktemp("rec") / "run1.rrd"
    return path, record(path, scene, solver)


def test_recording_verifies_and_has_the_entities(recorded):
    path, _ = recorded
    verified(path)
    rec = read_recording(path)
    expected = {R.E_WORLD, R.E_CABLE, R.E_FRAMES, "world/grips/left", "world/grips/left/force", "world/grips/right",
                "world/grips/right/force", "world/targets/left", "world/targets/right", "world/obstacles/0_table",
                R.E_SOLVE_TIME, R.E_ITERATIONS, R.E_ENERGY, R.E_EIGEN, R.E_STATUS, R.E_REJECTED, R.E_MODEL,
                R.E_SCENE, R.E_LEGEND, R.E_DATA_RESULT, R.E_DATA_TARGETS}
    assert expected <= rec.entities, expected - rec.entities
    assert rec.scene_name == "default_cable" and rec.solver_kind == "ShapeSolver"
    assert "default_cable" in rec.scene_yaml and "bend_stiffness" in rec.scene_yaml


def test_recording_holds_every_update_and_the_shapes(recorded):
    path, results = recorded
    rec = read_recording(path)
    assert rec.updates == list(range(UPDATES + 1))
    assert sorted(rec.centrelines) == list(range(UPDATES + 1))
    for k, r in enumerate(results):
        got = next(x for x in rec.results if x.update == k)
        assert got.status == "ok" and got.warm_started == (k > 0) and got.warm_call == (k > 0)
        np.testing.assert_array_equal(got.points, r.points)  # exact: float64 copy in data/result
        np.testing.assert_allclose(rec.centrelines[k], r.points, atol=1e-6)  # as drawn (float32 line strips)
        assert got.energy["total"] == pytest.approx(r.energy["total"], abs=0)
        assert set(got.targets) == {"left", "right"}
    assert len(rec.targets) == UPDATES + 1  # every target message, as received
    assert rec.rejected == [(UPDATES, "grip 'middle': unknown (configured grips: ['left', 'right'])")]
    assert (R.E_MODEL, UPDATES, "switched to the planar model (test)") in rec.events
    statuses = [e for e in rec.events if e[0] == R.E_STATUS]
    assert statuses == [(R.E_STATUS, 0, "ok: converged")]  # logged only when the status changes
    # the (fixed) model on the timeline: order, size, planar; a ShapeSolver estimates no error
    steps = list(range(UPDATES + 1))
    assert rec.model_series["order"] == [(k, float(results[0].model.order)) for k in steps]
    assert rec.model_series["variables"] == [(k, float(results[0].model.variables)) for k in steps]
    assert rec.model_series["planar"] == [(k, 0.0) for k in steps]
    assert "estimated_error_m" not in rec.model_series and "tolerance_m" not in rec.model_series
    assert rec.results[0].model["order"] == results[0].model.order  # recorded: the JSON form


def test_resolve_reproduces_the_recording(recorded):
    report = resolve(read_recording(recorded[0]), tolerance=1e-9, compile="off")
    assert report["ok"], report
    assert report["count"] == UPDATES + 1 and report["max_deviation_m"] <= 1e-9


def test_the_solve_times_are_read_back_and_resolve_names_the_slowest(recorded, tmp_path, scene, solver):
    """timeseries/solve_time_ms, read back per update, and the report's slowest solves: where a
    recorded stream stalled (the main job's node: its maximum latency was update 113's solve)."""
    path, results = recorded
    rec = read_recording(path)
    assert rec.solve_times == [(k, r.solve_time_ms) for k, r in enumerate(results)]  # float64: exact
    report = resolve(rec, tolerance=1e-9, compile="off")
    slowest = sorted(((k, r.solve_time_ms) for k, r in enumerate(results)), key=lambda t: -t[1])[:5]
    assert [(d["update"], d["solve_time_ms"]) for d in report["slowest_recorded_solves"]] == slowest
    # a recording without the series (dropped, as two runs are compared): nothing named, no error
    filtered = tmp_path / "no_times.rrd"
    out = rerun_tool("rrd", "filter", "--drop-entity", "/" + R.E_SOLVE_TIME, str(path), "-o", str(filtered))
    assert out.returncode == 0, out.stderr
    without = read_recording(filtered)
    assert without.solve_times == [] and len(without.results) == len(results)
    assert resolve(without, tolerance=1e-9, compile="off")["slowest_recorded_solves"] == []


def test_two_runs_compare_equal_and_a_different_run_does_not(recorded, tmp_path, scene, solver):
    again = tmp_path / "run2.rrd"
    record(again, scene, solver, backend="thread")  # other backend: other chunking, same data
    assert same_recordings(recorded[0], again, tmp_path)
    other = tmp_path / "other.rrd"
    record(other, scene, solver, step=0.011)
    assert not same_recordings(recorded[0], other, tmp_path)


def test_resolve_flags_a_changed_shape(tmp_path, scene, solver):
    path = tmp_path / "perturbed.rrd"
    record(path, scene, solver, perturb=2e-6)
    report = resolve(read_recording(path), tolerance=1e-6, compile="off")
    assert not report["ok"] and report["exceeding"] == [UPDATES // 2]
    assert report["max_deviation_m"] == pytest.approx(2e-6 * np.sqrt(3), rel=1e-6)
    done = subprocess.run([sys.executable, "-m", "dlo_ros.cli", "replay", str(path), "--resolve", "--json"],
                          capture_output=True, text=True, cwd=REPO, timeout=600,
                          env={**os.environ, "DLO_NO_COMPILE": "1"})
    assert done.returncode == 1, done.stderr
    out = json.loads(done.stdout)
    assert out["exceeding"] == [UPDATES // 2] and out["ok"] is False


def test_log_update_is_the_one_call_a_node_needs(tmp_path, scene, solver):
    """What the node's worker does after each streaming solve: log_update(result, problem=...)."""
    solver.reset()
    path = tmp_path / "node_like.rrd"
    q = scene.problem.grip("right").pose.orientation
    with R.Recorder(rrd=path) as rec:
        rec.log_scene(scene, solver=solver)
        for k in range(4):
            r = solver.solve({"right": ([0.6 - 0.02 * k, 0.0, 0.4], q)}, warm=True)
            rec.log_update(r, update=k, problem=solver.problem, ros_time_ns=1_700_000_000_000_000_000 + k,
                           warm=k > 0)
    got = read_recording(path)
    assert got.updates == [0, 1, 2, 3] and all(x.targets for x in got.results)
    assert [x.ros_time_ns for x in got.results] == [1_700_000_000_000_000_000 + k for k in range(4)]
    np.testing.assert_allclose(got.results[-1].targets["right"][0], [0.54, 0.0, 0.4])
    assert resolve(got, tolerance=1e-9, compile="off")["ok"]


def test_an_auto_model_is_on_the_timeline(tmp_path, scene, solver):
    """ShapeResult.model of each update as model/<key> scalars and in data/result (a failed solve's too);
    model events in events/model at their update; an auto scene gets the error-vs-tolerance plot."""
    solver.reset()
    q = scene.problem.grip("right").pose.orientation
    base = ModelSummary(planar=True, twist=False, stretch=False, gravity=True, order=12, obstacles=1, variables=15,
                        rotation="planar", estimated_error_m=4.3e-5, auto=True, obstacle_samples=41, tolerance_m=1e-3,
                        tolerance_met=True, checked=True, checks="background",
                        reasons=("planar: scene lies in one plane",), changes=(), changed=())
    left_plane = "targets left the plane (grips[1].position is 0.05 m out of the plane): full model"
    full = replace(base, planar=False, twist=True, order=16, variables=51, rotation="quaternion", changes=(left_plane,))
    models = [base, base,
              replace(full, estimated_error_m=None, tolerance_met=None, checked=False, changed=(left_plane,)),
              replace(full, estimated_error_m=6.1e-5)]
    auto_scene = replace(scene, options=replace(scene.options, model="auto"))
    path = tmp_path / "auto.rrd"
    with R.Recorder(rrd=path) as rec:
        rec.log_scene(auto_scene)
        for k, model in enumerate(models):
            r = solver.solve({"right": ([0.6 - 0.02 * k, 0.0, 0.4], q)}, warm=True)
            r.model = model
            for reason in model.changed:
                rec.log_model_change(f"model change: {reason}", update=k, ros_time_ns=1_000 + k)
            rec.log_update(r, update=k, problem=solver.problem, ros_time_ns=1_000 + k, warm=k > 0)
        failed = ShapeResult(status="unreachable", message="too far", model=models[-1])
        rec.log_update(failed, update=len(models), ros_time_ns=2_000)
    assert rec.errors == 0, rec.last_error
    got = read_recording(path)
    n = len(models) + 1
    assert got.model_series["order"] == [(0, 12.0), (1, 12.0), (2, 16.0), (3, 16.0), (4, 16.0)]
    assert got.model_series["variables"] == [(0, 15.0), (1, 15.0), (2, 51.0), (3, 51.0), (4, 51.0)]
    assert got.model_series["planar"] == [(0, 1.0), (1, 1.0), (2, 0.0), (3, 0.0), (4, 0.0)]
    assert got.model_series["estimated_error_m"] == [(0, 4.3e-5), (1, 4.3e-5), (3, 6.1e-5), (4, 6.1e-5)]  # None: none
    assert got.model_series["tolerance_m"] == [(k, 1e-3) for k in range(n)]
    assert [x.model.get("order") for x in got.results] == [12, 12, 16, 16, 16]
    assert got.results[-1].status == "unreachable" and got.results[-1].model["planar"] is False
    assert got.results[2].model["changed"] == [left_plane]
    assert (R.E_MODEL, 2, f"model change: {left_plane}") in got.events
    assert R.default_blueprint(R.scene_info(auto_scene)) is not None
    assert R.auto_model(R.scene_info(auto_scene)) and R.auto_model(R.scene_info(auto_scene, solver="AutoShapeSolver"))
    assert not R.auto_model(R.scene_info(auto_scene, solver=solver))  # a ShapeSolver: no error-estimate plot
    assert not R.auto_model(R.scene_info(replace(scene, options=replace(scene.options, model="full"))))


# ---- the recorder's mechanics ------------------------------------------------------------------------------
def test_the_eigenvalue_a_solve_left_unread_is_recorded_at_most_once_a_period(
        tmp_path, scene, solver, monkeypatch):
    """Where the inertia showed a shape stable, the solve leaves ``min_eigenvalue`` to be worked out
    on first read (an eigendecomposition): the recorder reads it at most once per EIGEN_PERIOD_S,
    sends the others' as absent, and leaves them unread; one already read is sent."""
    from dlo_ros.recording import recorder
    from dlo_ros.solver.results.result import known

    solver.reset()
    q = scene.problem.grip("right").pose.orientation
    start = scene.problem.grip("right").pose.position
    results = [solver.solve({"right": (start - np.array([0.01 * k, 0.0, 0.0]), q)}, warm=k > 0)
               for k in range(5)]
    assert all(r.ok and r.stable for r in results)
    assert all(known(r, "min_eigenvalue") is None for r in results[1:])  # the inertia decided
    read_before = results[3].min_eigenvalue  # a caller read this one first

    def sent(period: float) -> list:
        monkeypatch.setattr(recorder, "EIGEN_PERIOD_S", period)
        items: list = []
        with R.Recorder(rrd=tmp_path / f"eigen{period:g}.rrd", backend="thread") as rec:
            monkeypatch.setattr(rec, "_put", lambda item, keep=False: items.append(item))
            for k, r in enumerate(results):
                rec.log_result(r, update=k, warm=k > 0)
        return [item[6] for item in items if item[0] == "R"]  # encode_result's eigenvalue

    eig = sent(3600.0)
    assert known(results[1], "min_eigenvalue") is None and known(results[4], "min_eigenvalue") is None
    assert eig[0] == results[0].min_eigenvalue and eig[3] == read_before and read_before > 0
    assert eig[1] is None and eig[2] is None and eig[4] is None
    assert sent(0.0) == [r.min_eigenvalue for r in results]  # every one, with a period of zero


def test_disabled_recorder_is_a_no_op(scene):
    rec = R.Recorder()
    assert not rec.enabled and rec.pending == 0 and rec.dropped == 0
    rec.log_scene(scene)
    rec.log_targets({"left": ([0, 0, 0], [0, 0, 0, 1])}, update=0)
    rec.log_rejected("x", update=0)
    assert rec.flush() is True
    rec.close()
    rec.close()


def test_log_calls_are_thread_safe_and_cheap(tmp_path, scene, solver):
    solver.reset()
    r = solver.solve()
    path = tmp_path / "threads.rrd"
    costs = []
    with R.Recorder(rrd=path) as rec:
        rec.log_scene(scene)

        def producer(offset: int) -> None:
            for k in range(50):
                t0 = time.perf_counter()
                rec.log_result(r, update=offset + k)
                costs.append(time.perf_counter() - t0)
                rec.log_rejected(f"bad input {offset + k}", update=offset + k)

        threads = [threading.Thread(target=producer, args=(i * 100,)) for i in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert rec.errors == 0 and rec.dropped == 0
    got = read_recording(path)
    assert len(got.results) == 150 and len(got.rejected) == 150
    assert float(np.median(costs)) < 2e-3  # a copy into a pipe, not rerun work (typically ~50 µs)


def test_full_queue_drops_the_oldest_and_says_so(tmp_path, scene, solver, monkeypatch):
    solver.reset()
    r = solver.solve()
    gate = threading.Event()
    original = R.Writer.handle

    def slow_handle(self, message, dropped_total=0):
        gate.wait(30)
        original(self, message, dropped_total)

    monkeypatch.setattr(R.Writer, "handle", slow_handle)
    path = tmp_path / "dropped.rrd"
    rec = R.Recorder(rrd=path, backend="thread", queue_size=4)
    rec.log_scene(scene)  # never dropped
    for k in range(20):
        rec.log_result(r, update=k)
    rec.log_model_change("kept", update=19)  # never dropped
    assert rec.dropped >= 12
    gate.set()
    rec.close()
    got = read_recording(path)
    assert got.scene_yaml and (R.E_MODEL, 19, "kept") in got.events
    assert 19 in got.updates and len(got.results) == 20 - rec.dropped
    assert any(e[0] == R.E_RECORDER and "dropped" in e[2] for e in got.events)


def test_bad_options_fail_clearly(monkeypatch):
    with pytest.raises(ValueError, match="--connect"):
        R.Recorder(connect="http://example.org:9876")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="no display"):
        R.Recorder(spawn=True)


# ---- pure helpers ------------------------------------------------------------------------------------------
def test_grpc_url():
    assert R.grpc_url("") == "rerun+http://127.0.0.1:9876/proxy"
    assert R.grpc_url("10.0.0.5") == "rerun+http://10.0.0.5:9876/proxy"
    assert R.grpc_url("viewer:9000") == "rerun+http://viewer:9000/proxy"
    assert R.grpc_url(":9001") == "rerun+http://127.0.0.1:9001/proxy"
    assert R.grpc_url("rerun+https://h:1/proxy") == "rerun+https://h:1/proxy"
    with pytest.raises(ValueError):
        R.grpc_url("h:99999")


def test_bend_energy_density_of_a_circle():
    radius, rf = 0.2, 0.02
    a = np.linspace(0, np.pi, 101)
    pts = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], axis=1)
    density = R.bend_energy_density(pts, rf)
    assert density.shape == (100,)
    np.testing.assert_allclose(density, 0.5 * rf / radius**2, rtol=1e-3)
    np.testing.assert_allclose(R.bend_energy_density(pts, np.full(101, rf)), density)
    assert np.all(R.bend_energy_density(np.outer(np.linspace(0, 1, 5), [1, 0, 0]), rf) == 0)


def test_colours_and_rotations():
    np.testing.assert_array_equal(R.viridis([0.0, 1.0, 2.0]), [[68, 1, 84], [253, 231, 37], [253, 231, 37]])
    q = np.random.default_rng(1).normal(size=(6, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    m = R.quats_to_matrices(q)
    for i in range(6):
        np.testing.assert_allclose(m[i], quat_to_matrix(q[i]), atol=1e-12)


@pytest.mark.parametrize("spec, kind", [
    ({"type": "halfspace", "point": [0, 0, 0.1], "normal": [0, 1, 1]}, "Boxes3D"),
    ({"type": "sphere", "center": [1, 2, 3], "radius": 0.5}, "Ellipsoids3D"),
    ({"type": "capsule", "a": [0, 0, 0], "b": [0, 0.3, 0.4], "radius": 0.05}, "Capsules3D"),
    ({"type": "box", "center": [0, 0, 1], "orientation": [0, 0, 0.3826834, 0.9238795], "half_extents": [0.1, 0.2, 0.3]},
     "Boxes3D"),
])
def test_obstacle_shapes(spec, kind):
    ob = Obstacle.from_dict(spec)
    got, kwargs = obstacle_shape(ob, np.array([0.3, 0.0, 0.4]), 0.8)
    assert got == kind
    if spec["type"] == "halfspace":  # the slab's top face lies in the plane, its +z along the normal
        n = np.array([0, 1, 1]) / np.sqrt(2)
        rz = quat_to_matrix(kwargs["quaternions"][0])[:, 2]
        np.testing.assert_allclose(rz, n, atol=1e-12)
        top = kwargs["centers"][0] + kwargs["half_sizes"][0][2] * n
        assert np.dot(top - np.array([0, 0, 0.1]), n) == pytest.approx(0, abs=1e-12)
    if spec["type"] == "capsule":
        assert kwargs["lengths"][0] == pytest.approx(0.5)
        np.testing.assert_allclose(quat_to_matrix(kwargs["quaternions"][0])[:, 2], [0, 0.6, 0.8], atol=1e-12)
    if spec["type"] == "box":
        np.testing.assert_allclose(np.abs(kwargs["quaternions"][0]), spec["orientation"], atol=1e-6)


def test_every_primitive_kind_has_a_drawing():
    # a drawing per kind of Primitive, none per obstacle type: a new type draws through its
    # primitive; a new kind without a drawing fails here
    assert set(DRAWINGS) == set(PrimitiveKind)
    for kind in OBSTACLE_TYPES.values():
        assert kind.primitive.__qualname__.startswith(type(kind).__name__)  # the type's own


def test_the_writer_process_does_not_import_the_model():
    # the recorder's child runs `from dlo_ros.recording.transport import child_main`: it must not
    # pay for the model and CasADi (scene_info converts obstacles in the caller's process)
    code = ("import sys; import dlo_ros.recording.transport, dlo_ros.recording.writer; "
            "print(sorted(m for m in sys.modules if m.startswith(('dlo_ros.model', 'casadi'))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


# ---- the command line --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cli_solve(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "solve.rrd"
    done = run_cli("solve", "default_cable", "--json", "--rrd", str(path))
    return path, done


def test_cli_solve_records_the_shape_it_prints(cli_solve):
    path, done = cli_solve
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)  # still exactly one JSON document on stdout
    assert "recording saved to" in done.stderr
    verified(path)
    rec = read_recording(path)
    assert rec.updates == [0] and rec.scene_name == "default_cable"
    np.testing.assert_allclose(rec.results[0].points, out["points"], atol=1e-11)  # JSON rounds to 12 digits
    np.testing.assert_allclose(rec.centrelines[0], out["points"], atol=1e-6)
    assert rec.results[0].targets is not None and rec.targets


def test_cli_solve_recording_resolves(cli_solve):
    done = run_cli("replay", str(cli_solve[0]), "--resolve")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 above the tolerance" in done.stdout and "-> OK" in done.stdout


def solver_demo() -> list[str]:
    """`dlo demo` runs the ROS node demo by default now; the in-process solver demo is `--solver-only`."""
    return ["demo", "--solver-only"] if "--solver-only" in run_cli("demo", "--help").stdout else ["demo"]


def test_cli_demo_records_every_step_and_resolves(tmp_path):
    path = tmp_path / "demo.rrd"
    done = run_cli(*solver_demo(), "--steps", "4", "--rrd", str(path))
    assert done.returncode == 0, done.stderr
    verified(path)
    rec = read_recording(path)
    assert rec.updates == [0, 1, 2, 3, 4]
    assert [r.warm_call for r in rec.results] == [False, True, True, True, True]
    assert len(rec.targets) == 5 and set(rec.targets[1][1]) == {"right"}
    again = run_cli("replay", str(path), "--resolve", "--json")
    assert again.returncode == 0, again.stderr
    report = json.loads(again.stdout)
    assert report["ok"] and report["count"] == 5


def test_cli_replay_without_a_display_explains(cli_solve):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run([sys.executable, "-m", "dlo_ros.cli", "replay", str(cli_solve[0])], capture_output=True,
                          text=True, cwd=REPO, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "no display" in done.stdout and "--web" in done.stdout and "--screenshot" in done.stdout


def test_cli_replay_opens_the_viewer_when_there_is_a_display(cli_solve, tmp_path):
    fake = tmp_path / "fake-rerun"
    fake.write_text("#!/bin/sh\necho viewer \"$@\"\n")
    fake.chmod(0o755)
    done = run_cli("replay", str(cli_solve[0]), env={"DISPLAY": ":99", "DLO_RERUN_EXE": str(fake)})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"viewer {cli_solve[0]}"


def test_cli_replay_bad_files(tmp_path):
    missing = run_cli("replay", str(tmp_path / "missing.rrd"))
    assert missing.returncode == 2 and "no such file" in missing.stderr
    junk = tmp_path / "junk.rrd"
    junk.write_text("not a recording\n")
    bad = run_cli("replay", str(junk), "--resolve")
    assert bad.returncode == 2 and "dlo: error:" in bad.stderr and "Traceback" not in bad.stderr


def test_cli_recording_flag_errors():
    done = run_cli("solve", "default_cable", "--connect", "http://example.org")
    assert done.returncode == 2 and "--connect" in done.stderr and "Traceback" not in done.stderr
    env = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}
    done = run_cli("solve", "default_cable", "--spawn", env=env)
    assert done.returncode == 2 and "--spawn" in done.stderr and "no display" in done.stderr


@pytest.mark.skipif(os.environ.get("DLO_TEST_SCREENSHOT") != "1",
                    reason="opt-in (DLO_TEST_SCREENSHOT=1): renders with a headless viewer, needs a Vulkan driver")
def test_screenshot(cli_solve, tmp_path):
    png = tmp_path / "shot.png"
    done = run_cli("replay", str(cli_solve[0]), "--screenshot", str(png))
    assert done.returncode == 0, done.stderr[-3000:]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 50_000
