"""Dead point moments that turn the string far, against the independent shooting reference.

A dead moment M (fixed in the world) does virtual work M·δθ, which is not the variation of a function
of the rotation.  These cantilevers, with gravity, a point force and a moment about a skew axis, turn
the string by about a radian at the load: re-centring a pseudo-potential on the solution (a fixed
point) cycles there, so the solver solves the exact equilibrium equations by Newton's method.  The
reference is shooting on the Kirchhoff rod equations (test/reference), loads raised from zero; it knows
nothing of the solver's discretisation.  Each case is solved cold and reached by a stream of warm
updates that moves and turns the clamp and brings it back.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from reference.kirchhoff import continuation, solve_clamped
from scipy.integrate import simpson
from scipy.interpolate import interp1d

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.model.rotations import quat_to_matrix
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

CLAMP = np.array([0.0, 0.0, 1.0])
LENGTH = 1.0


def cantilever(moment) -> Problem:
    """1 m cantilever, clamp at s = 0 (tangent +x), 0.5 N/m weight, force and moment at s = 0.6 m."""
    string = StringProperties(LENGTH, Profile.constant(0.05), Profile.constant(0.04), Profile.constant(0.5))
    grip = Grip("clamp", 0.0, "clamp", GripPose.checked(CLAMP, [0.0, 0.0, 0.0, 1.0], "clamp"))
    load = Load(0.6, force=np.array([0.1, 0.2, 0.0]), moment=np.array(moment, dtype=float))
    return Problem(string, (grip,), gravity=np.array([0.0, 0.0, -1.0]), loads=(load,))


@lru_cache(maxsize=None)
def shooting_reference(moment: tuple[float, float, float]) -> tuple[interp1d, np.ndarray]:
    """x(s) of the Kirchhoff equilibrium of ``cantilever(moment)``, loads raised from zero in 40 steps,
    and its centroid."""
    problem = cantilever(moment)
    st, grip, load = problem.string, problem.grips[0], problem.loads[0]

    def at(fraction, guess):
        return solve_clamped(st.length, st.bend_stiffness.maximum, st.twist_stiffness.maximum, grip.pose.position,
                             quat_to_matrix(grip.pose.orientation), mode_end="free",
                             D=fraction * st.weight_per_length.maximum, g=problem.gravity,
                             loads=[(load.s, fraction * load.force, fraction * load.moment)], guess=guess,
                             s_eval=np.linspace(0.0, st.length, 201))

    solution = continuation(at, np.linspace(0.0, 1.0, 41), guess=(np.zeros(3), np.zeros(3)))[-1][1]
    assert solution.residual < 1e-9
    centroid = simpson(solution.x, x=solution.s, axis=0) / st.length
    return interp1d(solution.s, solution.x, axis=0, kind="cubic"), centroid


def turn_about_z(angle: float) -> list[float]:
    return [0.0, 0.0, float(np.sin(angle / 2)), float(np.cos(angle / 2))]


# moments [N·m] for which re-centring the pseudo-potential did not settle (rotation at the load 6e-4 and
# 0.95 rad from its centre after 30 rounds)
MOMENTS = [(0.02, -0.12, 0.1), (0.1, 0.1, 0.1)]


@pytest.mark.parametrize("moment", MOMENTS)
@pytest.mark.parametrize("how", ["cold", "stream"])
def test_far_turning_moment_matches_shooting(moment, how):
    problem = cantilever(moment)
    reference, centroid = shooting_reference(moment)
    solver = ShapeSolver(problem, SolverOptions(model="full", order=16), compile="off")
    r = solver.solve()
    if how == "stream":
        assert r.ok, r.message
        # move and turn the clamp, then bring it back: every update a checked equilibrium
        path = [(CLAMP + [0.0, 0.02 * k, -0.01 * k], turn_about_z(0.05 * k)) for k in (1, 2, 3, 4, 3, 2, 1, 0)]
        for position, quat in path:
            r = solver.solve({"clamp": (position, quat)})
            assert r.ok and r.warm_started, r.message
            assert r.equilibrium_residual_m < 1e-6
    assert r.ok and r.stable, r.message
    assert np.abs(r.points - reference(r.s)).max() < 1e-6 * LENGTH
    # the clamp reacts the weight, the force and the moment (statics, independent of the shape's accuracy)
    load = problem.loads[0]
    weight = np.array([0.0, 0.0, -0.5 * LENGTH])
    np.testing.assert_allclose(r.grips["clamp"].force, -(weight + load.force), atol=1e-8)
    x_load = reference(np.array([load.s]))[0]
    torque = -(np.cross(x_load - CLAMP, load.force) + load.moment + np.cross(centroid - CLAMP, weight))
    np.testing.assert_allclose(r.grips["clamp"].torque, torque, atol=1e-8)
