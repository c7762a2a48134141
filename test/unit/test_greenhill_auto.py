"""Greenhill post-buckling under ``model: auto`` (#37), against exact and independent answers.

A straight extensible rod between two clamps exactly its length apart, the far clamp turned by Φ
about the chord: straight while Φ < Φ_c = 2 x0 Rf / Rt (x0 the first positive root of
tan x = x: the clamped–clamped Greenhill twist, test_kirchhoff_reference.py), buckled beyond it,
where the straight state is unstable and the buckle (of amplitude set by the stretch) is reached
only by stretching.  The references: the closed-form threshold and the straight state's energy
Rt Φ² / 2L, and an independent shooting solution of the extensible Kirchhoff rod
(test/reference/extensible_shooting.py).  The buckle's orientation about the chord is free (no
gravity), so shapes are compared by their distance from the chord and their axial coordinate.

Auto used to model this scene inextensible (no grip force, so the elongation bound saw nothing):
its only feasible shape is then the straight line, and every update past Φ_c failed
('IPOPT: Error_In_Step_Computation') or answered the straight shape as stable.
"""

from __future__ import annotations

import numpy as np
import pytest
from reference.extensible_shooting import shoot_clamped
from scipy.optimize import brentq
from support.problems import quat_about

from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties
from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.options import SolverOptions

L, RF, RE = 1.0, 1.0, 1e4
#: Rt > Rf puts 1.3 Φ_c below half a turn, so that a cold solve (which cannot know the clamp's
#: turns) faces the same twist as the stream
RT = 4.0
PHI_C = 2.0 * brentq(lambda x: np.tan(x) - x, 4.4, 4.6, xtol=1e-15) * RF / RT  # 2.2467
TOL = 1e-3 * L  # auto's default error tolerance


def greenhill(phi: float) -> Problem:
    """The rod clamped at the origin and at (L, 0, 0), the far clamp turned by ``phi`` [rad]."""
    string = StringProperties(
        L,
        Profile.constant(RF),
        Profile.constant(RT),
        Profile.constant(0.0),
        stretch_stiffness=Profile.constant(RE),
    )
    grips = (
        Grip("a", 0.0, "clamp", GripPose.checked((0, 0, 0), quat_about("x", 0.0), "a")),
        Grip("b", L, "clamp", GripPose.checked((L, 0, 0), quat_about("x", phi), "b")),
    )
    return Problem(string, grips)


def deflection(r) -> float:
    """Largest distance [m] of the centreline from the chord."""
    return float(np.hypot(r.points[:, 1], r.points[:, 2]).max())


def assert_matches_shooting(r, phi: float) -> None:
    """The buckled answer against the shooting reference started from its grip wrench."""
    c, s = np.cos(phi), np.sin(phi)
    r1 = np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])
    wrench = r.grips["a"]  # the clamp's action on the rod: minus the internal n(0), m(0)
    ref = shoot_clamped(L, RF, RT, RE, np.array([L, 0, 0]), r1, -wrench.force, -wrench.torque, r.s)
    assert ref.residual < 1e-9, ref.residual
    radial_ref = np.hypot(ref.x[:, 1], ref.x[:, 2])
    assert radial_ref.max() > 10 * TOL  # the reference buckled too: not the straight rod
    error = max(
        np.abs(r.points[:, 0] - ref.x[:, 0]).max(),
        np.abs(np.hypot(r.points[:, 1], r.points[:, 2]) - radial_ref).max(),
    )
    assert error < TOL, error
    assert r.energy["total"] == pytest.approx(ref.energy, rel=1e-4)
    assert ref.energy < RT * phi**2 / (2 * L)  # below the straight state's energy


def test_streamed_past_the_threshold_follows_the_buckle():
    """0.02 rad steps from 0.8 Φ_c to 1.3 Φ_c under make_solver's defaults: every update ok and
    warm; straight below Φ_c, buckled (and stable) past it, never the straight shape called stable;
    the last one matches the shooting reference within the tolerance."""
    solver = make_solver(greenhill(0.0))
    try:
        assert solver.solve().ok
        for phi in np.arange(0.25, 0.8 * PHI_C, 0.25):
            assert solver.solve({"b": ((L, 0, 0), quat_about("x", phi))}).ok
        r = None
        for phi in np.arange(0.8 * PHI_C, 1.3 * PHI_C + 1e-9, 0.02):
            r = solver.solve({"b": ((L, 0, 0), quat_about("x", phi))})
            assert r.ok and r.warm_started, (phi, r.status, r.message)
            if phi < PHI_C - 0.02:
                assert deflection(r) < 1e-6, (phi, deflection(r))
            if phi > PHI_C + 0.02:  # past the threshold the straight shape is unstable
                assert r.stable and deflection(r) > 0.1 * TOL, (phi, r.stable, deflection(r))
        assert_matches_shooting(r, phi)
    finally:
        solver.close()


def test_cold_past_the_threshold_is_buckled():
    """Cold at 1.3 Φ_c under the defaults: ok, stable, buckled, within the tolerance of the
    shooting reference."""
    phi = 1.3 * PHI_C
    solver = make_solver(greenhill(phi))
    try:
        r = solver.solve()
    finally:
        solver.close()
    assert r.ok and r.stable, (r.status, r.message)
    assert deflection(r) > 10 * TOL
    assert_matches_shooting(r, phi)
