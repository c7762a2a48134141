"""The cable as a chain of capsules, for a planning scene: pure numpy, no ROS.

``capsule_chain(points, radius, padding)`` covers a string's tube (every point within ``radius``
r of its centreline) with capsules of one radius R along consecutive chords of the centreline,
and keeps every capsule within r + ``padding`` p of the centreline:

* **containment**: every point within r of the centreline is inside some capsule;
* **tightness**: every point of every capsule is within r + p of the centreline.

The construction.  R = r + p/2, and the chords a_i b_i join samples of the centreline chosen so
that the centreline between a chord's ends stays within δ ≤ p/2 of the chord (the *deviation*).

* Containment: a point x of the tube is within r of a centreline point c, and c lies between the
  ends of some chord S, so dist(x, S) ≤ r + dist(c, S) ≤ r + δ ≤ R.
* Tightness: a capsule point y is within R of a point q of its chord S.  The curve from a to b
  runs continuously from one end of S to the other, so some curve point c projects onto q; as
  dist(c, S) ≤ δ, |c - q| ≤ δ, and y is within R + δ ≤ r + p of the curve.

The deviation bound.  The given points are exact samples of a smooth curve, dense enough that its
curvature changes little from one sample to the next.  Between two consecutive samples k, k + 1
(h_k apart) the curve stays within the allowance e_k = SAFETY · h_k² κ_k / 8 of their segment:
h² κ / 8 is a circular arc's sagitta for small angles, κ_k the largest curvature estimated at the
four samples around the segment (from the turning angle between neighbouring segments), and
SAFETY covers curvature that grows along the segment and the small-angle approximation.
Distance to a segment is convex, so a dense segment's points are no farther from a chord than
its ends are; a chord therefore deviates from the curve by at most the largest distance of the
samples between its ends plus the largest allowance there, and that sum is what is held ≤ p/2.
Only an input whose segments turn by more than MAX_TURN is refused: too coarse to bound.  Two
points are taken as a straight cable.

The chords are chosen greedily from the first sample: each reaches as far along the samples as
the bound allows (a galloping then bisecting search, every chosen chord checked), so a straight
cable is one capsule and a bend gets more.  ``max_capsules`` caps the count: a chain over it is
refused with CapsuleLimitError, which says the smallest padding that fits.  A chain that drops
part of the cable (containment) or reaches farther than r + p (tightness) is never returned,
since a planner trusting either would collide or refuse reachable motions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

#: the largest turning angle [rad] between consecutive input segments the bound trusts
MAX_TURN = np.pi / 2
#: factor on the sagitta estimate of the curve between two consecutive samples
SAFETY = 2.0
#: capsules in a chain unless the caller says otherwise
MAX_CAPSULES = 256
#: bisection steps of the smallest padding that fits the cap (only when refusing)
_BISECT_STEPS = 40


@dataclass(frozen=True, eq=False)
class CapsuleChain:
    """Capsules of one radius along consecutive chords of a centreline.

    joints: (K + 1, 3) chord ends [m]; capsule i runs from joints[i] to joints[i + 1].  radius: R
    [m], the capsules' radius (r + p/2).  string_radius: r [m]; padding: p [m].  deviation: δ
    [m], the bound on how far the centreline strays from its chords (≤ p/2).  indices: (K + 1,)
    which input points the joints are.  The arrays are read-only.
    """

    joints: np.ndarray
    radius: float
    string_radius: float
    padding: float
    deviation: float
    indices: np.ndarray

    @property
    def count(self) -> int:
        """Return the number of capsules K."""
        return len(self.joints) - 1

    @property
    def starts(self) -> np.ndarray:
        """Return the capsules' first ends a_i, (K, 3) [m]."""
        return self.joints[:-1]

    @property
    def ends(self) -> np.ndarray:
        """Return the capsules' second ends b_i, (K, 3) [m]."""
        return self.joints[1:]

    @property
    def lengths(self) -> np.ndarray:
        """Return the capsules' axis lengths |b_i - a_i|, (K,) [m]."""
        return np.linalg.norm(self.ends - self.starts, axis=1)

    @property
    def reach(self) -> float:
        """Return R + δ [m]: no capsule point is farther from the centreline (≤ r + p)."""
        return self.radius + self.deviation


class CapsuleLimitError(ValueError):
    """The chain needs more capsules than ``max_capsules`` at this padding.

    needed: the capsules the padding needs; max_capsules: the cap; min_padding [m]: a padding
    whose chain fits in the cap.
    """

    def __init__(self, needed: int, max_capsules: int, padding: float, min_padding: float):
        """Keep the numbers and say them."""
        self.needed = needed
        self.max_capsules = max_capsules
        self.min_padding = min_padding
        super().__init__(
            f"max_capsules: a padding of {padding:.4g} m needs {needed} capsules, over "
            f"max_capsules {max_capsules}; a padding of {min_padding:.4g} m fits in "
            f"{max_capsules}"
        )


def capsule_chain(
    points: ArrayLike,
    radius: float,
    padding: float,
    *,
    max_capsules: int = MAX_CAPSULES,
) -> CapsuleChain:
    """Return capsules that contain the string's tube and stay within radius + padding of it.

    points: (N, 3) samples along the centreline [m], N ≥ 2, in order (a ShapeResult's points).
    radius: the string's radius r ≥ 0 [m]; padding: p > 0 [m].  The capsules' radius is r + p/2
    and the centreline stays within p/2 of their axes (module docstring: why that contains the
    tube and stays within r + p).  Consecutive repeated points are dropped.

    Raises ValueError naming the argument: points not (N, 3), not finite, fewer than 2 distinct,
    or turning by more than MAX_TURN between consecutive segments (sample more densely); radius
    negative or not finite; padding not > 0 or too small for the sampling (the curve between two
    samples may stray farther than p/2 from them); max_capsules < 1.  CapsuleLimitError (a
    ValueError) when the chain needs more than max_capsules capsules.
    """
    pts, indices = _checked_points(points)
    r, p = _checked_sizes(radius, padding, max_capsules)
    allowance = _allowance(pts, indices)
    bound = p / 2
    worst = int(np.argmax(allowance))
    if allowance[worst] > bound:
        raise ValueError(
            f"padding: {p:.4g} m is too small for the sampling: between points "
            f"{indices[worst]} and {indices[worst + 1]} the centreline may stray "
            f"{allowance[worst]:.3g} m from them, over padding/2; sample more densely or raise "
            "the padding"
        )
    cuts = _greedy_cuts(pts, allowance, bound, max_capsules)
    if cuts is None:
        every = _greedy_cuts(pts, allowance, bound, len(pts))
        needed = len(pts) - 1 if every is None else len(every) - 1
        fits = _fitting_padding(pts, allowance, max_capsules)
        raise CapsuleLimitError(needed, max_capsules, p, fits)
    deviation = max(_deviation(pts, allowance, i, j) for i, j in zip(cuts[:-1], cuts[1:]))
    joints = pts[cuts].copy()
    chosen = indices[cuts].copy()
    joints.setflags(write=False)
    chosen.setflags(write=False)
    return CapsuleChain(joints, r + bound, r, p, float(deviation), chosen)


def _checked_points(points: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return the points as a float (M, 3) array without repeats, and their input indices."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        raise ValueError(f"points: must be an (N, 3) array with N >= 2, got shape {pts.shape}")
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise ValueError(f"points: row {int(np.argmax(bad))} is not finite (NaN or inf)")
    # a repeated sample has no direction: its zero-length segment would give no turning angle
    keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)])
    if keep.sum() < 2:
        raise ValueError("points: fewer than 2 distinct points")
    return pts[keep], np.flatnonzero(keep)


def _checked_sizes(radius: float, padding: float, max_capsules: int) -> tuple[float, float]:
    """Return (r, p) as floats, checked."""
    r, p = float(radius), float(padding)
    if not (np.isfinite(r) and r >= 0.0):
        raise ValueError(f"radius: must be a finite number >= 0 m, got {radius!r}")
    if not (np.isfinite(p) and p > 0.0):
        raise ValueError(f"padding: must be a finite number > 0 m, got {padding!r}")
    if int(max_capsules) != max_capsules or max_capsules < 1:
        raise ValueError(f"max_capsules: must be an integer >= 1, got {max_capsules!r}")
    return r, p


def _allowance(pts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Return e_k [m]: how far the curve may stray from the segment of samples k, k + 1.

    indices: the input index of each sample, for the error message.
    """
    seg = np.diff(pts, axis=0)
    h = np.linalg.norm(seg, axis=1)
    u = seg / h[:, None]
    turn = np.arctan2(np.linalg.norm(np.cross(u[:-1], u[1:]), axis=1), np.sum(u[:-1] * u[1:], 1))
    if len(turn) and turn.max() > MAX_TURN:
        j = indices[int(np.argmax(turn)) + 1]
        raise ValueError(
            f"points: the centreline turns by {np.degrees(turn.max()):.0f} degrees at point {j}, "
            f"over {np.degrees(MAX_TURN):.0f}: too coarse to bound the curve between samples; "
            "sample it more densely"
        )
    # κ at each sample (0 at the ends): the turning angle over the mean of its two segments,
    # a circle's curvature when the samples lie on one
    kappa = np.zeros(len(pts))
    kappa[1:-1] = 2.0 * turn / (h[:-1] + h[1:])
    k = np.arange(len(h))
    # segment k lies between samples k and k + 1; samples k - 1 and k + 2 see a growing bend
    around = np.stack([kappa[np.clip(k + off, 0, len(pts) - 1)] for off in (-1, 0, 1, 2)])
    return SAFETY * h**2 * around.max(axis=0) / 8.0


def _deviation(pts: np.ndarray, allowance: np.ndarray, i: int, j: int) -> float:
    """Return the bound [m] on the curve's distance from the chord of samples i and j (i < j)."""
    a, b = pts[i], pts[j]
    ab = b - a
    span = pts[i : j + 1] - a
    length2 = float(ab @ ab)
    t = np.clip(span @ ab / length2, 0.0, 1.0) if length2 > 0.0 else np.zeros(len(span))
    off = np.linalg.norm(span - t[:, None] * ab, axis=1)
    return float(off.max() + allowance[i:j].max())


def _reach_from(pts: np.ndarray, allowance: np.ndarray, i: int, bound: float) -> int:
    """Return the farthest sample j > i found whose chord from i keeps the deviation ≤ bound.

    The caller has checked allowance ≤ bound, so j = i + 1 always fits.  Galloping then
    bisecting between a fitting and a failing j: every returned chord has been checked.
    """
    last = len(pts) - 1
    good, bad = i + 1, None
    while good < last:
        j = min(i + 2 * (good - i), last)
        if _deviation(pts, allowance, i, j) <= bound:
            good = j
        else:
            bad = j
            break
    while bad is not None and bad - good > 1:
        mid = (good + bad) // 2
        if _deviation(pts, allowance, i, mid) <= bound:
            good = mid
        else:
            bad = mid
    return good


def _greedy_cuts(
    pts: np.ndarray, allowance: np.ndarray, bound: float, max_capsules: int
) -> np.ndarray | None:
    """Return the chosen samples' indices (chord ends), or None past max_capsules chords."""
    cuts = [0]
    while cuts[-1] < len(pts) - 1:
        if len(cuts) > max_capsules:
            return None
        cuts.append(_reach_from(pts, allowance, cuts[-1], bound))
    return np.asarray(cuts)


def _fitting_padding(pts: np.ndarray, allowance: np.ndarray, max_capsules: int) -> float:
    """Return a padding [m] whose chain fits in max_capsules, near the smallest (bisection)."""
    # at a bound over the points' extent plus every allowance, each chord fits: one capsule
    hi = float(np.linalg.norm(np.ptp(pts, axis=0)) + allowance.max()) * 1.01
    lo = float(allowance.max())
    for _ in range(_BISECT_STEPS):
        mid = 0.5 * (lo + hi)
        if _greedy_cuts(pts, allowance, mid, max_capsules) is None:
            lo = mid
        else:
            hi = mid
    return 2.0 * hi
