"""A verdict moving a breakpoint onto a contact is dropped when it comes due after the contact left.

A stream's mesh check may find a slot's contact inside an element and move a breakpoint onto it
(``mesh_check.moved_verdict``); the switch takes effect CHECK_LAG + BUILD_LAG updates after the
shape it checked.  On the main job's post the contact rolled from s = 0.417 to 0.503 meanwhile,
and the breakpoint moved to 0.417 left the new contact inside an element: the true error went
from 3e-5 to 6.1e-4 m.  ``stream_checks.contact_left`` tells such a verdict from one whose contact
is still there (a slot carrying force within CARRIED·L of the moved breakpoint, or an obstacle row
carrying force within the rows' spacing: ``contact_places``); ``apply_due`` drops it and checks
the shape again.  (A strip on
a floor, whose breakpoints move onto its line contact's ends: test_plane_keep.py's streamed Fig. 3,
whose estimate bounds its error within 10×.)  Asserted on a solver pressed on the post (the fixed model on the main job's landing
mesh, its contact at s = 0.476), with the verdicts a check could make.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from types import SimpleNamespace

import pytest
import test_post_landing as landing
import test_post_last_pose as post

from dlo_ros.solver.auto.choice import ModelChoice
from dlo_ros.solver.auto.check_schedule import PendingCheck
from dlo_ros.solver.auto.stream_checks import CheckBook, apply_due, contact_left
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.shape_solver import ShapeSolver


@pytest.fixture(scope="module")
def pressed():
    """An auto stand-in streaming the fixed landing model, pressed on the post at target 411."""
    options = replace(
        post.scene().options, model="full", obstacle_points="nodes", obstacle_slots=2,
        slotted_obstacles="points", output_points=post.POINTS, update_time_limit=0.0,
    )  # fmt: skip
    solver = ShapeSolver(post.problem_at(409), options, compile="off", mesh=landing.LANDING_MESH)
    assert solver.solve().ok
    for k in (410, 411):
        result = solver.solve(post.targets(k))
    (load,) = result.contact_loads
    choice = ModelChoice(planar=False, twist=True, stretch=False, gravity=True, order=12,
                         obstacles=(0, 1), mesh=landing.LANDING_MESH)  # fmt: skip
    auto = SimpleNamespace(choice=choice, inner=solver, problem=solver.problem)
    return auto, load.s_start


def moved_to(auto, breakpoint: float) -> ModelChoice:
    return replace(auto.choice, mesh=MeshSpec((breakpoint,), landing.LANDING_MESH.counts))


def test_a_move_onto_the_contact_still_there_is_applied(pressed):
    auto, s = pressed
    assert s == pytest.approx(0.476, abs=2e-3)
    assert not contact_left(auto, moved_to(auto, s))
    assert not contact_left(auto, moved_to(auto, s + 0.005))  # within CARRIED·L


def test_a_move_onto_where_the_contact_was_is_dropped(pressed):
    auto, s = pressed
    assert contact_left(auto, moved_to(auto, 0.417))


def test_other_verdicts_are_not_moves(pressed):
    auto, _ = pressed
    split = replace(auto.choice, mesh=MeshSpec((0.417, 0.5), (8, 8, 8)))  # a refinement
    assert not contact_left(auto, split)
    other = replace(moved_to(auto, 0.417), order=16)  # another model
    assert not contact_left(auto, other)
    assert not contact_left(auto, auto.choice)  # nothing moved


def test_a_dropped_move_cancels_its_lead_ins_queued_solves(pressed):
    """Its lead-in's solves still queued on the worker never run: the check started next would
    wait behind them (the main job: a lead-in solve of 0.24-0.3 s, and those after it, ran after
    the switch they led into was dropped, and update 449 waited 39 ms for the next check)."""
    auto, _ = pressed
    choice = moved_to(auto, 0.417)
    book = CheckBook(updates=446, index=445, generation=3)
    verdict = SimpleNamespace(choice=choice, snapshot=SimpleNamespace(generation=3), reason="")
    decided, job = Future(), Future()
    decided.set_result(verdict)
    job.set_result(verdict)
    ran: list[int] = []
    release = threading.Event()
    with ThreadPoolExecutor(1) as worker:
        busy = worker.submit(release.wait, 10.0)  # the lead-in solve the worker is running
        steps = [worker.submit(ran.append, k) for k in (443, 444, 445)]
        pending = PendingCheck(445, job=job, decided=decided, switching=True, steps=steps)
        book.pending = pending
        stand_in = SimpleNamespace(**vars(auto), book=book)
        notes: list[str] = []
        apply_due(stand_in, notes)
        release.set()
        busy.result()
    assert book.pending is None and book.unchecked  # dropped: checked again from here
    assert all(step.cancelled() for step in steps)
    assert ran == []
    assert notes == []  # no switch
