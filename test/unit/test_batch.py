"""Many queries at once (dlo_ros.solver.parallel.batch, #14): the batch answers equal the single answers
(``solve(poses, commit=False)``), in order, with any executor; the caller's stream is untouched; a bad
query answers with its status without losing the others."""
from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver
from dlo_ros.solver.parallel.batch import process_pool, query_many, stop_pool
from random_scenes import targets_near


@pytest.fixture(scope="module")
def scene():
    return load_scene("default_cable")


def assert_same_answers(batch, single):
    assert [r.status for r in batch] == [r.status for r in single]
    for a, b in zip(batch, single):
        if a.ok:
            np.testing.assert_allclose(a.points, b.points, atol=1e-9)
            assert a.stable == b.stable


@pytest.mark.parametrize("model", ["full"])  # auto: test_any_executor_order_kept_and_bad_queries_answered
def test_batch_answers_equal_single_answers_and_leave_the_stream_alone(scene, model, monkeypatch):
    monkeypatch.setenv("DLO_NO_COMPILE", "1")  # inherited by the spawned workers
    from dataclasses import replace

    options = replace(scene.options, model=model)
    solver = make_solver(scene.problem, options, compile="off", checks="sync")
    assert solver.solve().ok
    targets = targets_near(scene.problem, 8, radius=0.1)
    single = [solver.solve(t, commit=False) for t in targets]
    assert all(r.ok for r in single)
    step = {"right": (scene.problem.grip("right").pose.position + [0.01, 0.0, 0.0],
                      scene.problem.grip("right").pose.orientation)}
    reference = make_solver(scene.problem, options, compile="off", checks="sync")
    reference.solve()
    expected = reference.solve(step)  # the stream's next update without any query in between
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        batch = solver.query_many(targets, executor=pool)
    assert_same_answers(batch, single)
    after = solver.solve(step)
    assert after.iterations == expected.iterations
    np.testing.assert_allclose(after.points, expected.points, atol=1e-12)


def test_any_executor_order_kept_and_bad_queries_answered(scene, monkeypatch):
    monkeypatch.setenv("DLO_NO_COMPILE", "1")
    targets = targets_near(scene.problem, 5, radius=0.1, seed=1)
    far = {"right": ((5.0, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))}  # beyond the string's reach
    unknown = {"middle": ((0.3, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))}
    queries = [targets[0], far, targets[1], unknown, *targets[2:]]
    solver = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    solver.solve()
    single = [solver.solve(t, commit=False) for t in queries]
    assert single[1].status == "unreachable" and single[3].status == "invalid"
    with ThreadPoolExecutor(2) as threads:  # in-process: the workers share one solver, one at a time
        batch = query_many(make_solver, scene.problem, scene.options, queries, threads, chunks=3)
    assert_same_answers(batch, single)
    assert "middle" in batch[3].message


def test_a_fixed_model_solver_s_queries_are_answered_by_its_own_model(scene, monkeypatch):
    """``ShapeSolver.query_many`` hands its workers its own class as the factory: a ShapeSolver of
    ``model: auto`` options (the full model) gets the answers of that model, not those of an auto
    solver, which chooses a smaller model for this scene."""
    import collections

    from dlo_ros.solver import ShapeSolver
    from dlo_ros.solver.parallel import batch

    monkeypatch.setenv("DLO_NO_COMPILE", "1")
    monkeypatch.setattr(batch, "_WORKER_SOLVERS", collections.OrderedDict())
    assert scene.options.model == "auto"
    solver = ShapeSolver(scene.problem, scene.options, compile="off")
    assert solver.solve().ok
    targets = targets_near(scene.problem, 3, radius=0.1, seed=4)
    single = [solver.solve(t, commit=False) for t in targets]
    with ThreadPoolExecutor(1) as threads:  # in-process: the worker's solver can be looked at
        answers = solver.query_many(targets, executor=threads)
    assert_same_answers(answers, single)
    (held,) = (entry[1] for entry in batch._WORKER_SOLVERS.values())
    assert type(held) is ShapeSolver


def test_a_dask_cluster_runs_the_same_call(scene, monkeypatch):
    """Optional extra: a local Dask cluster's executor (``client.get_executor()``)."""
    distributed = pytest.importorskip("distributed")
    monkeypatch.setenv("DLO_NO_COMPILE", "1")
    targets = targets_near(scene.problem, 4, radius=0.1, seed=2)
    solver = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    solver.solve()
    single = [solver.solve(t, commit=False) for t in targets]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster, \
            distributed.Client(cluster) as client:
        batch = solver.query_many(targets, executor=client.get_executor())
    assert_same_answers(batch, single)


STOP_POOL_SCRIPT = """
import time
from dlo_ros.solver.parallel.batch import process_pool, stop_pool

if __name__ == "__main__":
    pool = process_pool(2)
    pool.submit(time.sleep, 0.0).result()
    in_flight = [pool.submit(time.sleep, 60.0) for _ in range(4)]
    time.sleep(0.5)
    started = time.monotonic()
    ended = stop_pool(pool, timeout=10.0)
    print(ended, round(time.monotonic() - started, 3), all(f.done() for f in in_flight))
"""


def test_a_pool_stops_at_once_and_its_process_exits_cleanly(tmp_path):
    """The node's shutdown: queries in flight (here a minute long) are abandoned, the pool's manager
    thread has ended when ``stop_pool`` returns, and the interpreter then exits with no traceback
    (CPython 3.11 printed 'OSError: Bad file descriptor' when a pool shut down with wait=False raced
    the exit hook)."""
    import subprocess
    import sys

    script = tmp_path / "stop_pool.py"
    script.write_text(STOP_POOL_SCRIPT)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    ended, seconds, all_done = proc.stdout.split()
    assert ended == "True" and all_done == "True"
    assert float(seconds) < 10.0  # well below the minute a graceful shutdown would wait


def test_background_workers_yield_to_the_parent():
    """A node's query and fit workers (``background=True``) run BACKGROUND_NICE above the caller's nice
    value (so that on a shared core the stream's updates come first); a planner's default pool runs at
    the caller's."""
    import os

    from dlo_ros.solver.parallel.batch import BACKGROUND_NICE

    base = os.nice(0)
    for background, nice in ((True, min(base + BACKGROUND_NICE, 19)), (False, base)):
        pool = process_pool(1, background=background)
        try:
            assert pool.submit(os.nice, 0).result(timeout=60) == nice
        finally:
            stop_pool(pool)


def test_a_worker_follows_a_moving_stream_by_warm_updates(scene, monkeypatch):
    """A node's worker gets the scene at the stream's current targets with every query.  When only the
    grips moved since its last call, it updates its held shape as the stream does (a warm update, auto's
    checks every recheck_every updates) instead of re-setting the scene (which checks the model at once):
    its answers equal those of one in-process auto solver taken through the same targets."""
    import collections

    from dlo_ros.model.problem import GripPose
    from dlo_ros.solver.parallel import batch

    monkeypatch.setattr(batch, "_WORKER_SOLVERS", collections.OrderedDict())
    problem = scene.problem
    rot = problem.grip("right").pose.orientation
    held = [problem.with_grip_poses({"right": GripPose(problem.grip("right").pose.position + d, rot)})
            for d in (np.zeros(3), np.array([0.004, 0.0, 0.003]), np.array([0.008, 0.0, 0.006]))]
    queries = targets_near(problem, 3, seed=3)
    reference = make_solver(problem, scene.options, compile="off", checks="sync")
    assert reference.solve().ok
    checks = []
    original = batch._grips_moved_only
    monkeypatch.setattr(batch, "_grips_moved_only", lambda a, b: checks.append(original(a, b)) or checks[-1])
    for k, (h, q) in enumerate(zip(held, queries)):
        (answer,) = batch.solve_chunk(batch.scene_payload(make_solver, h, scene.options), [q], "off")
        if k:
            assert reference.solve({g.name: g.pose for g in h.grips}).ok
        expected = reference.solve(q, commit=False)
        assert answer.ok and expected.ok
        np.testing.assert_allclose(answer.points, expected.points, atol=1e-12)
    assert checks == [True, True]
    stiffer = replace(problem, string=replace(problem.string, bend_stiffness=problem.string.bend_stiffness.scaled(2.0)))
    assert not original(problem, stiffer) and original(problem, held[2])


def test_a_node_workers_checks_run_beside_its_queries_not_in_front_of_them(scene, monkeypatch):
    """The node's query workers (``checks='background'``) hold a shape that follows the stream: auto's
    checks, due every recheck_every held updates, run on the worker's check thread, never inside the
    held update a query waits for (only the cold first solve is checked in line, as in both modes);
    a batch's workers (``'sync'``) run them in line, as before."""
    import collections
    import threading

    from dlo_ros.model.problem import GripPose
    from dlo_ros.solver.auto.checks import ModelChecks
    from dlo_ros.solver.parallel import batch

    ran_on = {"background": [], "sync": []}  # the threads each mode's checks ran on
    original = ModelChecks.evaluate

    def recording(self, snap, *a, **kw):
        ran_on[current].append(threading.current_thread().name)
        return original(self, snap, *a, **kw)

    monkeypatch.setattr(ModelChecks, "evaluate", recording)
    problem = scene.problem
    rot = problem.grip("right").pose.orientation
    query = targets_near(problem, 1, seed=5)[0]
    updates = scene.options.recheck_every + 2
    for checks in ("background", "sync"):
        current = checks
        monkeypatch.setattr(batch, "_WORKER_SOLVERS", collections.OrderedDict())
        for k in range(updates):
            moved = problem.with_grip_poses(
                {"right": GripPose(problem.grip("right").pose.position + 0.002 * k * np.array([1.0, 0.0, 1.0]), rot)})
            (answer,) = batch.solve_chunk(batch.scene_payload(make_solver, moved, scene.options), [query], "off", checks)
            assert answer.ok, answer.message
        (solver,) = (entry[1] for entry in batch._WORKER_SOLVERS.values())
        assert solver.checks == checks
        solver.close()
    # a cold solve is checked before it returns in both modes (#37, check_schedule.py), on the
    # caller's thread; a held update's check, on the check thread with 'background'
    main = threading.current_thread().name
    background, sync = ran_on["background"], ran_on["sync"]
    assert len(background) >= 2 and background[0] == main, background
    assert all(name.startswith("dlo-auto-check") for name in background[1:]), background
    assert len(sync) >= 2 and set(sync) == {main}, sync
