"""Where a point contact held at a node row touches (``adapt/contact_shift.py``, contact_shift).

The touching point is where the clearance g(s) = h(x(s)) + r has its largest value near the row
s_j.  One Newton step, Δs = −g'/g'', finds it where g is curved; where g is nearly straight (a
heavy string touching down on a floor) the step ran centimetres past the neighbouring rows,
although the rows on both sides hold g ≤ 0 while g(s_j) = 0, so the largest g lies between
them.  A step that leaves that bracket gives way to the largest g on a grid of the bracket.

A synthetic clearance along a straight centreline over a floor (h = the height below z = 0):
a parabola with its top inside the bracket gives the Newton step (exact for a parabola); a nearly
straight clearance gives a point in the bracket, the largest g there.
"""

from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.solver.adapt.contact_shift import contact_shift, row_bracket

L = 1.0


class Floor:
    """h(x) = z: a clearance read straight off the centreline's third coordinate."""

    @staticmethod
    def h_many(points: np.ndarray) -> np.ndarray:
        return np.asarray(points)[:, 2]


def centreline(g):
    """positions(s) with z = g(s): the clearance along the string is g."""
    return lambda s: np.column_stack([s, np.zeros_like(s), g(np.asarray(s, dtype=float))])


def test_curved_clearance_gives_the_newton_step():
    s_j, top = 0.40, 0.403
    g = lambda s: -50.0 * ((s - top) ** 2 - (s_j - top) ** 2)  # noqa: E731  (g(s_j) = 0)
    shift = contact_shift(centreline(g), Floor, 0.0, s_j, L, bracket=(0.39, 0.41))
    assert shift == pytest.approx(top - s_j, rel=1e-4)


def test_nearly_straight_clearance_stays_between_the_rows():
    s_j, bracket = 0.40, (0.385, 0.42)
    # rising by 1e-4 per metre with curvature -1e-6: the Newton step is +100 m
    g = lambda s: 1e-4 * (s - s_j) - 0.5e-6 * (s - s_j) ** 2  # noqa: E731
    shift = contact_shift(centreline(g), Floor, 0.0, s_j, L, bracket=bracket)
    assert bracket[0] <= s_j + shift <= bracket[1]
    assert s_j + shift == pytest.approx(bracket[1], abs=(bracket[1] - bracket[0]) / 50)
    # without a bracket: the old step
    assert contact_shift(centreline(g), Floor, 0.0, s_j, L) == pytest.approx(100.0, rel=1e-3)


def test_row_bracket_is_the_neighbouring_rows():
    rows = np.array([0.0, 0.1, 0.2, 0.3, 1.0])
    assert row_bracket(rows, 0.2, 0.2, L) == (0.1, 0.3)
    assert row_bracket(rows, 0.2, 0.3, L) == (0.1, 1.0)
    assert row_bracket(rows, 0.0, 0.0, L) == (0.0, 0.1)
