"""The node's worker processes (#35): none outlives a SIGKILLed node (query workers, the fit worker and
multiprocessing's resource tracker), and a query worker that dies is replaced: the next query is
answered with a shape."""
from __future__ import annotations

import os
import signal
import sys

import pytest

from dlo_ros.node.client import NodeProcess, allocate_domain_id, running_node
from support.node import group_processes, node_args, wait_until
from support.procs import children, ended

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

LEFT = ((0.0, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))
RIGHT = ((0.55, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))


def test_no_child_outlives_a_sigkilled_node(tmp_path):
    with allocate_domain_id() as lease:
        proc = NodeProcess(list(node_args("query_workers:=2", "fit.enabled:=true")), lease.domain_id,
                           log_path=tmp_path / "node.log")
        try:
            # two query workers, the fit worker and the resource tracker, started after the first shape
            started = wait_until(lambda: len(children(proc.pid)) >= 4 or not proc.alive(), 120.0)
            assert started and proc.alive(), (group_processes(proc.pid), proc.output())
            before = group_processes(proc.pid)
            proc.send_signal(signal.SIGKILL)
            assert proc.wait(10.0) == -signal.SIGKILL
            assert wait_until(lambda: not group_processes(proc.pid), 5.0), \
                f"left running: {group_processes(proc.pid)} (before the kill: {before})"
        finally:
            proc.stop(sig=signal.SIGKILL)
            for line in group_processes(proc.pid):  # a failed test leaves nothing behind
                os.kill(int(line.split()[0]), signal.SIGKILL)


def test_a_dead_query_worker_is_replaced(tmp_path):
    with running_node(*node_args("query_workers:=1"), log_path=tmp_path / "node.log") as (proc, cl):
        points, _ = cl.query(LEFT, RIGHT, timeout=60.0)
        assert len(points), proc.output()
        workers = [p for p in children(proc.pid)
                   if "spawn_main" in open(f"/proc/{p}/cmdline").read()]
        assert len(workers) == 1, workers
        os.kill(workers[0], signal.SIGKILL)
        # ended: a zombie or gone.  An empty cmdline is not enough: the kernel drops the memory
        # map (and the cmdline) before it closes the files, and the pool sees a death by the
        # worker's pipe closing; a query sent in between is in flight on the dying worker
        wait_until(lambda: ended(workers[0]), 5.0)
        points, _ = cl.query(LEFT, RIGHT, timeout=60.0)  # on a new worker (it builds its solver first)
        assert len(points), proc.output()
    assert proc.returncode == 0, proc.output()
