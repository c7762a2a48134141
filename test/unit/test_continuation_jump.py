"""The warm ladder's continuation (``update/ladder.py``, rung 2) splits the jump from the start's
parameters to the update's; with no jump (the same targets again: a refinement pass started from
the mesh before, a re-solve at the committed poses) each of its steps would be the warm IPOPT solve
just made, from the same start, and fail alike: it is skipped, and the cold rung follows at once.

Measured before: the paper's Fig. 3 floor at ρ = 2000, cold, spent 4 × 180 ms repeating IPOPT's
same 200 iterations on its third mesh.  Here the warm rungs are made to fail (Newton refused,
warm IPOPT out of iterations) and the IPOPT calls are counted; the answer is the cold rung's, a
real solve.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import dlo_ros.solver.update.attempts as attempts
import dlo_ros.solver.update.substeps as substeps
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver

SCENE = load_scene("default_cable")
RIGHT = SCENE.problem.grip("right").pose


@pytest.fixture
def warm_rungs_fail(monkeypatch):
    """Newton refused and every warm IPOPT call out of iterations; returns the calls' kinds."""
    calls: list[str] = []
    original = attempts.ipopt_call

    def refused(ctx, start, p, problem=None):
        return False, start, 0, np.inf

    def ipopt(ctx, warm, z0, p, start=None, escape=False):
        calls.append("warm" if warm else "cold")
        if warm:
            return False, start, "Maximum_Iterations_Exceeded", 200, np.inf
        return original(ctx, warm, z0, p, start, escape)

    monkeypatch.setattr(attempts, "newton_to", refused)
    monkeypatch.setattr(substeps, "newton_in_substeps", refused)
    monkeypatch.setattr(attempts, "ipopt_call", ipopt)
    return calls


def held_solver() -> ShapeSolver:
    solver = ShapeSolver(SCENE.problem, replace(SCENE.options, model="full"), compile="off")
    assert solver.solve().ok
    return solver


def test_no_jump_no_continuation(warm_rungs_fail):
    solver = held_solver()
    warm_rungs_fail.clear()  # (the held shape's cold solve)
    again = solver.solve({"right": (RIGHT.position, RIGHT.orientation)})
    assert again.ok, again.message
    assert warm_rungs_fail == ["warm", "cold"]


def test_a_jump_is_continued_in_steps_before_the_cold_rung(warm_rungs_fail):
    solver = held_solver()
    warm_rungs_fail.clear()
    steps = solver.options.max_continuation_steps
    up = RIGHT.position + np.array([0.0, 0.0, 0.01])
    moved = solver.solve({"right": (up, RIGHT.orientation)})
    assert moved.ok, moved.message
    # the warm solve, the first step of each split into 2, 4, ... max_continuation_steps parts
    # (each fails at its first step), then the cold rung
    splits = int(np.log2(steps))
    assert warm_rungs_fail == ["warm"] * (1 + splits) + ["cold"], warm_rungs_fail
