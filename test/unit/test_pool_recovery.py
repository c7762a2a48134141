"""Worker processes that recover and clean up after themselves (dlo_ros.solver.parallel.batch, #35): a worker
killed mid-batch makes only its queries answer ``failed`` (naming the cause) and the next call runs on
a rebuilt pool; a query past its timeout answers ``failed``/timeout and its worker is replaced; and
no worker or resource tracker outlives a SIGKILLed parent."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver
from dlo_ros.solver.parallel.batch import query_many
from dlo_ros.solver.parallel.worker_pool import TaskTimeout, WorkerDied, WorkerPool
from random_scenes import targets_near
from support.node import wait_until
from support.procs import children, ended


@pytest.fixture(scope="module")
def scene():
    return load_scene("default_cable")


def reference_answers(scene, targets):
    """Independent answers: one in-process solver, each query from the scene's held shape."""
    solver = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    assert solver.solve().ok
    return [solver.solve(t, commit=False) for t in targets]


def assert_answers(batch, single):
    assert [r.status for r in batch] == [r.status for r in single]
    for a, b in zip(batch, single):
        if a.ok:
            np.testing.assert_allclose(a.points, b.points, atol=1e-9)


def test_a_worker_killed_mid_batch_fails_its_queries_and_the_pool_is_rebuilt(scene, monkeypatch):
    monkeypatch.setenv("DLO_NO_COMPILE", "1")  # inherited by the spawned workers
    targets = targets_near(scene.problem, 24, radius=0.05)
    pool = WorkerPool(2)
    try:
        batch: list = []
        call = threading.Thread(target=lambda: batch.extend(query_many(make_solver, scene.problem, scene.options, targets,
                                                                       pool, chunks=2)))
        call.start()
        pids = wait_until(lambda: pool.worker_pids() if len(pool.worker_pids()) == 2 else None, 60.0)
        assert pids, "the workers never started"
        time.sleep(0.5)  # inside the build or the first queries: the batch takes seconds interpreted
        os.kill(pids[0], signal.SIGKILL)
        call.join(60.0)
        assert not call.is_alive(), "query_many hung on a dead worker"
        assert len(batch) == len(targets)
        failed = [r for r in batch if r.status == "failed" and "SIGKILL" in r.message]
        assert failed, [r.message for r in batch]
        assert all(f"pid {pids[0]}" in r.message for r in failed)
        # the next call: a new pool, every answer equal to the in-process solver's
        again = query_many(make_solver, scene.problem, scene.options, targets[:6], pool, chunks=2)
        assert pool.restarts == 1 and pids[0] not in pool.worker_pids()
        assert_answers(again, reference_answers(scene, targets[:6]))
    finally:
        pool.stop()


def _die() -> None:
    """A task that kills its own worker."""
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_task_whose_worker_dies_is_retried_once_when_asked():
    """retries=1: a task in flight on a worker killed from outside is answered by a new pool; a task
    that kills its worker every time fails with WorkerDied after its one retry (two pools replaced);
    retries=0 (the default) fails at once."""
    pool = WorkerPool(1)
    try:
        first = pool.worker_pids() or [pool.submit(os.getpid).result(60)]
        slow = pool.submit(_sleep_then_pid, 3.0, retries=1)
        time.sleep(1.0)  # the task is running on the worker
        os.kill(first[0], signal.SIGKILL)
        answered_by = slow.result(60)
        assert answered_by != first[0] and answered_by in pool.worker_pids()
        assert pool.restarts == 1
        with pytest.raises(WorkerDied, match="SIGKILL"):
            pool.submit(_die, retries=1).result(60)
        assert pool.restarts == 3
        with pytest.raises(WorkerDied):
            pool.submit(_die).result(60)
        assert pool.restarts == 4
    finally:
        pool.stop()


def test_every_task_in_flight_on_a_pool_whose_worker_died_is_retried():
    """Two workers, two tasks running, one worker killed: its pool is replaced, so both tasks lose
    their pool; with retries=1 both are answered by the new one (the second used to fail at once:
    the first's replacement was taken for a deliberate kill, as a timeout's is)."""
    pool = WorkerPool(2)
    try:
        jobs = [pool.submit(_sleep_then_pid, 3.0, retries=1) for _ in range(2)]
        time.sleep(1.0)
        victim = pool.worker_pids()[0]
        os.kill(victim, signal.SIGKILL)
        answered_by = [job.result(60) for job in jobs]
        assert victim not in answered_by and pool.restarts == 1
    finally:
        pool.stop()


def _sleep_then_pid(seconds: float) -> int:
    time.sleep(seconds)
    return os.getpid()


def test_a_query_past_its_timeout_answers_timeout_and_its_worker_is_replaced(scene, monkeypatch):
    monkeypatch.setenv("DLO_NO_COMPILE", "1")
    targets = targets_near(scene.problem, 4, radius=0.05)
    pool = WorkerPool(1)
    try:
        # a stuck task through the public seam: its worker is killed after 1 s
        assert pool.submit(os.getpid).result(60) > 0
        stuck_pid = pool.worker_pids()[0]
        t0 = time.monotonic()
        with pytest.raises(TaskTimeout, match="timeout"):
            pool.submit(time.sleep, 600.0, timeout=1.0).result(30)
        assert time.monotonic() - t0 < 10.0
        assert wait_until(lambda: not os.path.exists(f"/proc/{stuck_pid}") or ended(stuck_pid), 10.0)
        # a real query batch past its timeout (a fresh worker builds its solver first: seconds)
        t0 = time.monotonic()
        late = query_many(make_solver, scene.problem, scene.options, targets, pool, timeout=0.05)
        assert time.monotonic() - t0 < 10.0
        assert [r.status for r in late] == ["failed"] * len(targets)
        assert all(r.message.startswith("timeout:") for r in late), [r.message for r in late]
        # then answered on a replaced worker
        assert_answers(query_many(make_solver, scene.problem, scene.options, targets, pool), reference_answers(scene, targets))
        assert pool.restarts == 2
    finally:
        pool.stop()


PARENT = """
import os, sys, threading, time
from dlo_ros.solver.parallel.worker_pool import {factory}

if __name__ == "__main__":
    pool = {factory}(2)
    def work():  # from a thread that ends: PR_SET_PDEATHSIG follows the creating thread
        futures = [pool.submit(time.sleep, 0.5) for _ in range(2)]
        [f.result() for f in futures]
        pool.submit(time.sleep, 600.0)  # one worker busy, one idle when the parent dies
    t = threading.Thread(target=work)
    t.start()
    t.join()
    time.sleep(1.0)
    print("ready", flush=True)
    time.sleep(600)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("factory", ["WorkerPool", "process_pool"])
def test_no_worker_or_resource_tracker_outlives_a_sigkilled_parent(tmp_path, factory):
    script = tmp_path / "parent.py"
    script.write_text(PARENT.format(factory=factory))
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    kids: list[int] = []
    try:
        assert parent.stdout.readline().strip() == "ready"
        kids = children(parent.pid)
        names = {pid: open(f"/proc/{pid}/cmdline").read().replace("\0", " ") for pid in kids}
        assert len(kids) == 3, names  # two workers and multiprocessing's resource tracker
        assert any("resource_tracker" in n for n in names.values()), names
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(10)
        deadline = time.monotonic() + 5.0
        while (left := [p for p in kids if not ended(p)]) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not left, {p: names[p] for p in left}
    finally:
        if parent.poll() is None:
            parent.kill()
        for pid in kids:  # whatever survived (the test failed): not left running
            if not ended(pid):
                os.kill(pid, signal.SIGKILL)
