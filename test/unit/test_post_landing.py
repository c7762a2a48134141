"""The main job's cable landing on its post (#37): the contact's slot follows a fast slide.

The case (test_post_last_pose.py's scene and exact reference): ``model: auto`` at δ = 1 mm
streamed from a cold solve at the demo's target 390; the cable touches the post at 409 and its
contact slides 1.5 cm along the cable in each of the next updates (s = 0.491 → 0.476 → 0.468 →
0.461).  The first solve of update 411 keeps the slot where 410 left it and cuts into the post
2.4 cm away, beyond the reach of the slot's row (``build/slot_envelope.py``); moving the slot
alone there swung the cable about the post by more each round (2.4 → 4 → 3.7 cm), the rounds ran
out and the answers of 411–413 came back ``ok`` 1.5–1.7 cm from the reference.  Asserted:

* streamed and cold, the answers at 411–413 are ``ok`` and within δ of the reference (a slot whose
  contact jumped out of its reach keeps its place beside the new one for a round:
  ``slot_rounds._jumped``);
* with no slot rounds at all, no answer a round would have moved is ``ok``: each ``ok`` answer
  at 410–413 is within δ, and the answer at 411 (its slot 2.4 cm from the contact) is
  ``unverified`` and says why (``slot_rounds._flag_unsettled``).  (At 409 the cable grazes the
  post with 0.04 N, and the reference's own residual check refuses to match it.)

Later the contact rolls back along the cable fast (s = 0.419 at 427, 0.460 at 429, 0.474 at 431):
a stream that takes every second or third target (a planner at 25 Hz, or the node's coalescing
under load) moves it 4 cm in one update, and the rounds' σ ← s* does not converge there (the
string nearly conforms to the sphere, s*(σ) − σ kept one sign over 2.5 cm of σ).  Asserted: such an
update is solved again in substeps of the grip poses (``pipeline.run_update``: two 2 cm moves the
rounds follow) and is ``ok`` within δ of the reference; without that retry it is ``unverified``.
(The other stream's rounds settle by themselves since a round that lets go of the post and falls
into it is not followed: ``slot_rounds._let_go``.)  The whole manoeuvre by every third target
moves the contact 2 cm in the third quarter of update 429's move and 0.7 cm in its first half: a
substep that does not settle is split in two again (``substeps.in_substeps``, down to an eighth);
every update is ``ok``, 429 and 432 within δ of the reference; with quarters at the finest they
are ``unverified``.

The main job's own stream lands on a mesh split at the middle (the breakpoint 0.5, 8 + 8 nodes:
the planar check's refinement, kept in 3D).  Its round at update 411 moved the slot 1.3 cm to
the answer's closest approach; that solve let go of the post (multiplier 0) and the cable fell
2.8 mm into it at s = 0.516, the rounds followed the cut, and the stream ended the update on the
mirror equilibrium (contact 0.524 instead of 0.476: the cable on the post's other side) and
stayed there.  Asserted on that mesh, fixed (``model: full``): streamed 410–413 the contact stays
on its side and slides as the reference's does, each answer ``ok`` within δ of the reference;
with such rounds followed the stream flips.
"""

from __future__ import annotations

from dataclasses import replace

import pytest
import test_post_last_pose as post

from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.shape_solver import ShapeSolver
from dlo_ros.solver.update import pipeline, slot_rounds, substeps

TOLERANCE = 1e-3
FIRST, LANDED = 390, (411, 412, 413)


#: (cold at, every ``step``-th target, to): streams whose last update moves the contact 4 cm
ROLLING = ((422, 2, 428), (421, 2, 429))


def solver_at(k: int):
    """The default at δ = TOLERANCE on the problem at target k, interpreted, checks inline, no
    update time limit: a test must not depend on timing."""
    options = replace(
        post.scene().options, model="auto", error_tolerance=TOLERANCE,
        output_points=post.POINTS, update_time_limit=0.0,
    )  # fmt: skip
    return make_solver(post.problem_at(k), options, compile="off", checks="sync")


def stream(last: int) -> dict:
    """The default's answers at targets FIRST + 1 … ``last``, streamed from cold at FIRST."""
    solver = solver_at(FIRST)
    try:
        assert solver.solve().ok
        return {k: solver.solve(post.targets(k)) for k in range(FIRST + 1, last + 1)}
    finally:
        solver.close()


def true_error(k: int, result) -> float:
    return post.Reference(post.problem_at(k), result).error(result)


@pytest.fixture(scope="module")
def streamed() -> dict:
    return stream(LANDED[-1])


@pytest.mark.parametrize("k", LANDED)
def test_the_landing_streamed_is_within_the_tolerance(streamed, k):
    result = streamed[k]
    assert result.status == "ok", result.message
    assert true_error(k, result) <= TOLERANCE


@pytest.mark.parametrize("k", [LANDED[0], *sorted({last for _, _, last in ROLLING})])
def test_the_landing_and_the_rolled_contact_cold_are_within_the_tolerance(k):
    solver = solver_at(k)
    try:
        result = solver.solve()
    finally:
        solver.close()
    assert result.status == "ok", result.message
    assert true_error(k, result) <= TOLERANCE


def test_without_slot_rounds_an_unsettled_contact_is_not_ok(monkeypatch):
    monkeypatch.setattr(pipeline, "SLOT_ROUNDS", 0)
    answers = stream(LANDED[-1])
    unsettled = answers[LANDED[0]]
    assert unsettled.status == "unverified"
    assert unsettled.stable is None
    assert "did not settle" in unsettled.message
    for k in range(410, LANDED[-1] + 1):
        result = answers[k]
        if result.status == "ok":
            assert true_error(k, result) <= TOLERANCE, k


def stream_every(first: int, step: int, last: int):
    """The default's answer at ``last`` streamed from a cold solve at ``first`` by every
    ``step``-th target."""
    solver = solver_at(first)
    try:
        assert solver.solve().ok
        for k in range(first + step, last + 1, step):
            result = solver.solve(post.targets(k))
        return result
    finally:
        solver.close()


@pytest.mark.parametrize("first, step, last", ROLLING)
def test_a_contact_rolling_faster_than_the_rounds_is_within_the_tolerance(first, step, last):
    result = stream_every(first, step, last)
    assert result.status == "ok", result.message
    if (first, step, last) == ROLLING[0]:
        assert "substeps" in result.message and "did not settle" in result.message
    assert true_error(last, result) <= TOLERANCE


def test_without_the_substeps_the_rolling_contact_is_unverified(monkeypatch):
    monkeypatch.setattr(pipeline, "unsettled", lambda result: False)
    first, step, last = ROLLING[0]
    result = stream_every(first, step, last)
    assert result.status == "unverified" and result.stable is None
    assert "did not settle" in result.message


def manoeuvre_by_every(step: int) -> dict:
    """The default's answers along the main job's whole manoeuvre by every ``step``-th target,
    streamed from a cold solve at its start (target 0), by target."""
    solver = solver_at(0)
    try:
        assert solver.solve().ok
        return {k: solver.solve(post.targets(k)) for k in range(step, post.LAST + 1, step)}
    finally:
        solver.close()


def test_the_manoeuvre_by_every_third_target_settles_in_finer_substeps():
    answers = manoeuvre_by_every(3)
    assert all(r.status == "ok" for r in answers.values()), [
        (k, r.message) for k, r in answers.items() if r.status != "ok"
    ]
    assert "substeps" in answers[429].message
    for k in (429, 432):
        assert true_error(k, answers[k]) <= TOLERANCE, k


@pytest.mark.slow  # ~7 s: the counterfactual of the test above, left out of the whole suite's run
def test_with_quarters_at_the_finest_the_third_targets_contact_is_unverified(monkeypatch):
    monkeypatch.setattr(substeps, "FINEST", 1 / 4)
    answers = manoeuvre_by_every(3)
    assert answers[429].status == "unverified" and "did not settle" in answers[429].message


#: the main job's mesh when its cable lands on the post (the planar check's, kept in 3D)
LANDING_MESH = MeshSpec((0.5,), (8, 8))


def fixed_landing() -> dict:
    """The fixed model on LANDING_MESH, cold at 409, streamed 410–413."""
    options = replace(
        post.scene().options, model="full", obstacle_points="nodes", obstacle_slots=2,
        slotted_obstacles="points", output_points=post.POINTS, update_time_limit=0.0,
    )  # fmt: skip
    solver = ShapeSolver(post.problem_at(409), options, compile="off", mesh=LANDING_MESH)
    assert solver.solve().ok
    return {k: solver.solve(post.targets(k)) for k in range(410, 414)}


def contact_s(result) -> float:
    (load,) = result.contact_loads
    return load.s_start


def test_the_landing_on_the_split_mesh_keeps_its_side_of_the_post():
    answers = fixed_landing()
    assert contact_s(answers[410]) < 0.5  # the side it lands on
    for k, result in answers.items():
        assert result.status == "ok", (k, result.message)
        assert contact_s(result) < 0.5, k
        assert true_error(k, result) <= TOLERANCE, k
    # sliding as the reference's contact does (0.491 → 0.476 → 0.468 → 0.461)
    slides = [contact_s(answers[k]) - contact_s(answers[k + 1]) for k in range(410, 413)]
    assert all(0.0 < d < 0.02 for d in slides), slides


def test_following_a_round_that_let_go_flips_the_landing_to_the_mirror(monkeypatch):
    monkeypatch.setattr(slot_rounds, "_let_go", lambda *args: False)
    answers = fixed_landing()
    assert contact_s(answers[411]) > 0.5
