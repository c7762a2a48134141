"""What a report calls a contact (#36): a force on an obstacle the string is not touching is barrier
residue, not a contact.  ``default_cable`` hangs 5 cm above its table (scene description); lowered grips
lay it on the table.  The gap is measured independently here, from the answer's points and the table's
plane z = 0."""

from dataclasses import replace

import numpy as np

from dlo_ros.cli.solve import format_summary
from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver
from dlo_ros.solver.results.contacts import pressed_obstacles

RADIUS = 0.005  # default_cable's string radius [m]


def solve(scene):
    solver = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    try:
        return solver.solve()
    finally:
        solver.close()


def contact_lines(scene, result):
    return [line for line in format_summary(scene, result).splitlines() if line.startswith("contact")]


def test_a_cable_hanging_above_the_table_reports_no_contact():
    scene = load_scene("default_cable")
    result = solve(scene)
    assert result.ok, result.message
    gap = result.points[:, 2].min() - RADIUS  # the table is z <= 0
    assert gap > 0.02, "the cable no longer hangs clear of the table: the test tests nothing"
    # the premise of the bug: the interior-point answer leaves a tiny force on the table
    assert np.linalg.norm(result.contact_forces[0]) > 0
    assert pressed_obstacles(result, scene.problem) == {}
    assert contact_lines(scene, result) == []


def test_a_cable_lying_on_the_table_reports_its_contact():
    scene = load_scene("default_cable")
    low = {g.name: GripPose(g.pose.position * [1.0, 1.0, 0.0] + [0.0, 0.0, 0.3], g.pose.orientation)
           for g in scene.problem.grips}
    scene = replace(scene, problem=scene.problem.with_grip_poses(low),
                    options=replace(scene.options, update_time_limit=60.0))  # a slow shared machine
    result = solve(scene)
    assert result.ok, result.message
    # independently: the lowest point of the string's surface is on the table (gap ~ 0) ...
    assert abs(result.points[:, 2].min() - RADIUS) < 1e-4
    # ... and the table carries a real part of the weight D L = 0.5 N
    force = result.contact_forces[0]
    assert force[2] > 0.01
    assert set(pressed_obstacles(result, scene.problem)) == {0}
    (line,) = contact_lines(scene, result)
    assert line.startswith("contact obstacles[0] table: total force")
