"""The echo of bench/perf/node_latency.py's floor (bench/perf/echo_node.py): started like the node, it answers
each target with a Path of the node's size carrying the target's stamp, with either executor, and stops
cleanly on SIGINT.  No timing is asserted."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from dlo_ros.node.client import running_node

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from bench.perf.node_latency import ECHO_MODULE, OUTPUT_POINTS, closed_loop, echo_env  # noqa: E402


@pytest.mark.parametrize("executor", ["single", "events"])
def test_echo_answers_each_target_with_its_stamp(tmp_path, executor):
    log = tmp_path / "echo.log"
    with running_node("--executor", executor, module=ECHO_MODULE, env=echo_env(), log_path=log,
                      startup_timeout=30.0, executor=executor) as (proc, client):
        latencies, _ = closed_loop(client, 5)  # raises when a target's Path does not come back
        assert len(latencies) == 5 and min(latencies) > 0
        path = client.latest_path()
        assert path.points.shape == (OUTPUT_POINTS, 3) and path.frame_id == "world"
    assert proc.returncode == 0, proc.output()
    assert "answered 5 targets" in log.read_text()
