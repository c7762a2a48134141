"""The managed (lifecycle) node over real DDS (#40): every transition, what each state publishes and
refuses, the bad-scene failure, memory and worker processes returned by cleanup, and the exit after
shutdown."""
from __future__ import annotations

import sys
import time

import pytest

from dlo_ros.node.client import DloClient, NodeProcess, allocate_domain_id
from dlo_ros.node.client.lifecycle import LifecycleClient
from visualization_msgs.msg import Marker, MarkerArray
from support.node import node_args, wait_until
from support.procs import children

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

LEFT = ((0.0, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))
RIGHT = ((0.55, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))
RIGHT2 = ((0.5, 0.05, 0.35), (0.0, 0.0, 0.0, 1.0))


def workers(pid: int) -> list[int]:
    """The node's worker processes (query and fit workers; not multiprocessing's resource tracker)."""
    out = []
    for p in children(pid):
        try:
            if "spawn_main" in open(f"/proc/{p}/cmdline").read():
                out.append(p)
        except OSError:
            pass
    return out


@pytest.fixture
def managed(tmp_path, request):
    """A managed node (query_workers 1; more -p values from the test's parameter) in its own domain,
    a client and a lifecycle client."""
    extra = getattr(request, "param", ())
    with allocate_domain_id() as lease:
        proc = NodeProcess(["--managed", *node_args("query_workers:=1", *extra)], lease.domain_id,
                           log_path=tmp_path / "node.log")
        client = DloClient(lease.domain_id)
        try:
            yield proc, client, LifecycleClient(client), lease.domain_id
        finally:
            client.close()
            proc.stop()


def test_every_transition_and_what_each_state_publishes(managed):
    proc, client, lc, domain = managed
    capsules = client.collect(MarkerArray, "capsules")
    assert lc.state(30.0) == "unconfigured"
    assert "configure" in lc.available()
    assert client.wait_for_path(1.0) is None  # nothing before configure
    assert lc.change("configure"), proc.output()
    assert lc.state() == "inactive"
    assert wait_until(lambda: workers(proc.pid), 60.0), "the query worker starts on configure"
    # inactive: the first shape is held, not published; targets and queries are refused
    assert client.wait_for_path(1.0) is None, "a shape was published while inactive"
    assert client.wait_for_subscribers(10.0)
    client.publish_targets([LEFT, RIGHT2])
    answer = client.query_shape(LEFT, RIGHT, timeout=30.0)
    assert not answer.verified and answer.status == "inactive", answer
    assert client.wait_for_path(1.0) is None
    assert client.wait_for_diagnostics(lambda v, _s: v.get("lifecycle") == "inactive", 10.0)
    assert not capsules, "capsules were published while inactive"
    # active: the held shape at once, then every target
    assert lc.change("activate")
    first = client.wait_for_path(5.0)
    assert first is not None and len(first.points) > 2
    n = client.path_count
    client.publish_targets([LEFT, RIGHT2])
    assert client.wait_for(lambda: client.path_count > n, 30.0)
    moved = client.latest_path()
    assert abs(moved.points[-1][1] - 0.05) < 1e-6
    assert client.query_shape(LEFT, RIGHT, timeout=60.0).verified
    assert wait_until(lambda: capsules, 5.0), "no capsules while active"
    # inactive again: refused, the capsules withdrawn, the last shape stays latched for a late
    # subscriber
    shown = len(capsules)
    assert lc.change("deactivate")
    assert client.wait_for(lambda: len(capsules) > shown and len(capsules[-1].markers) == 1, 5.0)
    assert capsules[-1].markers[0].action == Marker.DELETEALL
    n = client.path_count
    client.publish_targets([LEFT, RIGHT])
    time.sleep(1.0)
    assert client.path_count == n, "a shape was published while inactive"
    with DloClient(domain, client_name="late_subscriber") as late:
        latched = late.wait_for_path(10.0)
        assert latched is not None
        assert abs(latched.points[-1][1] - 0.05) < 1e-6, "the latched shape is the last active one"
    # cleanup: the workers end; unconfigured again
    assert lc.change("cleanup")
    assert lc.state() == "unconfigured"
    assert wait_until(lambda: not workers(proc.pid), 10.0), workers(proc.pid)
    assert lc.change("shutdown")
    assert proc.wait(15.0) == 0, proc.output()
    assert wait_until(lambda: lc.events and lc.events[-1] == ("shuttingdown", "finalized"), 5.0)
    expected = ["configuring", "inactive", "activating", "active", "deactivating", "inactive",
                "cleaningup", "unconfigured", "shuttingdown", "finalized"]
    assert [goal for _, goal in lc.events] == expected
    assert "Traceback" not in proc.output(), proc.output()


def test_shutdown_from_active_leaves_no_worker(managed):
    proc, client, lc, _ = managed
    assert lc.change("configure", 60.0) and lc.change("activate")
    assert wait_until(lambda: workers(proc.pid), 60.0)
    pid_workers = workers(proc.pid)
    assert lc.change("active_shutdown")
    assert proc.wait(15.0) == 0, proc.output()
    assert wait_until(lambda: not any(p in children(proc.pid) for p in pid_workers), 5.0)
    assert "Traceback" not in proc.output(), proc.output()


def test_a_bad_scene_fails_configure_with_the_reason(tmp_path):
    with allocate_domain_id() as lease:
        proc = NodeProcess(["--managed", "--scene", "no_such_scene"], lease.domain_id,
                           log_path=tmp_path / "node.log")
        try:
            with DloClient(lease.domain_id) as client:
                lc = LifecycleClient(client)
                assert lc.state(30.0) == "unconfigured"
                assert not lc.change("configure")
                assert lc.state() == "unconfigured"
                assert proc.alive()
                assert wait_until(lambda: "configure failed" in proc.output(), 5.0)
                line = next(x for x in proc.output().splitlines() if "configure failed" in x)
                assert "no_such_scene" in line and "scene" in line, line
                assert lc.change("shutdown")
            assert proc.wait(15.0) == 0, proc.output()
        finally:
            proc.stop()
    assert "Traceback" not in proc.output()


@pytest.mark.parametrize("managed", [("fit.enabled:=true",)], indirect=True)
def test_configure_cleanup_cycles_return_their_memory(managed):
    """RSS after each cleanup stays at the level of the second cleanup: 20 cycles, no growth, with
    every part (query and fit workers, whose guard condition once kept each old core alive: 20 MB a
    cycle).  The first configure loads what a process loads once (bench/results/managed_memory.md)."""
    proc, client, lc, _ = managed
    assert lc.state(30.0) == "unconfigured"
    base = proc.rss_bytes()
    after = []
    configured = []
    for _ in range(20):
        assert lc.change("configure", 60.0), proc.output()
        configured.append(proc.rss_bytes())
        assert lc.change("cleanup")
        after.append(proc.rss_bytes())
    mb = 1e-6
    growth = (after[-1] - after[1]) * mb
    print(f"RSS unconfigured {base * mb:.0f} MB, configured {configured[0] * mb:.0f}..{max(configured) * mb:.0f} MB, after cleanup "
          f"{after[0] * mb:.0f} (1st) {after[1] * mb:.0f} (2nd) {after[-1] * mb:.0f} MB (20th)")
    assert growth < 8.0, (after, configured)
    assert after[-1] < max(configured), (after, configured)


def test_transitions_the_state_does_not_have_are_refused(managed, tmp_path):
    """rclpy raises out of change_state for a transition the state lacks (ros2/rclpy#1209): the node
    answers success = False and keeps running; a shutdown from inactive ends the process."""
    proc, client, lc, _ = managed
    assert lc.state(30.0) == "unconfigured"
    assert not lc.change("deactivate") and not lc.change("activate")
    assert lc.state() == "unconfigured" and proc.alive()
    assert lc.change("configure", 60.0)
    assert not lc.change("configure") and lc.state() == "inactive"
    assert lc.change("inactive_shutdown")
    assert proc.wait(15.0) == 0, proc.output()
    assert "Traceback" not in proc.output() and "refused" in proc.output()


def test_each_configure_records_to_its_own_file(tmp_path):
    rrd = tmp_path / "run.rrd"
    with allocate_domain_id() as lease:
        proc = NodeProcess(["--managed", *node_args(f"record.rrd:={rrd}", "query_workers:=0")],
                           lease.domain_id, log_path=tmp_path / "node.log")
        try:
            with DloClient(lease.domain_id) as client:
                lc = LifecycleClient(client)
                assert lc.state(30.0) == "unconfigured"
                for _ in range(2):
                    assert lc.change("configure", 60.0) and lc.change("cleanup")
                assert lc.change("shutdown")
            assert proc.wait(15.0) == 0, proc.output()
        finally:
            proc.stop()
    second = tmp_path / "run.2.rrd"
    assert rrd.is_file() and second.is_file(), sorted(p.name for p in tmp_path.iterdir())
    assert rrd.stat().st_size > 1000 and second.stat().st_size > 1000
