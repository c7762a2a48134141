"""`dlo dataset`: a plan's samples solved into Parquet shards, every answer stored, resumable (#39).

Checked against the solver itself in this process (each stored shape equals the answer of the same
query to a solver of the scene), against the plan (every sample once, in order, the same targets
for the same seed), and through the command line as a user runs it: a malformed plan, an occupied
output folder, Ctrl-C in the middle and ``--resume``, a Dask cluster.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.dataset import (
    DatasetError,
    PlanError,
    build_dataset,
    load,
    load_arrays,
    plan_from_dict,
    read_manifest,
)
from dlo_ros.dataset.store import shard_path
from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver

ROOT = Path(__file__).resolve().parents[2]
# around the right grip (0.6, 0, 0.4): reachable, some samples pressed onto the table
BOX = {"min": [0.5, -0.1, -0.05], "max": [0.7, 0.1, 0.45]}


def plan_dict(samples=12, chunk=4, **more) -> dict:
    return {"samples": samples, "seed": 5, "chunk": chunk, "grips": {"right": {"position_box": BOX}}, **more}


@pytest.fixture(scope="module")
def scene():
    return load_scene("default_cable")


@pytest.fixture(scope="module")
def built(scene, tmp_path_factory):
    """A data set of 12 samples in 3 shards, made on two local workers."""
    out = tmp_path_factory.mktemp("dataset") / "out"
    summary = build_dataset(scene, plan_from_dict(plan_dict()), out, workers=2, progress=False)
    return out, summary


@pytest.mark.parametrize(
    "change, field",
    [
        ({"sample": 3}, "plan.sample: unknown key"),
        ({"samples": 0}, "plan.samples: must be an integer"),
        ({"samples": True}, "plan.samples: must be an integer"),
        ({"seed": -1}, "plan.seed"),
        ({"start": "warm"}, "plan.start: must be one of held, cold, previous"),
        ({"grips": {}}, "plan.grips: must map at least one grip"),
        ({"grips": {"right": {"position_grid": {"min": [0, 0, 0], "max": [1, 1, 1], "counts": [2, 0, 1]}}}},
         "plan.grips.right.position_grid.counts: each ≥ 1"),
        ({"grips": {"right": {"around_path": {"points": [[0, 0, 0]], "spread": 0.0}}}},
         "plan.grips.right.around_path.points: must be 2 to"),
        ({"grips": {"right": {"around_path": {"points": [[0, 0, 0], [1, 0, 0]], "spread": -1}}}},
         "plan.grips.right.around_path.spread: must be a number"),
        ({"grips": {"right": {"position_box": {"min": [0, 0], "max": [1, 1, 1]}}}},
         "plan.grips.right.position_box.min: must be 3 finite numbers"),
        ({"grips": {"right": {"position_box": {"min": [0, 0, float("nan")], "max": [1, 1, 1]}}}},
         "plan.grips.right.position_box.min"),
        ({"grips": {"right": {"position_box": {"min": [1, 0, 0], "max": [0, 1, 1]}}}},
         "plan.grips.right.position_box: min must not exceed max"),
        ({"grips": {"right": {"box": BOX}}}, "plan.grips.right: must be one of {position_box"),
        ({"resolution": 1}, "plan.resolution: 0"),
        ({"resolution": 10001}, "plan.resolution: must be an integer in"),
        ({"samples": 10**7, "chunk": 1}, "plan.chunk: 10000000 shards, at most 1000000"),
        ({"chunk": 10000, "samples": 20000, "resolution": 401}, "plan.chunk: 10000 samples × 401"),
        ({"samples": 2.5}, "plan.samples: must be an integer"),
        ({"string": {"radius": {"min": 0.0, "max": 0.01}}}, "plan.string.radius: unknown"),
        ({"string": {"bend_stiffness": {"min": 0.02, "max": 0.01}}}, "plan.string.bend_stiffness: min and max"),
        ({"string": {"weight_per_length": {"min": 0.0, "max": 1.0, "log": True}}},
         "plan.string.weight_per_length.min: must be > 0"),
        ({"string": {"bend_stiffness": {"min": 0.0, "max": 1.0}}}, "plan.string.bend_stiffness.min: must be > 0"),
        ({"grips": {"right": {"position_box": {"min": [0, 0, 0], "max": [1e308, 1, 1]}}}},
         "plan.grips.right.position_box.max: must be 3 finite numbers"),
    ],
)
def test_a_malformed_plan_names_its_field(change, field):
    with pytest.raises(PlanError, match=field.replace("{", r"\{").replace("(", r"\(")):
        plan_from_dict({**plan_dict(), **change})


def test_a_grip_the_scene_lacks_is_named(scene, tmp_path):
    plan = plan_from_dict({**plan_dict(), "grips": {"middle": {"position_box": BOX}}})
    with pytest.raises(PlanError, match=r"plan.grips.middle: no such grip"):
        build_dataset(scene, plan, tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


def test_the_same_plan_and_seed_give_the_same_samples_in_any_chunking(scene):
    plan = plan_from_dict(plan_dict(samples=50))
    whole = plan.targets(scene.problem)
    again = plan_from_dict(plan_dict(samples=50, chunk=7)).targets(scene.problem, 13, 29)
    assert len(whole) == 50 and len(again) == 16
    for a, b in zip(whole[13:29], again):
        np.testing.assert_array_equal(a["right"].position, b["right"].position)
    positions = np.array([t["right"].position for t in whole])
    assert np.all(positions >= BOX["min"]) and np.all(positions <= BOX["max"])
    other = plan_from_dict({**plan_dict(samples=50), "seed": 6}).targets(scene.problem)
    assert not np.allclose(positions, [t["right"].position for t in other])
    # orientations kept, the other grip untouched
    assert all(set(t) == {"right"} for t in whole)
    np.testing.assert_array_equal(whole[0]["right"].orientation, scene.problem.grip("right").pose.orientation)


def test_string_values_are_drawn_per_sample_and_solved_with(scene, tmp_path):
    """A plan's material ranges: each sample's values in range (log-uniform where asked), the same
    for any chunking; every row stores the values it was solved with, and its shape is the answer
    of a solver of the scene with those values (the query from its own equilibrium)."""
    ranges = {"bend_stiffness": {"min": 0.01, "max": 0.04, "log": True},
              "weight_per_length": {"min": 0.3, "max": 0.7}}
    plan = plan_from_dict({**plan_dict(samples=6, chunk=3), "string": ranges})
    values = plan.values()
    assert values[3:5] == plan_from_dict({**plan_dict(samples=6, chunk=2), "string": ranges}).values(3, 5)
    rf = np.array([v["bend_stiffness"] for v in values])
    assert np.all((rf >= 0.01) & (rf <= 0.04)) and len(set(rf)) == 6
    summary = build_dataset(scene, plan, tmp_path / "out", workers=1, progress=False)
    a = load_arrays(tmp_path / "out")
    assert summary.complete
    np.testing.assert_allclose(a["bend_stiffness"], rf)
    np.testing.assert_allclose(a["weight_per_length"], [v["weight_per_length"] for v in values])
    np.testing.assert_allclose(a["twist_stiffness"], 0.015)  # the scene's, not drawn
    from dlo_ros.dataset.materials import with_values

    targets = plan.targets(scene.problem)
    for i in (0, 4):
        solver = make_solver(with_values(scene.problem, values[i]), scene.options, compile="off", checks="sync")
        solver.solve()
        r = solver.solve(targets[i], commit=False)
        assert r.status == a["status"][i]
        if r.ok:
            np.testing.assert_allclose(a["points"][i], r.points, atol=1e-6)
    with pytest.raises(PlanError, match="plan.string.stretch_stiffness: the scene's string is inextensible"):
        build_dataset(scene, plan_from_dict({**plan_dict(), "string": {"stretch_stiffness": {"min": 1, "max": 2}}}),
                      tmp_path / "other", progress=False)


def test_an_integral_float_is_a_count():
    assert plan_from_dict({**plan_dict(), "samples": 1e6, "chunk": 1e3}).samples == 10**6


def test_a_grid_visits_every_lattice_point_and_a_path_runs_in_plan_order(scene):
    grid = plan_from_dict({"samples": 12, "seed": 0, "grips": {"right": {"position_grid": {
        "min": [0.5, -0.1, 0.3], "max": [0.7, 0.1, 0.4], "counts": [3, 2, 2]}}}})
    points = np.array([t["right"].position for t in grid.targets(scene.problem)])
    expected = [[x, y, z] for x in (0.5, 0.6, 0.7) for y in (-0.1, 0.1) for z in (0.3, 0.4)]
    np.testing.assert_allclose(points, expected, atol=1e-15)
    path = plan_from_dict({"samples": 5, "seed": 0, "grips": {"right": {"around_path": {
        "points": [[0.5, 0.0, 0.4], [0.7, 0.0, 0.4], [0.7, 0.2, 0.4]], "spread": 0.0}}}})
    points = np.array([t["right"].position for t in path.targets(scene.problem)])
    np.testing.assert_allclose(points, [[0.5, 0, 0.4], [0.6, 0, 0.4], [0.7, 0, 0.4], [0.7, 0.1, 0.4],
                                        [0.7, 0.2, 0.4]], atol=1e-15)
    spread = plan_from_dict({"samples": 5, "seed": 0, "grips": {"right": {"around_path": {
        "points": [[0.5, 0.0, 0.4], [0.7, 0.0, 0.4]], "spread": 0.01}}}}).targets(scene.problem, 1, 4)
    moved = np.array([t["right"].position for t in spread]) - [[0.55, 0, 0.4], [0.6, 0, 0.4], [0.65, 0, 0.4]]
    assert np.all(np.abs(moved) <= 0.01) and np.any(np.abs(moved) > 0.001)
    # the plan round-trips through its manifest form
    for plan in (grid, path):
        assert plan_from_dict(plan.as_dict()) == plan


def test_every_sample_is_stored_once_with_the_solvers_own_answer(scene, built):
    out, summary = built
    a = load_arrays(out)
    assert summary.complete and summary.written == 12 and not summary.failed_chunks
    np.testing.assert_array_equal(a["sample"], np.arange(12))
    assert set(a["status"]) <= {"ok", "unverified", "infeasible", "failed"} and "ok" in set(a["status"])
    plan = plan_from_dict(plan_dict())
    targets = plan.targets(scene.problem)
    np.testing.assert_allclose(a["targets"][:, 0, :3], [t["right"].position for t in targets])
    solver = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    solver.solve()
    for i in (0, 5, 11):
        r = solver.solve(targets[i], commit=False)
        assert a["status"][i] == r.status
        if r.ok:
            np.testing.assert_allclose(a["points"][i], r.points, atol=1e-9)
            np.testing.assert_allclose(a["grip_force"][i, 1], r.grips["right"].force, atol=1e-9)
    # every stored ok row, re-solved from its poses, is the same verified equilibrium
    for i in np.flatnonzero(a["status"] == "ok"):
        r = solver.solve(targets[i], commit=False)
        assert r.ok and r.equilibrium_residual_m <= a["tolerance_m"][i]
        np.testing.assert_allclose(a["points"][i], r.points, atol=1e-9)
    ok = a["status"] == "ok"
    # an ok sample is a verified equilibrium with a verdict: residual within the tolerance, stable
    # said; its model's estimate meets the tolerance where auto checked it (a query touching the
    # table, or refined), else there is none (null), never a "met" without one
    assert all(v is not None for v in a["stable"][ok])
    checked = np.isfinite(a["estimated_error_m"])
    assert all(a["tolerance_met"][ok & checked]) and all(v is None for v in a["tolerance_met"][ok & ~checked])
    assert np.all(a["estimated_error_m"][ok & checked] <= a["tolerance_m"][ok & checked])
    assert np.all(a["equilibrium_residual_m"][ok] <= a["tolerance_m"][ok])
    assert np.all(np.isfinite(a["energy_total"][ok]))
    m = read_manifest(out)
    assert m["complete"] and sum(m["counts"].values()) == 12 and m["plan"]["seed"] == 5
    assert m["plan_grips"] == ["right"] and m["scene_grips"] == ["left", "right"]
    assert m["scene"]["name"] == "default_cable" and m["chunks"] == 3


def test_resume_solves_only_the_missing_shard_and_refuses_another_plan(scene, built, tmp_path):
    out, _ = built
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-r", str(out), str(copy)], check=True)
    first = load(copy)
    shard_path(copy, 1).unlink()
    summary = build_dataset(scene, plan_from_dict(plan_dict()), copy, workers=1, resume=True, progress=False)
    assert summary.written == 4 and summary.resumed == 8 and summary.complete
    again = load(copy)
    assert again.column("sample").to_pylist() == list(range(12))
    assert again.column("status").to_pylist() == first.column("status").to_pylist()
    for x, y in zip(again.column("points").to_pylist(), first.column("points").to_pylist()):
        np.testing.assert_allclose(x, y, atol=1e-9)
    with pytest.raises(DatasetError, match="cannot resume: it was made with another plan"):
        build_dataset(scene, plan_from_dict({**plan_dict(), "seed": 9}), copy, resume=True, progress=False)
    with pytest.raises(DatasetError, match="not empty; --resume"):
        build_dataset(scene, plan_from_dict(plan_dict()), copy, progress=False)


def test_start_previous_streams_each_chunk_along_the_plan(scene, tmp_path):
    """'previous': within a chunk each sample starts from the one before it (a stream, the branch
    its neighbour leads to); the rows equal an in-process stream of the same chunk, every one ok."""
    from dataclasses import replace

    plan = plan_from_dict({"samples": 8, "seed": 0, "chunk": 4, "start": "previous", "grips": {"right": {
        "around_path": {"points": [[0.6, 0.0, 0.4], [0.45, 0.0, 0.25], [0.45, 0.15, 0.25]], "spread": 0.0}}}})
    summary = build_dataset(scene, plan, tmp_path / "out", workers=1, progress=False)
    a = load_arrays(tmp_path / "out")
    assert summary.complete and list(a["start"]) == ["held", "previous", "previous", "previous"] * 2
    assert set(a["status"]) == {"ok"}
    targets = plan.targets(scene.problem)
    for chunk in (0, 1):
        solver = make_solver(scene.problem, replace(scene.options, update_time_limit=0.0), compile="off",
                             checks="sync")
        solver.solve()
        for i in range(4 * chunk, 4 * chunk + 4):
            # the chunk's first sample, and any unverified one, checked at once (work._along)
            r = solver.solve(targets[i], commit=True, check_now=i == 4 * chunk)
            if r.status == "unverified":
                r = solver.solve(targets[i], commit=True, check_now=True)
            assert a["status"][i] == r.status
            if r.ok:
                np.testing.assert_allclose(a["points"][i], r.points, atol=1e-9)
        solver.close()


def test_resume_refuses_a_folder_without_its_manifest_and_redoes_a_damaged_shard(scene, built, tmp_path):
    out, _ = built
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-r", str(out), str(copy)], check=True)
    (copy / "manifest.json").rename(tmp_path / "manifest.json")
    with pytest.raises(DatasetError, match="not empty; it holds no data-set manifest"):
        build_dataset(scene, plan_from_dict(plan_dict()), copy, resume=True, progress=False)
    (tmp_path / "manifest.json").rename(copy / "manifest.json")
    damaged = shard_path(copy, 2)
    damaged.write_bytes(damaged.read_bytes()[:100])
    with pytest.raises(ValueError, match="part-000002.parquet: damaged shard"):
        load(copy)
    (copy / "manifest.json").write_text("{ not json")
    with pytest.raises(DatasetError, match="cannot resume: its manifest.json is unreadable"):
        build_dataset(scene, plan_from_dict(plan_dict()), copy, resume=True, progress=False)
    (copy / "manifest.json").write_text((out / "manifest.json").read_text())
    summary = build_dataset(scene, plan_from_dict(plan_dict()), copy, workers=1, resume=True, progress=False)
    assert summary.written == 4 and summary.resumed == 8 and sum(summary.counts.values()) == 12
    assert read_manifest(copy)["counts"] == read_manifest(out)["counts"]
    with pytest.raises(FileNotFoundError, match="no data set here"):
        load(tmp_path / "nothing")


def test_samples_without_a_shape_load_as_nan_rows(scene, tmp_path):
    """Every sample infeasible (the right grip 1.5 m from the left on a 1 m cable): stored, and
    load_arrays still gives (N, K, 3) centrelines, all NaN."""
    plan = plan_from_dict({"samples": 3, "seed": 0, "grips": {"right": {"position_box": {
        "min": [1.5, 0.0, 0.4], "max": [1.6, 0.0, 0.4]}}}})
    summary = build_dataset(scene, plan, tmp_path / "out", workers=1, progress=False)
    a = load_arrays(tmp_path / "out")
    assert summary.complete and "ok" not in summary.counts
    assert a["points"].shape == (3, 51, 3) and np.all(np.isnan(a["points"]))
    assert all(m for m in a["message"])


def test_a_killed_worker_costs_a_retry_not_the_chunk(tmp_path):
    """SIGKILL one local worker while chunks are in flight: its chunk runs again on a new pool,
    the run ends complete (exit 0) with every sample once."""
    psutil = pytest.importorskip("psutil")
    plan = tmp_path / "plan.yaml"
    plan.write_text("samples: 40\nseed: 2\nchunk: 5\n"
                    "grips: {right: {position_box: {min: [0.5, -0.1, 0.3], max: [0.7, 0.1, 0.45]}}}\n")
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen([sys.executable, "-m", "dlo_ros.cli", "dataset", "default_cable", "--plan", str(plan),
                             "--out", str(out), "--workers", "2", "--quiet"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not list((out / "shards").glob("part-*.parquet")) and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = [c for c in psutil.Process(proc.pid).children(recursive=True)
               if "spawn_main" in " ".join(c.cmdline())]
    assert len(workers) == 2
    workers[-1].kill()
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    assert "40 of 40 samples stored" in stdout
    assert load(out).column("sample").to_pylist() == list(range(40))


def _dlo(*args, **kw):
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run([sys.executable, "-m", "dlo_ros.cli", *args], capture_output=True, text=True,
                          env=env, timeout=600, **kw)


def test_the_command_line_refuses_bad_input_in_one_line(tmp_path):
    plan = tmp_path / "plan.yaml"
    plan.write_text("samples: 10\nseed: 1\ngrips: {right: {position_box: {min: [0, 0, 0], max: [1, 1]}}}\n")
    r = _dlo("dataset", "default_cable", "--plan", str(plan), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip() == ("dlo: error: plan.grips.right.position_box.max: must be 3 finite numbers "
                                "[x, y, z] in metres, each within ±1e6")
    r = _dlo("dataset", "default_cable", "--plan", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "none.yaml" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("text, says", [
    ("a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"  # a billion-laughs: 10^6 nodes by aliases
     + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]\n" for i in range(1, 6)), "over a limit"),
    ("samples: [unclosed\n", "YAML syntax error"),
    ("- just\n- a list\n", "plan: must be a mapping"),
    ("samples: 5\nseed: 1\ngrips: {right: {position_box: {min: [0, 0, 0], max: [1, 1, 1]}}}\nextra: !!python/object:os.system {}\n",
     "could not determine a constructor"),
])
def test_a_hostile_plan_file_gets_one_line_naming_it(tmp_path, text, says):
    plan = tmp_path / "plan.yaml"
    plan.write_text(text)
    r = _dlo("dataset", "default_cable", "--plan", str(plan), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.startswith("dlo: error: ") and says in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


def test_a_full_disk_stops_the_run_cleanly_and_what_was_written_stays(scene, tmp_path, monkeypatch):
    """ENOSPC on the third shard: the run stops with one clear error, the two shards written read
    back, and --resume, once there is room, completes the same data set."""
    from dlo_ros.dataset import store

    real, calls = store.write_atomic, []

    def full_after_two(path, data):
        if path.name.endswith(".parquet"):
            calls.append(path.name)
            if len(calls) == 3:
                raise OSError(28, "No space left on device")
        real(path, data)

    monkeypatch.setattr(store, "write_atomic", full_after_two)
    plan = plan_from_dict(plan_dict())
    with pytest.raises(DatasetError, match="cannot write chunk .*No space left on device.*--resume"):
        build_dataset(scene, plan, tmp_path / "out", workers=1, progress=False)
    assert load(tmp_path / "out").num_rows == 8
    assert not list((tmp_path / "out" / "shards").glob(".*tmp"))
    monkeypatch.setattr(store, "write_atomic", real)
    summary = build_dataset(scene, plan, tmp_path / "out", workers=1, resume=True, progress=False)
    assert summary.complete and summary.resumed == 8 and summary.written == 4


def test_a_read_only_output_folder_is_refused_in_one_line(scene, tmp_path, monkeypatch):
    """Where the folder cannot be made or written (read-only: as root here, simulated), one clear
    error and nothing half-made."""
    from pathlib import Path

    def refuse(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "mkdir", refuse)
    with pytest.raises(DatasetError, match=r"out: cannot write there \(Permission denied\)"):
        build_dataset(scene, plan_from_dict(plan_dict()), tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


def _in_the_foreground() -> None:
    """(In the child, before exec) the run as a shell starts it in the foreground: SIGINT and
    SIGTERM at their default actions, whatever this process has (an ignored signal is inherited
    across exec: the suite started in the background by a non-interactive shell has SIGINT
    ignored, and the run, interrupted, went on to exit 0), and niced, its workers too: on a
    loaded machine this process, polling, must not wake only after the run has ended."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.nice(10)


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_keeps_the_written_shards_and_resume_finishes(tmp_path, stop):
    """The command interrupted (Ctrl-C, or a batch scheduler's SIGTERM) once its first shards are
    written: exit 130, what was written stays, and the same command with --resume stores every
    sample once."""
    plan = tmp_path / "plan.yaml"
    plan.write_text(
        "samples: 60\nseed: 3\nchunk: 5\n"
        "grips: {right: {position_box: {min: [0.5, -0.1, 0.2], max: [0.7, 0.1, 0.45]}}}\n"
    )
    out = tmp_path / "out"
    args = ["dataset", "default_cable", "--plan", str(plan), "--out", str(out), "--workers", "2", "--quiet"]
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen([sys.executable, "-m", "dlo_ros.cli", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=_in_the_foreground)
    deadline = time.monotonic() + 300
    while not list((out / "shards").glob("part-*.parquet")) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(stop)
    _, err = proc.communicate(timeout=120)
    written = len(list((out / "shards").glob("part-*.parquet")))
    assert proc.returncode == 130 and "--resume" in err and "Traceback" not in err
    assert 1 <= written < 12 and not list((out / "shards").glob(".*tmp"))
    assert not read_manifest(out)["complete"]
    if stop != signal.SIGINT:
        return  # what --resume then does is the same after either signal: checked once, below
    r = _dlo(*args, "--resume")
    assert r.returncode == 0, r.stderr
    assert "60 of 60 samples stored" in r.stdout and f"{5 * written} were there already" in r.stdout
    table = load(out)
    assert table.column("sample").to_pylist() == list(range(60))
    assert read_manifest(out)["complete"]
    # the same data set as a run never interrupted
    whole = build_dataset(load_scene("default_cable"), plan_from_dict({
        "samples": 60, "seed": 3, "chunk": 5,
        "grips": {"right": {"position_box": {"min": [0.5, -0.1, 0.2], "max": [0.7, 0.1, 0.45]}}}}),
        tmp_path / "whole", workers=2, progress=False)
    assert whole.complete
    other = load(tmp_path / "whole")
    assert table.column("status").to_pylist() == other.column("status").to_pylist()
    for x, y in zip(table.column("points").to_pylist(), other.column("points").to_pylist()):
        np.testing.assert_allclose(x, y, atol=1e-9)


def test_a_dask_cluster_gives_the_local_answers(scene, tmp_path):
    """200 samples on a local Dask cluster of two worker processes: the local pool's rows."""
    distributed = pytest.importorskip("distributed")
    plan = plan_from_dict({"samples": 200, "seed": 8, "chunk": 25, "grips": {"right": {"position_box": {
        "min": [0.5, -0.1, 0.3], "max": [0.7, 0.1, 0.45]}}}})
    assert build_dataset(scene, plan, tmp_path / "local", workers=2, progress=False).complete
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        summary = build_dataset(scene, plan, tmp_path / "dask", executor=client.get_executor(),
                                executor_name="dask", in_flight=4, progress=False)
    assert summary.complete
    local, remote = load(tmp_path / "local"), load(tmp_path / "dask")
    assert remote.num_rows == 200 and "ok" in set(remote.column("status").to_pylist())
    assert remote.column("status").to_pylist() == local.column("status").to_pylist()
    for x, y in zip(remote.column("points").to_pylist(), local.column("points").to_pylist()):
        np.testing.assert_allclose(x, y, atol=1e-9)
    assert read_manifest(tmp_path / "dask")["machine"]["executor"] == "dask"
