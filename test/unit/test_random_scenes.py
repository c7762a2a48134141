"""Seeded random scenes (test/random_scenes.py): every result is an honest answer.

Each scene is reachable and feasible by construction (its grips sit on a smooth curve of the string's
length, obstacles clear of it), so 'unreachable', 'invalid' and 'infeasible' would be false verdicts.
An 'ok' result has a finite stability eigenvalue and passes the equilibrium residual check, and the
same scene at a higher order (warm-started on the same branch) gives the same shape within the
tolerance.  'unverified' and 'failed' are allowed (they are true statements about the solve) but must
not be the common case: at most 2 of the 16 seeds.
"""
from __future__ import annotations

import numpy as np
import pytest
from random_scenes import random_scene

from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

SEEDS = range(16)
FALSE_VERDICTS = ("unreachable", "invalid", "infeasible")


@pytest.fixture(scope="module")
def outcomes():
    return {}


@pytest.mark.parametrize("seed", SEEDS)
def test_random_scene_full_model(seed, outcomes):
    problem = random_scene(seed)
    tol = 1e-3 * problem.string.length
    solver = ShapeSolver(problem, SolverOptions(model="full", order=16), compile="off")
    r = solver.solve()
    outcomes[seed] = r.status
    assert r.status not in FALSE_VERDICTS, r.message
    if r.status == "failed":
        assert r.points.size == 0 and r.stable is None and not r.energy  # no shape to mistake for one
        return
    assert r.equilibrium_residual_m <= tol or r.status == "unverified"
    if r.ok:
        assert r.min_eigenvalue is None or np.isfinite(r.min_eigenvalue)
        # no update_time_limit: a warm-started reference must not depend on the machine's load
        fine = ShapeSolver(problem, SolverOptions(model="full", order=24, update_time_limit=0.0), compile="off")
        assert fine.adopt_warm_start(solver)
        r24 = fine.solve()
        assert r24.ok, r24.message
        assert np.max(np.linalg.norm(r24.points - r.points, axis=1)) <= tol


def test_random_scenes_are_mostly_verified(outcomes):
    if len(outcomes) < len(SEEDS):
        pytest.skip("needs the whole parametrised set")
    assert sum(status != "ok" for status in outcomes.values()) <= 2, outcomes


@pytest.mark.parametrize("seed", [0, 3, 10])
def test_random_scene_auto(seed):
    """auto (checked inline, as the CLI) on the same scenes: a true status, and within its tolerance of
    the full model at order 24 on its branch when ok."""
    problem = random_scene(seed)
    solver = make_solver(problem, SolverOptions(), compile="off", checks="sync")
    r = solver.solve()
    assert r.status not in FALSE_VERDICTS, r.message
    if r.ok:
        assert r.model.tolerance_met in (True, None)
        assert r.equilibrium_residual_m <= r.model.tolerance_m
