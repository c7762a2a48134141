"""Dead point moments that turn the string by whole turns (#37, random scenes 31 and 57).

A clamped string under a dead moment M alone has a closed form: the internal moment is M on
[0, s_k] (no force), so the tangent turns about M at the rate |M|/Rf (t' = (M × t)/Rf, whatever the
twist stiffness) and the centreline is a helix about M's axis, straight beyond s_k.  At 1.9 turns
the default model's first rotation field (order 12) cannot follow it: neighbouring nodes reach the
fold guard, and the moment's path stopped there ('failed').  Now that failure says why
(``update/moments.UNRESOLVED_MESSAGE``) and ``solver.model: auto`` raises the order.
"""

from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.update.moment_paths import raise_along
from dlo_ros.solver.update.moments import UNRESOLVED_MESSAGE

L, RF, RT, S_K = 1.0, 1.0, 0.7, 0.5
MOMENT = 24.0 * np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)  # 12 rad of bending by s_k: 1.9 turns


def helix_problem(moment: np.ndarray = MOMENT) -> Problem:
    """A cantilever clamped at the origin along +x, a dead moment at s_k, no weight."""
    string = StringProperties(L, Profile.constant(RF), Profile.constant(RT), Profile.constant(0.0))
    grip = Grip("g0", 0.0, "clamp", GripPose.checked(np.zeros(3), np.array([0, 0, 0, 1.0]), "g0"))
    return Problem(string, (grip,), loads=(Load(S_K, moment=moment),))


def helix(s: np.ndarray, moment: np.ndarray = MOMENT) -> np.ndarray:
    """The closed-form centreline [m] at arc lengths s (module docstring)."""
    k = np.linalg.norm(moment) / RF
    axis = moment / np.linalg.norm(moment)
    t0 = np.array([1.0, 0.0, 0.0])
    along = np.dot(axis, t0) * axis
    across = t0 - along
    side = np.cross(axis, across)

    def x(u):
        return (
            np.outer(u, along)
            + np.outer(np.sin(k * u) / k, across)
            + np.outer((1.0 - np.cos(k * u)) / k, side)
        )

    inside = np.minimum(s, S_K)
    t_k = along + np.cos(k * S_K) * across + np.sin(k * S_K) * side
    return x(inside) + np.outer(np.maximum(s - S_K, 0.0), t_k)


@pytest.mark.parametrize("warm", [False, True])
def test_auto_follows_a_moment_of_two_turns(warm):
    """auto answers the 1.9-turn helix ok, with a stability verdict, within its tolerance of the
    closed form: cold, and at the end of a stream that raises the moment in warm updates."""
    problem = helix_problem()
    tol = 1e-3 * L
    if not warm:
        solver = make_solver(problem, SolverOptions(), compile="off", checks="sync")
        r = solver.solve()
    else:
        # a stream: the scene with a quarter of the moment cold, then the whole moment warm
        solver = make_solver(
            helix_problem(0.25 * MOMENT), SolverOptions(), compile="off", checks="sync"
        )
        assert solver.solve().ok
        solver.set_problem(problem)
        r = solver.solve()
    solver.close()
    assert r.ok and r.stable is not None, r.message
    assert np.max(np.linalg.norm(r.points - helix(r.s), axis=1)) <= tol


def test_a_fixed_coarse_model_says_why():
    """The full model at order 12 cannot follow the turns: 'failed', and the message says so."""
    solver = make_solver(helix_problem(), SolverOptions(model="full", order=12), compile="off")
    r = solver.solve()
    assert r.status == "failed" and r.message.startswith(UNRESOLVED_MESSAGE), r.message


def test_raise_along_keeps_a_step_that_works():
    """A path whose Newton solves fail on steps longer than 0.03 of the load (Newton's step
    limit) reaches the whole load in 71 solves (counted by hand from the rule: four solves per
    cycle of 0.0176, 0.0176, 0.0264 and a failed 0.0396).  Doubling after every success (the old
    rule) alternated a success of 0.0156 with a failure: 130 solves, and its budget of 40 ended
    near 0.3 (seed 57's pure moment stopped at 0.594 that way)."""
    calls = []

    def solve_at(start, fraction):
        calls.append(fraction)
        ok = fraction - start <= 0.03 + 1e-12
        return ok, fraction if ok else start, 1, 0.0

    out = raise_along(solve_at, 0.0)
    assert out.done and out.state == 1.0
    assert out.solves <= 75, out.solves
