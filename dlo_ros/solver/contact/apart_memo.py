"""A shape proved apart once, and the shapes near it that the same proof covers (``ApartMemo``).

``certainly_apart`` (``apart.py``) proves that no two strands of a sampled centreline come within
reach from four inequalities, each with room to spare on a stream's shapes (#38: a hanging cable
turns 0.4 rad over the 11 segments it bounds at π/2; the subsample's closest pair is 18 mm beyond
what it needs):

1. every step is longer than 0.1 h;
2. the turning over ``big`` − 1 consecutive segments is below π/2;
3. cos(T_m / 2) × the shortest length of ``m`` consecutive steps is above D (T_m: the largest
   turning over m segments);
4. the turning over ``wide`` − 1 segments is below π/2, and the subsample's pairs b − a ≥
   ``wide`` − j are farther apart than reach + j × the longest step (j = ``apart.SUBSAMPLE``).

A stream's next answer Q is the proved shape P moved by E (one displacement per sample).  With ε
the largest change of a step, |E_{i+1} − E_i|, and δ the largest |E_i − Ē| (Ē: E's mean), each
quantity of Q is bounded by P's: a step's length by ε; a step's direction by α = asin(ε / ℓ_min)
(ℓ_min: P's shortest step), so a turning over k segments by 2 (k − 1) α; the distance of two
samples by 2 δ.  Where the four inequalities hold for those bounds (``covers``), they hold for Q:
Q is apart, as certainly as ``certainly_apart`` would have found (the same statement, proved from
P's numbers; slack for their rounding: ``LENGTH_SLACK``, ``ANGLE_SLACK``).  Otherwise Q is proved
afresh and, proved by the subsample test, becomes the memo's shape (``ApartMemo.apart``).

Where the samples are a linear map of the shape's tangents at its quadrature nodes, x_i = x0 + Σ_j
W_ij T_j (a director model: ``DirectorModel.positions_with``), ε and δ are bounded without sampling
Q at all (``ApartMemo.apart_linear``): E_{i+1} − E_i = Σ_j (W_{i+1,j} − W_ij) ΔT_j and E_i − Ē =
Σ_j (W_ij − W̄_j) ΔT_j (x0 cancels), so ε ≤ max_i Σ_j |W_{i+1,j} − W_ij| · max_j |ΔT_j| and δ ≤
max_i Σ_j |W_ij − W̄_j| · max_j |ΔT_j| (``Linear``); Q's samples are worked out only when that
does not settle it.

Per solver (``ShapeSolver`` keeps one): the memo holds a copy of P (and of its tangents) and is
keyed by its sampling (the ``ContactGeometry`` object, and W as the model's memo holds it);
nothing is shared between solvers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .apart import SUBSAMPLE, subsample_band, min_squared, certainly_apart

if TYPE_CHECKING:
    from .self_contact import ContactGeometry

#: added to ε and δ [m]: the rounding of the differences they are computed from
LENGTH_SLACK = 1e-12
#: added per segment to a turning bound [rad]: arccos's rounding of P's turns near 0 (~1e-8)
ANGLE_SLACK = 1e-6


@dataclass(frozen=True)
class Linear:
    """The proved samples as x0 + W T: W (N, M), P's tangents T (3, M) and W's two norms.

    step_norm: max_i Σ_j |W_{i+1,j} − W_ij|; spread_norm: max_i Σ_j |W_ij − W̄_j| (W̄: the mean
    row), the factors of max_j |ΔT_j| that bound ε and δ (module docstring).
    """

    rows: np.ndarray
    tangents: np.ndarray
    step_norm: float
    spread_norm: float


def linear(rows: np.ndarray, tangents: np.ndarray) -> Linear:
    """Return ``Linear`` of the sample rows W and the proved shape's tangents T (copied)."""
    mean = np.add.reduce(rows, axis=0) / len(rows)
    held = np.array(tangents, dtype=float)
    held.flags.writeable = False
    return Linear(
        rows,
        held,
        float(np.abs(rows[1:] - rows[:-1]).sum(axis=1).max()),
        float(np.abs(rows - mean).sum(axis=1).max()),
    )


@dataclass(frozen=True)
class ApartProof:
    """What ``certainly_apart``'s subsample test read of the shape ``points`` it proved apart.

    lmin, lmax: its shortest and longest step [m]; turning_big, turning_m, turning_wide: its
    largest turning [rad] over ``big`` − 1, ``m`` and ``wide`` − 1 consecutive segments;
    shortest: the shortest length of m consecutive steps [m]; sub_distance: the subsample's
    closest pair b − a ≥ wide − j [m].
    """

    geometry: ContactGeometry
    points: np.ndarray
    lmin: float
    lmax: float
    turning_big: float
    turning_m: float
    shortest: float
    turning_wide: float
    sub_distance: float
    #: the samples as a linear map of the tangents, where they are one (``ApartMemo.apart_linear``)
    linear: Linear | None = None


def prove(points: np.ndarray, geometry: ContactGeometry) -> tuple[bool, ApartProof | None]:
    """Return (``certainly_apart(points, geometry)``, its proof by the subsample test or None).

    No proof where ``certainly_apart`` finds nothing or proves it otherwise (a short string, the
    dense test): those shapes are not memoised.  The proof's inequalities at no move (``holds``)
    are the subsample test's with room to spare (the same numbers: ``certainly_apart``'s
    arithmetic), so where they hold ``certainly_apart`` answers True and is not asked.
    """
    n, plan = len(points), geometry.apart_plan
    m, big = plan.m, plan.big
    wide = big + 2 * SUBSAMPLE
    if n < 3 or n > 401 or m >= n or plan.grips_close or wide > n - 1:
        return certainly_apart(points, geometry), None
    steps = points[1:] - points[:-1]
    lengths = np.sqrt(np.einsum("ij,ij->i", steps, steps))
    if not lengths.min() > 0.1 * geometry.spacing:
        return certainly_apart(points, geometry), None
    unit = steps / lengths[:, None]
    cosines = np.einsum("ij,ij->i", unit[:-1], unit[1:])
    total = np.concatenate(([0.0], np.cumsum(np.arccos(np.clip(cosines, -1.0, 1.0)))))

    def most_turning(segments: int) -> float:
        segments = min(segments, n - 1)
        return float((total[segments - 1 :] - total[: n - segments]).max())

    windows = np.concatenate(([0.0], np.cumsum(lengths)))
    idx, band = subsample_band(n, SUBSAMPLE, wide - SUBSAMPLE)
    proof = ApartProof(
        geometry,
        np.array(points, dtype=float),
        float(lengths.min()),
        float(lengths.max()),
        most_turning(big - 1),
        most_turning(m),
        float((windows[m:] - windows[: n - m]).min()),
        most_turning(wide - 1),
        math.sqrt(max(min_squared(points[idx], band), 0.0)),
    )
    proof.points.flags.writeable = False
    if holds(proof, geometry, LENGTH_SLACK, LENGTH_SLACK):
        return True, proof
    return certainly_apart(points, geometry), None


def covers(proof: ApartProof, points: np.ndarray, geometry: ContactGeometry) -> bool:
    """Tell whether ``proof`` shows ``points`` apart too (the module docstring's bounds).

    False (then ``certainly_apart`` decides) for another sampling, for a move too large for the
    margins, and for a non-finite point.
    """
    if geometry is not proof.geometry or points.shape != proof.points.shape:
        return False
    moved = points - proof.points
    bend = moved[1:] - moved[:-1]
    centred = moved - np.add.reduce(moved, axis=0) / len(moved)
    eps = math.sqrt(float(np.einsum("ij,ij->i", bend, bend).max())) + LENGTH_SLACK
    dev = math.sqrt(float(np.einsum("ij,ij->i", centred, centred).max())) + LENGTH_SLACK
    return holds(proof, geometry, eps, dev)


def holds(proof: ApartProof, geometry: ContactGeometry, eps: float, dev: float) -> bool:
    """Tell whether ``certainly_apart``'s inequalities hold for P moved by ε and δ (bounds, m).

    ``eps``: the largest change of a step; ``dev``: the largest displacement from the mean one.
    """
    if not (eps < 0.5 * proof.lmin and dev < proof.sub_distance):  # (nan: not covered)
        return False
    n, plan = len(proof.points), geometry.apart_plan
    m, big = plan.m, plan.big
    alpha = math.asin(eps / proof.lmin)

    def bound(turning: float, segments: int) -> float:
        """Return the largest turning over ``segments`` segments of the moved shape, bounded."""
        segments = min(segments, n - 1)
        return turning + 2 * (segments - 1) * alpha + segments * ANGLE_SLACK

    if not proof.lmin - eps > 0.1 * geometry.spacing:
        return False
    if not bound(proof.turning_big, big - 1) < np.pi / 2 - 1e-9:
        return False
    turning_m = bound(proof.turning_m, m)
    if not turning_m < np.pi:
        return False
    shortest = proof.shortest - m * eps
    if not math.cos(turning_m / 2) * shortest > geometry.distance * (1 + 1e-9):
        return False
    if not bound(proof.turning_wide, big + 2 * SUBSAMPLE - 1) < np.pi / 2 - 1e-9:
        return False
    closest = proof.sub_distance - 2 * dev
    reach = geometry.reach + SUBSAMPLE * (proof.lmax + eps)
    return closest * closest > reach**2 * (1 + 1e-9) + 1e-15


class ApartMemo:
    """One solver's shape proved apart last (``ApartProof``), for the shapes near it."""

    def __init__(self) -> None:
        """Start with nothing proved."""
        self._proof: ApartProof | None = None

    def apart(self, points: np.ndarray, geometry: ContactGeometry) -> bool:
        """Tell whether no two strands of ``points`` come within reach (``certainly_apart``).

        From the memo's proof where it covers ``points``; else proved afresh (a proof by the
        subsample test then replaces the memo's; a shape not proved leaves it).
        """
        proof = self._proof
        if proof is not None and covers(proof, points, geometry):
            return True
        apart, fresh = prove(points, geometry)
        if fresh is not None:
            self._proof = fresh
        return apart

    def apart_linear(
        self,
        geometry: ContactGeometry,
        tangents: np.ndarray,
        points: Callable[[], np.ndarray],
        rows: Callable[[], np.ndarray],
    ) -> bool:
        """``apart`` for samples x0 + W Tᵀ of the tangents T = ``tangents`` (3, M).

        From the memo's proof where its ``Linear`` bounds (module docstring) cover the move of
        the tangents, without sampling; else ``apart(points())`` (``points``: the samples, worked
        out on this call), a new proof keeping W = ``rows()`` and T.  W is the one model's at
        ``geometry.s`` (the memo is one solver's, made anew with its model): a proof of the same
        geometry keeps it.
        """
        proof = self._proof
        lin = proof.linear if proof is not None else None
        if (
            proof is not None
            and lin is not None
            and proof.geometry is geometry
            and tangents.shape == lin.tangents.shape
        ):
            d = tangents - lin.tangents
            change = math.sqrt(float(np.einsum("ij,ij->j", d, d).max()))
            eps = lin.step_norm * change + LENGTH_SLACK
            dev = lin.spread_norm * change + LENGTH_SLACK
            if holds(proof, geometry, eps, dev):
                return True
        apart, fresh = prove(points(), geometry)
        if fresh is not None:
            if lin is None or proof is None or proof.geometry is not geometry:
                lin = linear(rows(), tangents)  # W's norms: once per sampling
            else:
                held = np.array(tangents, dtype=float)
                held.flags.writeable = False
                lin = replace(lin, tangents=held)
            self._proof = replace(fresh, linear=lin)
        return apart
