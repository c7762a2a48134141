"""One strike of ``solver.update_time_limit`` (solver/update/time_limit.py ``LimitStrikes``): the
streamed update after one the limit stopped is not limited, so a stream whose next shape needs more
than the limit answers at the next update instead of failing at every one.

Measured before: the main job starved of CPU (``taskset -c 0`` with two busy loops) failed eight
updates in a row after a switch to a finer mesh ("no answer within solver.update_time_limit (2 s)",
each starting the same IPOPT solve afresh) and held its last target 40 s without a checked shape.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.shape_solver import with_checked_poses
from dlo_ros.solver.update.time_limit import LimitStrikes

SCENE = load_scene("default_cable")
Q = (0.0, 0.0, 0.0, 1.0)


def targets(x: tuple) -> dict:
    return {"left": ((0.0, 0.0, 0.4), Q), "right": (x, Q)}


def test_the_solve_after_a_stop_is_not_limited_and_then_the_limit_is_back():
    strikes = LimitStrikes()
    first = strikes.deadline(10.0, 2.0, True)
    assert first == 12.0
    assert not strikes.stopped(None, "failed")  # an unlimited solve is never stopped by it
    assert not strikes.stopped(float("inf"), "failed")  # failed before its deadline
    assert not strikes.stopped(0.0, "ok")  # answered, however late
    assert strikes.deadline(20.0, 2.0, False) is None  # a query or a cold solve: never limited
    assert strikes.stopped(0.0, "failed") and strikes.struck
    assert strikes.deadline(30.0, 2.0, False) is None and strikes.struck  # queries keep the strike
    assert strikes.deadline(40.0, 2.0, True) is None and not strikes.struck  # the strike's solve
    assert strikes.deadline(50.0, 2.0, True) == 52.0  # limited again
    assert strikes.deadline(60.0, 0.0, True) is None  # a limit of 0: none


def test_a_stream_stopped_by_its_limit_answers_at_the_next_update():
    """A 1 ns limit: a jump that needs IPOPT fails, saying so; the same target again is answered
    (the cold solve's shape, to 1e-6 m); the same jump later is limited again."""
    options = replace(SCENE.options, model="full", update_time_limit=1e-9)
    solver = ShapeSolver(SCENE.problem, options, compile="off")
    assert solver.solve().ok
    for x in ((0.5, 0.0, 0.4), (0.35, 0.1, 0.3)):  # Newton: no IPOPT to stop
        assert solver.solve(targets(x)).ok
    far = (0.7, -0.1, 0.45)
    stopped = solver.solve(targets(far))
    assert stopped.status == "failed" and "update_time_limit" in stopped.message, stopped.message
    answered = solver.solve(targets(far))
    assert answered.status == "ok" and answered.stable, (answered.status, answered.message)
    cold = ShapeSolver(with_checked_poses(SCENE.problem, targets(far)), options, compile="off")
    reference = cold.solve()
    assert reference.ok
    assert np.max(np.linalg.norm(answered.points - reference.points, axis=1)) < 1e-6
    # back where the jump started (twice: a second strike's answer if the way back needs IPOPT
    # too), then the same jump: limited again
    for _ in range(2):
        back = solver.solve(targets((0.35, 0.1, 0.3)))
    assert back.ok, back.message
    again = solver.solve(targets(far))
    assert again.status == "failed" and "update_time_limit" in again.message, again.message
