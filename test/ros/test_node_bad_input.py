"""The node over real DDS: every kind of bad input, sent for real, leaves the node alive, the last good
shape published (a late subscriber still gets it) and the problem reported in /diagnostics."""
from __future__ import annotations

import math

import numpy as np
import pytest

from dlo_ros.node.client import DloClient
from support.node import clean_node, node_args

NODE_ARGS = node_args("diagnostics_period:=0.2", "warn_throttle:=0.0")
Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)
RIGHT = ((0.5, 0.0, 0.42), Q)
NAN, INF = float("nan"), float("inf")


@pytest.fixture
def node(tmp_path):
    with clean_node(*NODE_ARGS, log_path=tmp_path / "node.log") as proc_client:
        yield proc_client


# (kind reported, words in the report, how to send it)
CASES = [
    ("size", "bytes is over the limit", lambda cl: cl.publish_oversized_targets(1_000_000)),
    ("non_finite", "position", lambda cl: cl.publish_targets([((NAN, 0.0, 0.4), Q), RIGHT])),
    ("non_finite", "orientation", lambda cl: cl.publish_grip("right", RIGHT[0], (0.0, 0.0, INF, 1.0))),
    ("quaternion", "zero quaternion", lambda cl: cl.publish_grip("left", LEFT[0], (0.0, 0.0, 0.0, 0.0))),
    ("quaternion", "norm is 1.01", lambda cl: cl.publish_targets([LEFT, (RIGHT[0], (0.0, 0.0, 0.0, 1.01))])),
    ("frame", "'map', not 'world'", lambda cl: cl.publish_grip("right", *RIGHT, frame_id="map")),
    ("frame", "frame_id is empty", lambda cl: cl.publish_targets([LEFT, RIGHT], frame_id="")),
    ("count", "1 poses for 2 grips", lambda cl: cl.publish_targets([LEFT])),
    ("count", "3 poses for 2 grips", lambda cl: cl.publish_targets([LEFT, RIGHT, RIGHT])),
    ("unreachable", "reaches at most", lambda cl: cl.publish_targets([LEFT, ((2.0, 0.0, 0.4), Q)])),
    # the right grip below the table (half-space z <= 0): no shape satisfies the constraints
    ("infeasible", "Infeasible", lambda cl: cl.publish_targets([LEFT, ((0.5, 0.0, -0.05), Q)])),
]


def test_bad_inputs_keep_the_last_good_shape(node):
    proc, cl = node
    stamp = cl.publish_targets([LEFT, RIGHT])
    good = cl.wait_for_path(15.0, where=lambda e: e.stamp_ns == stamp)
    assert good is not None
    n_paths = cl.path_count
    expected: dict[str, int] = {}
    for kind, words, send in CASES:
        expected[kind] = expected.get(kind, 0) + 1
        send(cl)
        got = cl.wait_for_diagnostics(lambda v, st: v.get(f"errors.{kind}") == str(expected[kind]), 15.0)
        assert got is not None, f"{kind} not reported; diagnostics {cl.diagnostic_values()}\n{proc.output()}"
        values, status = got
        assert values["last error kind"] == kind and words in values["last error"], values["last error"]
        assert status.level == b"\x01", status.message  # WARN
        assert "last good shape" in status.message
        assert proc.alive(), proc.output()
        assert cl.path_count == n_paths, f"{kind}: a centreline was published for a bad input"
    values = cl.diagnostic_values()
    assert values["rejected inputs"] == "9" and values["failures"] == "2" and values["updates"] == "2"
    assert values["errors.internal"] == "0"

    # the last good shape is what a newcomer gets
    with DloClient(proc.domain_id, client_name="newcomer") as late:
        ev = late.wait_for_path(10.0)
        assert ev is not None and ev.stamp_ns == stamp
        np.testing.assert_array_equal(ev.points, good.points)

    # each problem was logged as a warning naming it (warn_throttle 0: none is throttled away)
    log = proc.output()
    for kind, words, _ in CASES:
        assert f"({kind})" in log and words in log, kind

    # a quaternion off by less than the tolerance is normalised and accepted; the node recovers
    q = np.array([0.0, 0.0, math.sin(0.1), math.cos(0.1)]) * 1.0005
    stamp = cl.publish_targets([LEFT, (RIGHT[0], tuple(q))])
    ev = cl.wait_for_path(15.0, where=lambda e: e.stamp_ns == stamp)
    assert ev is not None
    np.testing.assert_allclose(ev.points[-1], RIGHT[0], atol=1e-7)
    assert abs(abs(np.dot(ev.orientations[-1], q / np.linalg.norm(q))) - 1) < 1e-9
    values, status = cl.wait_for_diagnostics(lambda v, st: v.get("updates") == "3", 5.0)
    assert status.level == b"\x00" and values["last error kind"] == "infeasible"  # history kept, level back to OK
