"""A stream's element mesh stays near what a cold solve needs while its contact slides (#37).

``default_cable`` lying on the table, the right grip along the closed 3D path of
test_director_stream.py for 300 updates (checks inline, so the stream is the same on any
machine): the lift-off slides about 0.1 L along the cable.  Each check that refines splits at the
new lift-off; the breakpoint the contact left behind has calm elements on both sides and merges
away (``adapt/rule.py``, the stream's anchors from ``auto/mesh_check.py``).

Measured (this test's stream): 263 unknowns in 8 elements at update 300 before the merge, 163 in 5
after; a cold solve at the same targets takes 103 in 3.
"""

from __future__ import annotations

import numpy as np

from dlo_ros.scene import load_scene
from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.shape_solver import with_checked_poses
from test_director_stream import path, scene

UPDATES = 300


def test_a_sliding_contact_leaves_no_trail_of_elements():
    problem, options = scene(True), load_scene("default_cable").options
    start = problem.grip("right").pose.position
    solver = make_solver(problem, options, compile="off", checks="sync")
    try:
        assert solver.solve().ok
        for k in range(1, UPDATES + 1):
            streamed = solver.solve({"right": path(k, start)})
            assert streamed.ok, (k, streamed.message)
    finally:
        solver.close()
    poses = {"right": path(UPDATES, start)}
    cold_solver = make_solver(
        with_checked_poses(problem, poses), options, compile="off", checks="sync"
    )
    try:
        cold = cold_solver.solve()
    finally:
        cold_solver.close()
    assert cold.ok and cold.model.tolerance_met, cold.message
    delta = cold.model.tolerance_m
    # the stream's answer and the cold one: each within δ of the exact shape
    assert np.max(np.linalg.norm(streamed.points - cold.points, axis=1)) <= 2 * delta
    assert streamed.model.variables <= 2 * cold.model.variables, (
        streamed.model.variables,
        cold.model.variables,
    )
    assert streamed.model.elements <= 2 * cold.model.elements, (
        streamed.model.breakpoints,
        cold.model.breakpoints,
    )
