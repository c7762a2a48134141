"""A switch of physics carries the finer mesh a held check decided (#37: every update ok).

The main job's manoeuvre (the default cable beside its post, ``node.demo``) streamed by every
second target, as a planner at 25 Hz or the node coalescing targets under load sends it: the
planar model's check finds its one element too coarse (estimate 0.53 mm, over δ/2) shortly before
the targets leave the plane (update 102), and its switch to two elements is held for
CHECK_LAG + BUILD_LAG updates, past that.  The 3D model the stream switched to used to start on the
planar model's one element: residual 1.0–1.17 mm, over δ = 1 mm, and the next 30 updates were
published ``unverified`` until the 3D model's own check (which started only once the dropped
planar verdict had come due) refined it.  Asserted, in both check modes: the 3D model starts on
the mesh the held check decided, and every update is ``ok`` with a residual under δ; without the
carried mesh the 3D model's first answer is unverified.
"""

from __future__ import annotations

import pytest
import test_post_last_pose as post  # the main job's scene and targets

from dlo_ros.solver.auto import follow, make_solver

STEP, LAST = 2, 130  # the demo's 50 Hz targets, every STEP-th, up to LAST


def stream(checks: str) -> dict:
    """The default (interpreted, no update time limit: no timing) by every STEP-th target."""
    s = post.scene()
    options = s.options.__class__(**{**vars(s.options), "update_time_limit": 0.0})
    solver = make_solver(s.problem, options, compile="off", checks=checks)
    try:
        assert solver.solve().ok
        return {k: solver.solve(post.targets(k)) for k in range(STEP, LAST + 1, STEP)}
    finally:
        solver.close()


def switch_to_3d(answers: dict) -> int:
    """The update the stream switched to the 3D model at."""
    left = [k for k, r in answers.items() if any("left the plane" in c for c in r.model.changed)]
    return left[0]


@pytest.mark.parametrize("checks", ["sync", "background"])
def test_the_3d_switch_starts_on_the_held_finer_mesh(checks):
    answers = stream(checks)
    k = switch_to_3d(answers)
    assert answers[k].model.elements == 2, answers[k].model  # the planar check's decision
    for j, result in answers.items():
        assert result.status == "ok", (j, result.message)
        assert result.equilibrium_residual_m < 1e-3, j


def test_without_the_carried_mesh_the_3d_model_starts_too_coarse(monkeypatch):
    monkeypatch.setattr(follow, "held_refinement", lambda *args, **kwargs: None)
    answers = stream("sync")
    k = switch_to_3d(answers)
    assert answers[k].model.elements == 1
    assert answers[k].status == "unverified"
