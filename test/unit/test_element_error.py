"""The per-element error estimate (solver/results/element_error.py) against independent answers.

true = max_s |x(s) − x_ref(s)| with x_ref from shooting (test/reference/kirchhoff.py,
test/reference/post_contact.py) or a closed form; the estimate must bound it and stay within
ten times it: true ≤ estimate ≤ 10 · max(true, FLOOR · L), on the default meshes of orders 6–32
and on uneven MeshSpec meshes, solved cold and streamed (a grip moved and back, warm updates).
A contact inside an element (the heavy strip on a post) must be the element marked for a split.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.problems import clamped_pair, quat_about

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.model.elements import ElementMesh
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.results import element_error as EE
from dlo_ros.solver.shape_solver import ShapeSolver
from reference import post_contact
from support.post import BEND, HEIGHT, POST, POST_RADIUS, RADIUS, WEIGHT, post_scene
from reference.kirchhoff import solve_clamped

from test_moment_energy import MOMENT, cantilever as mid_moment_cantilever
from test_mesh_spec import exact_tip

LEVEL = [0.0, 0.0, 0.0, 1.0]
GRID = np.linspace(0.0, 1.0, 401)
MESHES = [MeshSpec((0.3,), (7, 9)), MeshSpec((0.2, 0.7), (6, 12, 5))]


def estimate(solver: ShapeSolver) -> EE.ElementErrors:
    return EE.element_errors(solver.outputs, solver.problem, solver.committed_state)


def check_bound(true: float, errors: EE.ElementErrors) -> None:
    floor = EE.FLOOR * 1.0
    ratio = errors.estimate_m / max(true, floor)
    print(f"ratio {ratio:.3f} true {true:.2e} estimate {errors.estimate_m:.2e}")
    assert true <= errors.estimate_m <= 10 * max(true, floor), (true, errors)


def true_error(solver: ShapeSolver, ref_points) -> float:
    z = solver.committed_state.z
    return float(np.max(np.linalg.norm(solver.model.positions(z, GRID) - ref_points, axis=1)))


# ---- cantilevers: a tip force (large deflection) and the string's own weight -------------------
def cantilever(tip_force: float, weight: float) -> Problem:
    string = StringProperties(
        1.0, Profile.constant(1.0), Profile.constant(0.8), Profile.constant(weight)
    )
    grip = Grip("clamp", 0.0, "clamp", GripPose.checked([0.0, 0.0, 0.0], LEVEL, "clamp"))
    loads = (Load(1.0, force=np.array([0.0, 0.0, -tip_force]), moment=np.zeros(3)),)
    return Problem(string, (grip,), gravity=np.array([0.0, 0.0, -1.0]), loads=loads)


@pytest.fixture(scope="module", params=[(3.0, 0.0), (0.0, 8.0)], ids=["tip-force", "heavy"])
def loaded(request):
    force, weight = request.param
    sol = None
    for f in np.linspace(0.1, 1.0, 10):  # continuation in the load
        sol = solve_clamped(
            1.0,
            1.0,
            0.8,
            np.zeros(3),
            np.eye(3),
            mode_end="free",
            D=f * weight,
            loads=[(1.0, (0.0, 0.0, -f * force), None)],
            guess=sol,
        )
    return cantilever(force, weight), sol.position(GRID)


@pytest.mark.parametrize(
    "order, mesh", [(n, None) for n in (6, 8, 12, 16, 24, 32)] + [(16, m) for m in MESHES]
)
def test_cantilevers_cold_and_streamed(loaded, order, mesh):
    problem, ref = loaded
    solver = ShapeSolver(
        problem, SolverOptions(model="full", order=order), compile="off", mesh=mesh
    )
    solver.solve()
    check_bound(true_error(solver, ref), estimate(solver))
    for dy in (0.01, 0.0):  # the clamp moves 1 cm sideways and back: the shape translates
        assert solver.solve({"clamp": ([0.0, dy, 0.0], LEVEL)}).warm_started
        errors = estimate(solver)
        check_bound(true_error(solver, ref + [0.0, dy, 0.0]), errors)
        assert not errors.split.any()  # smooth on every element


def test_an_exact_solution_reports_the_floor():
    """The mid-moment cantilever is exact on its mesh: the estimate is the floor, ≥ its error."""
    solver = ShapeSolver(
        mid_moment_cantilever([0.0, MOMENT, 0.0]), SolverOptions(model="full"), compile="off"
    )
    r = solver.solve()
    errors = estimate(solver)
    assert errors.estimate_m == EE.FLOOR * 1.0
    assert np.abs(r.points[-1] - exact_tip()).max() <= errors.estimate_m


# ---- a clamp–clamp string bent and twisted out of its plane ------------------------------------
END = (np.array([0.6, 0.25, 0.15]), np.array(quat_about("z", 0.9)))


def twisted_reference(x1, q1):
    """Shooting, continued from the straight string along the end pose (slerp)."""
    from scipy.spatial.transform import Rotation, Slerp

    turn, sol = Slerp([0, 1], Rotation.from_quat([LEVEL, q1])), None
    for f in np.linspace(0.0, 1.0, 21)[1:]:
        x = (1 - f) * np.array([1.0, 0.0, 0.0]) + f * np.asarray(x1)
        sol = solve_clamped(
            1.0, 1.0, 0.8, np.zeros(3), np.eye(3), x, turn(f).as_matrix(), guess=sol
        )
    return sol.position(GRID)


@pytest.fixture(scope="module")
def twisted():
    return twisted_reference(*END)


@pytest.mark.parametrize(
    "order, mesh", [(n, None) for n in (6, 8, 12, 16, 24, 32)] + [(16, m) for m in MESHES]
)
def test_a_twisted_clamp_clamp_string_cold_and_streamed(twisted, order, mesh):
    problem = clamped_pair(right=tuple(END[0]), q_right=list(END[1]), twist=0.8)
    solver = ShapeSolver(
        problem, SolverOptions(model="full", order=order), compile="off", mesh=mesh
    )
    solver.solve()
    check_bound(true_error(solver, twisted), estimate(solver))
    for x in (END[0] + [0.0, 0.0, 0.02], END[0]):  # the right grip up 2 cm and back
        assert solver.solve({"right": (x, END[1])}).warm_started
    check_bound(true_error(solver, twisted), estimate(solver))


# ---- a kink inside an element: the heavy strip on a post ---------------------------------------


def post_problem(order: int):
    """test_obstacle_slots.py's strip on a post, the post a cylinder across the plane."""
    return post_scene({"model": "full", "order": order, "obstacle_slots": 2})


@pytest.fixture(scope="module")
def on_post():
    """The shooting solution (one touching point s*); its guess from a converged solve."""
    sc = post_problem(24)
    r = ShapeSolver(sc.problem, sc.options, compile="off").solve()
    assert r.ok and np.abs(r.points[:, 1]).max() == 0.0
    k = int(np.argmin(np.linalg.norm(r.points[:, [0, 2]] - POST, axis=1)))
    guess = [
        -r.grips["left"].force[0],
        -r.grips["left"].force[2],
        r.grips["left"].torque[1],
        r.s[k],
        float(np.linalg.norm(r.contact_forces[0])),
    ]
    ref = post_contact.solve(
        1.0, BEND, WEIGHT, [0.0, HEIGHT], 0.0, [0.6, HEIGHT], 0.0, POST, POST_RADIUS, RADIUS, guess
    )
    assert ref.residual < 1e-10 and ref.push > 0 and ref.clearance > -1e-9
    return ref


@pytest.mark.parametrize(
    "order, mesh",
    [
        (16, None),
        (32, None),
        (16, MeshSpec((0.25, 0.6), (10, 16, 10))),
        (16, MeshSpec((0.3, 0.5), (8, 20, 8))),
    ],
)
def test_a_contact_inside_an_element_is_marked_and_bounded(on_post, order, mesh):
    sc = post_problem(order)
    solver = ShapeSolver(sc.problem, sc.options, compile="off", mesh=mesh)
    ref = np.concatenate(
        [on_post.at(GRID)[:, :1], np.zeros((GRID.size, 1)), on_post.at(GRID)[:, 1:]], axis=1
    )
    kink = int(solver.model.mesh.element_of(np.array([on_post.s_contact]))[0])
    assert solver.solve().ok
    errors = estimate(solver)
    check_bound(true_error(solver, ref), errors)
    assert list(np.flatnonzero(errors.split)) == [kink]
    if mesh is not None and mesh.counts[0] == 10:  # its neighbours resolved: the kink worst
        assert errors.worst == kink
    # streamed: the right grip 2 cm out and back.  The kink is marked again; the bound is not
    # asserted: the warm return rests on the post with a 1 % different push (slot and sample
    # rows share it), a contact-discretisation error that no residual of the basis sees
    for x in (0.62, 0.6):
        r = solver.solve({"right": ([x, 0.0, HEIGHT], LEVEL)})
        assert r.ok and r.warm_started
    assert list(np.flatnonzero(estimate(solver).split)) == [kink]


# ---- the coefficient part on its own: a smooth field and a kinked one --------------------------
def test_coefficient_decay_tells_a_kink_from_a_smooth_field():
    """|s − 0.41|³ has a jump in its third derivative at 0.41 (a contact's jump of t''): only
    the element holding it decays algebraically.  cos(3s) is smooth everywhere."""
    mesh = ElementMesh(1.0, [0.3, 0.5], 16, counts=(12, 16, 12))
    s = mesh.nodes
    kinked = np.stack([np.abs(s - 0.41) ** 3, np.cos(3 * s)], axis=1)
    rates, tails = EE.coefficient_decay(mesh, kinked)
    assert list(rates > EE.SMOOTH_RATE) == [False, True, False]
    rates, _ = EE.coefficient_decay(mesh, np.cos(3 * s)[:, None])
    assert not np.any(rates > EE.SMOOTH_RATE)
    # a constant field is resolved to rounding on every element
    assert np.all(EE.coefficient_decay(mesh, np.ones((mesh.count, 3)))[0] == 0.0)
