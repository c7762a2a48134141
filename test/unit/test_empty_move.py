"""A refused or unsettled warm update is solved again in substeps of its move
(``update/substeps.in_substeps``); with no move (the same grip poses as the committed scene: a
refinement pass of a cold solve, a re-solve at the held target) each substep would be the
refused solve again from the same start, so none is made and the refusal stands as it was.

Measured before: the main job's post cold at δ = 1e-4 m re-solved two refinement passes at the
same poses in three substeps each, every one unsettled as the pass itself (4 s each time).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.results.result import ShapeResult
from dlo_ros.solver.update.substeps import in_substeps, moves

SCENE = load_scene("default_cable")


def test_a_move_is_any_grip_pose_that_differs():
    problem = SCENE.problem
    right = problem.grip("right").pose
    assert not moves(problem, problem)
    near = GripPose(right.position + 1e-12, right.orientation)
    nudged = problem.with_grip_poses({"right": near})
    assert moves(problem, nudged)
    q = right.orientation + np.array([1e-9, 0.0, 0.0, 0.0])
    turned = problem.with_grip_poses({"right": GripPose(right.position, q / np.linalg.norm(q))})
    assert moves(problem, turned)


def substeps_of(target_offset: np.ndarray) -> tuple[ShapeResult, list]:
    """in_substeps of an update refused at the held scene + offset; the substeps solved."""
    solver = ShapeSolver(SCENE.problem, replace(SCENE.options, model="full"), compile="off")
    assert solver.solve().ok
    ctx = solver.update_context()
    right = ctx.scene.grip("right").pose
    problem = ctx.scene.with_grip_poses(
        {"right": GripPose(right.position + target_offset, right.orientation)}
    )
    refused = ShapeResult(status="failed", message="topology: a made-up refusal")
    solved = []

    def solve(ctx, step, warm):
        solved.append(step)
        return ShapeResult(status="failed", message="topology: again"), None

    result, state = in_substeps(ctx, problem, refused, solve, solver._turn_tracker)
    assert state is None
    return result, solved


def test_no_move_no_substeps():
    result, solved = substeps_of(np.zeros(3))
    assert solved == []
    assert result.message == "topology: a made-up refusal"


def test_a_move_is_split_until_the_finest_substep():
    result, solved = substeps_of(np.array([0.0, 0.0, 0.01]))
    # halves (the first fails), then quarters from the start down to eighths
    assert len(solved) == 3, len(solved)
    assert "in substeps" in result.message
