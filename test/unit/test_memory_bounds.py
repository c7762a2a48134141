"""Unit tests (no ROS graph) of what the node's solver holder keeps alive (issue #35: node memory
flat after warm-up): live parameter changes, rebuilds for new options and model switches of
``auto`` must not leave solvers behind.

Counts are of live objects (``gc.get_objects`` by exact type after ``gc.collect``), less those
alive before the test (other tests in the same worker process may keep some), an independent
measure of what is kept: a ShapeSolver owns its NLP's CasADi functions and IPOPT instances,
whose memory tracemalloc cannot see.  Interpreted derivatives (``compile='off'``): nothing here
depends on gcc.
"""
from __future__ import annotations

import gc
import time
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from dlo_ros.model import GripPose
from dlo_ros.node import params as P
from dlo_ros.node.engine import ShapeEngine, build_solver, options_with_output_points
from dlo_ros.scene import load_scene
from dlo_ros.solver.auto import ORDERS, AutoShapeSolver
from dlo_ros.solver.shape_solver import ShapeSolver


def live(kind: type) -> int:
    """Objects of exactly ``kind`` still reachable (after a full collection)."""
    gc.collect()
    return sum(1 for o in gc.get_objects() if type(o) is kind)


@pytest.fixture
def baseline():
    """live() of each kind before the test builds anything: what other tests left reachable."""
    return {kind: live(kind) for kind in (ShapeSolver, ca.Function, AutoShapeSolver)}


@pytest.fixture
def engine(baseline):
    scene = load_scene("default_cable")
    failures = []
    eng = ShapeEngine(scene.problem, scene.options,
                      make_solver=lambda p, o: build_solver(p, o, "off"), on_update=lambda u: None,
                      on_failure=lambda kind, msg, u: failures.append((kind, msg)))
    eng.start()
    deadline = time.monotonic() + 120.0
    while not eng.ready and time.monotonic() < deadline:
        time.sleep(0.05)
    assert eng.ready, eng.state
    yield eng, scene
    eng.stop()
    assert failures == []


def bend(value: float):
    """The node's edit for a live ``string.bend_stiffness`` change (its _after_set_parameters)."""
    values = {"string.bend_stiffness": value}
    return lambda problem: replace(problem, string=P.apply_string(problem.string, values))


def stream(eng: ShapeEngine, scene, n: int, phase: float) -> None:
    """n targets of the right grip on a small 3D loop (out of the plane: the 3D model streams)."""
    right = scene.problem.grips[1]
    for k in range(n):
        a = phase + 0.3 * k
        step = 0.03 * np.array([np.cos(a) - 1, np.sin(a), 0.5 * np.sin(a)])
        target = GripPose(right.pose.position + step, right.pose.orientation)
        eng.submit_targets({right.name: target})
        time.sleep(0.01)


def test_parameter_changes_keep_the_solvers_flat(engine, baseline):
    """Each bend-stiffness change re-solves with the same models (values are NLP parameters): after
    the first change the live ShapeSolvers and CasADi functions do not grow, and stay within auto's
    pool."""
    eng, scene = engine
    seen = []
    for i in range(6):
        stream(eng, scene, 10, i)
        result = eng.change_problem(bend(0.025 if i % 2 == 0 else 0.02)).result(120.0)
        assert result is not None and result.ok, result
        # the re-solve was for the changed stiffness
        stiffness = eng._solver.problem.string.bend_stiffness.maximum
        assert stiffness == pytest.approx(0.025 if i % 2 == 0 else 0.02)
        seen.append((live(ShapeSolver) - baseline[ShapeSolver], live(ca.Function) - baseline[ca.Function]))
    assert all(n <= AutoShapeSolver.POOL_SIZE for n, _ in seen), seen
    # flat after the warm-up (the first change may build a check's models)
    assert seen[-1] == seen[1], seen


def test_option_rebuilds_release_the_old_solver(engine, baseline):
    """A rebuild for new options (output_points) closes and drops the old auto solver, its pool
    too."""
    eng, _ = engine
    counts = []
    for n in (41, 61, 41, 61):
        edit = lambda o, n=n: options_with_output_points(o, n)  # noqa: E731
        result = eng.change_options(edit).result(120.0)
        assert result is not None and result.ok, result
        assert len(result.points) == n
        counts.append((live(AutoShapeSolver) - baseline[AutoShapeSolver],
                       live(ShapeSolver) - baseline[ShapeSolver]))
    assert all(autos == 1 for autos, _ in counts), counts
    assert counts[-1][1] == counts[0][1], counts


def test_model_switches_stay_within_the_pool(baseline):
    """Switching auto's stream over ten models twice keeps at most POOL_SIZE models: the replaced
    ones are freed, not just forgotten by the pool."""
    scene = load_scene("default_cable")
    solver = AutoShapeSolver(scene.problem, scene.options, compile="off", checks="sync")
    assert solver.solve().ok
    base = replace(solver.choice, planar=False, reasons=[])
    for _ in range(2):
        for order in ORDERS:
            for samples in (41, 81):
                solver.switch(replace(base, order=order, samples=samples, reasons=[]), "test")
        assert len(solver.pool) <= AutoShapeSolver.POOL_SIZE
        assert live(ShapeSolver) - baseline[ShapeSolver] <= AutoShapeSolver.POOL_SIZE
    solver.close()


def test_the_models_matrix_memo_is_bounded_in_bytes():
    """A model's memo of matrices per arc-length array (``model.memo.ArrayMemo``) keeps the least
    recently used out once its bytes pass the limit: a stream that asks at a new residual grid at
    every check held 5 GB of them under a bound of 256 entries."""
    from dlo_ros.model.memo import ArrayMemo

    memo: ArrayMemo[np.ndarray] = ArrayMemo(limit=10 * 8000)
    made = []

    def make(s):
        made.append(s[0])
        return np.zeros(1000)  # 8,000 bytes

    for k in range(30):
        memo.get("W", np.array([float(k)]), make)
        memo.get("W", np.array([0.0]), make)  # used at every step: stays
        assert memo.nbytes <= memo.limit
    assert made.count(0.0) == 1 and len(made) == 30
    memo.get("W", np.array([1.0]), make)  # long gone: made again
    assert made[-1] == 1.0 and len(made) == 31
    memo.get("B", np.array([0.0]), make)  # another kind at the same s: its own entry
    assert len(made) == 32
    big = memo.get("W", np.array([99.0]), lambda s: np.zeros(20_000))  # over the limit: not kept
    assert big.size == 20_000 and memo.nbytes <= memo.limit


def test_a_memo_entry_cannot_be_written_into():
    """Every caller shares a memo's entries: one written into in place would change what the next
    caller reads.  Entries (arrays, and the arrays of a tuple) are read-only."""
    from dlo_ros.model.memo import ArrayMemo

    memo: ArrayMemo[tuple[np.ndarray, np.ndarray]] = ArrayMemo()
    b, w = memo.get("BW", np.array([0.5]), lambda s: (np.ones((1, 3)), np.ones(1)))
    for a in (b, w):
        with pytest.raises(ValueError, match="read-only"):
            a *= 2.0
    assert memo.get("BW", np.array([0.5]), lambda s: (np.zeros((1, 3)), np.zeros(1)))[0][0, 0] == 1.0
