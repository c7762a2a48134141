"""The contact-free Newton functions are built on first use; ``ShapeSolver.prepare`` builds them.

A cold refinement's passes on contact never take a contact-free step (the paper's Fig. 3 floor
evaluated the full KKT function 115 times and the contact-free one never), so the contact-free
KKT function and the Newton-step function around it are built when a solve first needs them.  A
model a stream may switch to is prepared on the worker, so that its first contact-free update
builds nothing on the stream's thread.  And the lazy functions are the eager ones: a warm update
through them equals one through functions built before it.
"""

from __future__ import annotations

import numpy as np

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.compiled import DeferredFunction


def deferred_unbuilt(solver: ShapeSolver) -> list[str]:
    fns = solver.functions
    return [
        name
        for name in ("kkt_free", "newton_step")
        if isinstance(getattr(fns, name), DeferredFunction) and getattr(fns, name)._built is None
    ]


def test_prepare_builds_the_contact_free_functions():
    scene = load_scene("default_cable")
    solver = ShapeSolver(scene.problem, scene.options, compile="off", lazy_ipopt=True)
    assert deferred_unbuilt(solver) == ["kkt_free", "newton_step"]
    solver.prepare()
    assert deferred_unbuilt(solver) == []


def test_a_lazily_built_update_equals_a_prepared_one():
    scene = load_scene("default_cable")
    right = scene.problem.grip("right").pose
    poses = {"right": GripPose(right.position + np.array([-0.01, 0.0, 0.01]), right.orientation)}
    answers = []
    for prepared in (False, True):
        solver = ShapeSolver(scene.problem, scene.options, compile="off")
        if prepared:
            solver.prepare()
        assert solver.solve().ok
        result = solver.solve(poses)
        assert result.ok
        assert deferred_unbuilt(solver) == []  # the warm update took contact-free Newton steps
        answers.append(result.points)
    assert np.array_equal(answers[0], answers[1])
