"""Model layer (no solver, no ROS): bases, quadrature, rotations, profiles, obstacles, validation."""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model import ChebyshevQuadrature, FourierBasis, Obstacle, Profile, make_basis
from dlo_ros.model.rotations import (
    TANGENT_X, check_quaternion, euler_from_frame, material_frames, matrix_to_quat, pose_quaternions, quat_to_matrix,
    reference_frame,
)
from support.problems import clamped_pair, quat_about


@pytest.mark.parametrize("name", ["chebyshev", "fourier"])
def test_basis_derivative_matches_finite_difference(name):
    basis = make_basis(name, 9, 0.7)
    s = np.linspace(0.01, 0.69, 50)
    h = 1e-6
    fd = (basis.values(s + h) - basis.values(s - h)) / (2 * h)
    assert np.max(np.abs(fd - basis.derivatives(s))) < 1e-5 * np.max(np.abs(fd) + 1)


def test_fourier_basis_is_the_papers():
    b = FourierBasis(10, 2.0)
    s = np.array([0.3])
    expected = [1, 0.15] + sum(([np.sin(2 * n * np.pi * 0.15), np.cos(2 * n * np.pi * 0.15)] for n in range(1, 5)), [])
    assert np.allclose(b.values(s)[0], expected)


def test_quadrature_integrates_smooth_functions_exactly_enough():
    q = ChebyshevQuadrature(30, 2.0)
    f = np.exp(np.sin(q.nodes))
    s = np.array([0.0, 0.5, 1.3, 2.0])
    from scipy.integrate import quad

    exact = [quad(lambda x: np.exp(np.sin(x)), 0, si)[0] for si in s]
    assert np.allclose(q.integration_matrix(s) @ f, exact, atol=1e-12)
    assert abs(q.weights.sum() - 2.0) < 1e-13


def test_euler_angles_round_trip_and_curvature_formula():
    rng = np.random.default_rng(1)
    r0 = reference_frame(np.array([1.0, 0.2, 0.0]), np.array([0.0, 0.0, 1.0]))
    for _ in range(20):
        phi, theta, psi = rng.uniform(-3, 3), rng.uniform(0.1, 3.0), rng.uniform(-3, 3)
        q = material_frames(r0, np.array([phi]), np.array([theta]), np.array([psi]))[0]
        back = euler_from_frame(r0, q)
        q2 = material_frames(r0, *(np.array([v]) for v in back))[0]
        assert np.allclose(q, q2, atol=1e-12)
    # κ² = θ'² + sin²θ φ'² equals |dζ/ds|² (finite differences along a curve)
    s = np.linspace(0, 1, 2001)
    phi, theta = 0.7 * np.sin(3 * s), 1.2 + 0.4 * s**2
    zeta = material_frames(r0, phi, theta, 0 * s)[:, :, 2]
    dz = np.gradient(zeta, s, axis=0)
    kappa2 = np.gradient(theta, s) ** 2 + np.sin(theta) ** 2 * np.gradient(phi, s) ** 2
    assert np.allclose(np.sum(dz**2, axis=1)[5:-5], kappa2[5:-5], rtol=1e-4)


def test_reference_frame_puts_straight_chord_at_theta_half_pi():
    chord, up = np.array([0.3, 0.4, 0.0]), np.array([0, 0, 1.0])
    r0 = reference_frame(chord, up)
    assert np.allclose(r0.T @ r0, np.eye(3)) and np.isclose(np.linalg.det(r0), 1)
    q = material_frames(r0, np.array([0.0]), np.array([np.pi / 2]), np.array([0.0]))[0]
    assert np.allclose(q[:, 2], chord / np.linalg.norm(chord))


def test_pose_quaternions_from_euler_angles_are_the_rotation_matrices_quaternions():
    """The solver's fast path (quaternion products) against rotation matrices built one by one."""
    rng = np.random.default_rng(3)
    for chord in ([1.0, 0.2, 0.0], [0.0, 0.0, 1.0], [-0.3, 0.5, 0.8]):
        r0 = reference_frame(np.array(chord), np.array([0.0, 0.0, 1.0]))
        phi, theta, psi = rng.uniform(-7, 7, (3, 40))
        q = pose_quaternions(r0, phi, theta, psi)
        assert np.all(q[:, 3] >= 0) and np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)
        for k in range(len(phi)):
            r = r0 @ material_frames(np.eye(3), phi[k:k + 1], theta[k:k + 1], psi[k:k + 1])[0] @ TANGENT_X
            assert np.allclose(quat_to_matrix(q[k]), r, atol=1e-13)


def test_pole_geometry():
    from dlo_ros.model.rotations import farthest_pole, frame_with_pole, pole_angle_deg

    s = np.linspace(0, 2 * np.pi, 50)
    in_plane = np.stack([np.cos(s), np.sin(s), 0 * s], axis=1)  # tangents around a circle in z = 0
    assert np.isclose(pole_angle_deg(in_plane, [0, 0, 1]), 90.0)
    assert pole_angle_deg(in_plane, [1, 0, 0]) < 1e-6
    normal, angle = farthest_pole(in_plane)
    assert abs(normal[2]) > 0.999 and angle > 87.0  # the grid's resolution is about 2°
    r0 = frame_with_pole(np.array([0.3, -0.4, 0.8]), np.array([1.0, 0.0, 0.0]))
    assert np.allclose(r0.T @ r0, np.eye(3)) and np.isclose(np.linalg.det(r0), 1.0)
    assert np.allclose(r0[:, 2], np.array([0.3, -0.4, 0.8]) / np.linalg.norm([0.3, -0.4, 0.8]))


def test_the_first_frame_avoids_held_tangents_on_its_pole():
    """Grippers holding the string across the chord (tangents along y = chord × up): the chord-and-gravity
    frame has them on its pole, so the pole is turned away; along the chord, it is not."""
    from dlo_ros.model.rotations import pole_angle_deg
    from dlo_ros.solver.build.nlp import choose_reference_frame

    along = choose_reference_frame(clamped_pair(right=(0.6, 0, 0)), "auto")
    assert np.allclose(np.abs(along[:, 2]), [0, 1, 0])  # the chord-and-gravity plane's normal
    q = quat_about("z", np.pi / 2)
    across = choose_reference_frame(clamped_pair(right=(0.6, 0, 0), q_left=q, q_right=q), "auto")
    assert pole_angle_deg(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]), across[:, 2]) > 40.0


def test_quaternions():
    rng = np.random.default_rng(2)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[3] >= 0 else -q
        assert np.allclose(matrix_to_quat(quat_to_matrix(q)), q, atol=1e-12)
    assert np.allclose(TANGENT_X @ np.array([1.0, 0, 0]), [0, 0, 1])  # Q_out e_x = Q e_z: pose x-axis = ζ
    with pytest.raises(ValueError, match="orientation: zero quaternion"):
        check_quaternion([0, 0, 0, 0], "orientation")
    with pytest.raises(ValueError, match="norm is 2"):
        check_quaternion([0, 0, 0, 2], "q")
    with pytest.raises(ValueError, match="NaN"):
        check_quaternion([0, np.nan, 0, 1], "q")
    assert np.allclose(check_quaternion([0, 0, 0, 1.0005], "q"), [0, 0, 0, 1])


def test_profile_table_expresses_the_papers_trapezoid():
    # Rf = 330 b, b = 50 + s/4 (mm): linear in s, so two rows are exact
    prof = Profile.table([[0.0, 330 * 50], [200.0, 330 * 100]])
    s = np.linspace(0, 200, 7)
    assert np.allclose(prof(s), 330 * (50 + s / 4))


@pytest.mark.parametrize(
    "spec, inside, outside",
    [
        ({"type": "halfspace", "point": [0, 0, 0], "normal": [0, 0, 2]}, [0, 0, -0.1], [0, 0, 0.1]),
        ({"type": "sphere", "center": [1, 0, 0], "radius": 0.5}, [1.2, 0, 0], [1.6, 0, 0]),
        ({"type": "capsule", "a": [0, 0, 0], "b": [1, 0, 0], "radius": 0.1}, [0.5, 0.05, 0], [0.5, 0.15, 0]),
        ({"type": "box", "center": [0, 0, 0], "half_extents": [1, 0.5, 0.2]}, [0.9, 0, 0], [0, 0.6, 0]),
    ],
)
def test_obstacle_sign_convention(spec, inside, outside):
    ob = Obstacle.from_dict(spec)
    assert ob.h(np.array(inside, float)) > 0 > ob.h(np.array(outside, float))


@pytest.mark.parametrize("spec", [
    {"type": "halfspace", "point": [0.1, 0.2, 0.3], "normal": [0.3, -1, 2]},
    {"type": "sphere", "center": [1, 0, 0], "radius": 0.5},
    {"type": "capsule", "a": [0, 0, 0], "b": [1, 0.5, 0], "radius": 0.1},
])
def test_numeric_h_is_the_nlps_h(spec):
    """Obstacle.h (numpy, used every update to find obstacles within reach) against the CasADi
    expression the NLP constrains, at points on every side (the capsule beyond both ends too)."""
    from dlo_ros.model.obstacles import OBSTACLE_TYPES

    ob = Obstacle.from_dict(spec)
    assert ob.type in OBSTACLE_TYPES
    for x in np.random.default_rng(5).uniform(-1.5, 2.5, (50, 3)):
        assert np.isclose(ob.h(x), float(ob.h_many(x)[0]), rtol=1e-13, atol=1e-14)  # h_many: the CasADi h


def test_signed_distance_values():
    assert np.isclose(Obstacle.from_dict({"type": "halfspace", "normal": [0, 0, 1]}).h(np.array([0, 0, 0.3])), -0.3)
    assert np.isclose(Obstacle.from_dict({"type": "sphere", "center": [0, 0, 0], "radius": 1}).h(np.array([2.0, 0, 0])), -1)


@pytest.mark.parametrize(
    "change, field",
    [
        (lambda p: p.__class__(p.string.__class__(-1.0, *list(p.string.__dict__.values())[1:]), p.grips), "string.length"),
        (lambda p: p.__class__(p.string.__class__(1.0, Profile.constant(-2), p.string.twist_stiffness, p.string.weight_per_length), p.grips), "string.bend_stiffness"),
        (lambda p: p.__class__(p.string, p.grips, gravity=np.zeros(3)), "gravity.direction"),
        (lambda p: p.__class__(p.string, ()), "grips"),
    ],
)
def test_problem_validation_names_the_field(change, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        change(clamped_pair()).validate()


def test_obstacle_parse_errors_name_the_field():
    with pytest.raises(ValueError, match=r"obstacles\[2\]\.radius"):
        Obstacle.from_dict({"type": "sphere", "center": [0, 0, 0], "radius": -1}, "obstacles[2]")
    with pytest.raises(ValueError, match=r"obstacles\[0\]\.type"):
        Obstacle.from_dict({"type": "cone"}, "obstacles[0]")


def test_frame_to_quat_inverts_quat_to_frame_for_every_branch():
    """Shepperd's method picks its pivot from 1 + trace and the diagonal: random rotations plus the
    half turns about each axis (where the trace pivot would divide by zero) all come back."""
    from scipy.spatial.transform import Rotation

    from dlo_ros.model.director import frame_to_quat, quat_to_frame

    q = np.vstack([Rotation.random(500, random_state=3).as_quat(), np.eye(4), [[0.6, 0.8, 0.0, 0.0]]])
    frames = quat_to_frame(q)
    back = frame_to_quat(frames)
    np.testing.assert_allclose(quat_to_frame(back), frames, atol=1e-14)
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-14)
    assert frame_to_quat(frames[0]).shape == (4,)


def test_slerp_turns_a_fraction_of_the_shortest_rotation():
    """slerp(q0, q1, t) against the closed form: about a fixed axis, q(θ) = (sin(θ/2) a, cos(θ/2)), so the
    fraction t of the turn from θ0 to θ1 is q(θ0 + t (θ1 − θ0)); q1 given as −q1 (the same rotation) takes
    the same, shorter arc."""
    from dlo_ros.model.rotations import slerp

    axis = np.array([1.0, 2.0, 2.0]) / 3.0

    def q(theta):
        return np.concatenate([np.sin(theta / 2) * axis, [np.cos(theta / 2)]])

    for t in (0.0, 0.25, 0.5, 1.0):
        assert np.allclose(slerp(q(0.3), q(2.1), t), q(0.3 + t * 1.8), atol=1e-12)
        assert np.allclose(slerp(q(0.3), -q(2.1), t), q(0.3 + t * 1.8), atol=1e-12)
    assert np.allclose(slerp(q(0.5), q(0.5), 0.7), q(0.5), atol=1e-12)


@pytest.mark.parametrize("basis", ["chebyshev", "elements"])
def test_stiffness_matrices_travel_as_their_nonzeros(basis):
    """K_bend = B'ᵀ diag(w Rf) B' and K_stretch = Bᵀ diag(w Re) B, packed on the structural pattern
    (p holds their nonzeros: block-banded on elements, dense on one interval), rebuild exactly,
    and the element pattern holds O(n) entries, not n²."""
    import casadi as ca

    from dlo_ros.model.ritz import RitzModel
    from dlo_ros.solver.build.mesh import MeshSpec, element_mesh
    from dlo_ros.solver.options import SolverOptions

    problem = clamped_pair()
    options = SolverOptions(model="planar", basis=basis, order=12, quadrature_nodes=20)
    mesh = element_mesh(problem, options, MeshSpec((0.2, 0.5), (12, 12, 12))) if basis == "elements" else None
    model = RitzModel(problem.string.length, basis, 12, 20, np.eye(3), False, True, planar=True, mesh=mesh)
    M, n = model.quad.count, model.layout.order
    rng = np.random.default_rng(3)
    profiles = {k: rng.uniform(0.5, 2.0, M) for k in ("Rf", "Rt", "Re", "D")}
    terms = model.material_terms(profiles)
    w = model.quad.weights
    for name, basis_rows, stiffness in (("K_bend", model.dB, "Rf"), ("K_stretch", model.B, "Re")):
        assert terms[name].size == model.material_sizes()[name]
        rebuilt = np.array(ca.DM(model.stiffness_sym(ca.DM(terms[name]))).full())
        exact = basis_rows.T @ ((w * profiles[stiffness])[:, None] * basis_rows)
        assert np.max(np.abs(rebuilt - exact)) <= 1e-13 * np.max(np.abs(exact))
    nnz = model.stiffness_pattern.nnz
    assert nnz == n * n if basis == "chebyshev" else nnz < n * n / 2
