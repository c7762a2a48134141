"""solver.model: auto — each reduction where it applies and where it must not, always within the
tolerance of the full model's answer (solved here with the full 3D model at a high order)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model import Obstacle, Profile
from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver.auto.pool import ModelPool
from dlo_ros.solver import AutoShapeSolver, ShapeSolver, SolverOptions, make_solver
from support.problems import clamped_pair, quat_about

TOL = 1e-3  # m, on a 1 m string (the default: 1e-3·L)


def full_reference(problem):
    r = ShapeSolver(problem, SolverOptions(model="full", order=24, output_points=51)).solve()
    assert r.ok, r.message
    return r


def auto(problem, **opts):
    solver = make_solver(problem, SolverOptions(output_points=51, **opts), compile="off", checks="sync")
    assert isinstance(solver, AutoShapeSolver)
    r = solver.solve()
    assert r.ok, r.message
    return solver, r


def assert_close_to_full(r, problem):
    ref = full_reference(problem)
    dev = np.max(np.linalg.norm(r.points - ref.points, axis=1))
    assert dev <= TOL, (dev, r.model)
    assert r.model.estimated_error_m is not None and r.model.estimated_error_m <= TOL


def hanging(**kw):
    args = dict(left=(0, 0, 0.4), right=(0.6, 0, 0.4), bend=0.02, twist=0.015, weight=0.5)
    return clamped_pair(**{**args, **kw})


def test_planar_scene_gets_the_planar_model():
    prob = hanging()
    _, r = auto(prob)
    assert r.model.planar and not r.model.twist and r.model.gravity
    assert_close_to_full(r, prob)


def test_small_out_of_plane_offset_makes_it_3d():
    prob = hanging(right=(0.6, 0.01, 0.4))
    _, r = auto(prob)
    assert not r.model.planar
    assert any(reason.startswith("3D:") for reason in r.model.reasons), r.model.reasons
    assert_close_to_full(r, prob)


def test_twist_free_scene_drops_twist_and_clamped_twist_keeps_it():
    free = clamped_pair(right=(0.6, 0.1, 0.05), modes=("tangent", "tangent"), twist=0.5, weight=0.2)
    _, r = auto(free)
    assert not r.model.twist
    assert_close_to_full(r, free)
    twisted = clamped_pair(right=(0.6, 0.0, 0.0), q_right=quat_about("x", 1.5), twist=0.5, weight=0.2)
    _, r = auto(twisted)
    assert r.model.twist and not r.model.planar
    assert any("twist" in reason for reason in r.model.reasons)
    assert_close_to_full(r, twisted)


def test_planar_but_unstable_in_3d_escalates_to_full():
    """A compressed strip with little twist stiffness leaves its plane (paper Fig. 2's regime)."""
    prob = clamped_pair(right=(0.3, 0, 0), twist=0.0, weight=0.0)
    _, r = auto(prob)
    assert not r.model.planar and any("unstable in 3D" in c for c in r.model.changes)
    assert r.stable


def test_stretch_only_when_it_matters():
    stiff = replace(hanging().string, stretch_stiffness=Profile.constant(1e7))
    prob = replace(hanging(), string=stiff)
    _, r = auto(prob)
    assert not r.model.stretch
    soft = replace(hanging().string, stretch_stiffness=Profile.constant(20.0))
    prob = replace(hanging(), string=soft)
    _, r = auto(prob)
    assert r.model.stretch and any("elongation" in c for c in r.model.changes)
    ref = ShapeSolver(prob, SolverOptions(model="full", order=24, output_points=51)).solve()
    assert np.max(np.linalg.norm(r.points - ref.points, axis=1)) <= TOL


def test_negligible_gravity_is_dropped():
    prob = clamped_pair(right=(0.6, 0, 0), weight=1e-7)
    _, r = auto(prob)
    assert not r.model.gravity
    assert_close_to_full(r, prob)
    _, r = auto(hanging())
    assert r.model.gravity


def test_an_obstacle_clear_of_the_plane_keeps_the_planar_model_and_one_across_it_does_not():
    """A sphere beside the plane (within reach, but farther from the plane than its radius) cannot
    touch a planar string: the scene stays planar.  The same sphere cutting the plane, off-centre, makes
    it 3D (the string may be pushed sideways)."""
    beside = Obstacle.from_dict({"type": "sphere", "center": [0.3, 0.3, 0.2], "radius": 0.1})
    prob = replace(hanging(), obstacles=(beside,))
    solver, r = auto(prob)
    assert r.model.planar and r.model.obstacles == 0, r.model
    assert any("clear of the plane" in c for c in r.model.reasons), r.model.reasons
    assert_close_to_full(r, prob)
    across = Obstacle.from_dict({"type": "sphere", "center": [0.3, 0.05, 0.2], "radius": 0.1})
    _, r = auto(replace(hanging(), obstacles=(across,)))
    assert not r.model.planar and r.model.obstacles == 1, r.model
    # moving one grip sideways toward the sphere: 3D, with the sphere in the model
    r = solver.solve({"right": ([0.6, 0.05, 0.4], [0, 0, 0, 1])})
    assert r.ok and not r.model.planar and r.model.obstacles == 1, r.model


def test_obstacles_enter_the_nlp_only_within_reach_and_keep_the_warm_start():
    far = Obstacle.from_dict({"type": "sphere", "center": [0.3, 0, -3.0], "radius": 0.2})
    prob = replace(hanging(), obstacles=(far,))
    solver, r = auto(prob)
    assert r.model.obstacles == 0
    # carry both grips down toward the sphere: it comes within reach and is added, warm start kept
    q = [0, 0, 0, 1]
    for z in np.linspace(0.3, -1.9, 12):
        r = solver.solve({"left": ([0, 0, z], q), "right": ([0.6, 0, z], q)})
        assert r.ok, r.message
    assert r.model.obstacles == 1
    assert any("came within reach" in c for c in r.model.changes)
    assert r.warm_started


def test_mesh_is_refined_as_far_as_the_tolerance_needs():
    """The element mesh is refined from the shape's own estimate: for 1 mm, not for 2 cm; each
    estimate bounds the true error (against the full model at order 24), within 10x."""
    prob = clamped_pair(right=(0.5, 0, 0.05), q_left=quat_about("y", -0.5), twist=0.5)
    _, r = auto(prob)
    coarse, rc = auto(prob, error_tolerance=0.02)
    assert any("mesh of" in c for c in r.model.changes), r.model.changes
    assert not any("mesh of" in c for c in rc.model.changes), rc.model.changes
    assert rc.model.variables < r.model.variables
    assert_close_to_full(r, prob)
    ref = full_reference(prob)
    for result, tolerance in ((r, 1e-3), (rc, 0.02)):
        true = np.max(np.linalg.norm(result.points - ref.points, axis=1))
        estimate = result.model.estimated_error_m
        assert true <= tolerance and true <= estimate <= 10 * max(true, 1e-10), (true, result.model)


def test_explicit_model_overrides_auto():
    solver = make_solver(hanging(), SolverOptions(model="full"), compile="off", checks="sync")
    assert isinstance(solver, ShapeSolver)
    assert not solver.solve().model.planar


def test_targets_leaving_the_plane_switch_to_3d_with_the_warm_start():
    """A scene built planar must follow a target that leaves its plane (never project it)."""
    prob = hanging()
    solver, r = auto(prob)
    assert r.model.planar
    q = [0, 0, 0, 1]
    r = solver.solve({"right": ([0.5, 0.05, 0.45], q)})
    assert r.ok, r.message
    assert not r.model.planar and any("left the plane" in c for c in r.model.changes)
    assert np.allclose(r.points[-1], [0.5, 0.05, 0.45], atol=1e-8)
    assert r.warm_started


def test_planar_model_rejects_out_of_plane_targets():
    solver = ShapeSolver(hanging(), SolverOptions(model="planar"), compile="off")
    assert solver.solve().ok
    r = solver.solve({"right": ([0.5, 0.05, 0.45], [0, 0, 0, 1])})
    assert r.status == "invalid" and "grips[1].position" in r.message


def test_a_query_that_needs_a_richer_model_answers_with_it_and_leaves_the_stream_alone():
    """A planar stream with an obstacle clear of its plane; a query moves a grip toward it: the answer
    comes from the 3D model with that obstacle (its model object says so), the stream keeps its model."""
    beside = Obstacle.from_dict({"type": "sphere", "center": [0.3, 0.12, 0.25], "radius": 0.1})
    table = Obstacle.from_dict({"type": "halfspace", "point": [0, 0, 0], "normal": [0, 0, 1]})
    prob = replace(hanging(), obstacles=(table, beside))
    solver, r = auto(prob)
    assert r.model.planar and r.model.obstacles == 1
    query = solver.solve({"right": ([0.6, 0.1, 0.4], [0, 0, 0, 1])}, commit=False)
    assert query.ok and not query.model.planar and query.model.obstacles == 2, query.model
    assert set(query.contact_forces) <= {0, 1}
    after = solver.solve()
    assert after.ok and after.model.planar and after.model.obstacles == 1
    np.testing.assert_allclose(after.points, r.points, atol=1e-9)


def test_tangents_across_the_chord_need_no_frame_turn_and_the_order_converges():
    """Clamps holding the string across the chord (tangents along +y: the pole of the old Euler frame).
    The 3D model has no pole, so auto turns nothing; its answer agrees, within the tolerance, with the
    same branch solved at order 32 (warm-started from auto's shape), and its residual is verified."""
    q = quat_about("z", np.pi / 2)
    problem = clamped_pair(left=(0, 0, 0), right=(0.3, 0, 0), q_left=q, q_right=q, weight=0.5, twist=0.7)
    solver, r = auto(problem)
    assert r.model.rotation == "quaternion"
    assert not any("frame" in reason for reason in r.model.reasons + r.model.changes), r.model
    assert r.model.estimated_error_m is not None and r.model.estimated_error_m <= TOL
    assert r.equilibrium_residual_m <= TOL
    # no update_time_limit: a warm-started reference must not depend on the machine's load
    fine = ShapeSolver(problem, SolverOptions(model="full", order=32, output_points=51, update_time_limit=0.0),
                       compile="off")
    fine.adopt_warm_start(solver.inner)
    ref = fine.solve()
    assert ref.ok and ref.stable, ref.message
    assert np.max(np.linalg.norm(r.points - ref.points, axis=1)) <= TOL
    assert abs(r.energy["total"] - ref.energy["total"]) <= 1e-3 * abs(ref.energy["total"])


def _peg_on_the_free_path(offset: float):
    """The planar hanging string (chord 0.6 m) and a 6 mm sphere ('peg') centred ``offset`` m below its
    free shape at s = 0.51 m, between the 41 default samples (0.5 and 0.525 m)."""
    free = clamped_pair(right=(0.6, 0.0, 0.0), weight=1.0, bend=0.05, twist=0.04)
    f = ShapeSolver(free, SolverOptions(model="planar", order=16), compile="off")
    assert f.solve().ok
    centre = f.model.positions(f.snapshot().z, np.array([0.51]))[0] - np.array([0.0, 0.0, offset])
    peg = Obstacle("sphere", np.array([*centre, 0.006]), "peg")
    return clamped_pair(right=(0.6, 0.0, 0.0), weight=1.0, bend=0.05, twist=0.04, obstacles=(peg,)), peg


def test_the_mesh_is_split_where_the_string_cuts_into_an_obstacle_between_the_rows():
    """auto's element models enforce obstacles at the mesh nodes (#37): a 6 mm peg on the free path
    between two nodes is cut through, which the equilibrium residual cannot see.  The mesh check
    measures the cut on 8× as many points (contact/penetration.py), counts it in the estimate and
    splits the mesh there; no uniform samples are added.  The final shape is out of the peg to within
    δ/2 on 4001 points (measured here independently), and the estimate includes the cut."""
    prob, peg = _peg_on_the_free_path(0.0)
    # the node rows on the peg, as on a bar (auto's own slots would hold a sphere's contact
    # where it touches: solver.slotted_obstacles 'points')
    solver, r = auto(prob, error_tolerance=0.002, obstacle_slots=2, slotted_obstacles="flat")
    assert r.model.obstacle_samples is None
    assert any("mesh of" in c for c in r.model.changes), r.model.changes
    x = solver.inner.model.positions(solver.inner.snapshot().z, np.linspace(0.0, 1.0, 4001))
    depth = float(np.max(peg.h_many(x)))
    assert depth <= 0.001, depth
    assert r.model.estimated_error_m >= depth and r.model.tolerance_met
    # the sampled 41-point model alone passes straight through the peg
    sampled = ShapeSolver(prob, SolverOptions(model="planar", order=12), compile="off")
    assert sampled.solve().ok
    assert float(np.max(peg.h_many(sampled.model.positions(sampled.snapshot().z, np.linspace(0.0, 1.0, 4001))))) > 0.005


@pytest.mark.parametrize("slots", [0, 2], ids=["rows on nodes", "contact slots"])
def test_a_string_pressed_onto_a_ball_is_within_the_tolerance_of_a_converged_reference(slots):
    """A string pressed onto a ball (8 cm sphere pushed 4 cm into its free sag, off centre): it can slide
    over the ball at almost no cost of energy, so where the rows sit moves the shape by millimetres
    although no row cuts in.  auto's rows sit on the mesh nodes and its mesh check splits the mesh at
    the contact (#37; before, it doubled uniform samples up to 641); with contact slots a row sits at
    the closest approach itself.  Either final answer is within δ/2 of an order-24 solve with 321
    samples (an independent reference by convergence), where the 41-sample answer without slots is
    not."""
    free = clamped_pair(right=(0.6, 0.0, 0.0), weight=1.0, bend=0.05, twist=0.04)
    f = ShapeSolver(free, SolverOptions(model="planar", order=16), compile="off")
    assert f.solve().ok
    x = f.model.positions(f.snapshot().z, np.linspace(0.0, 1.0, 2001))
    radius, push = 0.08, 0.04
    ball = Obstacle("sphere", np.array([0.35, 0.0, np.interp(0.35, x[:, 0], x[:, 2]) - radius + push, radius]), "ball")
    prob = clamped_pair(right=(0.6, 0.0, 0.0), weight=1.0, bend=0.05, twist=0.04, obstacles=(ball,))
    solver, r = auto(prob, error_tolerance=0.002, obstacle_slots=slots)
    assert r.ok and r.contact_forces and np.linalg.norm(r.contact_forces[0]) > 0.01, r.contact_forces
    assert r.model.obstacle_samples is None and not any("samples" in c for c in r.model.changes)
    assert r.model.tolerance_met
    # the reference starts from auto's shape: a warm solve, which update_time_limit bounds (#37: it
    # bounds every warm committed solve), so it is off here: a reference must not depend on timing
    ref = ShapeSolver(prob, SolverOptions(model="full", order=24, obstacle_samples=321, obstacle_slots=0,
                                          output_points=51, update_time_limit=0.0), compile="off")
    ref.adopt_warm_start(solver.inner)
    reference = ref.solve()
    assert reference.ok and reference.stable, reference.message
    assert np.max(np.linalg.norm(r.points - reference.points, axis=1)) <= 0.001
    # the same order with the default 41 samples and no slots, from the same shape: millimetres off
    coarse = ShapeSolver(prob, SolverOptions(model="full", order=r.model.order, obstacle_slots=0, output_points=51,
                                             update_time_limit=0.0), compile="off")
    coarse.adopt_warm_start(solver.inner)
    sampled = coarse.solve()
    assert sampled.status in ("ok", "unverified"), sampled.message
    assert np.max(np.linalg.norm(sampled.points - reference.points, axis=1)) > 0.001


def test_an_obstacle_nothing_touches_changes_nothing():
    """The same peg 2 cm below the free path: nothing is cut or touched, so the answer is the one
    without the peg (to solver precision) and no change of model names it."""
    prob, _ = _peg_on_the_free_path(0.02)
    _, r = auto(prob, error_tolerance=0.002)
    _, free = auto(replace(prob, obstacles=()), error_tolerance=0.002)
    assert r.model.obstacle_samples is None
    assert not any("cut" in c or "samples" in c for c in r.model.changes), r.model.changes
    assert np.max(np.linalg.norm(r.points - free.points, axis=1)) < 1e-6


def _stretchy(chord: float):
    p = clamped_pair(right=(chord, 0, 0), weight=1.0, bend=0.05)
    return replace(p, string=replace(p.string, stretch_stiffness=Profile.constant(200.0)))


def test_extensible_string_beyond_its_length_gets_the_stretch_field():
    """Grips 1.1 L apart on an extensible string: unreachable for the inextensible first model, so auto
    starts extensible (cold) or switches when a stream carries the grips past L; it then agrees with the
    full extensible model at order 24 within the tolerance."""
    ref = ShapeSolver(_stretchy(1.1), SolverOptions(model="full", order=24, output_points=51), compile="off").solve()
    assert ref.ok, ref.message
    _, r = auto(_stretchy(1.1))
    assert r.model.stretch and any("extensible" in reason for reason in r.model.reasons)
    assert np.max(np.linalg.norm(r.points - ref.points, axis=1)) <= TOL
    solver = make_solver(_stretchy(0.9), SolverOptions(output_points=51), compile="off")
    try:
        assert solver.solve().ok
        for c in np.linspace(0.94, 1.1, 5):
            r = solver.solve({"right": ((c, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))})
            assert r.ok, (c, r.message)
        assert r.model.stretch and any("extensible" in change for change in r.model.changes)
        assert np.max(np.linalg.norm(r.points - ref.points, axis=1)) <= TOL
    finally:
        solver.close()


def test_closed_hanging_loop_both_clamps_at_one_point():
    """Both clamps at the same point with the same orientation (a closed hanging loop; #13 saw auto fail
    it cold: its straight first guess missed the second clamp by L): auto answers it cold, a ring hanging
    from the clamps, within the tolerance of the full model at order 24, stable and verified; streamed
    away from the closed pose and back, it returns to that answer.  (Streamed in from an open U, the
    tangent's winding is kept and the U closes into a self-crossing teardrop instead: self-contact, #15.)
    The stream moves the right clamp against its tangent: along it (+x), the string's end would have to pass
    through the left clamp's point, and self-contact (#15) makes it bend round it instead."""
    closed = hanging(right=(0, 0, 0.4))
    ref = full_reference(closed)
    assert np.ptp(ref.points[:, 2]) > 0.3  # a ring of circumference L is 1/π across: not a folded line
    solver, r = auto(closed)
    assert r.stable is True and r.equilibrium_residual_m <= TOL
    assert np.max(np.linalg.norm(r.points - ref.points, axis=1)) <= TOL
    for x in [-0.05, -0.1, -0.15, -0.1, -0.05, 0.0]:
        r = solver.solve({"right": ((x, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))})
        assert r.ok, (x, r.message)
    assert r.stable is True
    assert np.max(np.linalg.norm(r.points - ref.points, axis=1)) <= TOL


def test_out_of_plane_queries_reuse_the_mapped_held_shape_until_the_stream_moves():
    """A planar stream answers out-of-plane queries with the 3D model, warm-started from the held shape
    mapped onto it (ShapeSolver.adopt_warm_start).  The mapping is made once per held shape and reused
    by the next queries: each query's start is, bit for bit, the mapping made afresh for it, also after
    the stream committed a new shape; it is at the stream's held targets (the equilibrium's own, from
    which a solve moves to the query's), with its derivatives there, evaluated once per mapping; and
    the answers equal those of a fresh solver holding the same shape to rounding."""
    q1 = {"right": ([0.55, 0.06, 0.38], [0, 0, 0, 1])}
    q2 = {"right": ([0.62, -0.05, 0.42], [0, 0, 0, 1])}
    moved = {"right": ([0.58, 0.0, 0.36], [0, 0, 0, 1])}
    solver, r = auto(hanging())
    assert r.model.planar

    answered_by = []
    finish = solver.finish
    solver.finish = lambda *a, **kw: answered_by.append(kw.get("solver")) or finish(*a, **kw)

    def query(q):
        answer = solver.solve(q, commit=False)
        assert answer.ok and not answer.model.planar
        other = answered_by[-1]  # the 3D model's solver
        assert other is not None and other is not solver.inner
        held, nf = other.committed_state, other.nlp.n_free_rows  # commit=False leaves the start in place
        np.testing.assert_array_equal(held.p[other.nlp.params["grip:right:position"]],
                                      solver.problem.grip("right").pose.position)
        # its stored derivatives (evaluated once per mapping) are those at its own z and p
        kkt, residual, _, _ = other.functions.kkt_free(held.z, held.p, held.lam_g[:nf])
        np.testing.assert_allclose(held.kkt, kkt, rtol=0, atol=1e-12 * np.abs(kkt).max())
        np.testing.assert_allclose(held.residual, residual[:, 0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(held.g, np.asarray(other.nlp.g_fn(held.z, held.p)).ravel(), rtol=0, atol=1e-12)
        start = held.copy()
        other.forget_adoption()  # the mapping made afresh
        assert other.adopt_warm_start(solver.inner)
        np.testing.assert_array_equal(other.committed_state.z, start.z)
        np.testing.assert_array_equal(other.committed_state.lam_g, start.lam_g)
        np.testing.assert_array_equal(other.committed_state.p, start.p)
        return answer

    first = [query(q) for q in (q1, q2, q1)]
    np.testing.assert_array_equal(first[0].points, first[2].points)
    for q, answer in ((q1, first[0]), (q2, first[1])):
        fresh, _ = auto(hanging())
        np.testing.assert_allclose(answer.points, fresh.solve(q, commit=False).points, atol=1e-12)
    assert solver.solve(moved).ok  # the stream commits a new held shape
    query(q2)


def test_a_query_newton_cannot_take_in_one_move_is_answered_in_substeps_from_the_held_targets():
    """``default_cable`` held planar, queried 15 cm away towards the table: one Newton move from the
    mapped held shape makes a contact appear and the active-set steps grow too large.  The 3D model's
    start is at the held targets, so the move is split into substeps (ShapeSolver._newton_in_substeps)
    and Newton answers; with the start labelled with the query's own targets the substeps were no
    move at all, and IPOPT answered in tens of milliseconds.  The answer is the stable shape a cold
    solve of the same targets finds: the query presses on the table, whose rows sit on the mesh
    nodes (#37), so it is refined as the cold solve is (on the first mesh it cut the table by 0.9 mm
    between two nodes and was 6.2 mm from the cold answer)."""
    scene = load_scene("default_cable")
    target = {"right": GripPose(np.array([0.57548848, -0.03298794, 0.28098936]), np.array([0.0, 0.0, 0.0, 1.0]))}
    solver = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    assert solver.solve().model.planar
    answered = solver.solve(target, commit=False)
    assert answered.ok and answered.stable and not answered.model.planar
    assert any(r.startswith("query: ") for r in answered.model.reasons), answered.model.reasons
    cold = make_solver(scene.problem.with_grip_poses(target), scene.options, compile="off", checks="sync").solve()
    assert cold.ok and cold.stable
    assert np.max(np.linalg.norm(answered.points - cold.points, axis=1)) < 1e-7


def test_a_fourier_basis_serves_the_planar_model_and_the_3d_model_uses_its_own_elements():
    """solver.basis belongs to the planar (and Euler-angle) models: auto streams its planar model in that
    basis, and when a target leaves the plane it builds the director model with its default options instead
    of refusing them (SolverOptions.with_model); each result reports the basis its model used."""
    opts = SolverOptions(basis="fourier", order=12)
    solver = make_solver(clamped_pair(right=(0.7, 0, 0)), opts, compile="off", checks="sync")
    planar = solver.solve()
    assert planar.ok and planar.model.planar and planar.basis == "fourier"
    # checked before it returns (a streamed update's check would take effect CHECK_LAG updates later)
    out_of_plane = solver.solve({"right": ([0.6, 0.2, 0.1], [0, 0, 0, 1])}, check_now=True)
    assert out_of_plane.ok and not out_of_plane.model.planar, out_of_plane.message
    assert out_of_plane.basis == "chebyshev"
    assert opts.with_model("full").basis == "chebyshev" and opts.with_model("planar").basis == "fourier"
    assert SolverOptions(basis="fourier", rotation="euler").with_model("full").basis == "fourier"


@pytest.mark.parametrize("checks", ["background", "sync"])
def test_background_checks_compile_their_order_shadows_ahead(checks, monkeypatch):
    """Beside a stream (background checks) the order shadows a check solves are compiled ahead, as the
    models of a switch or a query are: interpreted, they held the GIL through long CasADi calls while the
    stream's updates waited.  A one-shot solve (sync checks) compiles nothing it does not stream."""
    ahead = []
    monkeypatch.setattr(ModelPool, "compile_ahead", lambda self, solver, switch=False: ahead.append(solver))
    # the order shadows check the models off the element family (#37): here the fourier planar one
    options = SolverOptions(output_points=51, basis="fourier", order=12)
    solver = make_solver(hanging(), options, compile="off", checks=checks)
    try:
        assert solver.solve().ok
        for k in range(4):  # the first background job builds the models ahead; a check follows it
            solver._wait_for_check()
            assert solver.solve({"right": ([0.58, 0.0, 0.39 - 0.002 * k], [0, 0, 0, 1])}).ok
        solver._wait_for_check()
        shadows = [s for s in ahead if s.options.order != solver.choice.order]
        if checks == "background":
            assert shadows and all(s is not solver.inner for s in shadows)
        else:
            assert not shadows
    finally:
        solver.close()


def test_an_unverified_answer_of_auto_does_not_advise_raising_the_order():
    """A fixed model's 'unverified' says to raise solver.order; auto chooses its order and mesh
    itself (the main job with both cores busy published two such answers at its switch to 3D)."""
    import time as _time

    from dlo_ros.solver.auto import report
    from dlo_ros.solver.results.outputs import unverified_because
    from dlo_ros.solver.results.result import ShapeResult

    message = unverified_because(1.16e-3, 1e-3, 1.0)
    assert "raise solver.order" in message
    auto = report.finished(ShapeResult(status="unverified", message=message), _time.perf_counter(), (0,), 1)
    assert "raise solver.order" not in auto.message and report.AUTO_REFINES in auto.message
    assert auto.message.startswith("not a verified equilibrium: the equilibrium residual is 0.00116 m")


def test_moments_auto_cannot_follow_say_which_orders_it_tried():
    """Random scene 146 (bench/suite/random_scenes.py): point moments that turn the string more
    than any order's nodes follow.  auto tries every order; its failure says so instead of the
    fixed model's advice to raise solver.order, which it has followed."""
    from random_scenes import random_scene

    problem = random_scene(146)
    options = SolverOptions(error_tolerance=1e-3 * problem.string.length)
    result = make_solver(problem, options, compile="off", checks="sync").solve()
    assert result.status == "failed"
    assert result.message.startswith("point moments: unresolved:")
    assert "raise solver.order" not in result.message
    assert "(auto tried every order up to 32)" in result.message
    assert result.model.order == 32
