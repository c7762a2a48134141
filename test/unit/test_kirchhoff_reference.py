"""Tests of the independent Kirchhoff-rod reference solver (test/reference/kirchhoff.py) against closed
forms.  Nothing here imports dlo_ros.

Run:  bash scripts/dlo-env test test/unit/test_kirchhoff_reference.py   (-s shows the
continuation table of the 3D test).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar
from scipy.special import ellipe, ellipeinc, ellipj, ellipk, ellipkinc

from reference.kirchhoff import (
    RodSolution,
    blas_threads,
    boundary_jacobian,
    continuation,
    discrete_stability,
    frame_curvature_energy,
    relaxed_guess,
    rot_x,
    solve_clamped,
)

I3 = np.eye(3)
O3 = np.zeros(3)


@pytest.fixture(autouse=True, scope="module")
def _single_threaded_blas():
    """Small dense linear algebra only: threaded OpenBLAS on a busy 2-core machine is up to 100x
    slower.  Restored after this module."""
    with blas_threads(1):
        yield


# ------------------------------------------------------------------------------------------------
# closed forms
# ------------------------------------------------------------------------------------------------
def clamped_clamped_elastica(c_over_L: float, L: float, Rf: float):
    """First (symmetric) buckling mode of the planar elastica clamped at both ends with parallel end
    tangents, chord c along the tangents.  Pendulum equation Rf theta'' = -P sin(theta), solution
    theta = 2 asin(k sn(lam s, k)), lam = sqrt(P/Rf); clamped ends with theta = 0 at s = 0, L/2, L
    means one full period: L = 4 K(k)/lam.  Then

        c/L = 2 E(k)/K(k) - 1,   P = lam^2 Rf = 16 K^2 Rf / L^2,
        x(s) = (2 E(am(lam s), k) - lam s)/lam,   y(s) = (2k/lam)(1 - cn(lam s, k)),
        midpoint height h = y(L/2) = 4k/lam = k L / K,   end moment |m(0)| = Rf theta'(0) = 2 k lam Rf.

    (The brief quoted P = 4K^2 Rf/L^2 and h = 2k/lam: those are the pinned-pinned values, where
    L = 2K/lam; for clamped ends L = 4K/lam gives the values above.  Small-amplitude check: k -> 0,
    K -> pi/2, P -> 4 pi^2 Rf/L^2, the clamped Euler load.)
    Returns (m = k^2, P, h, M0, shape(s) -> (x, y))."""
    m = brentq(lambda mm: 2.0 * ellipe(mm) / ellipk(mm) - 1.0 - c_over_L, 1e-14, 1.0 - 1e-14,
               xtol=1e-16, rtol=1e-15)
    K = ellipk(m)
    k = np.sqrt(m)
    lam = 4.0 * K / L
    P = lam**2 * Rf

    def shape(s):
        u = lam * np.asarray(s)
        sn, cn, dn, ph = ellipj(u, m)
        return (2.0 * ellipeinc(ph, m) - u) / lam, 2.0 * k / lam * (1.0 - cn)

    return m, P, 4.0 * k / lam, 2.0 * k * lam * Rf, shape


def tip_loaded_cantilever(P: float, L: float, Rf: float):
    """Exact large-deflection cantilever (clamped at 0 along +x, dead tip force P along -y).
    phi = deflection angle: Rf phi'' = -P cos(phi), phi(0) = 0, phi'(L) = 0.  With
    1 + sin(phi) = 2 k^2 sin^2(psi) (so the tip angle alpha has sin(alpha) = 2k^2 - 1) and
    sin(psi0) = 1/(sqrt(2) k):
        lam L = K(k) - F(psi0, k),                      lam = sqrt(P/Rf)
        x_tip = sqrt(2 sin(alpha)) / lam,
        y_tip = -[(K - F(psi0)) - 2 (E(k) - E(psi0, k))] / lam.
    Returns (x_tip, y_tip, alpha)."""
    lam = np.sqrt(P / Rf)

    def eq(k):
        m = k * k
        return ellipk(m) - ellipkinc(np.arcsin(1.0 / (np.sqrt(2.0) * k)), m) - lam * L

    k = brentq(eq, (1.0 + 1e-15) / np.sqrt(2.0), 1.0 - 1e-15, xtol=1e-16, rtol=1e-15)
    m = k * k
    psi0 = np.arcsin(1.0 / (np.sqrt(2.0) * k))
    x_tip = np.sqrt(2.0 * (2.0 * m - 1.0)) / lam
    y_tip = -L + 2.0 * (ellipe(m) - ellipeinc(psi0, m)) / lam
    return x_tip, y_tip, np.arcsin(2.0 * m - 1.0)


GREENHILL_CLAMPED = 2.0 * brentq(lambda x: np.tan(x) - x, 4.4, 4.6, xtol=1e-15)  # 8.98681891581813


# ------------------------------------------------------------------------------------------------
# 1. cantilever with a tip moment: circular arc
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("turn", [0.3, 0.95])  # kappa L / (2 pi): a short arc and an almost closed circle
def test_tip_moment_gives_circular_arc(turn):
    L, Rf, Rt = 1.3, 0.7, 0.5
    kappa = 2 * np.pi * turn / L
    M = kappa * Rf
    sol = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, None, (0.0, 0.0, M))])
    s = sol.s
    exact = np.c_[np.sin(kappa * s) / kappa, (1 - np.cos(kappa * s)) / kappa, 0 * s]
    assert sol.residual < 1e-10
    assert np.abs(sol.x - exact).max() < 1e-8 * L                      # achieved ~3e-12 L
    assert np.abs(sol.position([0.123, 0.77]) - exact_at([0.123, 0.77], kappa)).max() < 1e-8 * L
    # frames: rotation by kappa s about z
    ang = np.arctan2(sol.frames[:, 1, 0], sol.frames[:, 0, 0])
    assert np.abs(np.unwrap(ang) - kappa * s).max() < 1e-9
    # internal moment uniform, no force; reactions; energy (point-moment work omitted by convention)
    assert np.abs(sol.m - [0, 0, M]).max() < 1e-9 * M and np.abs(sol.n).max() < 1e-9
    assert np.allclose(sol.moment0, [0, 0, -M], atol=1e-10) and np.allclose(sol.force0, 0, atol=1e-10)
    assert sol.energy == pytest.approx(0.5 * M**2 * L / Rf, rel=1e-10)


def exact_at(s, kappa):
    s = np.asarray(s)
    return np.c_[np.sin(kappa * s) / kappa, (1 - np.cos(kappa * s)) / kappa, 0 * s]


def test_tip_twist_moment_keeps_rod_straight():
    L, Rf, Rt, M = 0.9, 1.0, 0.4, 0.3
    sol = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, None, (M, 0.0, 0.0))])
    assert np.abs(sol.x[:, 1:]).max() < 1e-12 and np.allclose(sol.x[:, 0], sol.s, atol=1e-12)
    for sk, Rk in zip(sol.s[::50], sol.frames[::50]):
        assert np.abs(Rk - rot_x(M * sk / Rt)).max() < 1e-10
    assert sol.energy == pytest.approx(0.5 * M**2 * L / Rt, rel=1e-10)


# ------------------------------------------------------------------------------------------------
# 2. cantilever with a perpendicular tip force: exact elastica
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("PL2", [1e-3, 1.0, 3.0, 10.0])
def test_tip_force_elastica(PL2):
    L, Rf, Rt = 0.8, 0.3, 0.25
    P = PL2 * Rf / L**2
    F = np.array([0.0, -P, 0.0])
    if PL2 <= 3.0:
        sol = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, F, None)])
    else:  # from the straight guess Newton stalls this far out: march the load (continuation)
        steps = continuation(
            lambda lf, guess: solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, lf * F, None)],
                                            guess=guess),
            [0.3, 1.0])
        sol = steps[-1][1]
    x_tip, y_tip, alpha = tip_loaded_cantilever(P, L, Rf)
    tip = sol.x[-1]
    assert sol.residual < 1e-10
    assert np.abs(tip - [x_tip, y_tip, 0.0]).max() < 1e-8 * L          # achieved ~1e-13 L
    t_tip = sol.frames[-1][:, 0]
    assert np.arctan2(-t_tip[1], t_tip[0]) == pytest.approx(alpha, abs=1e-9)
    # n is the tip force everywhere; the clamp reaction balances force and moment (about x0 = 0)
    assert np.abs(sol.n - F).max() < 1e-10 * P
    assert np.allclose(sol.force0, -F, atol=1e-12 * P)
    assert np.allclose(sol.moment0, -np.cross(tip, F), atol=1e-10 * P * L)
    # energy: elastic - F.x_tip; elastic = 1/2 Rf int theta'^2
    assert sol.energy == pytest.approx(sol.elastic_energy - F @ tip, rel=1e-12)
    assert frame_curvature_energy(sol) == pytest.approx(sol.elastic_energy, rel=1e-4)
    if PL2 <= 1e-3:  # Euler-Bernoulli
        assert -tip[1] == pytest.approx(P * L**3 / (3 * Rf), rel=1e-3)   # achieved 1.1e-7


# ------------------------------------------------------------------------------------------------
# 3. planar clamped-clamped elastica, chord 0.6 L
# ------------------------------------------------------------------------------------------------
def planar_buckling_guess(c_over_L, L, Rf):
    """Small-amplitude (linear) guess for the first clamped-clamped mode in the xy plane:
    P ~ 4 pi^2 Rf/L^2, k ~ sqrt(1 - c/L), m(0) ~ 2 k lam Rf about +z."""
    lam = 2 * np.pi / L
    k = np.sqrt(1 - c_over_L)
    return np.array([-lam**2 * Rf, 0.0, 0.0]), np.array([0.0, 0.0, 2 * k * lam * Rf])


@pytest.mark.parametrize("segments", [1, 4])
def test_clamped_clamped_elastica(segments):
    L, Rf, Rt, c = 1.3, 0.7, 0.5, 0.6
    m, P, h, M0, shape = clamped_clamped_elastica(c, L, Rf)
    sol = solve_clamped(L, Rf, Rt, O3, I3, (c * L, 0, 0), I3, guess=planar_buckling_guess(c, L, Rf),
                        segments=segments)
    assert sol.residual < 1e-10
    # end forces (gripper on rod): the rod pushes the grippers apart
    assert -sol.forceL[0] == pytest.approx(P, rel=1e-6)                 # achieved ~8e-13
    assert sol.force0[0] == pytest.approx(P, rel=1e-6)
    assert np.abs(sol.forceL[1:]).max() < 1e-9 * P
    assert sol.position(L / 2)[1] == pytest.approx(h, rel=1e-6)         # achieved ~1e-13
    assert sol.m[0][2] == pytest.approx(M0, rel=1e-6)
    xs, ys = shape(sol.s)
    assert np.abs(sol.x[:, 0] - xs).max() < 1e-8 * L
    assert np.abs(sol.x[:, 1] - ys).max() < 1e-8 * L
    assert np.abs(sol.x[:, 2]).max() < 1e-10 * L
    # energy by the frame-only recomputation (second order in the 401-point sampling)
    assert frame_curvature_energy(sol) == pytest.approx(sol.energy, rel=1e-4)


# ------------------------------------------------------------------------------------------------
# 4. heavy cantilever, point loads, cross-checks of the end modes
# ------------------------------------------------------------------------------------------------
def test_heavy_cantilever_linear_limit():
    L, Rf, Rt = 0.5, 2e-3, 2e-3 / 1.3
    D = 1e-3 * Rf / L**3                                               # D L^3 / Rf = 1e-3
    sol = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", D=D, g=(0, 0, -1))
    assert sol.residual < 1e-10
    assert -sol.x[-1][2] == pytest.approx(D * L**4 / (8 * Rf), rel=1e-3)  # achieved 1.2e-8
    # exact statics: the clamp carries the weight, n(s) = -D (L - s) g
    assert np.allclose(sol.force0, [0, 0, D * L], atol=1e-12 * D * L)
    assert np.abs(sol.n[:, 2] + D * (L - sol.s)).max() < 1e-12 * D * L
    assert sol.moment0[1] == pytest.approx(-D * L**2 / 2, rel=1e-6)
    # energy of the linear problem: U = -W/2, elastic = W/2, W = D^2 L^5 / (20 Rf)
    W = D**2 * L**5 / (20 * Rf)
    assert sol.energy == pytest.approx(-W / 2, rel=1e-5)                 # achieved 6e-9
    assert sol.elastic_energy == pytest.approx(W / 2, rel=1e-5)
    assert frame_curvature_energy(sol) == pytest.approx(sol.elastic_energy, rel=1e-4)


@pytest.mark.parametrize("a_frac", [0.3, 0.5])  # 0.5 L is a multiple-shooting node (segments=4)
def test_interior_point_force_linear(a_frac):
    L, Rf, Rt = 1.0, 1.0, 1.0
    a, P = a_frac * L, 1e-4 * Rf / L**2
    sol = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(a, (0, 0, -P), None)])
    assert -sol.x[-1][2] == pytest.approx(P * a**2 * (3 * L - a) / (6 * Rf), rel=1e-6)
    # n jumps by -F at s = a: n = F before (left limit, as sampled), 0 after
    assert np.abs(sol.n[sol.s <= a][:, 2] + P).max() < 1e-12 and np.abs(sol.n[sol.s > a]).max() < 1e-12
    assert sol.energy == pytest.approx(-0.5 * P**2 * a**3 / (3 * Rf), rel=1e-6)


def test_end_modes_reproduce_free_end_solution():
    """A free-end solution under tip load is also the solution of the clamp/pin/tangent problems with
    the end placed where it went; their end reactions must then equal the applied tip load."""
    L, Rf, Rt = 1.0, 1.0, 0.6
    F = np.array([0.4, -1.5, 0.9])
    Mt = np.array([0.2, 0.3, -0.5])
    free_fm = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, F, Mt)])
    clamp = solve_clamped(L, Rf, Rt, O3, I3, free_fm.x[-1], free_fm.frames[-1], guess=free_fm)
    assert np.allclose(clamp.forceL, F, atol=1e-9) and np.allclose(clamp.momentL, Mt, atol=1e-9)
    assert np.abs(clamp.x - free_fm.x).max() < 1e-10
    free_f = solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, F, None)])
    for mode, end in (("pin", None), ("tangent", free_f.frames[-1][:, 0])):
        sol = solve_clamped(L, Rf, Rt, O3, I3, free_f.x[-1], end, mode_end=mode)  # straight guess
        assert np.allclose(sol.forceL, F, atol=1e-9) and np.allclose(sol.momentL, 0, atol=1e-9)
        assert np.abs(sol.x - free_f.x).max() < 1e-10
        assert sol.energy == pytest.approx(free_f.elastic_energy, rel=1e-10)


# ------------------------------------------------------------------------------------------------
# 5. Greenhill: straight twisted rod between clamps at distance L
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mu", [2.0, 8.0, 9.5])  # M L / Rf, below and above the critical 8.9868
def test_straight_twisted_rod_is_equilibrium(mu):
    L, Rf, Rt = 1.0, 1.0, 0.8
    M = mu * Rf / L
    Phi = M * L / Rt                                                    # up to ~ 1.9 turns
    # a guess with 80% of the twist and no lateral component: converges to the straight state
    sol = solve_clamped(L, Rf, Rt, O3, I3, (L, 0, 0), rot_x(Phi), guess=(O3, [0.8 * M, 0, 0]))
    twist = np.einsum("ki,ki->k", sol.m, sol.tangents)
    assert sol.residual < 1e-10
    assert np.abs(twist - Rt * Phi / L).max() < 1e-9 * M
    assert np.abs(sol.x[:, 1:]).max() < 1e-12 and np.abs(sol.m[:, 1:]).max() < 1e-9 * M
    # with a lateral kick too it still returns to the straight state; the inextensible rod at chord
    # exactly L admits only straight shapes, but the axial tension is indeterminate (rank-deficient
    # Jacobian) and a lateral bulge a only changes the chord by O(a^2): a is fixed to ~sqrt(residual)
    sol = solve_clamped(L, Rf, Rt, O3, I3, (L, 0, 0), rot_x(Phi), guess=((0, 0.3, 0), (0.8 * M, 0.3, 0)))
    twist = np.einsum("ki,ki->k", sol.m, sol.tangents)
    assert np.abs(twist - Rt * Phi / L).max() < 1e-8 * M
    assert np.abs(sol.x[:, 1:]).max() < 1e-5 * L


def test_greenhill_critical_twist_from_singular_jacobian():
    """At the straight twisted state (n = 0, m = M t) the shooting Jacobian always has the
    tension/axial-position null pair; with those removed, the remaining 5x5 block becomes singular at
    the clamped-clamped Greenhill moment M L/Rf = 2 x (root of tan x = x) = 8.98681891581813.
    (|det| of the lateral block is |complex det|^2 >= 0, so we minimise the smallest singular value,
    which vanishes linearly: a V.)"""
    L, Rf, Rt = 1.0, 1.0, 1.0

    def sigma_min(mu):
        M = mu * Rf / L
        F, J = boundary_jacobian(L, Rf, Rt, O3, I3, (L, 0, 0), rot_x(M * L / Rt), O3, (M, 0, 0))
        assert np.abs(F).max() < 1e-10 and np.abs(J[0]).max() < 1e-6 and np.abs(J[:, 0]).max() < 1e-6
        return np.linalg.svd(np.delete(np.delete(J, 0, 0), 0, 1), compute_uv=False)[-1]

    res = minimize_scalar(sigma_min, bounds=(8.5, 9.5), method="bounded", options={"xatol": 1e-10})
    assert res.x == pytest.approx(GREENHILL_CLAMPED, rel=1e-7)          # achieved ~5e-10
    assert sigma_min(8.0) > 1e-2 and sigma_min(res.x) < 1e-5


# ------------------------------------------------------------------------------------------------
# 6. 3D: clamp at 0, tangent held (twist free) at L, chord 0.8 L -> 0.3 L by continuation
# ------------------------------------------------------------------------------------------------
L6, RF6, RT6 = 1.0, 1.0, 0.01
CHORDS = np.round(np.arange(0.8, 0.3 - 1e-9, -0.05), 10)


@pytest.fixture(scope="module")
def loop_branch():
    # planar buckled shape of test 3 (full clamp) at c = 0.8 L, then kicked out of its plane
    planar = solve_clamped(L6, RF6, RT6, O3, I3, (0.8 * L6, 0, 0), I3,
                           guess=planar_buckling_guess(0.8, L6, RF6))
    n0 = planar.n0 + [0.0, 0.0, 0.3]
    m0 = planar.m0 + [0.0, 0.05 * np.abs(planar.m0).max(), 0.0]

    def solve(c, guess):
        return solve_clamped(L6, RF6, RT6, O3, I3, (c * L6, 0, 0), (1, 0, 0), mode_end="tangent",
                             guess=guess, s_eval=np.linspace(0, L6, 2001))

    rows = []

    def report(c, sol):
        dist = np.hypot(sol.x[:, 1], sol.x[:, 2])
        X = sol.x - sol.x.mean(0)
        sv = np.linalg.svd(X, compute_uv=False)
        rows.append((c, sol.energy, dist.max(), sv[-1], sol.forceL[0], sol.residual))

    out = continuation(solve, CHORDS, guess=(n0, m0), callback=report)
    print("\n  c/L      U [J]      max dist from chord   out-of-plane   F_L,x [N]    residual")
    for c, U, h, oop, fx, r in rows:
        print(f"  {c:4.2f}  {U:11.6f}   {h:10.6f}            {oop:9.2e}   {fx:11.6f}   {r:8.1e}")
    return out


def test_loop_continuation_converges(loop_branch):
    assert [c for c, _ in loop_branch] == list(CHORDS)
    for c, sol in loop_branch:
        assert isinstance(sol, RodSolution) and sol.residual < 1e-10
        assert np.allclose(sol.x[-1], [c * L6, 0, 0], atol=1e-10)
        assert sol.frames[-1][:, 0] @ [1, 0, 0] > 1 - 1e-10
        # free end twist: m.t = 0 all along (it is a first integral of the isotropic rod)
        assert np.abs(np.einsum("ki,ki->k", sol.m, sol.tangents)).max() < 1e-9


def test_loop_energy_increases_and_is_consistent(loop_branch):
    c = np.array([c for c, _ in loop_branch])
    U = np.array([s.energy for _, s in loop_branch])
    Fx = np.array([s.forceL[0] for _, s in loop_branch])
    assert np.all(np.diff(U) > 0)                                       # shorter chord, more energy
    # equilibrium check by energy: dU/dc = F_L . dx1/dc = F_L,x (work of the gripper; true only at
    # equilibrium).  Simpson over pairs of steps, error O(dc^5).
    for i in range(0, len(c) - 2, 2):
        simpson = (c[i + 2] - c[i]) / 6 * (Fx[i] + 4 * Fx[i + 1] + Fx[i + 2])
        assert simpson == pytest.approx(U[i + 2] - U[i], rel=1e-5)      # achieved 2e-7 .. 6e-7
    # the energy recomputed from the sampled frames alone (no use of m): 2001 points, O(ds^2)
    for _, sol in loop_branch:
        assert frame_curvature_energy(sol) == pytest.approx(sol.energy, rel=1e-5)


def test_loop_branch_matches_planar_elastica(loop_branch):
    """With the twist free at s = L the twist moment vanishes and the isotropic rod stays a planar
    clamped-clamped elastica (the out-of-plane kick only rotates its plane about the chord — a neutral
    direction of this problem, which the least-squares Newton handles)."""
    for c, sol in loop_branch:
        _, P, h, _, _ = clamped_clamped_elastica(c, L6, RF6)
        assert -sol.forceL[0] == pytest.approx(P, rel=1e-8)
        assert np.hypot(*sol.position(L6 / 2)[1:]) == pytest.approx(h, rel=1e-8)


def test_loop_planar_branch_loses_stability(loop_branch):
    """Discrete-rod second variation along the planar branch (40 edges): stable at c >= 0.65 L,
    unstable (one negative eigenvalue) from c = 0.6 L on; the rotation about the chord is neutral."""
    print("\n  c/L   lowest eigenvalues of the discrete second variation (x L^2/(Rf h))")
    reports = []
    for c, sol in loop_branch:
        rep = discrete_stability(sol, n_edges=40)
        reports.append((c, rep))
        print(f"  {c:4.2f}  {np.array2string(rep.eigenvalues[:3], precision=4)}  shift {rep.shift:.1e}")
        assert rep.n_zero >= 1 and rep.shift < 1e-3
    assert all(rep.stable for c, rep in reports if c >= 0.65)
    assert all(rep.n_negative == 1 for c, rep in reports if c <= 0.6)


@pytest.fixture(scope="module")
def nonplanar_at_half(loop_branch):
    """Branch switch at c = 0.5 L: the discrete rod descends from the unstable planar state to a
    local energy minimum; the shooting solver polishes that into a continuum equilibrium."""
    planar = dict(loop_branch)[0.5]
    fn, info = relaxed_guess(planar, n_edges=40)
    sol = solve_clamped(L6, RF6, RT6, O3, I3, (0.5 * L6, 0, 0), (1, 0, 0), mode_end="tangent", guess=fn,
                        s_eval=np.linspace(0, L6, 2001))
    return planar, sol, info


def test_loop_leaves_the_plane_where_planar_is_unstable(nonplanar_at_half):
    planar, sol, info = nonplanar_at_half
    X = sol.x - sol.x.mean(0)
    out_of_plane = np.linalg.svd(X / np.sqrt(len(X)), compute_uv=False)[-1]
    rep = discrete_stability(sol, n_edges=40)
    print(f"\n  c = 0.5 L: planar U = {planar.energy:.6f} J, non-planar U = {sol.energy:.6f} J, "
          f"out-of-plane rms {out_of_plane:.3e} L, "
          f"eigenvalues {np.array2string(rep.eigenvalues[:3], precision=4)}")
    assert sol.residual < 1e-10
    assert sol.energy < planar.energy - 0.5                              # 21.644 vs 22.802
    assert out_of_plane > 1e-2 * L6
    # a (discrete) minimum; the discrete equilibrium is O(h^2) away (8.7e-3 rad at 40 edges, 2.2e-3
    # at 80, 5.5e-4 at 160: the soft twist, Rt = Rf/100, makes the constant large)
    assert rep.stable and rep.shift < 2e-2
    assert np.abs(np.einsum("ki,ki->k", sol.m, sol.tangents)).max() < 1e-9
    assert frame_curvature_energy(sol) == pytest.approx(sol.energy, rel=1e-5)
    # equilibrium by energy: dU/dc = F_L,x, central difference over +-1e-3 L
    d = 1e-3
    U = [solve_clamped(L6, RF6, RT6, O3, I3, ((0.5 + e) * L6, 0, 0), (1, 0, 0), mode_end="tangent",
                       guess=sol).energy for e in (-d, d)]
    assert (U[1] - U[0]) / (2 * d * L6) == pytest.approx(sol.forceL[0], rel=1e-4)   # achieved 4e-6


# ------------------------------------------------------------------------------------------------
# 6b. genuinely 3D path: clamped end rotated about the chord, then the chord shortened
# ------------------------------------------------------------------------------------------------
def test_rotated_clamp_3d_path_energy_consistency():
    """Clamp-clamp, Rt = 0.77 Rf: from the planar arch at c = 0.8 L the far clamp is turned by
    Phi = pi/2 about the chord (dU/dPhi = M_L,x), then the chord is shortened to 0.3 L
    (dU/dc = F_L,x).  Both checked by Simpson's rule over pairs of steps."""
    L, Rf, Rt = 1.0, 1.0, 0.77
    planar = solve_clamped(L, Rf, Rt, O3, I3, (0.8 * L, 0, 0), I3, guess=planar_buckling_guess(0.8, L, Rf))
    phis = np.linspace(0.0, np.pi / 2, 5)
    turn = continuation(lambda p, g: solve_clamped(L, Rf, Rt, O3, I3, (0.8 * L, 0, 0), rot_x(p), guess=g),
                        phis, guess=planar)
    U = np.array([s.energy for _, s in turn])
    Mx = np.array([s.momentL[0] for _, s in turn])
    for i in (0, 2):
        simpson = (phis[i + 2] - phis[i]) / 6 * (Mx[i] + 4 * Mx[i + 1] + Mx[i + 2])
        assert simpson == pytest.approx(U[i + 2] - U[i], rel=1e-4)      # achieved 2e-5
    chords = np.round(np.arange(0.8, 0.3 - 1e-9, -0.05), 10)
    path = continuation(lambda c, g: solve_clamped(L, Rf, Rt, O3, I3, (c * L, 0, 0), rot_x(np.pi / 2),
                                                   guess=g, s_eval=np.linspace(0, L, 2001)),
                        chords, guess=turn[-1][1])
    U = np.array([s.energy for _, s in path])
    Fx = np.array([s.forceL[0] for _, s in path])
    print("\n  c/L      U [J]     F_L,x [N]   out-of-plane rms")
    for (c, s) in path:
        X = s.x - s.x.mean(0)
        oop = np.linalg.svd(X / np.sqrt(len(X)), compute_uv=False)[-1]
        print(f"  {c:4.2f}  {s.energy:10.6f}  {s.forceL[0]:10.5f}   {oop:.3e}")
        assert s.residual < 1e-10 and oop > 1e-2 * L
        assert frame_curvature_energy(s) == pytest.approx(s.energy, rel=1e-5)
    assert np.all(np.diff(U) > 0)
    for i in range(0, len(chords) - 2, 2):
        simpson = (chords[i + 2] - chords[i]) / 6 * (Fx[i] + 4 * Fx[i + 1] + Fx[i + 2])
        assert simpson == pytest.approx(U[i + 2] - U[i], rel=1e-3)      # achieved 5e-6 .. 4e-4


# ------------------------------------------------------------------------------------------------
# stability check on known cases
# ------------------------------------------------------------------------------------------------
def test_discrete_stability_classifies_known_equilibria():
    L, Rf, Rt, c = 1.0, 1.0, 0.8, 0.6
    # cantilevers: stable, no neutral direction
    for sol in (solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", D=3.0),
                solve_clamped(L, Rf, Rt, O3, I3, mode_end="free", loads=[(L, (0, -3, 0), None)])):
        rep = discrete_stability(sol, n_edges=40)
        assert rep.stable and rep.n_zero == 0 and rep.shift < 1e-3
    # clamped-clamped elastica: the first (symmetric) mode is stable, the second (antisymmetric,
    # P ~ 80.8 Rf/L^2 at small amplitude) is not; both have the neutral rotation about the chord
    sym = solve_clamped(L, Rf, Rt, O3, I3, (c * L, 0, 0), I3, guess=planar_buckling_guess(c, L, Rf))
    anti = solve_clamped(L, Rf, Rt, O3, I3, (c * L, 0, 0), I3, guess=((-80.76, 0, 0), (0, 0, 0.5)))
    assert np.allclose(anti.position(L / 2), [c * L / 2, 0, 0], atol=1e-9)   # point-symmetric S
    rs, ra = discrete_stability(sym, n_edges=40), discrete_stability(anti, n_edges=40)
    assert rs.stable and rs.n_zero == 1
    assert ra.n_negative >= 1 and ra.n_zero == 1


# ------------------------------------------------------------------------------------------------
# continuation helper: step halving on failure (pure logic, no ODEs)
# ------------------------------------------------------------------------------------------------
def test_continuation_halves_failed_steps():
    calls = []

    def fake_solve(p, guess):
        prev = -1.0 if guess is None else guess
        calls.append(p)
        if abs(p - prev) > 0.26 and guess is not None:
            raise RuntimeError("step too large")
        return p  # "solution" = parameter reached

    out = continuation(fake_solve, [0.0, 1.0], guess=None)
    assert [p for p, _ in out] == [0.0, 1.0] and out[-1][1] == 1.0
    assert 0.25 in calls and 0.5 in calls
    with pytest.raises(RuntimeError):
        continuation(fake_solve, [0.0, 1.0], max_halvings=1)


# ---- test/reference/twisted_contact_rod.py (quaternion edges, bend and twist joints) -----------------
def _twisted_rod_energy(n: int, end: np.ndarray, q_end: np.ndarray, start) -> float:
    from reference.twisted_contact_rod import solve_twisted_contact_rod

    q0 = np.array([start((j + 0.5) / n) for j in range(n)])
    ref = solve_twisted_contact_rod(q0, 1.0, 1.0, 0.7, (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])),
                                    (end, q_end), 0.01, 0.1, 0.0)
    assert ref.success, ref.message
    return ref.energy, ref.twist_energy


def _quat(axis: int, angle: float) -> np.ndarray:
    q = np.array([0.0, 0.0, 0.0, np.cos(angle / 2)])
    q[axis] = np.sin(angle / 2)
    return q


def test_twisted_contact_rod_closed_forms():
    """Richardson in h² (N = 20, 40; the half joints at the clamps leave an h³ term) against closed forms: a straight rod with its end clamp turned 1.5π
    about the tangent holds Rt α²/2L, all of it twist; a rod whose end clamp is turned π/2 about z, at the
    end of the quarter circle, holds Rf φ²/2L with no twist."""
    alpha = 1.5 * np.pi
    e = {n: _twisted_rod_energy(n, np.array([1.0, 0.0, 0.0]), _quat(0, alpha), lambda u: _quat(0, alpha * u))
         for n in (20, 40)}
    limit = e[40][0] + (e[40][0] - e[20][0]) / 3
    assert limit == pytest.approx(0.7 * alpha**2 / 2, rel=1e-4) and e[40][1] == pytest.approx(e[40][0], rel=1e-12)
    phi = np.pi / 2
    end = np.array([np.sin(phi), 1 - np.cos(phi), 0.0]) / phi
    e = {n: _twisted_rod_energy(n, end, _quat(2, phi), lambda u: _quat(2, phi * u)) for n in (20, 40)}
    limit = e[40][0] + (e[40][0] - e[20][0]) / 3
    assert limit == pytest.approx(phi**2 / 2, rel=1e-4) and abs(e[40][1]) < 1e-12
