"""A checked solve that switches to a model its check has just solved at the same poses from the
same shape takes that answer (``stream_checks.answer_on_switch``) instead of solving again: the
solve again would start where the check's did and repeat it.

The main job's last pose on its post, cold at δ = 1e-3 m (test_post_last_pose.py's case): its
check moves a breakpoint onto the contact and solves the moved mesh (a shadow); the escalation
then switched to that mesh and solved it again (measured: the same unsettled slot rounds twice,
1.5 s each, at 1e-4 m).  Against the solve again: the same answer to 1e-12 m, the same model
and estimate, and no model solved twice in a row.
"""

from __future__ import annotations

import numpy as np
from test_post_last_pose import solve

from dlo_ros.solver import shape_solver
from dlo_ros.solver.auto import stream_checks


def cold_post(monkeypatch, take_answers: bool):
    """The post's cold solve at 1e-3 m: (result, solves repeated on the same model in a row)."""
    solves, repeats = [], []
    original = shape_solver.ShapeSolver.solve

    def counted(self, *args, **kwargs):
        if solves and solves[-1] is self:
            repeats.append(self.nlp.z_sym.shape[0])
        solves.append(self)
        return original(self, *args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(shape_solver.ShapeSolver, "solve", counted)
        if not take_answers:
            m.setattr(
                stream_checks,
                "answer_on_switch",
                lambda auto, verdict, snap: auto.inner.solve(snap.poses, limited=snap.limited),
            )
        result = solve(1e-3, "cold")
    return result, repeats


def test_the_escalation_takes_the_checks_answer_on_the_mesh_it_moved(monkeypatch):
    taken, none = cold_post(monkeypatch, take_answers=True)
    again, repeated = cold_post(monkeypatch, take_answers=False)
    assert taken.ok and again.ok, (taken.message, again.message)
    assert repeated, "the case no longer switches to a model its check solved"
    assert none == []
    assert np.max(np.abs(taken.points - again.points)) < 1e-12
    assert taken.model.variables == again.model.variables
    assert taken.model.estimated_error_m == again.model.estimated_error_m
    assert taken.model.tolerance_met and taken.stable
