"""The contact-free Newton functions and IPOPT's Jacobian are built on first use.

A cold refinement's passes on contact never take a contact-free step (the paper's Fig. 3 floor
evaluated the full KKT function 115 times and the contact-free one never), so the contact-free
KKT function and the Newton-step function around it are built when a solve first needs them, and
the rows' Jacobian, which only IPOPT evaluates, with the first IPOPT solver (a refined query's
meshes are answered by Newton).  ``ShapeSolver.prepare`` builds them all: a model a stream may
switch to is prepared on the worker, so that its first update builds nothing on the stream's
thread.  And the lazy functions are the eager ones: a warm update through them equals one through
functions built before it.
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
    assert "jac_g_fn" not in vars(solver.nlp)  # IPOPT's alone: built with its first solver
    solver.prepare()
    assert deferred_unbuilt(solver) == []
    assert "jac_g_fn" in vars(solver.nlp)


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
