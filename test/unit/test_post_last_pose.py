"""``solver.error_tolerance`` on the main job's last pose on the post (#37): the default against an exact
reference.

The case: the demo's scene (config/scenes/default_cable.yaml plus ``dlo_ros.node.demo.POST``, a sphere
of radius 0.08 m) at the demo manoeuvre's last grip targets (``demo.targets_at``, 50 Hz, target 450 at
t = 9 s): the ends 0.35 m apart at z = 0.55 m, the right clamp turned by half a turn about its tangent.
The 1 m cable (Rf 0.02 N m², Rt 0.015 N m², 0.5 N/m, radius 5 mm) hangs past the post and presses on
its +x side at one point (0.28 N, slightly below the sphere's equator); the table (z ≤ 0) stays
0.23 m below it.  The scene has a second, mirror equilibrium of equal energy (the half turn about the
vertical through the post's centre maps the scene onto itself), 0.17 m away: the cable against the
post's −x side.  Which one an answer is on depends on its history (the stream here starts cold 40
targets earlier, near the top of the post, and may slide either way), so each answer is compared
with the reference started from its own contact.

The reference (test/reference/sphere_contact.py): shooting of the Kirchhoff rod of
test/reference/kirchhoff.py (gravity, twist, clamps; DOP853 at 1e-12) with one point force at s*,
solved with (F, s*) for an exact tangential contact with the sphere of radius R + r, started from the
answer's contact force and grip wrench and then checked: contact residual < 1e-9 m, the force a push,
no point of the rod closer than R + r to the centre (dense grid), the table clear.  Independently,
the discrete rod of test/reference/heavy_contact_rod.py (quaternion edges, gravity, the sphere and the
table at every vertex and midpoint, IPOPT) lands on the same contact set; its energy converges in h²
to the shooting's (N = 800 … 3200 edges, Richardson of the last two: 1.6e-8 J from it) and its shape
approaches it slowly and erratically (5.2e-4, 5.5e-4, 0.17 (mirror branch), 7.0e-5 m at N = 400, 800,
1600, 3200): a point contact held at grid points moves the shape by ~1 m per m of contact shift along
s, because the cable's swing about the post (the mode between the two mirror equilibria) is very
soft.  Here the discrete rod runs at N = 400 only, as a check of the branch and the contact set.

Asserted, cold and streamed (warm along the demo's last 40 targets from a cold solve at the first,
then held at the last until a check of a shape there says the tolerance is met, 120 updates at
most), at δ = 1e-3 and 1e-4 m, and cold at 1e-5 m: ``ok``, ``tolerance_met``, the centreline within δ of the reference
at the same arc lengths, and the reported ``model.estimated_error_m`` bounding the true error by at
most 10x.  And the contact's part of that estimate on its own (solver/adapt/contact_shift.py, the
family of equilibria pinned at the contact's arc length), on a fixed coarse mesh: where the
answer's contact sits along s against the reference's, and the error that stands for.

Measured with auto's slot on the post (``solver.slotted_obstacles: points``; true error /
estimate / unknowns, wall time): cold 1e-3 5.7e-5 / 1.4e-4 / 63, 0.9 s; streamed 1e-3 3.3e-5 /
1.2e-4 / 63; cold 1e-4 2.8e-6 / 1.1e-5 / 127, 4.0 s; streamed 1e-4 2.0e-5 / 2.3e-5 / 87; cold
1e-5 3.2e-8 / 1.3e-7 / 147, 2.4 s.  With the post's contact on node rows (before, auto's): cold
1e-3 6.06e-5 / 1.40e-4 / 163; cold 1e-5 2.28e-6 / 4.96e-6 / 283 after 28 refinement passes (the
contact's error fell by about 0.8 per pass).  Not asserted: 1e-5 m streamed.  Before the pinned
family (the contact's shift from the answer's own clearance, −g'/g'', and the shape's response
with the contact row held) the rows' estimate was 1.6–3x below the true error: the error is a
swing of the loop about the post (the soft mode above), which only a shape free to move with its
contact follows.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from reference.heavy_contact_rod import halfspace, solve_heavy_contact_rod, sphere
from reference.kirchhoff import blas_threads
from reference.sphere_contact import solve_sphere_contact
from scipy.spatial.transform import Rotation

from dlo_ros.model.problem import GripPose
from dlo_ros.node import demo
from dlo_ros.scene import load_scene, scene_from_dict, scene_to_dict
from dlo_ros.solver.adapt.contact_shift import pinned_family, point_contacts
from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.auto.choice import ModelChoice
from dlo_ros.solver.auto.mesh_check import mesh_verdict
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.shape_solver import ShapeSolver

TOLERANCES = (1e-3, 1e-4)
POINTS = 401
PERIOD = 0.02  # s: the demo's 50 Hz
LAST = int(demo.duration() / PERIOD)  # the demo's last target
STREAMED = 40  # targets streamed, the last one included
#: updates held at the last target at most: until a check of a shape there says the tolerance is
#: met (each refinement takes effect CHECK_LAG + BUILD_LAG = 20 updates after the shape it checked;
#: the stream's contact slid over 5 cm of the cable, and the mesh it left needs several)
HOLD = 200


def scene():
    """The demo's scene: the default cable plus the post (as ``demo.write_demo_scene``)."""
    d = scene_to_dict(load_scene(demo.DEMO_SCENE))
    d["obstacles"] = list(d.get("obstacles", [])) + [dict(demo.POST)]
    return scene_from_dict(d)


def targets(k: int) -> dict:
    """The demo's target k (time k × 20 ms)."""
    (pl, ql), (pr, qr) = demo.targets_at(k * PERIOD)
    return {"left": GripPose(pl, ql), "right": GripPose(pr, qr)}


def problem_at(k: int):
    return scene().problem.with_grip_poses(targets(k))


def post_and_table(problem):
    """The post (sphere) and the table (half-space) of the scene, by type."""
    by_type = {o.type: o for o in problem.obstacles}
    assert sorted(by_type) == ["halfspace", "sphere"], by_type
    return by_type["sphere"], by_type["halfspace"]


def rod_of(problem, s_eval=None) -> dict:
    """The scene's rod as keyword arguments of the reference's ``solve_clamped``."""
    st = problem.string
    left, right = problem.grip("left").pose, problem.grip("right").pose
    assert st.stretch_stiffness is None  # inextensible, as the reference
    return dict(
        L=st.length, Rf=scalar(st.bend_stiffness), Rt=scalar(st.twist_stiffness), x0=left.position,
        R0=Rotation.from_quat(left.orientation).as_matrix(), x1=right.position,
        R1_or_tangent=Rotation.from_quat(right.orientation).as_matrix(), mode_end="clamp",
        D=scalar(st.weight_per_length), g=problem.gravity_unit, s_eval=s_eval,
    )  # fmt: skip


def scalar(value) -> float:
    """A constant stiffness or weight of the scene (the reference takes constants only)."""
    values = np.atleast_1d(getattr(value, "values", value))
    assert np.ptp(values) == 0, value
    return float(values[0])


class Reference:
    """The shooting reference at the last target (module docstring), with its checks."""

    def __init__(self, problem, start):
        post, table = post_and_table(problem)
        st = problem.string
        self.reach = post.radius + st.radius
        self.centre = post.centre
        left = start.grips["left"]  # the clamp's action on the rod: minus the internal n(0), m(0)
        load = max(start.contact_loads, key=lambda c: np.linalg.norm(c.force))
        assert load.obstacle == problem.obstacles.index(post)
        with blas_threads(1):
            self.contact = solve_sphere_contact(
                rod_of(problem, np.linspace(0.0, st.length, POINTS)), post.centre, self.reach,
                start.contact_forces[load.obstacle], load.s_start, (-left.force, -left.torque),
            )  # fmt: skip
        c = self.contact
        assert c.residual < 1e-9, c.residual
        assert c.rod.residual < 1e-9, c.rod.residual
        assert c.clearance > -1e-9, c.clearance  # nowhere inside the post
        d = c.rod.state(c.s_contact)[0] - post.centre
        assert c.force @ d > 0.1 * self.reach, c.force  # a push, of more than 0.1 N
        lowest = np.min(table.normal @ (c.rod.position(c.rod.s) - table.point).T)
        assert lowest > st.radius + 0.1, lowest  # the table far below: not a contact

    def error(self, result) -> float:
        return float(np.linalg.norm(self.contact.rod.position(result.s) - result.points, axis=1).max())


@pytest.fixture(scope="module")
def cache():
    return {}


def solve(tolerance: float, how: str):
    """The default's answer at δ = ``tolerance`` [m], ``how``: 'cold' or 'streamed'."""
    # interpreted (compile off), no update time limit: a test must not depend on timing
    options = replace(
        scene().options, model="auto", error_tolerance=tolerance, output_points=POINTS,
        update_time_limit=0.0,
    )  # fmt: skip
    first = LAST if how == "cold" else LAST - STREAMED + 1
    solver = make_solver(problem_at(first), options, compile="off", checks="sync")
    try:
        result = solver.solve()
        if how == "cold":
            return result
        assert result.ok, result.message
        for k in range(first + 1, LAST + 1):
            result = solver.solve(targets(k))
        for at_pose in range(1, HOLD + 1):  # held: until a check of a shape here meets δ
            model = result.model
            if model.checked and model.checked_updates_ago < at_pose and model.tolerance_met:
                return result
            result = solver.solve(targets(LAST))
        return result  # the test says what the model reports
    finally:
        solver.close()


def answer(cache, tolerance: float, how: str):
    if (tolerance, how) not in cache:
        cache[tolerance, how] = solve(tolerance, how)
    return cache[tolerance, how]


def reference(cache) -> Reference:
    if "reference" not in cache:
        start = answer(cache, TOLERANCES[0], "cold")
        assert start.ok, start.message
        cache["reference"] = Reference(problem_at(LAST), start)
    return cache["reference"]


def test_discrete_rod_agrees(cache):
    """The discrete rod (N = 400, from the reference's frames) minimises onto the same contact set
    and branch: IPOPT succeeds, the table is clear, the post touches within 2 neighbouring points
    with the reference's force, and the shape is within its measured 5.2e-4 m (1e-3 m)."""
    ref = reference(cache)
    problem = problem_at(LAST)
    post, table = post_and_table(problem)
    st, rod = problem.string, ref.contact.rod
    n = 400
    mid = (np.arange(n) + 0.5) * st.length / n
    q0 = np.array([Rotation.from_matrix(rod.state(s)[1]).as_quat() for s in mid])
    grips = [(g.pose.position, g.pose.orientation) for g in (problem.grip("left"), problem.grip("right"))]
    d = solve_heavy_contact_rod(
        q0, st.length, scalar(st.bend_stiffness), scalar(st.twist_stiffness),
        scalar(st.weight_per_length), problem.gravity_unit, grips[0], grips[1], st.radius,
        obstacles=(halfspace(table.point, table.normal), sphere(post.centre, post.radius)),
    )  # fmt: skip
    assert d.success, d.message
    assert len(d.contacts[0][0]) == 0 and d.clearance[0] > 0.1  # the table clear
    on, forces = d.contacts[1]
    assert 1 <= len(on) <= 2 and np.ptp(on) <= 1, on  # one contact on the post
    force = forces.sum(axis=0)
    assert np.linalg.norm(force - ref.contact.force) < 0.05 * np.linalg.norm(ref.contact.force), force
    assert np.linalg.norm(d.at(rod.s) - rod.x, axis=1).max() < 1e-3


@pytest.mark.parametrize(
    "tolerance, how",
    [
        (1e-3, "cold"),
        (1e-3, "streamed"),
        # ~15-20 s each: the whole suite's run (CI) leaves them out (pytest.ini)
        pytest.param(1e-4, "cold", marks=pytest.mark.slow),
        pytest.param(1e-4, "streamed", marks=pytest.mark.slow),
        pytest.param(1e-5, "cold", marks=pytest.mark.slow),
    ],
)
def test_default_meets_the_tolerance(cache, tolerance, how):
    result = answer(cache, tolerance, how)
    ref = Reference(problem_at(LAST), result)  # on the answer's branch (module docstring)
    assert result.status == "ok", result.message
    assert result.model.tolerance_met is True, result.model
    error = ref.error(result)
    estimate = result.model.estimated_error_m
    assert error <= tolerance, (error, estimate, result.model.variables)
    # the estimate reported bounds the true error, and by at most 10x (issue #37)
    assert error <= estimate <= 10 * error, (estimate, error)


def test_the_pinned_family_finds_the_exact_contact():
    """The contact's error (solver/adapt/contact_shift.py) on a fixed coarse mesh (3D director
    model, three elements of 12 nodes, the rows on the nodes), cold: one Newton step along the
    family of equilibria pinned at the contact's arc length takes the contact most of the way
    to the reference's contact point, and the centreline error it predicts is the true one.

    Measured: the answer's contact 1.84 mm from the exact one along s, 0.11 mm after the step;
    predicted error 2.26e-3 m against a true 2.35e-3 m (the contact's error dominates it here).
    """
    options = replace(
        scene().options, model="full", obstacle_points="nodes", output_points=POINTS,
        update_time_limit=0.0,
    )  # fmt: skip
    solver = ShapeSolver(
        problem_at(LAST), options, compile="off", mesh=MeshSpec((0.45, 0.55), (12, 12, 12))
    )
    result = solver.solve()
    assert result.ok, result.message
    ref = Reference(problem_at(LAST), result)
    nlp, state = solver.nlp, solver.committed_state
    rows = np.asarray(nlp.kkt_fn(state.z, state.p, state.lam_g)[1])
    contacts = point_contacts(nlp, solver.problem, state, rows)
    assert len(contacts) == 1, contacts
    (contact,) = contacts
    offset = contact.s - ref.contact.s_contact
    assert 1e-3 <= abs(offset) <= 5e-3, offset  # else the case is no test of the step
    family = pinned_family(nlp, solver.problem, state, contact, np.linspace(0.0, 1.0, POINTS))
    assert family is not None
    assert abs(contact.s + family.shift - ref.contact.s_contact) <= 0.15 * abs(offset)
    error = ref.error(result)
    assert abs(family.error_m - error) <= 0.15 * error, (family.error_m, error)


def test_a_slot_at_a_breakpoint_holds_the_contact_to_round_off(cache):
    """A fixed 3D model split at the reference's contact s* and at its mirror L − s* (20 + 6 + 20
    nodes: either branch has its contact on a breakpoint), the post in one contact slot, solved
    cold: the centreline within 1e-8 m of the shooting reference on the answer's branch, the
    force in one slot.  The slot's row is the post's reach at the closest approach near it
    (solver/build/slot_envelope.py); with the row at its σ alone the cable slid along the post
    until a row 2–9 mm away took a quarter of the force, 1.6 mm from the reference (measured).
    """
    s_star = reference(cache).contact.s_contact
    L = scene().problem.string.length
    options = replace(
        scene().options, model="full", obstacle_points="nodes", obstacle_slots=1,
        output_points=POINTS, update_time_limit=0.0,
    )  # fmt: skip
    spec = MeshSpec(tuple(sorted((s_star, L - s_star))), (20, 6, 20))
    result = ShapeSolver(problem_at(LAST), options, compile="off", mesh=spec).solve()
    assert result.ok, result.message
    (load,) = result.contact_loads
    assert load.kind == "point"
    assert Reference(problem_at(LAST), result).error(result) < 1e-8


SLOTTED = dict(model="full", obstacle_points="nodes", obstacle_slots=2, output_points=POINTS,
               update_time_limit=0.0)  # fmt: skip
INSIDE = MeshSpec((0.49, 0.51), (16, 6, 16))  # either branch's contact 6-7 mm from a breakpoint


def test_a_contact_inside_an_element_is_split_at_not_estimated():
    """A fixed 3D model whose contact lies inside an element (breakpoints 0.49 and 0.51 m, either
    branch's contact 6–7 mm from one of them), the post in a slot: without a solve on another
    mesh the check cannot bound the error the unresolved kink carries (measured on a mesh split
    at 0.51 m alone: the residual's estimate 1.3e-6 m against a true 4.8e-6 m), so it reports no
    estimate (inf: tolerance not met) and proposes the mesh split at the contact."""
    options = replace(scene().options, **SLOTTED)
    spec = INSIDE
    solver = ShapeSolver(problem_at(LAST), options, compile="off", mesh=spec)
    result = solver.solve()
    assert result.ok, result.message
    (load,) = result.contact_loads
    assert 1e-3 < min(abs(load.s_start - b) for b in spec.breakpoints) < 1e-2
    choice = ModelChoice(planar=False, twist=True, stretch=False, gravity=True, order=12,
                         obstacles=(0, 1), mesh=spec)  # fmt: skip
    verdict = mesh_verdict(solver, solver.committed_state, choice, solver.problem, 1e-3, False)
    assert verdict.estimate == float("inf") and "inside an element" in verdict.reason
    assert verdict.choice is not None and verdict.choice.mesh is not None
    # split at the slot's σ, within the slot tolerance (4e-5 m here) of where the force acts
    assert min(abs(b - load.s_start) for b in verdict.choice.mesh.breakpoints) < 4e-5


@pytest.mark.parametrize("counts, tolerance", [((16, 6, 16), 1e-3), ((8, 6, 8), 1e-4)])
def test_a_contact_inside_an_element_is_bounded_by_a_mesh_moved_onto_it(counts, tolerance):
    """The shape of a mesh whose contact lies inside an element (breakpoints 0.49 and 0.51 m),
    checked with a solve on the mesh whose nearer breakpoint is moved onto the contact (the same
    counts: a clone of the NLP, auto/mesh_check.py ``moved_verdict``): the estimate, max_s
    |x − x_moved| + the moved mesh's own, bounds the true error against the exact reference by
    at most 10x.  16-node elements at δ = 1e-3 m: within δ/2, the mesh is kept; 8-node ones at
    1e-4 m: not, and the check switches to the moved mesh (refined as its own check says), with
    a breakpoint at the contact.  Measured: true 2.2e-7 / estimate 4.2e-7 m; 2.4e-5 / 1.1e-4 m.
    """
    mesh = MeshSpec(INSIDE.breakpoints, counts)
    options = replace(scene().options, **SLOTTED, error_tolerance=tolerance)
    solver = ShapeSolver(problem_at(LAST), options, compile="off", mesh=mesh)
    result = solver.solve()
    assert result.ok, result.message
    (load,) = result.contact_loads
    shadows = []

    def moved_shadow(spec):
        other = ShapeSolver(problem_at(LAST), options, compile="off", mesh=spec, template=solver)
        assert other.nlp.own_symbols is False  # the same counts: a clone
        other.adopt_warm_start(solver)
        shadows.append(spec)
        return other, other.solve(targets(LAST))

    choice = ModelChoice(planar=False, twist=True, stretch=False, gravity=True, order=12,
                         obstacles=(0, 1), mesh=mesh)  # fmt: skip
    verdict = mesh_verdict(
        solver, solver.committed_state, choice, solver.problem, tolerance, False, moved_shadow
    )
    (moved,) = shadows
    assert moved.counts == counts
    assert min(abs(b - load.s_start) for b in moved.breakpoints) < 4e-5  # onto the slot's σ
    error = Reference(problem_at(LAST), result).error(result)
    assert error <= verdict.estimate <= 10 * error, (verdict.estimate, error)
    if tolerance == 1e-3:
        assert verdict.choice is None  # within δ/2: kept
    else:
        assert verdict.choice is not None and "moved onto it" in verdict.reason, verdict.reason
        at = verdict.choice.mesh.breakpoints
        assert min(abs(b - load.s_start) for b in at) < 4e-5
