"""A stream's held verdict's model is compiled ahead of the switch (``ModelPool.compile_ahead``).

A check builds the model its verdict names on the worker without a compile (``solver_for``'s
``once``: a check's model is looked up in the cache only as a clone).  The switch BUILD_LAG
updates later then started that compile on the stream's thread: building the split KKT functions
and looking up their libraries took 22–43 ms of the main job's update 94 (the planar mesh
1 × 12 → 2 × 15, compiled, background checks), against 0.2–0.3 ms for the switch once the
verdict's model is compiled ahead.  The rule, with the pool's own method and a stand-in solver
that records its compile starts.
"""

from __future__ import annotations

import threading
from types import SimpleNamespace

import pytest

from dlo_ros.solver.auto.pool import ModelPool


class Solver:
    """What ``compile_ahead`` reads and calls of a ShapeSolver; records ``start_compile``."""

    def __init__(self, mode: str) -> None:
        self.compile_mode, self.all_compiled, self.compile_pending = mode, False, False
        self.started: list[tuple[str, str]] = []
        self.done = threading.Event()

    def start_compile(self, mode: str) -> None:
        self.started.append((mode, threading.current_thread().name))
        self.compile_mode = mode
        self.done.set()


def pool(compile: str) -> ModelPool:
    """A pool of a stream that compiles as ``compile`` says, its streaming model compiled."""
    p = object.__new__(ModelPool)
    p.compile = compile
    p.streaming = SimpleNamespace(wait_for_compile=lambda: True)
    return p


@pytest.mark.parametrize("mode", ["off", "cached"])
def test_a_switch_target_compiles_ahead_on_its_own_thread(mode):
    solver = Solver(mode)
    pool("background").compile_ahead(solver, switch=True)
    assert solver.done.wait(5.0)
    assert solver.started == [("background", "dlo-compile-ahead")]
    assert not solver.compile_pending


def test_without_switch_a_model_built_not_to_compile_stays_so():
    """A check's one-off model (compile 'off') is not compiled by other callers' compile_ahead."""
    solver = Solver("off")
    pool("background").compile_ahead(solver)
    assert not solver.done.wait(0.5)
    assert solver.started == [] and solver.compile_mode == "off"


@pytest.mark.parametrize("stream_compile", ["off", "cached"])
def test_a_stream_that_does_not_compile_compiles_nothing_ahead(stream_compile):
    solver = Solver("off")
    pool(stream_compile).compile_ahead(solver, switch=True)
    assert not solver.done.wait(0.5)
    assert solver.started == [] and solver.compile_mode == "off"
