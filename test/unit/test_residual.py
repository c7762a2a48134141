"""The equilibrium residual's balance moment against its definition evaluated point by point.

m_bal(s) = −Σ_{a: s_a < s} [(x_a − x(s)) × F_a + T_a] − ∫_0^s (x(σ) − x(s)) × D ĝ dσ (solver/results/residual.py),
written here as a plain double loop over grid points and actions, on random data.
"""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.rotations import cross3
from dlo_ros.solver.results.residual import BalanceInputs, PointAction, equilibrium_residual


def _direct_delta(s, x, moment_c, weight, weight_moment, actions, g):
    delta = np.zeros_like(moment_c)
    for k in range(len(s)):
        m_bal = -(np.cross(weight_moment[k], g) - np.cross(x[k], g) * weight[k])
        for a in actions:
            if a.s < s[k]:
                m_bal -= np.cross(a.position - x[k], a.force) + a.moment
        delta[k] = moment_c[k] - m_bal
    return delta


@pytest.mark.parametrize("n_actions", [0, 1, 7])
def test_balance_moment_matches_its_definition(n_actions):
    rng = np.random.default_rng(n_actions)
    s = np.sort(rng.uniform(0.0, 1.0, 60))
    x, moment_c, weight_moment = (rng.normal(size=(60, 3)) for _ in range(3))
    weight = np.cumsum(rng.uniform(size=60))
    g = np.array([0.0, 0.0, -1.0])
    # actions in random order of s, one of them exactly on a grid point (not before it)
    s_a = list(rng.uniform(0.0, 1.0, n_actions))
    if n_actions:
        s_a[-1] = s[30]
    actions = [PointAction(float(sa), rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)) for sa in s_a]
    delta = _direct_delta(s, x, moment_c, weight, weight_moment, actions, g)
    r = equilibrium_residual(BalanceInputs(s, x, moment_c, weight, weight_moment, actions, g, 2.0, 1.0, 1.0))
    assert r.moment == pytest.approx(np.max(np.linalg.norm(delta, axis=1)), rel=1e-12)
    total = 2.0 * g + sum((a.force for a in actions), np.zeros(3))
    assert r.force == pytest.approx(np.linalg.norm(total), rel=1e-12)


def test_cross3_is_the_cross_product_with_broadcasting():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=3)
    assert np.allclose(cross3(a, b), np.cross(a, b), rtol=0, atol=1e-15)
    assert np.allclose(cross3(b, a), np.cross(b, a), rtol=0, atol=1e-15)


@pytest.mark.parametrize("opts", [dict(model="planar", order=10), dict(model="full", rotation="euler", order=16)],
                         ids=["planar", "euler-3d-twist"])
def test_euler_moments_match_their_definition(opts):
    """The Euler models' constitutive moment written from the angles (wrenches.euler_moments) against its
    definition m = Q diag(Rf, Rf, Rt) axial(QᵀQ') on the published material frames Q(s), Q' by central
    differences, on a bent (and for the 3D model, twisted) solution."""
    from dataclasses import replace

    from dlo_ros.scene import load_scene
    from dlo_ros.solver import ShapeSolver
    from dlo_ros.solver.results.wrenches import euler_moments

    scene = load_scene("default_cable")
    solver = ShapeSolver(scene.problem, replace(scene.options, **opts), compile="off")
    grip = scene.problem.grip("right").pose
    offset = np.array([-0.05, 0.05 if opts["model"] == "full" else 0.0, 0.03])
    assert solver.solve({"right": (grip.position + offset, grip.orientation)}).ok
    z, L, string = solver.snapshot().z, scene.problem.string.length, scene.problem.string
    s = np.linspace(0.02, 0.98, 40) * L
    rf, rt = string.bend_stiffness(s), string.twist_stiffness(s)
    h = 1e-5 * L
    q = solver.frames(z, s)
    dq = (solver.frames(z, s + h) - solver.frames(z, s - h)) / (2 * h)
    skew = np.einsum("kji,kjl->kil", q, dq)
    omega = 0.5 * np.stack([skew[:, 2, 1] - skew[:, 1, 2], skew[:, 0, 2] - skew[:, 2, 0], skew[:, 1, 0] - skew[:, 0, 1]], 1)
    twist = rt if solver.model.layout.twist else np.zeros_like(rt)
    expected = np.einsum("kij,kj->ki", q, np.stack([rf, rf, twist], axis=1) * omega)
    assert np.abs(expected).max() > 1e-2  # bent
    np.testing.assert_allclose(euler_moments(solver.nlp, z, s, rf, rt), expected, rtol=0, atol=1e-7 * np.abs(expected).max())


def test_the_grid_integrates_polynomials_exactly():
    """ResidualGrid.cumulative: Gauss–Legendre on each interval between knots, exact to degree
    2q − 1 at the knots and q − 1 at the points (q = GAUSS_POINTS), against the antiderivative."""
    from dlo_ros.solver.results.residual import GAUSS_POINTS, evaluation_grid

    grid = evaluation_grid(2.0, [0.3, 0.30000000000000004, 1.7], points=7, kinks=[0.55, 1.01])
    assert np.all(np.diff(grid.knots) > 0) and grid.knots[0] == 0.0 and grid.knots[-1] == 2.0
    assert np.isin([0.3, 0.55, 1.01, 1.7], grid.knots).all()
    s = grid.s
    assert s.size == GAUSS_POINTS * (grid.knots.size - 1)
    assert not np.isin(s, grid.knots).any()  # never on a knot: B′ may be one-sided there
    rng = np.random.default_rng(3)
    for degree, where in ((2 * GAUSS_POINTS - 1, "knots"), (GAUSS_POINTS - 1, "points")):
        c = rng.normal(size=(degree + 1, 3))
        f = np.stack([np.polynomial.polynomial.polyval(s, c[:, k]) for k in range(3)], axis=1)
        at_points, at_knots = grid.cumulative(f)
        exact = lambda x: np.stack(  # noqa: E731
            [np.polynomial.polynomial.polyval(x, np.polynomial.polynomial.polyint(c[:, k])) for k in range(3)],
            axis=1,
        )
        got, want = (at_knots, exact(grid.knots)) if where == "knots" else (at_points, exact(s))
        assert np.max(np.abs(got - want)) < 1e-12 * np.max(np.abs(want)), where


def test_a_sawtooth_kinked_at_the_rows_integrates_exactly_with_the_rows_as_knots():
    """δm along a string lying on an obstacle: kinked at every row, zero on average between rows.
    With the rows among the knots its integral is exact; a grid blind to them aliases it (the reason
    the residual's grid is split at the obstacle rows)."""
    from dlo_ros.solver.results.residual import evaluation_grid

    rows = np.linspace(0.2, 0.8, 31)  # 2 cm apart on a 1 m string
    h = rows[1] - rows[0]

    def sawtooth(s):  # (s − r_i)(r_i+1 − s) − h²/6 between rows: zero mean, a kink at each row
        i = np.clip(np.searchsorted(rows, s) - 1, 0, rows.size - 2)
        inside = (s > rows[0]) & (s < rows[-1])
        return np.where(inside, (s - rows[i]) * (rows[i + 1] - s) - h * h / 6, 0.0)

    def antiderivative(x):  # every whole bump integrates to 0; the one x lies in, in part
        i = np.clip(np.searchsorted(rows, x) - 1, 0, rows.size - 2)
        u = np.clip(x - rows[i], 0.0, None) * ((x > rows[0]) & (x < rows[-1]))
        return h * u**2 / 2 - u**3 / 3 - h * h * u / 6

    for kinks, agrees in ((rows, True), ((), False)):
        grid = evaluation_grid(1.0, [], points=64, kinks=kinks)
        f = np.repeat(sawtooth(grid.s)[:, None], 3, axis=1)
        at_points, at_knots = grid.cumulative(f)
        errors = np.concatenate(
            [at_points[:, 0] - antiderivative(grid.s), at_knots[:, 0] - antiderivative(grid.knots)]
        )
        assert bool(np.max(np.abs(errors)) < 1e-15) is agrees, np.max(np.abs(errors))
