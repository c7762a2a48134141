"""When a streamed check's verdict takes effect (``solver/auto/check_schedule.py``), without a solver.

A verdict that keeps the model takes effect CHECK_LAG updates after the update it checked; one
that switches models BUILD_LAG updates later still, so that the worker builds the model beside the
stream.  The decision is known before the build: the stream waits for the decision alone at
CHECK_LAG.  A check that raises before it has decided must not leave the stream waiting forever.
The stream-level consequences (the same switches at the same updates in both modes) are in
test_auto_determinism.py.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import pytest

from dlo_ros.solver.auto import check_schedule as cs
from dlo_ros.solver.auto.choice import ModelChoice
from dlo_ros.solver.build.mesh import MeshSpec

K = 7  # the update whose shape is checked


@dataclass
class FakeSnap:
    update: int = K
    generation: int = 0


@dataclass
class FakeVerdict:
    snapshot: FakeSnap = field(default_factory=FakeSnap)
    choice: object | None = None


def held(verdict) -> cs.PendingCheck:
    return cs.PendingCheck(K + cs.CHECK_LAG, verdict=verdict)


def first_due(pending: cs.PendingCheck, generation: int = 0) -> int:
    """The first update (from K on) at which ``pending`` takes effect."""
    for update in range(K, K + 100):
        if cs.due(pending, update, generation):
            return update
    raise AssertionError("never due")


def test_a_kept_model_takes_effect_check_lag_updates_later():
    assert first_due(held(FakeVerdict())) == K + cs.CHECK_LAG


def test_a_switch_takes_effect_build_lag_updates_later_still():
    assert cs.BUILD_LAG > 0
    assert first_due(held(FakeVerdict(choice="richer"))) == K + cs.CHECK_LAG + cs.BUILD_LAG


def test_a_stale_switch_is_dropped_when_read():
    """A switch about a model the stream has left (generation moved on) is not held longer."""
    pending = held(FakeVerdict(choice="richer"))
    assert first_due(pending, generation=1) == K + cs.CHECK_LAG
    assert not pending.switching


class FakeChecks:
    """``model_checks.evaluate``: decides, then 'builds' until released."""

    def __init__(self, choice, fail_before_deciding=False):
        self.choice, self.fail = choice, fail_before_deciding
        self.build = threading.Event()

    def evaluate(self, snap, prepare, decided=None):
        if self.fail:
            raise RuntimeError("check failed")
        verdict = FakeVerdict(snap, self.choice)
        decided.set_result(verdict)
        assert self.build.wait(10)  # the build runs until the test lets it finish
        return verdict


class FakeWorker:
    def __init__(self):
        self.pool = ThreadPoolExecutor(1)
        self.background = True

    def submit(self, fn, keys, *args) -> Future:
        return self.pool.submit(fn, *args)


@dataclass
class FakeChoice:
    order: int = 12
    plane_kept: bool = True
    may_leave_plane: bool = False  # no 3D model checks it

    def key(self):
        return (self.order,)


class FakePool:
    def pooled(self, choice):  # no model built: a switch's lead-in (lead_in.py) does not begin
        return None


@dataclass
class FakeAuto:
    model_checks: FakeChecks
    worker: FakeWorker = field(default_factory=FakeWorker)
    pool: FakePool = field(default_factory=FakePool)


def started(checks: FakeChecks) -> cs.PendingCheck:
    snap = FakeSnap()
    snap.choice = FakeChoice()  # type: ignore[attr-defined]  # what start_check reads of it
    return cs.start_check(FakeAuto(checks), snap)  # type: ignore[arg-type]


def test_the_decision_is_read_before_the_build_has_finished():
    checks = FakeChecks(choice="richer")
    pending = started(checks)
    try:
        # due at CHECK_LAG reads the decision while the build still runs: held, not waited for
        assert not cs.due(pending, K + cs.CHECK_LAG, 0)
        assert pending.switching and not pending.job.done()
    finally:
        checks.build.set()
    assert pending.outcome().choice == "richer"
    assert cs.due(pending, K + cs.CHECK_LAG + cs.BUILD_LAG, 0)


def test_a_check_that_fails_before_deciding_raises_in_the_stream():
    pending = started(FakeChecks(choice=None, fail_before_deciding=True))
    with pytest.raises(RuntimeError, match="check failed"):
        cs.due(pending, K + cs.CHECK_LAG, 0)


# ---- held_refinement: the finer mesh a held verdict carries into a switch of physics ----------
def planar_choice(mesh=None):
    return ModelChoice(True, False, False, True, 12, (0,), mesh=mesh)


def refining(estimate: float, generation: int = 0, **changes):
    """A held verdict: the planar choice on a 2-element mesh (``changes`` on top), ``estimate``."""
    finer = replace(planar_choice(MeshSpec((0.5,), (8, 8))), **changes)
    verdict = FakeVerdict(FakeSnap(generation=generation), finer)
    verdict.estimate = estimate
    return held(verdict), finer.mesh


TOL = 1e-3


def test_a_held_refinement_is_carried():
    pending, mesh = refining(0.6 * TOL)
    assert cs.held_refinement(pending, planar_choice(), 0, TOL, wait=True) == mesh


@pytest.mark.parametrize(
    "case",
    ["coarsening", "stale", "other physics", "nothing held", "keeps the model"],
)
def test_no_refinement_is_carried(case):
    pending, _ = {
        "coarsening": lambda: refining(0.01 * TOL),  # the estimate says the mesh is fine
        "stale": lambda: refining(0.6 * TOL, generation=1),
        "other physics": lambda: refining(0.6 * TOL, order=16),
        "nothing held": lambda: (None, None),
        "keeps the model": lambda: (held(FakeVerdict()), None),
    }[case]()
    assert cs.held_refinement(pending, planar_choice(), 0, TOL, wait=True) is None


def test_an_undecided_background_check_is_waited_for_only_when_asked():
    pending, mesh = refining(0.6 * TOL)
    undecided: Future = Future()
    background = cs.PendingCheck(K + cs.CHECK_LAG, decided=undecided)
    assert cs.held_refinement(background, planar_choice(), 0, TOL, wait=False) is None
    undecided.set_result(pending.verdict)
    assert cs.held_refinement(background, planar_choice(), 0, TOL, wait=True) == mesh


def test_a_check_that_raised_carries_nothing():
    failed = cs.PendingCheck(K + cs.CHECK_LAG, error=RuntimeError("boom"))
    assert cs.held_refinement(failed, planar_choice(), 0, TOL, wait=True) is None
