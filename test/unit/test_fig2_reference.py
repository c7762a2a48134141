"""The paper's Fig. 2 set-up against an independent Kirchhoff rod (test/reference, shooting on the rod
equations with scipy) and the closed-form elastica, cold and streamed, from chord 0.8 L down to 0.3 L
(below 0.5 L on the branch the reference follows down from 0.5 L: bench/suite/fig2_knots.py has the numbers).

Clamp at s = 0 (pose identity at the origin), the end s = L held by its tangent (+x, twist free) at
(c, 0, 0), Rf/Rt = 100, no weight.  The twist is free at the far end, so the rod carries no twisting
moment and the planar clamped–clamped elastica is an equilibrium for every chord; it is stable down to
c ≈ 0.65 L and unstable from 0.6 L on (test/reference), where the stable shape leaves the plane.  The
rotation of the whole shape about the chord is neutral (no gravity), and the non-planar shape comes in
two mirror images, so centrelines are compared after the best rotation about the chord (and mirror).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize
from support.problems import clamped_pair
from reference.kirchhoff import blas_threads, continuation, discrete_stability, relaxed_guess, solve_clamped
from test_kirchhoff_reference import planar_buckling_guess

from dlo_ros.model.elastica import clamped_clamped_elastica
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

L, RF, RT = 1.0, 1.0, 0.01
ORDER = 24
S = np.linspace(0.0, L, 51)


def fig2(c: float):
    return clamped_pair(right=(c, 0.0, 0.0), bend=RF, twist=RT, modes=("clamp", "tangent"))


def reference(c: float):
    """The stable equilibrium at chord c: the planar elastica where it is stable, else the shooting
    solution polished from the discrete rod's descent off the (unstable) planar one."""
    with blas_threads(1):
        planar = solve_clamped(L, RF, RT, np.zeros(3), np.eye(3), (c, 0, 0), (1, 0, 0), mode_end="tangent",
                               guess=planar_buckling_guess(c, L, RF), s_eval=np.linspace(0, L, 2001))
        if discrete_stability(planar, n_edges=40).stable:
            return planar, True
        fn, _ = relaxed_guess(planar, n_edges=40)
        sol = solve_clamped(L, RF, RT, np.zeros(3), np.eye(3), (c, 0, 0), (1, 0, 0), mode_end="tangent",
                            guess=fn, s_eval=np.linspace(0, L, 2001))
        assert discrete_stability(sol, n_edges=40).stable
        return sol, False


def branch_references(chords, step: float = 0.01) -> dict:
    """The stable non-planar branch of chord 0.5 L (``reference``) followed down to every chord in
    ``chords`` (< 0.5 L): natural-parameter continuation in steps of ``step``, each shooting solve started
    from the previous solution (single shooting: 6 unknowns; a failed step is halved).  Below 0.5 L the
    shape closes a loop, and a cold start, or the discrete rod relaxed from the planar one, lands
    elsewhere; only branch-following stays on this branch."""
    start, _ = reference(0.5)
    wanted = np.round(np.arange(0.5 - step, min(chords) - 1e-9, -step), 10)
    wanted = sorted(set(wanted) | set(np.round(chords, 10)), reverse=True)

    def step_to(c, guess):
        return solve_clamped(L, RF, RT, np.zeros(3), np.eye(3), (c, 0, 0), (1, 0, 0), mode_end="tangent",
                             guess=guess, s_eval=np.linspace(0, L, 401), segments=1)

    with blas_threads(1):
        path = dict(continuation(step_to, wanted, guess=start))
    return {c: path[round(c, 10)] for c in chords}


def closest_self_approach(s: np.ndarray, x: np.ndarray, gap: float = 0.05 * L) -> tuple[float, float, float]:
    """(distance, s_a, s_b): the closest approach of the centreline to itself between points more than
    ``gap`` apart along s.  The closest pair of samples, then refined on the cubic spline through the
    samples (minimised over both arc lengths within a sample spacing of that pair, keeping them ``gap``
    apart).  When the pair ends up exactly ``gap`` apart, the centreline comes no closer to itself than
    its own arc over ``gap`` does."""
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    far = s[None, :] - s[:, None] > gap
    i, j = np.unravel_index(np.argmin(np.where(far, d, np.inf)), d.shape)
    spline, h = CubicSpline(s, x, axis=0), s[1] - s[0]
    bounds = [(max(s[i] - h, 0.0), s[i] + h), (s[j] - h, min(s[j] + h, s[-1]))]
    best = minimize(lambda ab: np.sum((spline(ab[0]) - spline(ab[1])) ** 2), [s[i], s[j]], bounds=bounds,
                    constraints=[{"type": "ineq", "fun": lambda ab: ab[1] - ab[0] - gap}], method="SLSQP",
                    options={"ftol": 1e-20, "maxiter": 200})
    a, b = best.x if best.fun < d[i, j] ** 2 and best.x[1] - best.x[0] >= gap * (1 - 1e-9) else (s[i], s[j])
    return float(np.linalg.norm(spline(a) - spline(b))), float(a), float(b)


@pytest.fixture(scope="module")
def references():
    return {c: reference(c) for c in (0.8, 0.7, 0.6, 0.5)}


def distance_modulo_chord_rotation(points: np.ndarray, ref: np.ndarray) -> float:
    """max |R p − q| over the best rotation R about the x-axis, with or without the mirror y → −y."""
    best = np.inf
    for mirror in (1.0, -1.0):
        p = points * np.array([1.0, mirror, 1.0])
        a = np.sum(p[:, 1] * ref[:, 1] + p[:, 2] * ref[:, 2])
        b = np.sum(p[:, 1] * ref[:, 2] - p[:, 2] * ref[:, 1])
        angle = np.arctan2(b, a)
        c, s = np.cos(angle), np.sin(angle)
        turned = np.stack([p[:, 0], c * p[:, 1] - s * p[:, 2], s * p[:, 1] + c * p[:, 2]], axis=1)
        best = min(best, float(np.max(np.linalg.norm(turned - ref, axis=1))))
    return best


def check(result, c, references):
    sol, planar = references[c]
    assert result.ok and result.stable, (c, result.message)
    assert result.energy["total"] == pytest.approx(sol.energy, rel=1e-5), c
    assert distance_modulo_chord_rotation(result.points, sol.position(S)) < 1e-4 * L, c
    if planar:  # the closed form, too
        assert result.energy["total"] == pytest.approx(clamped_clamped_elastica(L, RF, c).energy, rel=1e-5)
    else:
        assert np.ptp(result.points[:, 1]) > 1e-2 and np.ptp(result.points[:, 2]) > 1e-2  # left the plane


@pytest.mark.parametrize("c", [0.8, 0.7, 0.6, 0.5])
def test_fig2_cold(c, references):
    solver = ShapeSolver(fig2(c), SolverOptions(model="full", order=ORDER, output_points=51), compile="off")
    check(solver.solve(), c, references)


KNOTS = (0.4, 0.3)
#: the loops below 0.5 L share one reference followed down from 0.5 L (~30 s of shooting):
#: the whole suite's run (CI) leaves them out (pytest.ini); chords 0.8-0.5 L stay in it
SLOW = pytest.mark.slow


@pytest.fixture(scope="module")
def knot_references():
    """chord → (the reference followed down from 0.5 L, its discrete-rod stability verdict)."""
    refs = branch_references(KNOTS)
    with blas_threads(1):
        return {c: (sol, discrete_stability(sol, n_edges=40).stable) for c, sol in refs.items()}


def check_knot(result, c, knot_references):
    """Below 0.5 L the shape closes a loop: the answer must lie on the reference's branch (energy, shape),
    with the reference's stability verdict.  Its closest self-approach is printed, not judged (#15)."""
    sol, stable = knot_references[c]
    assert result.ok, (c, result.message)
    assert result.stable == stable, (c, result.min_eigenvalue)
    assert result.energy["total"] == pytest.approx(sol.energy, rel=1e-5), c
    assert distance_modulo_chord_rotation(result.points, sol.position(S)) < 1e-4 * L, c
    d, a, b = closest_self_approach(S, result.points, 0.05 * L)
    s_ref = np.linspace(0.0, L, 1001)
    d_ref, _, _ = closest_self_approach(s_ref, sol.position(s_ref), 0.05 * L)
    print(f"\nchord {c} L: closest self-approach {d:.2e} L (s = {a:.3f}, {b:.3f}); reference {d_ref:.2e} L")


@SLOW
@pytest.mark.parametrize("c", KNOTS)
def test_fig2_knot_cold(c, knot_references):
    solver = ShapeSolver(fig2(c), SolverOptions(model="full", order=ORDER, output_points=51), compile="off")
    check_knot(solver.solve(), c, knot_references)


@SLOW
def test_fig2_streamed(references, knot_references):
    """From 0.8 L down to 0.3 L in steps of 0.01 L, each a warm update: the stream follows the planar
    branch while it is stable, leaves it for the stable non-planar shape once it is not, and follows
    that one as it closes a loop."""
    solver = ShapeSolver(fig2(0.8), SolverOptions(model="full", order=ORDER, output_points=51), compile="off")
    check(solver.solve(), 0.8, references)
    for c in np.round(np.arange(0.79, 0.295, -0.01), 10):
        r = solver.solve({"right": ((c, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))})
        assert r.ok and r.stable and r.warm_started, (c, r.message)
        if c in references:
            check(r, c, references)
        if c in knot_references:
            check_knot(r, c, knot_references)


@SLOW
def test_fig2_knot_cold_at_the_default_order_leaves_the_unstable_branch(knot_references):
    """Order 16, cold, at 0.4 L: IPOPT stops near an unstable equilibrium that the residual check cannot
    confirm at this order (unverified, a negative eigenvalue); the solver leaves it along that mode and
    lands on the reference's stable branch within the tolerance 1e-3 L."""
    solver = ShapeSolver(fig2(0.4), SolverOptions(model="full", order=16, output_points=51), compile="off")
    r = solver.solve()
    sol, stable = knot_references[0.4]
    assert stable and r.ok and r.stable, r.message
    assert r.energy["total"] == pytest.approx(sol.energy, rel=2e-4)
    assert distance_modulo_chord_rotation(r.points, sol.position(S)) < 1e-3 * L
