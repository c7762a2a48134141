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
from scipy.interpolate import CubicSpline
from random_scenes import random_scene
from reference.kirchhoff import blas_threads, continuation, solve_clamped

from dlo_ros.model.rotations import quat_to_matrix
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
        assert (
            r.points.size == 0 and r.stable is None and not r.energy
        )  # no shape to mistake for one
        return
    assert r.equilibrium_residual_m <= tol or r.status == "unverified"
    if r.ok:
        assert r.min_eigenvalue is None or np.isfinite(r.min_eigenvalue)
        # no update_time_limit: a warm-started reference must not depend on the machine's load
        fine = ShapeSolver(
            problem, SolverOptions(model="full", order=24, update_time_limit=0.0), compile="off"
        )
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


REPORTED = (97, 109)  # #37: reported 'infeasible' under auto, 'unverified' 0.3-0.65 m under full


def distance(a, b) -> float:
    """Largest distance [m] between two centrelines sampled at the same arc lengths."""
    return float(np.max(np.linalg.norm(a.points - b.points, axis=1)))


@pytest.mark.parametrize("model", ["full", "auto"])
@pytest.mark.parametrize("seed", REPORTED)
def test_reported_scenes_cold_and_streamed(seed, model):
    """Seeds 97 and 109 (#37's report) answer ok with a stability verdict, cold and at the end of a
    warm stream, within 1e-3 L of the full model at order 24 solved cold (the tighter model).

    These pass on the code the report was checked against (f61f8ff and a745b85, pre-#36 328f6a6
    too): a guard, not a reproduction; the report's mechanism was not found.
    """
    cold_and_streamed(seed, model)


def cold_and_streamed(seed: int, model: str) -> None:
    """Seed's scene under ``model``: ok with a stability verdict, cold and at the end of a warm
    stream, within 1e-3 L of the full model at order 24 solved cold."""
    problem = random_scene(seed)
    tol = 1e-3 * problem.string.length
    fine = SolverOptions(model="full", order=24, update_time_limit=0.0)
    reference = ShapeSolver(problem, fine, compile="off").solve()
    assert reference.ok, reference.message
    solver = make_solver(problem, SolverOptions(model=model), compile="off", checks="sync")
    cold = solver.solve()
    assert cold.ok and cold.stable is not None, cold.message
    assert cold.equilibrium_residual_m <= tol
    assert distance(cold, reference) <= tol
    # a stream from a nearby ok shape: the last grip 3 cm nearer the first, back in 5 warm steps
    first, last = problem.grips[0].pose, problem.grips[-1].pose
    toward = (first.position - last.position) / np.linalg.norm(first.position - last.position)
    start = last.position + 0.03 * toward
    name = problem.grips[-1].name
    r = solver.solve({name: (start, last.orientation)}, warm=False)
    assert r.ok, r.message
    for k in range(1, 6):
        r = solver.solve({name: (start + k / 5 * (last.position - start), last.orientation)})
        assert r.ok, (k, r.message)
    assert r.stable is not None and r.equilibrium_residual_m <= tol
    assert distance(r, reference) <= tol
    solver.close()


# ---- point moments that turn the string by whole turns (#37's 200 random scenes) ----------
def moments_first_reference(problem, s: np.ndarray) -> np.ndarray:
    """Centreline [m] at ``s`` of a cantilever scene's equilibrium by the independent shooting
    reference (test/reference/kirchhoff.py): its point moments raised from zero alone (a clamped
    string under a dead moment alone is a helix about the moment's axis, one branch without a
    limit point), then its weight and forces, each in 10 continuation steps (halved where one
    fails)."""
    grip, st, load = problem.grips[0], problem.string, problem.loads[0]
    dense = np.linspace(0.0, st.length, 401)

    def solve_at(moments, forces, guess):
        return solve_clamped(
            st.length,
            st.bend_stiffness.maximum,
            st.twist_stiffness.maximum,
            grip.pose.position,
            quat_to_matrix(grip.pose.orientation),
            mode_end="free",
            D=forces * st.weight_per_length.maximum,
            g=problem.gravity,
            loads=[(load.s, forces * load.force, moments * load.moment)],
            guess=guess,
            s_eval=dense,
            fallback=False,
        )

    steps = np.linspace(0.0, 1.0, 11)
    with blas_threads(1):
        zero = (np.zeros(3), np.zeros(3))
        sol = continuation(lambda f, g: solve_at(f, 0.0, g), steps, guess=zero)[-1][1]
        sol = continuation(lambda f, g: solve_at(1.0, f, g), steps[1:], guess=sol)[-1][1]
    return CubicSpline(sol.s, sol.x, axis=0)(s)  # error O(h⁴κ³) at h = L/400: under 1e-6 m


@pytest.mark.slow  # ~25 s; seed 31 below keeps auto's turning moments in the whole suite's run
def test_turning_moment_cantilever_seed_57_auto():
    """Seed 57 (a cantilever; a dead moment that alone would bend it by 18 rad, about 2.9 turns; a
    force, weight and a ball) failed under auto: its order-12 rotation field cannot follow the
    turns (a fold guard at its bound at 0.60 of the moment), and with the other loads on, the
    moment meets a limit point at 0.773 (the shooting reference folds there too).  auto now
    raises the order for it, and the moment is raised before the other loads: ok with a stability
    verdict, within the tolerance of the shooting reference on the same path."""
    problem = random_scene(57)
    tol = 1e-3 * problem.string.length
    solver = make_solver(problem, SolverOptions(), compile="off", checks="sync")
    r = solver.solve()
    solver.close()
    assert r.ok and r.stable is not None, r.message
    assert r.equilibrium_residual_m <= tol
    reference = moments_first_reference(problem, r.s)
    assert np.max(np.linalg.norm(r.points - reference, axis=1)) <= tol


def test_turning_moment_seed_31_auto_cold_and_streamed():
    """Seed 31 (tangent/tangent/clamp, a dead moment that turns the string by more than auto's
    order-12 rotation field can follow) failed under auto ("stopped at 0.854 of them"): now
    auto raises the order, cold and streamed, within 1e-3 L of the full model at order 24 solved
    cold."""
    cold_and_streamed(31, "auto")
