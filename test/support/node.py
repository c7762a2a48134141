"""Harness of the tests that run the node (test/ros): which scene and model they run on, and helpers
around :func:`dlo_ros.node.client.running_node` and :class:`dlo_ros.node.client.NodeProcess`."""
from __future__ import annotations

import os
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

from dlo_ros.node.client import running_node

#: The scene the node tests run on: default_cable, or $DLO_NODE_TEST_SCENE (a name or a path), e.g. to
#: tell a node problem from a solver problem by running the tests on a scene with another solver.model.
TEST_SCENE = os.environ.get("DLO_NODE_TEST_SCENE") or "default_cable"
#: The solver.model the node tests run with, or $DLO_NODE_TEST_MODEL.  'full', not the shipped 'auto':
#: these tests compare the node's shapes with an in-process solver to 1e-7 m, which needs both to solve
#: the same model at the same moment, while auto's background checks change the model on their own
#: timing.  test/ros/test_node_auto_model.py runs the node with auto (model changes, diagnostics, recording).
TEST_MODEL = os.environ.get("DLO_NODE_TEST_MODEL") or "full"


def node_args(*params: str) -> tuple[str, ...]:
    """The node's command line in the tests: TEST_SCENE, no compiling, TEST_MODEL, then ``-p`` with each
    of ``params`` ('name:=value')."""
    args = ["--scene", TEST_SCENE, "--ros-args", "-p", "compile:=off", "-p", f"solver.model:={TEST_MODEL}"]
    for param in params:
        args += ["-p", param]
    return tuple(args)


@contextmanager
def clean_node(*args: str, log_path: Path):
    """``running_node`` (the node in its own process and domain, a client); afterwards the node must
    have exited with code 0 and logged no traceback (its log is the assertion message)."""
    with running_node(*args, log_path=log_path) as (proc, client):
        yield proc, client
    text = Path(log_path).read_text()
    assert proc.returncode == 0, text
    assert "Traceback" not in text, text


def group_processes(pgid: int) -> list[str]:
    """'pid name' of the live (not zombie) processes in process group ``pgid`` (Linux /proc).

    A NodeProcess runs in its own session, so its group id is its pid: after it stopped, this lists
    anything it left behind.
    """
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            out.append(f"{entry} {stat[stat.index('(') + 1:stat.rindex(')')]}")
    return out


def assert_stopped_cleanly(proc, signalled_at: float, wait_s: float, within_s: float) -> None:
    """The node process signalled at ``signalled_at`` (time.monotonic) exits with 0 within
    ``wait_s`` s of this call and ``within_s`` s of the signal, and leaves nothing in its process
    group."""
    assert proc.wait(wait_s) == 0, proc.output()
    assert time.monotonic() - signalled_at < within_s
    assert wait_until(lambda: not group_processes(proc.pid), 5.0), f"left running: {group_processes(proc.pid)}"


def wait_until(predicate: Callable[[], object], timeout: float, period: float = 0.05) -> object:
    """Poll ``predicate()`` until it is truthy or ``timeout`` s passed; its last value."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value or time.monotonic() >= deadline:
            return value
        time.sleep(period)
