"""The node over real DDS: ~/query_shape, ~/reset and the live parameters.

* query_shape returns the streaming shape for the same targets, publishes nothing, and the stream's
  next update still warm-starts exactly as if no query had happened (same iterations as a reference
  ShapeSolver that never saw the queries);
* an impossible query answers an empty plan and leaves the stream alone;
* reset goes back to a cold start;
* parameters: a valid change re-solves with the new value, a refused one says why and changes nothing,
  read-only parameters stay read-only, output_points changes the resolution.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model import Profile
from support.node import TEST_SCENE, clean_node, node_args, wait_until
from support.problems import quat_about

NODE_ARGS = node_args("diagnostics_period:=0.2")
Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)


@pytest.fixture
def node(tmp_path):
    """The node with its defaults: queries answered by a worker process (the solver thread's query path,
    query_workers:=0, is ShapeEngine.query: test_node_engine)."""
    with clean_node(*NODE_ARGS, log_path=tmp_path / "node.log") as proc_client:
        yield proc_client


def stream(cl, poses, timeout=15.0):
    stamp = cl.publish_targets(poses)
    ev = cl.wait_for_path(timeout, where=lambda e: e.stamp_ns == stamp)
    assert ev is not None, "no centreline for the target"
    return ev


def test_query_matches_stream_and_keeps_the_warm_start(node, node_scene):
    proc, cl = node
    scene, ShapeSolver = node_scene
    t1 = ((0.5, 0.05, 0.45), quat_about("z", 0.2))
    t2 = ((0.48, 0.06, 0.46), quat_about("z", 0.25))
    ev1 = stream(cl, [LEFT, t1])

    pts, qs = cl.query(LEFT, t1)
    np.testing.assert_allclose(pts, ev1.points, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(qs * ev1.orientations, axis=1)), 1.0, atol=1e-9)
    n = cl.path_count
    what_if = ((0.3, 0.1, 0.3), quat_about("z", 1.0))
    pts2, _ = cl.query(LEFT, what_if)
    assert len(pts2) == 51 and np.allclose(pts2[-1], what_if[0], atol=1e-7)
    empty, _ = cl.query(LEFT, ((3.0, 0.0, 0.4), Q))  # farther than the string reaches
    assert len(empty) == 0
    bad, _ = cl.query(LEFT, ((0.5, 0.0, 0.4), (0.0, 0.0, 0.0, 0.0)))  # zero quaternion
    assert len(bad) == 0
    time.sleep(0.3)
    assert cl.path_count == n, "a query published a centreline"
    values, st = cl.wait_for_diagnostics(lambda v, s: v.get("queries") == "4", 5.0)
    assert values["queries failed"] == "2" and "zero quaternion" in values["last query error"]
    assert st.level == b"\x00" and values["errors.unreachable"] == "0", "a query failure leaked into the stream"

    ev2 = stream(cl, [LEFT, t2])
    ref = ShapeSolver(scene.problem, scene.options)
    assert ref.solve().ok
    assert ref.solve({"left": LEFT, "right": t1}).ok
    r2 = ref.solve({"left": LEFT, "right": t2})
    np.testing.assert_allclose(ev2.points, r2.points, atol=1e-8)
    values, _ = cl.wait_for_diagnostics(lambda v, s: v.get("updates") == "3", 5.0)
    assert values["warm started"] == "true" and values["trigger"] == "targets"
    assert int(values["iterations"]) == r2.iterations, "the stream's warm start was disturbed by the queries"

    ok, message = cl.reset()
    assert ok and "cold" in message
    values, _ = cl.wait_for_diagnostics(lambda v, s: v.get("trigger") == "reset", 5.0)
    assert values["warm started"] == "false" and values["updates"] == "4"
    ev3 = cl.wait_for_path(5.0, after=n + 1)
    np.testing.assert_allclose(ev3.points, ev2.points, atol=1e-6)  # same equilibrium from a cold start

    # a slow query (grip below the table: IPOPT works ~1 s to prove it infeasible) does not stall the
    # node's executor: /diagnostics keeps coming (period 0.2 s) while the solver thread works on it
    n_diag, t0 = cl.diagnostics_count, time.monotonic()
    empty, _ = cl.query(LEFT, ((0.5, 0.0, -0.05), Q))
    took = time.monotonic() - t0
    assert len(empty) == 0
    if took > 0.6:
        assert cl.diagnostics_count - n_diag >= int(took / 0.2) - 2, (took, cl.diagnostics_count - n_diag)
    values, st = cl.wait_for_diagnostics(lambda v, s: v.get("queries") == "5", 5.0)
    assert "infeasible" in values["last query error"] and values["errors.infeasible"] == "0"
    assert proc.alive()


def test_parameters(node, node_scene):
    proc, cl = node
    scene, ShapeSolver = node_scene
    got = cl.get_parameters(["scene", "grip_names", "string.bend_stiffness", "output_points", "frame_id"])
    assert got["scene"] == TEST_SCENE and got["grip_names"] == ["left", "right"]
    assert got["string.bend_stiffness"] == 0.02 and got["output_points"] == 51

    n = cl.path_count
    accepted = cl.set_parameters({"string.bend_stiffness": 0.04, "string.weight_per_length": 0.8})
    assert accepted == [(True, ""), (True, "")]
    cl.wait_for_diagnostics(lambda v, s: v.get("updates") == "3", 10.0)  # both changes applied
    ev = cl.latest_path()
    string = replace(scene.problem.string, bend_stiffness=Profile.constant(0.04),
                     weight_per_length=Profile.constant(0.8))
    ref = ShapeSolver(replace(scene.problem, string=string), scene.options)
    r = ref.solve()
    np.testing.assert_allclose(ev.points, r.points, atol=1e-7)

    refused = cl.set_parameters({
        "string.bend_stiffness": 0.0, "string.twist_stiffness": 0.0, "string.weight_per_length": -1.0,
        "scene": "elastica_clamped", "output_points": 1, "compile": "blocking",
    })
    assert [ok for ok, _ in refused] == [False] * 6
    reasons = [reason for _, reason in refused]
    assert "must be > 0" in reasons[0] and "cannot switch" in reasons[1]
    assert "read-only" in reasons[3] and "read-only" in reasons[5]
    assert all(reasons), reasons
    got = cl.get_parameters(["string.bend_stiffness", "string.twist_stiffness", "scene", "output_points"])
    assert got == {"string.bend_stiffness": 0.04, "string.twist_stiffness": 0.015, "scene": TEST_SCENE,
                   "output_points": 51}

    assert cl.set_parameters({"output_points": 21}) == [(True, "")]
    ev = cl.wait_for_path(30.0, where=lambda e: len(e.points) == 21)
    assert ev is not None
    np.testing.assert_allclose(ev.points[[0, -1]], r.points[[0, -1]], atol=1e-7)
    assert proc.alive()


def matched(client, attempts: int = 3) -> np.ndarray:
    """The points of a first query that matches ``client`` to the node's service, asked again when
    the discovery race lost the answer (at most ``attempts`` times, 20 s each)."""
    for attempt in range(attempts):
        try:
            return client.query(LEFT, ((0.5, 0.0, 0.42), Q), timeout=20.0)[0]
        except TimeoutError:
            if attempt == attempts - 1:
                raise
    raise AssertionError("unreachable")


def test_concurrent_queries_beside_the_stream(tmp_path):
    """query_workers (default 1): queries are answered by a worker process while the stream goes on;
    several clients at once each get a plan through their goal, or at once an empty one ('busy') when
    more than QUERIES_PER_WORKER are pending; the stream keeps publishing meanwhile."""
    import threading

    from dlo_ros.node.client import DloClient

    with clean_node(*NODE_ARGS, "-p", "query_workers:=1", log_path=tmp_path / "node.log") as (proc, cl):
        stream(cl, [LEFT, ((0.5, 0.0, 0.42), Q)])
        goals = [((0.45 + 0.02 * i, 0.03 * (i % 3 - 1), 0.42), quat_about("z", 0.1 * i)) for i in range(6)]
        answers: dict[int, tuple] = {}
        errors: list[BaseException] = []

        # every client is matched to the service first, one at a time (a brand-new client can lose its
        # first answer in Fast DDS's discovery race, ros2/rclpy#1181: that is not what is tested here).
        # Asked again if it did: the node's answer was lost on the way (its log: "failed to send
        # response (timeout)"; CI under load, once), and the node counts it as answered
        clients = [DloClient(proc.domain_id, client_name=f"query_client_{i}") for i in range(len(goals))]
        for qc in clients:
            assert len(matched(qc))
        got = cl.wait_for_diagnostics(lambda v, s: int(v.get("queries", 0)) >= len(goals), 10.0)
        assert got is not None and got[0]["queries failed"] == "0"
        before = int(got[0]["queries"])

        def ask(i: int) -> None:
            try:
                answers[i] = clients[i].query(LEFT, goals[i], timeout=60.0)
            except BaseException as exc:  # noqa: BLE001 - reported below
                errors.append(exc)

        n0 = cl.path_count
        threads = [threading.Thread(target=ask, args=(i,)) for i in range(len(goals))]
        for t in threads:
            t.start()
        k = 0
        while any(t.is_alive() for t in threads) and k < 3000:  # the stream goes on at ~50 Hz meanwhile
            cl.publish_targets([LEFT, ((0.5, 0.0, 0.42 + 0.005 * math.sin(k / 20)), Q)])
            k += 1
            time.sleep(0.02)
        for t in threads:
            t.join(60.0)
        for qc in clients:
            qc.close()
        assert not errors, (errors, cl.diagnostic_values().get("queries"), cl.diagnostic_values().get("queries failed"))
        shaped = [i for i, (pts, _) in answers.items() if len(pts)]
        assert len(answers) == len(goals) and shaped, answers
        for i in shaped:
            np.testing.assert_allclose(answers[i][0][-1], goals[i][0], atol=1e-6)
        assert cl.path_count > n0, "no centreline while the queries were answered"
        refused = len(goals) - len(shaped)
        got = cl.wait_for_diagnostics(lambda v, s: v.get("queries") == str(before + len(goals)), 5.0)
        assert got is not None and int(got[0]["queries failed"]) == refused, cl.diagnostic_values()
        if refused:
            assert "busy" in proc.output()
        assert proc.alive()


def test_the_node_asks_its_query_workers_for_checks_beside_the_queries():
    """The node's query workers hold a shape that follows the stream; auto's checks due on its updates must
    run on the worker's check thread (``solve_chunk(..., checks='background')``, test_batch), not in front
    of the query waiting for that update.  In-process node, its pool replaced by one that records."""
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from dlo_ros.node.client import allocate_domain_id
    from dlo_ros.node.dlo_node import DloNode
    from dlo_ros.solver.parallel.batch import solve_chunk

    class Recording:
        def __init__(self):
            self.calls = []

        def submit(self, fn, *args, **kwargs):
            self.calls.append((fn, args, kwargs))
            return None

    with allocate_domain_id() as lease:
        context = Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        node = DloNode(context=context, parameter_overrides=[Parameter("scene", value=TEST_SCENE),
                                                             Parameter("compile", value="off"),
                                                             Parameter("query_workers", value=0)])
        try:
            wait_until(lambda: node.core.outputs.latest is not None, 60.0)  # the scene is there
            node.core.shape_services.query_pool = pool = Recording()
            node.core.shape_services.to_query_worker([])
            ((fn, args, kwargs),) = pool.calls
            assert fn is solve_chunk and args[1:] == ([], "off", "background")
            assert kwargs == {"timeout": None, "retries": 1}  # the warm-up builds the solver: not limited
        finally:
            node.core.shape_services.query_pool = None
            node.close()
            node.destroy_node()
            context.try_shutdown()
