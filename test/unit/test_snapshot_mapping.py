"""A snapshot maps onto another model the same whatever its solver did since.

A check on the worker thread maps the snapshot of a streamed update (its ``SolverState``) onto
the models it measures with (``update/warm_start.sample_source``), while the stream goes on
committing later updates on the same solver.  The mapping must read the snapshot only: its
state and the parameters it was solved at, never the solver's current scene.  A twist-free model
(tangent grips: no roll is held) carries its frames from the first held grip; the grip's
commanded roll changes no shape, only those frames.  On 2d9a8b9 the frames were carried from the
grip's *current* target, so a late check mapped another start than an inline one.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver
from dlo_ros.solver.update.warm_start import sample_source
from support.problems import clamped_pair

ROLL = 0.7  # rad: the left grip turned about its own tangent


def rolled(q: np.ndarray, angle: float) -> np.ndarray:
    """Quaternion (x, y, z, w) ``q`` turned by ``angle`` about its own x axis (the tangent)."""
    half = 0.5 * angle
    x, y, z, w = q
    rx, rw = np.sin(half), np.cos(half)  # q · (rx, 0, 0, rw)
    return np.array([w * rx + x * rw, y * rw + z * rx, z * rw - y * rx, w * rw - x * rx])


@pytest.mark.parametrize("rotation", ["director", "euler"])
def test_a_snapshot_maps_the_same_after_its_solver_moved_on(rotation):
    problem = clamped_pair(right=(0.7, 0.1, 0.05), modes=("tangent", "tangent"))
    # (the Euler basis at order 16 left a residual of 1.2 mm on this shape)
    options = SolverOptions(
        model="full", rotation=rotation, order=16 if rotation == "director" else 24
    )
    solver = ShapeSolver(problem, options, compile="off")
    assert solver.solve().ok
    assert not solver.model.layout.twist  # the roll is not solved: carried from the grip
    snapshot = solver.snapshot()
    # a director model on elements: it takes the source's frames (``SourceShape.frames``)
    target = ShapeSolver(
        problem, replace(options, rotation="director", order=20), compile="off"
    ).nlp
    before = sample_source(solver, snapshot, target)
    left = problem.grip("left").pose
    moved = solver.solve(
        {
            "left": GripPose(left.position, rolled(left.orientation, ROLL)),
            "right": GripPose(
                np.array([0.68, 0.12, 0.04]), problem.grip("right").pose.orientation
            ),
        }
    )
    assert moved.ok, moved.message
    after = sample_source(solver, snapshot, target)
    for name in ("frames", "eps", "fields"):
        a, b = getattr(before, name), getattr(after, name)
        if isinstance(a, dict):
            for key in a:
                np.testing.assert_allclose(b[key], a[key], atol=1e-12, err_msg=key)
        elif a is not None:
            np.testing.assert_allclose(b, a, atol=1e-12, err_msg=name)
