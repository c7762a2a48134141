"""The node over real DDS: bursts of 1,000 targets published as fast as possible.

* the node ends on the last target (its centreline arrives, and nothing older arrives after it);
* the burst builds no queue (far fewer solves than targets; the newest target's latency stays bounded);
* the node's memory (VmRSS from /proc) does not grow across repeated bursts;
* a burst of 1,000 bad targets is counted, logged a few times only (throttled), and harmless.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from support.node import clean_node, node_args

NODE_ARGS = node_args("diagnostics_period:=0.2", "warn_throttle:=1.0")
Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)
BURST = 1000
MIB = 1024 * 1024


@pytest.fixture
def node(tmp_path):
    with clean_node(*NODE_ARGS, log_path=tmp_path / "node.log") as proc_client:
        yield proc_client


def burst(cl, k: int):
    """1,000 targets sweeping the right grip between x = 0.6 and 0.45 (direction alternating per burst)."""
    xs = np.linspace(0.6, 0.45, BURST) if k % 2 == 0 else np.linspace(0.45, 0.6, BURST)
    y = 0.01 * k  # every burst ends somewhere new
    t0 = time.monotonic()
    stamp = 0
    for x in xs:
        stamp = cl.publish_targets([LEFT, ((float(x), y, 0.4), Q)])
    return stamp, (float(xs[-1]), y, 0.4), time.monotonic() - t0


def test_bursts_end_on_the_last_target_without_growing(node):
    proc, cl = node
    rss = []
    latencies = []
    for k in range(6):
        n0 = cl.path_count
        stamp, last, took = burst(cl, k)
        t_sent = time.monotonic_ns()
        ev = cl.wait_for_path(30.0, where=lambda e: e.stamp_ns == stamp)
        assert ev is not None, f"burst {k}: the last target's centreline never came\n{proc.output()}"
        latencies.append((ev.received_mono_ns - t_sent) / 1e9)
        np.testing.assert_allclose(ev.points[-1], last, atol=1e-7)
        solves = cl.path_count - n0
        assert solves < BURST / 4, f"burst {k}: {solves} centrelines for {BURST} targets: a queue"
        time.sleep(0.5)
        assert cl.latest_path().stamp_ns == stamp, "an older shape was published after the newest"
        rss.append(proc.rss_bytes())
        print(f"burst {k}: sent in {took * 1e3:.0f} ms, {solves} solves, newest after "
              f"{latencies[-1] * 1e3:.0f} ms, RSS {rss[-1] / MIB:.1f} MiB")
    values = cl.diagnostic_values()
    received, coalesced = int(values["targets received"]), int(values["targets coalesced"])
    # The target reader keeps only the newest sample (depth 1): DDS replaces most of a burst before the
    # callback, and how many of those the callback sees, and the node then merges, depends on the solve
    # time against the executor's intake (18 of 38 in one CI run, 2 tests at once; 0 in another, where
    # the loaded node took 3-6 samples of each burst).  So the merging itself is asserted without DDS
    # (test_node_engine.py: a burst of 500); here the absence of a queue, by the solve counts and the
    # latency, and that no update failed.
    assert 0 <= coalesced < received and values["failures"] == "0", values
    # one solve plus the last messages, not the burst; a last sample DDS lost is resent at the
    # writer's next heartbeat (Fast DDS: every 3 s), so up to about 3 s (2.4 s in a CI run)
    assert max(latencies) < 4.0, latencies
    # bursts 0-1 warm up (DDS buffers, allocator); afterwards RSS must stay flat
    growth = rss[-1] - rss[1]
    assert growth < 3 * MIB, f"RSS grew by {growth / MIB:.1f} MiB over {len(rss) - 2} bursts: {rss}"


def test_a_burst_of_bad_targets_is_counted_and_throttled(node):
    proc, cl = node
    good = cl.latest_path()
    t0 = time.monotonic()
    for i in range(BURST):
        cl.publish_grip("right", (0.5, 0.0, float("nan")), Q)
    got = cl.wait_for_diagnostics(lambda v, st: int(v.get("errors.non_finite", "0")) > 0, 10.0)
    assert got is not None
    time.sleep(1.0)
    values = cl.diagnostic_values()
    assert int(values["errors.non_finite"]) <= BURST and values["last error kind"] == "non_finite"
    warnings = proc.output().count("rejected target (non_finite)")
    assert 1 <= warnings <= 2 + (time.monotonic() - t0), warnings  # at most one per second (throttle 1 s)
    assert cl.latest_path().stamp_ns == good.stamp_ns and proc.alive()
