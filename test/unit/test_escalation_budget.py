"""How long a checked solve escalates (solver/auto/stream_checks.py, ``Escalations``): while its
estimate keeps falling, stopping after CHECK_NOW_STALL verdicts in a row without a new lowest
estimate (lower by CHECK_NOW_GAIN at least) or after CHECK_NOW_PASSES; a verdict without an
estimate (a change of physics or order) is no stall."""

from __future__ import annotations

import math

from dlo_ros.solver.auto.stream_checks import (
    CHECK_NOW_GAIN,
    CHECK_NOW_PASSES,
    CHECK_NOW_STALL,
    Escalations,
)


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
