"""How long a checked solve escalates (solver/auto/stream_checks.py, ``Escalations``): while its
estimate keeps falling, stopping after CHECK_NOW_STALL verdicts in a row without a new lowest
estimate (lower by CHECK_NOW_GAIN at least) or after CHECK_NOW_PASSES; a verdict without an
estimate (a change of physics or order) is no stall; a verdict without a new lowest that only
moves breakpoints (``moves_breakpoints``) ends it at once."""

from __future__ import annotations

import math
from dataclasses import replace

from dlo_ros.solver.auto.choice import ModelChoice
from dlo_ros.solver.auto.stream_checks import (
    CHECK_NOW_GAIN,
    CHECK_NOW_PASSES,
    CHECK_NOW_STALL,
    Escalations,
    moves_breakpoints,
)
from dlo_ros.solver.build.mesh import MeshSpec


def test_a_falling_estimate_escalates_until_the_pass_limit():
    budget = Escalations()
    spent = [budget.spent(0.8**k) for k in range(CHECK_NOW_PASSES + 1)]
    assert not any(spent[:-1]) and spent[-1]


def test_estimates_that_stop_falling_end_it_after_the_stall_limit():
    budget = Escalations()
    assert not budget.spent(1e-3) and not budget.spent(5e-4)
    stalls = [budget.spent(e) for e in [6e-4, 5e-4, 7e-4, 9e-4][:CHECK_NOW_STALL]]
    assert stalls == [False] * (CHECK_NOW_STALL - 1) + [True]


def test_a_new_lowest_estimate_resets_the_stall_count():
    budget = Escalations()
    budget.spent(1e-3)
    for _ in range(CHECK_NOW_STALL - 1):
        assert not budget.spent(2e-3)
    assert not budget.spent(9e-4)  # a new lowest: the count starts again
    for _ in range(CHECK_NOW_STALL - 1):
        assert not budget.spent(2e-3)
    assert budget.spent(2e-3)


def test_verdicts_without_an_estimate_are_no_stall():
    budget = Escalations()
    budget.spent(1e-3)
    assert not any(budget.spent(math.nan) for _ in range(2 * CHECK_NOW_STALL))


def test_estimates_that_barely_fall_end_it_after_the_stall_limit():
    """Fig. 3 at 1e-6 L at the unknowns cap: 6.22e-7, 6.17e-7, 6.16e-7 m ... each a new lowest by
    under 1 %: no progress."""
    budget = Escalations()
    assert not budget.spent(1e-6)
    barely = [1e-6 * (0.5 + 0.5 * CHECK_NOW_GAIN) ** (k + 1) for k in range(CHECK_NOW_STALL)]
    assert [budget.spent(e) for e in barely] == [False] * (CHECK_NOW_STALL - 1) + [True]


def test_a_move_of_breakpoints_without_a_new_lowest_ends_it_at_once():
    """Fig. 3 at 1e-6 L, ρ = 1000, at the unknowns cap: 6.32e-7, then 6.12e-7 m (3 % lower),
    whose verdict proposed the same 35 elements and 320 nodes again, breakpoints moved."""
    budget = Escalations()
    assert not budget.spent(1.27e-6) and not budget.spent(6.32e-7, moves_only=True)  # a gain
    assert budget.spent(6.12e-7, moves_only=True)
    other = Escalations()  # the same estimates with a proposal that adds nodes go on
    assert not other.spent(1.27e-6) and not other.spent(6.32e-7)
    assert not other.spent(6.12e-7)


def test_a_move_is_the_same_physics_elements_and_nodes_elsewhere():
    choice = ModelChoice(
        planar=True, twist=False, stretch=False, gravity=True, order=12, obstacles=(0,),
        mesh=MeshSpec((0.1, 0.2), (8, 9, 8)),
    )  # fmt: skip
    moved = replace(choice, mesh=MeshSpec((0.11, 0.2), (9, 8, 8)))
    assert moves_breakpoints(choice, moved)
    assert not moves_breakpoints(choice, replace(choice, mesh=MeshSpec((0.11, 0.2), (9, 9, 8))))
    assert not moves_breakpoints(choice, replace(choice, mesh=MeshSpec((0.1,), (12, 13))))
    assert not moves_breakpoints(choice, replace(moved, order=16))  # other physics or order
    assert not moves_breakpoints(replace(choice, mesh=None), moved)  # from the default mesh
