"""``certainly_apart``: a proof that no two strands of a sampled centreline come within reach.

The shortcut ``self_contact.candidate_pairs`` is asked for first (``results/self_pass.py``, auto's
``escalate.py``): True only when that search would find no pair, never a guess (its docstring
gives the proof).  What depends on the sampling alone is worked out once per ``ContactGeometry``
(``ApartPlan``, its ``apart_plan``); the per-shape work is array arithmetic on the N points.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .self_contact import ContactGeometry


def certainly_apart(points: np.ndarray, geometry: ContactGeometry) -> bool:
    """Tell whether no two strands of ``points`` can be within reach (cheap, conservative).

    True when ``candidate_pairs(points, geometry)`` is provably empty (no two strands within
    reach), from O(N) turning angles and one dense distance test; False when this shortcut cannot
    tell (then ``candidate_pairs`` decides).  Exact, never a guess:

    * pairs k = b − a samples apart with m ≤ k < K (m the smallest separation the exclusion arc
      allows, K ≈ 1.25 reach / h): if the polyline turns by less than 90° over every K − 1
      consecutive segments, all segment directions between a and b are within 90° of each other,
      so the inner neighbour pairs (a, b − 1) and (a + 1, b) are strictly closer than (a, b)
      (|c + e|² − |c|² = 2 c·e + |e|² > 0 with e the step and c the rest of the chord): no such
      pair is a local minimum, unless the inner neighbour is a step along the same strand (k = m);
      those pairs are minima only when closer than D, and their chord is at least cos(T/2) × the
      polyline's length over them (T the turning over those m segments: every direction is within
      T/2 of the middle one along the turning path);
    * pairs k ≥ K: none is within reach (their distances, from one Gram matrix, all above it);
    * no pair within K samples is placed by two different grips (their samples count as minima).

    What depends on the sampling alone (m, K, the grips' test, the subsample) is worked out once
    per geometry (``ApartPlan``); the per-shape work is array arithmetic on the N points.
    """
    n = len(points)
    plan = geometry.apart_plan
    m, big = plan.m, plan.big
    if n < 3 or n > 401 or m >= n:
        # no pair is far enough apart, or too many samples for the dense test
        return n < 2 or m >= n
    if plan.grips_close:
        return False
    steps = points[1:] - points[:-1]
    lengths = np.sqrt(np.einsum("ij,ij->i", steps, steps))
    # (a step this short would leave the strict inequalities to rounding)
    if not lengths.min() > 0.1 * geometry.spacing:
        return False
    unit = steps / lengths[:, None]
    cosines = np.einsum("ij,ij->i", unit[:-1], unit[1:])
    # (np.clip's bounds as two ufuncs: the same numbers without its dispatch)
    turns = np.arccos(np.minimum(np.maximum(cosines, -1.0), 1.0))
    total = np.empty(n - 1)  # turning from the first segment to each
    total[0] = 0.0
    np.cumsum(turns, out=total[1:])

    def most_turning(segments: int) -> float:
        """Return the largest turning [rad] over ``segments`` consecutive segments."""
        segments = min(segments, n - 1)
        return float((total[segments - 1 :] - total[: n - segments]).max())

    if not most_turning(big - 1) < np.pi / 2 - 1e-9:
        return False
    windows = np.empty(n)
    windows[0] = 0.0
    np.cumsum(lengths, out=windows[1:])
    shortest = float((windows[m:] - windows[: n - m]).min())
    if not np.cos(most_turning(m) / 2) * shortest > geometry.distance * (1 + 1e-9):
        return False
    reach = geometry.reach
    # the turning bound over 2·SUBSAMPLE more segments lets the dense test start there, where a
    # subsample of the points can settle it
    wide = big + 2 * SUBSAMPLE
    if wide <= n - 1 and most_turning(wide - 1) < np.pi / 2 - 1e-9:
        if _subsample_apart(points, wide, reach, float(lengths.max())):
            return True
    return (
        big > n - 1
        or min_squared(points, subsample_band(n, 1, big)[1]) > reach**2 * (1 + 1e-9) + 1e-15
    )


@dataclass(frozen=True)
class ApartPlan:
    """What ``certainly_apart`` needs of a geometry alone.

    m: the smallest sample separation the exclusion arc allows (as ``_far_pairs`` rounds it);
    big: K, past which the dense test answers; grips_close: two grips' samples fewer than K
    apart (the shortcut then declines).
    """

    m: int
    big: int
    grips_close: bool


def apart_plan(geometry: ContactGeometry) -> ApartPlan:
    """Return ``certainly_apart``'s plan of ``geometry`` (``ContactGeometry.apart_plan``)."""
    h, reach = geometry.spacing, geometry.reach
    near = geometry.exclusion - 1e-12
    m = int(np.ceil(near / h))
    while m > 1 and (m - 1) * h >= near:  # the smallest k with k h ≥ near, as _far_pairs rounds it
        m -= 1
    while m * h < near:
        m += 1
    big = max(m + 1, int(np.ceil(1.25 * reach / h)) + 1)
    close = False
    if geometry.held.size:
        grips = [
            np.flatnonzero(geometry.held == g)
            for g in np.unique(geometry.held[geometry.held >= 0])
        ]
        close = any(
            np.abs(gi[:, None] - gj[None, :]).min() < big
            for i, gi in enumerate(grips)
            for gj in grips[i + 1 :]
        )
    return ApartPlan(m, big, bool(close))


#: ``certainly_apart``'s dense test tries every SUBSAMPLE-th sample first
SUBSAMPLE = 4


def _subsample_apart(points: np.ndarray, wide: int, reach: float, longest: float) -> bool:
    """Tell (sufficient, not necessary) whether all pairs b − a ≥ ``wide`` are beyond ``reach``.

    Every sample a is within j/2 steps of a' of every j-th (j = SUBSAMPLE) and the last, so
    |x_a − x_b| ≥ |x_a' − x_b'| − j·``longest`` (the longest step), b' − a' ≥ ``wide`` − j: all
    such pairs beyond ``reach`` + j·``longest`` settle it with (n/j)² distances, not n².
    """
    j = SUBSAMPLE
    idx, band = subsample_band(len(points), j, wide - j)
    return min_squared(points[idx], band) > (reach + j * longest) ** 2 * (1 + 1e-9) + 1e-15


@functools.lru_cache(maxsize=16)
def subsample_band(n: int, step: int, gap: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the samples (every ``step``-th of n, and the last) and their band, read-only.

    The band is 0 where two of them are at least ``gap`` samples apart (b − a ≥ gap), +inf
    elsewhere: ``min_squared`` then measures those pairs alone.
    """
    idx = np.unique(np.append(np.arange(0, n, step), n - 1))
    band = np.where(idx[None, :] - idx[:, None] >= gap, 0.0, np.inf)
    idx.flags.writeable = band.flags.writeable = False
    return idx, band


def min_squared(points: np.ndarray, band: np.ndarray) -> float:
    """Return the smallest squared distance between samples over the pairs ``band`` leaves 0."""
    # smaller numbers: less rounding in |x|² + |y|² − 2 x·y (the mean as np.mean forms it)
    centred = points - np.add.reduce(points, axis=0) / len(points)
    sq = np.einsum("ij,ij->i", centred, centred)
    # (sq_a + sq_b) − 2 x_a·x_b + band in place: the same operations, two (n, n) arrays fewer
    out = np.add.outer(sq, sq)
    gram = centred @ centred.T
    gram *= 2.0
    out -= gram
    out += band
    return float(out.min())
