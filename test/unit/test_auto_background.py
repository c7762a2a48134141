"""solver.model: auto with checks on a worker thread (what the node streams with): the stream never
builds a model on its own thread once the checks have run, the background verdicts reach the same model
as the synchronous checks, and a switch keeps the warm start (Newton steps, not a cold solve)."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from dlo_ros.solver import AutoShapeSolver, ShapeSolver, SolverOptions, make_solver
from dlo_ros.solver import shape_solver as shape_solver_module
from support.problems import clamped_pair


def hanging(**kw):
    args = dict(left=(0, 0, 0.4), right=(0.6, 0, 0.4), bend=0.02, twist=0.015, weight=0.5)
    return clamped_pair(**{**args, **kw})


@pytest.fixture
def builds(monkeypatch):
    """Names of the threads on which ShapeSolvers were built, in order."""
    names: list[str] = []
    original = ShapeSolver.__init__

    def recording_init(self, *args, **kwargs):
        names.append(threading.current_thread().name)
        original(self, *args, **kwargs)

    monkeypatch.setattr(shape_solver_module.ShapeSolver, "__init__", recording_init)
    return names


def in_plane_move(problem, i, dx=0.0005):
    """The right grip's i-th target of a small move in the plane (y = 0)."""
    right = problem.grip("right").pose
    return {"right": (right.position + np.array([0.0, 0.0, dx * np.sin(i / 10)]), right.orientation)}


def stream_until_checked(solver, problem, steps=400):
    """Stream small moves in the plane (y = 0) until the current model's check has run."""
    r = None
    for i in range(steps):
        r = solver.solve(in_plane_move(problem, i))
        assert r.ok, r.message
        if r.model.checked and not solver.checks_pending:
            return r
        time.sleep(0.01)
    raise AssertionError(f"checks did not finish in {steps} updates: {r.model}")


def stream_fixed(solver, problem, steps=40):
    """``steps`` small moves in the plane (y = 0); returns the last result."""
    r = None
    for i in range(steps):
        r = solver.solve(in_plane_move(problem, i))
        assert r.ok, r.message
    return r


def test_background_checks_reach_the_synchronous_choice_without_building_on_the_stream(builds):
    """The same stream with background and inline checks: the same model changes at the same
    updates (#37: check_schedule.py), the same last shape, and with background checks no model
    built on the stream's thread after the (checked) cold solve."""
    problem = hanging()
    options = SolverOptions(output_points=51, error_tolerance=0.05)  # loose: the stream coarsens
    results = {}
    for checks in ("sync", "background"):
        solver = make_solver(problem, options, compile="off", checks=checks)
        try:
            first = solver.solve()
            assert first.ok and first.model.checked and first.model.checks == checks
            n_first = len(builds)
            results[checks] = (stream_fixed(solver, problem), builds[n_first:])
        finally:
            solver.close()
    (r_sync, _), (r, stream_builds) = results["sync"], results["background"]
    assert r.model.changes_at == r_sync.model.changes_at and r.model.changes == r_sync.model.changes
    assert any("mesh of" in c for c in r.model.changes), r.model.changes  # coarsened
    assert (r.model.planar, r.model.variables) == (r_sync.model.planar, r_sync.model.variables)
    assert np.max(np.abs(r.points - r_sync.points)) < 1e-9
    assert r.model.estimated_error_m <= 0.05 / 2
    assert stream_builds and all(name.startswith("dlo-auto-check") for name in stream_builds), (
        stream_builds
    )


def test_targets_leaving_the_plane_switch_to_the_prebuilt_3d_model(builds):
    problem = hanging()
    solver = make_solver(problem, SolverOptions(output_points=51), compile="off", checks="background")
    try:
        solver.solve()
        r = stream_until_checked(solver, problem)
        assert r.model.planar
        main = threading.current_thread().name
        before = builds.count(main)
        q = problem.grip("right").pose.orientation
        moved = solver.solve({"right": (np.array([0.6, 0.02, 0.4]), q)})
        assert moved.ok and not moved.model.planar
        assert any("left the plane" in c for c in moved.model.changed), moved.model
        assert builds.count(main) == before, "the 3D model was built on the streaming thread"
        assert moved.warm_started and moved.iterations <= 10, (moved.message, moved.iterations)
        full = ShapeSolver(problem, SolverOptions(model="full", order=24, output_points=51), compile="off")
        ref = full.solve({"right": (np.array([0.6, 0.02, 0.4]), q)})
        assert np.max(np.linalg.norm(moved.points - ref.points, axis=1)) < 1e-3
    finally:
        solver.close()


def test_background_checks_keep_ipopt_calls_serialised():
    """The worker's IPOPT calls and the stream's hold one process-wide lock (MUMPS is not thread-safe)."""
    assert isinstance(shape_solver_module.IPOPT_LOCK, type(threading.Lock()))
    problem = hanging()
    solver = make_solver(problem, SolverOptions(output_points=51), compile="off", checks="background")
    assert isinstance(solver, AutoShapeSolver)
    try:
        for i in range(30):  # cold solves take IPOPT on the stream while the worker checks
            r = solver.solve({"right": (np.array([0.6 - 0.005 * i, 0.0, 0.4]), problem.grip("right").pose.orientation)},
                             warm=(i % 3 != 0))
            assert r.ok, r.message
    finally:
        solver.close()


def test_reset_makes_the_next_solve_cold_in_every_pooled_model():
    """After reset, a pending switch must not bring back an older warm start from the pool."""
    problem = hanging()
    solver = make_solver(problem, SolverOptions(output_points=51), compile="off", checks="background")
    try:
        solver.solve()
        stream_until_checked(solver, problem)
        solver.reset()
        q = problem.grip("right").pose.orientation
        r = solver.solve({"right": (np.array([0.6, 0.02, 0.4]), q)})  # leaves the plane: a pooled 3D model
        assert r.ok and not r.model.planar and not r.warm_started, (r.message, r.model)
    finally:
        solver.close()


def test_after_close_the_solver_keeps_answering_with_inline_checks():
    problem = hanging()
    solver = make_solver(problem, SolverOptions(output_points=51), compile="off", checks="background")
    solver.solve()
    solver.close()
    r = solver.solve({"right": (np.array([0.58, 0.0, 0.4]), problem.grip("right").pose.orientation)})
    assert r.ok and r.model.checks == "sync" and r.model.checked, r.model


def test_background_checks_lower_the_gil_switch_interval_and_never_raise_it():
    """The stream thread waits for the GIL while the check worker runs Python, up to the switch interval:
    background checks lower it (5 ms by default) to SWITCH_INTERVAL_S; sync checks leave it alone, and a
    lower interval set by the application is kept."""
    import sys

    from dlo_ros.solver.auto import SWITCH_INTERVAL_S

    before = sys.getswitchinterval()
    try:
        sys.setswitchinterval(0.005)
        make_solver(hanging(), SolverOptions(), compile="off", checks="sync")
        assert sys.getswitchinterval() == pytest.approx(0.005)
        solver = make_solver(hanging(), SolverOptions(), compile="off", checks="background")
        assert sys.getswitchinterval() == pytest.approx(SWITCH_INTERVAL_S)
        solver.close()
        sys.setswitchinterval(SWITCH_INTERVAL_S / 2)
        make_solver(hanging(), SolverOptions(), compile="off", checks="background").close()
        assert sys.getswitchinterval() == pytest.approx(SWITCH_INTERVAL_S / 2)
    finally:
        sys.setswitchinterval(before)


def test_the_models_kept_are_capped_and_the_evicted_ones_freed(monkeypatch):
    """Memory (#13): auto keeps at most POOL_SIZE built models, whatever a long session goes through, and
    the ones it drops are freed (no reference left anywhere).  Counted by instrumentation: weak
    references to every ShapeSolver built, alive after a garbage collection."""
    import gc
    import weakref
    from dataclasses import replace

    from dlo_ros.model import Obstacle, Profile

    built: list[weakref.ref] = []
    original = ShapeSolver.__init__

    def recording_init(self, *args, **kwargs):
        built.append(weakref.ref(self))
        original(self, *args, **kwargs)

    monkeypatch.setattr(shape_solver_module.ShapeSolver, "__init__", recording_init)
    base = hanging()
    table = Obstacle("halfspace", np.array([0.0, 0.0, 0.25, 0.0, 0.0, 1.0]), "table")  # within reach of the sag
    variants = [base, replace(base, string=replace(base.string, weight_per_length=Profile.constant(0.0))),
                replace(base, obstacles=(table,))]
    solver = make_solver(base, SolverOptions(output_points=21), compile="off", checks="background")
    try:
        q = base.grip("right").pose.orientation
        for round_ in range(2):
            for problem in variants:
                solver.set_problem(problem)
                for y in (0.0, 0.03, 0.0):  # in the plane, out of it (3D), and back
                    r = solver.solve({"right": (np.array([0.55, y, 0.4]), q)})
                    # order 12 on the table is just over the tolerance (unverified, honest) until a check
                    # raises it; a warm IPOPT answer on a folded field (residual of metres) was seen here
                    assert r.ok or r.status == "unverified" and r.equilibrium_residual_m < 0.01, r.message
                stream_until_checked(solver, problem, steps=3000)  # 3D checks with an obstacle take seconds
        gc.collect()
        alive = [w for w in built if w() is not None]
        assert len(built) > AutoShapeSolver.POOL_SIZE, "the session did not build enough models to test the cap"
        print("MODELS", len(alive), len(built))
        assert len(alive) <= AutoShapeSolver.POOL_SIZE, (len(alive), len(built))
    finally:
        solver.close()


def test_a_refined_planar_mesh_comes_with_its_3d_model_built(builds):
    """The check that refines a planar mesh also builds that mesh's 3D model (checks.py).

    The main job's stream refines its planar mesh a few updates before the clamps twist it out of
    the plane: the new model's first check (the 3D eigenvalue at the planar shape) and the switch
    to 3D both need the new mesh's 3D model.  Built after the refinement took effect, it held up
    the check due at update 98 by 0.27 s and the switch at 100 by 0.15 s.  Now it is pooled when
    the refined mesh takes effect, and the worker builds nothing more; nothing is built on the
    stream's thread.
    """
    from dlo_ros.node import demo
    from dlo_ros.scene import load_scene
    from dlo_ros.solver.auto.choice import full_choice

    problem = load_scene("default_cable").problem
    auto = make_solver(problem, SolverOptions(model="auto"), compile="off", checks="background")
    try:
        assert auto.solve().ok
        auto._wait_for_check()  # the start-up builds (a node that has been up a few seconds)
        start = len(builds)
        for i in range(1, 100):
            (pl, ql), (pr, qr) = demo.targets_at(i * 0.02)
            r = auto.solve({"left": (pl, ql), "right": (pr, qr)})
            assert r.ok, r.message
            if any("mesh of" in c for c in r.model.changed):
                break
        else:
            raise AssertionError("the planar mesh was not refined before the twist")
        assert auto.choice.planar
        assert auto.pool.pooled(full_choice(auto.choice, auto.problem)) is not None
        built = len(builds)
        auto._wait_for_check()  # the refined model's first check, and any build ahead
        assert len(builds) == built, "the refined model's check or a build ahead built a model"
        assert "MainThread" not in builds[start:]
    finally:
        auto.close()
