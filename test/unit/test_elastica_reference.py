"""Independent checks of the closed-form clamped--clamped elastica (dlo_ros.model.elastica).

The closed form is the ground truth for the Ritz solver tests, so it is validated here
without reusing any of its own formulas:

1. against a direct numerical solution of the same boundary value problem
   (scipy.integrate.solve_bvp, started from a sine guess, not from the closed form);
2. against geometric identities (unit speed, end points, symmetry, tangent, curvature);
3. against the virtual-work identity dU/da = -P (energy vs. end force).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_bvp

from dlo_ros.model.elastica import ClampedElastica, clamped_clamped_elastica

# (L [m], Rf [N m^2], a/L)
BVP_CASES = [
    (1.0, 1.0, 0.9),
    (0.7, 0.3, 0.7),
    (1.0, 0.3, 0.5),
    (0.7, 1.0, 0.3),
]
GEOM_CASES = [
    (1.0, 1.0, 0.95),
    (0.7, 0.3, 0.9),
    (1.0, 0.3, 0.7),
    (0.7, 1.0, 0.5),
    (1.0, 1.0, 0.3),
    (0.7, 0.3, 0.1),
    (1.0, 1.0, 0.05),
]


def _solve_bvp(L: float, Rf: float, a: float):
    """Clamped--clamped elastica as a BVP, independent of the closed form.

    State z = (theta, theta', x, y), unknown parameters p = (P, Q): the internal force
    exerted by the part beyond s on the part before s is n = (-P, -Q) (P > 0 is
    compression).  Moment balance d/ds(Rf theta') + r' x n = 0 gives
        Rf theta'' + P sin(theta) - Q cos(theta) = 0,   x' = cos(theta),   y' = sin(theta).
    The lateral force Q is left free (6 BCs for 4 states + 2 parameters); for the
    symmetric mode it must come out as 0.
    """

    def rhs(s, z, p):
        P, Q = p
        th, om, _, _ = z
        return np.vstack([om, (Q * np.cos(th) - P * np.sin(th)) / Rf, np.cos(th), np.sin(th)])

    def bc(z0, zL, p):
        return np.array([z0[0], z0[2], z0[3], zL[0], zL[2] - a, zL[3]])

    # tol=1e-9 (relative collocation residual) gives ~1e-13 agreement; 1e-10 hits the
    # round-off floor of solve_bvp for some cases and then fails on the node limit.
    # Sine guess on the first symmetric mode, amplitude from the small-deflection
    # estimate a/L ~= 1 - sin^2(theta_max/2).
    s = np.linspace(0.0, L, 401)
    w = 2.0 * np.pi / L
    amp = 2.0 * np.arcsin(np.sqrt(1.0 - a / L))
    guess = np.vstack(
        [
            amp * np.sin(w * s),
            amp * w * np.cos(w * s),
            a * s / L,
            amp / w * (1.0 - np.cos(w * s)),
        ]
    )
    sol = solve_bvp(rhs, bc, s, guess, p=[Rf * w**2, 0.0], tol=1e-9, bc_tol=1e-12, max_nodes=100_000)
    assert sol.success, sol.message
    return sol


@pytest.fixture(scope="module", params=BVP_CASES, ids=lambda c: f"L={c[0]}-Rf={c[1]}-a/L={c[2]}")
def bvp_case(request):
    L, Rf, ratio = request.param
    a = ratio * L
    return L, Rf, a, clamped_clamped_elastica(L, Rf, a), _solve_bvp(L, Rf, a)


def test_positions_match_bvp(bvp_case):
    L, _, _, ref, sol = bvp_case
    s = np.linspace(0.0, L, 4001)
    xy_bvp = sol.sol(s)[2:4].T
    err = np.max(np.linalg.norm(ref.positions(s) - xy_bvp, axis=1))
    assert err < 1e-6 * L, err


def test_tangent_and_curvature_match_bvp(bvp_case):
    L, _, _, ref, sol = bvp_case
    s = np.linspace(0.0, L, 4001)
    z = sol.sol(s)
    np.testing.assert_allclose(ref.tangent_angle(s), z[0], rtol=0, atol=1e-6)
    kmax = np.max(np.abs(z[1]))
    np.testing.assert_allclose(ref.curvature(s), z[1], rtol=0, atol=1e-6 * kmax)


def test_end_force_matches_bvp(bvp_case):
    _, _, _, ref, sol = bvp_case
    P, Q = sol.p
    assert P > 0.0
    assert ref.end_force == pytest.approx(P, rel=1e-5)
    assert abs(Q) < 1e-6 * P  # symmetric mode: no lateral reaction


def test_end_moment_matches_bvp(bvp_case):
    _, Rf, _, ref, sol = bvp_case
    M0 = Rf * sol.y[1, 0]
    ML = Rf * sol.y[1, -1]
    assert M0 > 0.0  # buckled towards +y
    assert ref.end_moment == pytest.approx(M0, rel=1e-5)
    assert ref.end_moment == pytest.approx(ML, rel=1e-5)


def test_energy_matches_bvp(bvp_case):
    L, Rf, _, ref, sol = bvp_case
    s = np.linspace(0.0, L, 40_001)
    kappa = sol.sol(s)[1]
    energy_bvp = np.trapezoid(0.5 * Rf * kappa**2, s)
    assert ref.energy == pytest.approx(energy_bvp, rel=1e-6)


# ----------------------------------------------------------------------------- geometry


@pytest.fixture(scope="module", params=GEOM_CASES, ids=lambda c: f"L={c[0]}-Rf={c[1]}-a/L={c[2]}")
def geom_case(request):
    L, Rf, ratio = request.param
    return L, Rf, ratio * L, clamped_clamped_elastica(L, Rf, ratio * L)


def _fd(f: np.ndarray, h: float) -> np.ndarray:
    return np.gradient(f, h, axis=0, edge_order=2)


def test_unit_speed(geom_case):
    L, _, _, ref = geom_case
    s, h = np.linspace(0.0, L, 20_001, retstep=True)
    speed = np.linalg.norm(_fd(ref.positions(s), h), axis=1)
    np.testing.assert_allclose(speed, 1.0, rtol=0, atol=1e-6)


def test_end_points_and_clamp_angles(geom_case):
    L, _, a, ref = geom_case
    ends = ref.positions(np.array([0.0, L]))
    np.testing.assert_allclose(ends, [[0.0, 0.0], [a, 0.0]], rtol=0, atol=1e-12 * L)
    np.testing.assert_allclose(ref.tangent_angle(np.array([0.0, L])), 0.0, rtol=0, atol=1e-12)


def test_symmetry_and_upward_buckling(geom_case):
    L, _, a, ref = geom_case
    s = np.linspace(0.0, L, 2001)
    xy = ref.positions(s)
    xy_rev = ref.positions(L - s)
    np.testing.assert_allclose(xy[:, 1], xy_rev[:, 1], rtol=0, atol=1e-12 * L)
    np.testing.assert_allclose(xy[:, 0], a - xy_rev[:, 0], rtol=0, atol=1e-12 * L)
    assert np.all(xy[:, 1] >= -1e-14 * L)
    assert np.max(xy[:, 1]) > 0.0
    np.testing.assert_allclose(ref.positions(L / 2)[1], ref.max_deflection, rtol=1e-12)


def test_tangent_angle_is_direction_of_derivative(geom_case):
    L, _, _, ref = geom_case
    s, h = np.linspace(0.0, L, 20_001, retstep=True)
    d = _fd(ref.positions(s), h)
    theta_fd = np.arctan2(d[:, 1], d[:, 0])
    np.testing.assert_allclose(ref.tangent_angle(s), theta_fd, rtol=0, atol=1e-6)


def test_curvature_is_derivative_of_tangent_angle(geom_case):
    L, _, _, ref = geom_case
    s, h = np.linspace(0.0, L, 20_001, retstep=True)
    kappa_fd = _fd(ref.tangent_angle(s), h)
    kappa = ref.curvature(s)
    np.testing.assert_allclose(kappa, kappa_fd, rtol=0, atol=1e-6 * np.max(np.abs(kappa)))


def test_energy_is_quadrature_of_curvature(geom_case):
    L, Rf, _, ref = geom_case
    s = np.linspace(0.0, L, 40_001)
    energy_q = np.trapezoid(0.5 * Rf * ref.curvature(s) ** 2, s)
    assert ref.energy == pytest.approx(energy_q, rel=1e-7)


def test_virtual_work_energy_derivative_is_minus_end_force(geom_case):
    """Pulling the clamps apart by da releases energy P da:  dU/da = -P."""
    L, Rf, a, ref = geom_case
    h = 1e-5 * L
    up = clamped_clamped_elastica(L, Rf, a + h).energy
    dn = clamped_clamped_elastica(L, Rf, a - h).energy
    dUda = (up - dn) / (2.0 * h)
    assert dUda == pytest.approx(-ref.end_force, rel=1e-6)


def test_small_amplitude_limit():
    """a -> L: Euler load 4 pi^2 Rf / L^2 and linearised shape (A/2)(1 - cos 2 pi s/L)."""
    L, Rf = 0.7, 0.3
    a = L * (1.0 - 1e-8)
    ref = clamped_clamped_elastica(L, Rf, a)
    assert ref.end_force == pytest.approx(4.0 * np.pi**2 * Rf / L**2, rel=1e-7)
    s = np.linspace(0.0, L, 501)
    y = ref.positions(s)[:, 1]
    # linearised inextensibility for y = (A/2)(1 - cos 2 pi s/L):
    # L - a = 1/2 int y'^2 ds = pi^2 A^2 / (4 L)
    A = 2.0 * np.sqrt(L * (L - a)) / np.pi
    np.testing.assert_allclose(y, 0.5 * A * (1.0 - np.cos(2.0 * np.pi * s / L)), rtol=0, atol=1e-6 * A)


def test_rejects_invalid_input():
    for args in [(1.0, 1.0, 1.0), (1.0, 1.0, 0.0), (1.0, 1.0, -0.1), (1.0, 1.0, 1.2), (0.0, 1.0, 0.5), (1.0, -1.0, 0.5)]:
        with pytest.raises(ValueError):
            clamped_clamped_elastica(*args)


def test_dataclass_fields():
    ref = clamped_clamped_elastica(1.0, 1.0, 0.5)
    assert isinstance(ref, ClampedElastica)
    assert 0.0 < ref.k < 1.0 and ref.K > np.pi / 2
    with pytest.raises(Exception):
        ref.k = 0.1  # frozen
