"""Streaming on the new 3D model: 2,000 warm updates of ``default_cable`` along a closed 3D path of one
grip (translation, yaw, pitch and ±1.2 rad of twist) and back, hanging free and lying on the table.

Every update is ok (a verified equilibrium), the end of the stream matches a cold solve at the start
pose within 1e-6 m, and ``model: auto`` used from the library with its defaults builds no model on the
caller's thread (instrumented: every StringNLP construction records its thread).
"""
from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dlo_ros.scene import load_scene
from dlo_ros.solver.build import nlp as nlp_module
from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.shape_solver import ShapeSolver

UPDATES = 2000


def path(k: int, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The right grip's pose at update k of UPDATES: a closed loop that returns to ``start``."""
    u = 2 * np.pi * k / UPDATES
    position = start + np.array([-0.05 * np.sin(u), 0.08 * np.sin(u), 0.05 * (1 - np.cos(u))])
    turn = Rotation.from_euler("zyx", [0.3 * np.sin(u), 0.2 * np.sin(2 * u), 1.2 * np.sin(u)])
    return position, turn.as_quat()


def scene(on_table: bool):
    sc = load_scene("default_cable")
    if not on_table:
        return sc.problem
    lowered = {g.name: (g.pose.position - np.array([0.0, 0.0, 0.32]), g.pose.orientation) for g in sc.problem.grips}
    return sc.problem.with_grip_poses({name: type(sc.problem.grips[0].pose)(*pose) for name, pose in lowered.items()})


# hanging: ~10 s, left out of the whole suite's run (pytest.ini); auto streams the same path below
@pytest.mark.parametrize(
    "on_table", [pytest.param(False, marks=pytest.mark.slow), True], ids=["hanging", "on_table"]
)
def test_closed_3d_path_fixed_model(on_table):
    problem = scene(on_table)
    options = replace(load_scene("default_cable").options, model="full", order=16)
    solver = ShapeSolver(problem, options, compile="off")
    first = solver.solve()
    assert first.ok and first.stable, first.message
    start = problem.grip("right").pose.position
    touching = 0
    for k in range(1, UPDATES + 1):
        r = solver.solve({"right": path(k, start)})
        assert r.ok, (k, r.message)
        touching += bool(r.contact_forces and np.linalg.norm(r.contact_forces[0]) > 0)
    assert (touching > UPDATES // 2) == on_table, touching  # on the table it really lies on it
    cold = ShapeSolver(problem, options, compile="off").solve()
    assert cold.ok
    assert np.abs(r.points - cold.points).max() < 1e-6


def test_closed_3d_path_auto_builds_nothing_on_the_callers_thread(monkeypatch):
    builds: list[str] = []
    original = nlp_module.StringNLP.__init__

    def recording(self, *args, **kwargs):
        builds.append(threading.current_thread().name)
        original(self, *args, **kwargs)

    problem = scene(False)
    solver = make_solver(problem, load_scene("default_cable").options, compile="off")  # library defaults
    try:
        first = solver.solve()
        assert first.ok, first.message
        monkeypatch.setattr(nlp_module.StringNLP, "__init__", recording)
        start = problem.grip("right").pose.position
        caller = threading.current_thread().name
        statuses = set()
        for k in range(1, UPDATES + 1):
            r = solver.solve({"right": path(k, start)})
            statuses.add(r.status)
            assert r.status in ("ok", "unverified"), (k, r.message)
            assert r.ok or r.stable is None
        assert caller not in builds, builds
        assert not r.model.planar and r.model.rotation == "quaternion"
    finally:
        solver.close()
