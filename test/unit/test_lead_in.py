"""A mesh switch's lead-in (dlo_ros/solver/auto/lead_in.py).

The stream's switch to a new element mesh starts from the new mesh's own equilibrium of the update
before, solved on it as the check built it, instead of the streaming shape mapped onto it.  The
independent answer at each switch is a fixed model on the same mesh streamed along the same
targets from auto's cold answer (mapped onto that mesh; the fixed model's own cold solve lands
on another branch at three of the four switches): the switch update must be that equilibrium
(the same branch, to Newton's tolerance), reached by an ordinary warm update (Newton, a few
steps: mapped, the #37 table stream's switches took 10–34 steps).  With background checks, each
check started late (the stream commits later shapes meanwhile, as on a loaded machine), the stream
is the same: on a3a0339 the mesh check surveyed the contact rows of the stream's latest shape
instead of the checked one, and chose other meshes from update 81 on (0.58 mm apart).  The bookkeeping (which updates it follows, what ends it) is tested on a
fake solver.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver, make_solver
from dlo_ros.solver.auto import reduced
from dlo_ros.solver.auto.lead_in import FOLLOW, STRIDE, LeadIn
from test_auto_determinism import slow_worker  # noqa: F401 - a fixture
from test_director_stream import path

UPDATES = 170  # the table stream's first mesh switches (4, from update 81 on)
SAME = 1e-8  # m: one equilibrium, to Newton's tolerance


def table_stream():
    """#37's table stream (bench/perf/auto_vs_full.py path3d_stream): both grips 0.32 m lower."""
    scene = load_scene("default_cable")
    down = np.array([0.0, 0.0, 0.32])
    p = scene.problem.with_grip_poses(
        {g.name: GripPose(g.pose.position - down, g.pose.orientation) for g in scene.problem.grips}
    )
    start = p.grip("right").pose.position
    targets = [{"right": GripPose(*path(k, start))} for k in range(1, UPDATES + 1)]
    return replace(scene, problem=p), targets


@pytest.fixture(scope="module", autouse=True)
def rows_only():
    """auto's element models without their contact slots: the table's touch then held at mesh
    nodes, whose stream switches mesh as the touch slides (updates 81, 127, 147, 167; with the
    slots it keeps one mesh: test_table_touch.py), the switches a lead-in is for."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(reduced, "AUTO_OBSTACLE_SLOTS", 0)
        yield


def run(checks: str):
    """Stream auto; (results, per update the fixed model it solved on: its solver's arguments)."""
    scene, targets = table_stream()
    auto = make_solver(
        scene.problem, replace(scene.options, model="auto"), compile="off", checks=checks
    )
    try:
        assert auto.solve().ok
        # the cold answer, which the fixed references start from (their own cold solves land
        # on other branches: the cable 0.69 m away at three of the four switches)
        models = [(auto.inner, auto.inner.snapshot())]
        results = []
        for poses in targets:
            results.append(auto.solve(poses))
            models.append(
                (
                    auto.reduced.reduce(auto.choice, scene.problem)[0],
                    auto.inner.options,
                    dict(mesh=auto.inner.mesh_spec, reference_frame=auto.choice.reference_frame()),
                )
            )
    finally:
        auto.close()
    return scene, targets, results, models[1:], models[0]


@pytest.fixture(scope="module")
def inline():
    return run("sync")


def switches(results) -> list[int]:
    return [k for k, r in enumerate(results) if any("mesh of" in c for c in r.model.changed)]


def test_a_mesh_switch_starts_from_the_new_meshs_own_equilibrium(inline):
    scene, targets, results, models, start = inline
    assert all(r.ok for r in results), [r.message for r in results if not r.ok]
    at = switches(results)
    assert len(at) >= 2, [r.model.changed for r in results if r.model.changed]
    for k in at:
        r = results[k]
        assert r.ipopt_status == "Newton" and r.iterations <= 4, (k, r.ipopt_status, r.iterations)
        reduced, options, kw = models[k]
        fixed = ShapeSolver(reduced, options, compile="off", **kw)
        assert fixed.adopt_warm_start(*start)
        for poses in targets[: k + 1]:
            ref = fixed.solve(poses)
            assert ref.ok, ref.message
        dev = float(np.max(np.linalg.norm(r.points - ref.points, axis=1)))
        assert dev <= SAME, (k, dev)


def test_background_checks_lead_in_the_same_stream(inline, slow_worker):
    _, _, results, _, _ = inline
    _, _, background, _, _ = run("background")
    assert switches(background) == switches(results)
    for k, (a, b) in enumerate(zip(results, background)):
        assert a.status == b.status, k
        assert float(np.max(np.linalg.norm(a.points - b.points, axis=1))) <= 1e-9, k


@dataclass
class FakeResult:
    status: str


class FakeSolver:
    """Solves to the statuses it is given, in order; records the updates' poses it saw."""

    has_warm_start = True

    def __init__(self, statuses=()):
        self.statuses, self.seen = list(statuses), []

    def solve(self, poses, checked, limited):
        assert checked and limited  # a streamed update's solve, under the update time limit
        self.seen.append(poses["u"])
        return FakeResult(self.statuses.pop(0) if self.statuses else "ok")


K, LAST = 8, 27  # the checked update, and the last before the switch


@dataclass
class FakeChoice:
    mesh: tuple

    def key(self):
        return ("the same physics", self.mesh)


@dataclass
class FakeSnapshot:
    choice: FakeChoice
    update: int
    poses: dict
    generation: int


@dataclass
class FakeVerdict:
    snapshot: FakeSnapshot
    choice: FakeChoice | None


@dataclass
class FakePool:
    solver: FakeSolver

    def pooled(self, choice):
        return self.solver


def begun(solver, generation=3) -> LeadIn:
    """A lead-in begun on a check of update K whose verdict names another mesh, built."""
    lead = LeadIn(K, LAST, generation)
    snap = FakeSnapshot(FakeChoice((1,)), K, {"u": K}, generation)
    lead.begin(FakePool(solver), FakeVerdict(snap, FakeChoice((2,))))  # type: ignore[arg-type]
    return lead


def test_it_begins_on_a_change_of_mesh_alone():
    snap = FakeSnapshot(FakeChoice((1,)), K, {"u": K}, 3)
    for choice in (None, FakeChoice((1,))):  # the model kept; the same mesh
        lead = LeadIn(K, LAST, 3)
        lead.begin(FakePool(FakeSolver()), FakeVerdict(snap, choice))  # type: ignore[arg-type]
        assert lead.solver is None
    other_physics = FakeChoice((2,))
    other_physics.key = lambda: ("3D", (2,))  # type: ignore[method-assign]
    lead = LeadIn(K, LAST, 3)
    lead.begin(FakePool(FakeSolver()), FakeVerdict(snap, other_physics))  # type: ignore[arg-type]
    assert lead.solver is None
    solver = FakeSolver()
    assert begun(solver).solver is solver and solver.seen == [K]


def test_it_follows_every_strideth_update_and_the_last_before_the_switch():
    solver = FakeSolver()
    lead = begun(solver)
    for u in range(K + 1, LAST + 1):
        assert lead.ready(u + 1) is None
        lead.step(u, {"u": u}, 3)
    strided = list(range(K, LAST + 1 - FOLLOW, STRIDE))
    assert solver.seen == strided + list(range(LAST + 1 - FOLLOW, LAST + 1))
    assert lead.ready(LAST + 1) is solver  # holds update LAST's equilibrium: the switch's start
    lead.step(LAST + 1, {"u": LAST + 1}, 3)  # past the switch: nothing
    assert solver.seen[-1] == LAST and lead.ready(LAST + 1) is solver


def test_a_solve_that_is_not_ok_ends_it():
    lead = begun(FakeSolver(["ok", "ok", "failed"]))
    for u in range(K + 1, LAST + 1):
        lead.step(u, {"u": u}, 3)
    assert lead.ready(LAST + 1) is None and "failed" in lead.failed


def test_a_later_generation_or_a_missed_update_ends_it():
    lead = begun(FakeSolver())
    lead.step(K + STRIDE, {"u": 0}, 4)  # the stream switched meanwhile: the verdict is stale
    assert lead.ready(LAST + 1) is None
    lead = begun(FakeSolver())
    for u in [K + STRIDE] + list(range(K + 3 * STRIDE, LAST + 1)):  # K + 2·STRIDE never came
        lead.step(u, {"u": u}, 3)
    assert lead.ready(LAST + 1) is None and "out of order" in lead.failed
