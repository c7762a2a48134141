"""Self-contact: non-adjacent parts of the string stay at least two radii apart (issue #15).

Formulation (director 3D models, ``solver.self_contact_pairs`` > 0).  The centreline is sampled at
σ_j = j h, j = 0 … N−1, h = L/(N−1) (N = ``solver.self_contact_samples``, or from the radius: h =
r, clipped to [L/400, L/100]).  For a pair of samples further apart along s than the exclusion arc
S,

    |x(σ_a) − x(σ_b)|² ≥ D²,   D² = (2r)² + h²/2,   S = max(π D / 2, 2 h),

is an inequality row of the NLP.  The NLP has a fixed number K of pair slots (``StringNLP``): slot
k's parameters are q_k = W(σ_a) − W(σ_b) (rows of the centreline's integration matrix, so that
x(σ_a) − x(σ_b) = T q_k with T the quadrature-node tangents) and its bound b_k = D², both scaled by
1/(2D) so that the row reads a distance (``fill``); an empty slot has q_k = 0, b_k = −L and reads
−1 ≤ 0 for any shape.  Pairs are parameters, so the active set changes during a stream without
rebuilding the NLP.

Error bound between samples.  Near their closest points two strands are straight to O(κ h²), so
each sample pair's offset from the closest points is a u − b v with |a|, |b| ≤ h/2 (u, v the unit
tangents); choosing the signs of a and b so that a b (u·v) ≥ 0 gives |a u − b v|² ≤ h²/2 whatever
the angle.  Hence d_true² ≥ d_sample² − h²/2 ≥ (2r)²: the true centreline distance is at least
2r − κ_max h²/4 (κ_max the largest curvature of the two strands near contact; each strand leaves
its tangent line by at most κ (h/2)²/2 within half a spacing).  The price is a separation of at
most √((2r)² + h²/2) for parallel strands whose samples line up (D instead of 2r: 6 % of the
diameter at h = r).

Held contacts (radius > 0): a contact found on sample pairs is then held at the closest points of
its two strands, 2r apart (``ContactSlots.at``, ``fill``; update/contact_points.py), which removes
the D − 2r over-separation; crossing strands only (``closest_points.py``).

Radius zero ("may touch, may not cross"): D = h/√2.  Two polyline chords of length h that cross
have an end pair no further apart than h/√2, so a shape whose sample pairs all keep D does not
cross itself at the sample polyline's resolution; the centreline deviates from that polyline by at
most κ h²/8.

The exclusion arc S: on a circle of radius ρ the chord over an arc S is 2ρ sin(S/2ρ) ≥ D for every
ρ ≥ D/2 when S = πD/2, so the rows never act on a bend gentler than radius D/2 ≈ r (a tube cannot
bend tighter than its radius); pairs closer along s than that are neighbours on one strand, not a
contact. Pairs of samples within S of two different grips are not checked either: the scene places
those grips (both ends of a closed loop held at one point, or two grips closer than 2r).

Candidate pairs come from the current shape: a k-d tree over the N samples (scipy's cKDTree) gives
the pairs within the reach D + max(4 h, 0.03 L) (O(N log N), nothing quadratic); of those, the
pairs whose distance is a local minimum along either strand (the closest partner of each sample on
the other strand) fill the slots, nearest first.  A pair in a slot that carries a force keeps its
slot.  After a solve the same query on the answer finds every penetration (``penetrations``); a
penetrating pair not in a slot is added and the solve repeated from the same start
(``ShapeSolver``).  auto asks on every update whether a shape without self-contact rows comes
within reach of itself: ``certainly_apart`` answers "no" from the turning angles and one dense
distance test when it can prove it, the search otherwise.

Topology, along a warm stream (both reported as a failure, the shape not published):
* ``crossing_flips``: for each pair within reach whose tangents cross (|t_a × t_b| ≥ 0.3) the sign
  of (x_b − x_a)·(t_a × t_b) says which strand lies on top; it cannot change while the strands stay
  within reach of each other unless one passed through the other between two updates.  (x_b −
  x_a)·n̂ (n̂ the unit normal t_a × t_b) is the signed distance between the two tangent lines, so
  the sign is kept only where that is at least half the pair's distance (``CROSSING_OVERLAP``):
  there the lines' closest points lie near the samples and the strands do lie over one another.
  Side by side in one plane (the legs of a planar hairpin) the tangent lines meet far from the
  samples, the product is rounding noise, and a tiny out-of-plane motion flipped it: a crossing the
  string never made (measured: a pinned hairpin at order 32, refused at its first 15° turn of a
  clamp).
* ``swept_crossing``: a jump (IPOPT may land far from the start, e.g. a twisted rod releasing its
  twist)
  is checked by moving every sample straight from the old shape to the new one: if no two samples
  meet on the way, the shapes are isotopic; if two do, the string may have passed through itself.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .apart import ApartPlan, apart_plan
from .apart import certainly_apart as certainly_apart  # (its callers ask for it here)

#: how many times a solve is repeated with the pairs it penetrated added to the slots
CONTACT_ROUNDS = 4

#: |t_a × t_b| below this: the strands are too close to parallel for the crossing sign to mean
#: anything
CROSSING_SINE = 0.3

#: |(x_b − x_a)·n̂| below this fraction of |x_b − x_a|: the strands lie side by side, not over one
#: another, and the crossing sign means nothing (module docstring)
CROSSING_OVERLAP = 0.5


@dataclass(frozen=True)
class ContactGeometry:
    """The sampling of the self-contact rows (see the module docstring).

    The sampling of the self-contact rows (module docstring): sample arc lengths s [m], spacing
    h [m], the sample-pair distance D [m] the rows keep, the exclusion arc S [m], and the candidate
    reach [m].
    """

    s: np.ndarray
    spacing: float
    distance: float
    exclusion: float
    reach: float
    radius: float
    held: np.ndarray = field(
        default_factory=lambda: np.zeros(0, dtype=int)
    )  # per sample: grip index within S, or −1

    @property
    def key(self) -> tuple:
        return (len(self.s), self.distance)

    @functools.cached_property
    def apart_plan(self) -> ApartPlan:
        """``certainly_apart``'s plan of this sampling, worked out on first use."""
        return apart_plan(self)

    def tolerance(self, curvature: float) -> float:
        """Return how far below 2r the centreline distance may come between samples [m].

        How far below 2r the true centreline distance may come between samples [m] (module
        docstring).
        """
        return curvature * self.spacing**2 / 4


@functools.lru_cache(maxsize=16)
def contact_geometry(
    length: float, radius: float, samples: int = 0, grip_s: tuple[float, ...] = ()
) -> ContactGeometry:
    """Return the self-contact sampling for a string of ``length`` and ``radius`` [m].

    The sampling for a string of ``length`` and ``radius`` [m]; ``samples`` 0 picks h = r within
    [L/400, L/100].  ``grip_s``: the grips' arc lengths [m] (pairs of samples within the exclusion
    arc of two different grips are never checked: the scene places those grips, e.g. both ends of a
    closed loop at one point).
    """
    if samples:
        n = samples
    else:
        h = min(max(radius, length / 400), length / 100)
        n = int(np.ceil(length / h - 1e-9)) + 1
    h = length / (n - 1)
    distance = float(np.sqrt(4 * radius**2 + h**2 / 2))
    exclusion = max(np.pi * distance / 2, 2 * h)
    reach = distance + max(4 * h, 0.03 * length)
    s = np.linspace(0.0, length, n)
    held = np.full(n, -1, dtype=int)
    for i, sg in enumerate(grip_s):
        held[np.abs(s - sg) <= exclusion] = i
    return ContactGeometry(s, h, distance, exclusion, reach, radius, held)


@dataclass
class ContactSlots:
    """The pair held by each self-contact slot, its geometry and the last crossing signs.

    The pair held by each slot ((a, b) sample indices, a < b, or None) with the geometry they
    index, and the crossing signs of the shape they were last checked on.
    """

    geometry: ContactGeometry
    pairs: list[tuple[int, int] | None]
    signs: dict[tuple[int, int], float] = field(default_factory=dict)
    #: ``candidate_pairs`` of that shape (the next warm update selects its pairs from them)
    candidates: list[tuple[tuple[int, int], float]] | None = None
    #: slot → (σ_a, σ_b) [m]: slots held at the closest points of two strands, 2r apart
    #: (``closest_points.py``; the slot's pair is then the samples nearest those points)
    at: dict[int, tuple[float, float]] = field(default_factory=dict)

    def copy(self) -> ContactSlots:
        return ContactSlots(
            self.geometry, list(self.pairs), dict(self.signs), self.candidates, dict(self.at)
        )

    def distance(self, k: int) -> float:
        """Return the distance [m] slot ``k``'s row keeps: 2r where held exactly, else D."""
        return 2.0 * self.geometry.radius if k in self.at else self.geometry.distance

    def arc_lengths(self, k: int) -> tuple[float, float]:
        """Return the arc lengths [m] of slot ``k``'s two points (its pair must be set)."""
        if k in self.at:
            return self.at[k]
        pair = self.pairs[k]
        assert pair is not None
        return float(self.geometry.s[pair[0]]), float(self.geometry.s[pair[1]])


def _far_pairs(
    points: np.ndarray, geometry: ContactGeometry, radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Return the sample pairs within ``radius`` and the exclusion arc apart, with distances.

    Sample pairs (P, 2), a < b, within ``radius`` of each other and at least the exclusion arc
    apart, and their distances.
    """
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")  # rows (i, j) with i < j
    if pairs.size == 0:
        return np.zeros((0, 2), dtype=int), np.zeros(0)
    far = (pairs[:, 1] - pairs[:, 0]) * geometry.spacing >= geometry.exclusion - 1e-12
    if geometry.held.size:
        ga, gb = geometry.held[pairs[:, 0]], geometry.held[pairs[:, 1]]
        far &= ~((ga >= 0) & (gb >= 0) & (ga != gb))
    pairs = pairs[far]
    d = points[pairs[:, 0]] - points[pairs[:, 1]]
    return pairs, np.sqrt(np.einsum("ij,ij->i", d, d))


def candidate_pairs(
    points: np.ndarray, geometry: ContactGeometry
) -> list[tuple[tuple[int, int], float]]:
    """Return the pairs within reach at a local minimum of distance, nearest first.

    Pairs within reach whose distance is a local minimum along one strand, with their distances
    [m], nearest first.  A neighbour closer along s than the exclusion arc is a step along the same
    strand: a pair next to one is a minimum only when it is already closer than D (a bend tighter
    than D/2). Vectorised over the pairs the tree returned (neighbours read from a table of their
    distances).
    """
    pairs, dist = _far_pairs(points, geometry, geometry.reach)
    if not len(pairs):
        return []
    n = len(geometry.s)
    a, b = pairs[:, 0], pairs[:, 1]
    # the distance of each pair within reach at [a + 1, b + 1]; a neighbour pair off the string,
    # not within reach or left out (held by two grips) reads +inf, which leaves the pair a minimum
    # on that side
    table = np.full((n + 2, n + 2), np.inf)
    table[a + 1, b + 1] = dist
    held = np.concatenate(([-1], geometry.held, [-1])) if geometry.held.size else None
    near = geometry.exclusion - 1e-12
    closer_than_d = dist < geometry.distance

    def leaves_minimum(a2: np.ndarray, b2: np.ndarray) -> np.ndarray:
        """Tell whether each neighbour pair leaves its pair's distance a minimum on its side.

        Whether each neighbour pair (a2, b2) leaves its pair's distance a minimum on its
        side.
        """
        # (a neighbour off the string is one sample further apart than its pair: never on the same
        # strand)
        same_strand = (b2 - a2) * geometry.spacing < near
        out = np.where(same_strand, closer_than_d, dist <= table[a2 + 1, b2 + 1])
        if held is not None:  # both samples placed by two different grips
            ga, gb = held[a2 + 1], held[b2 + 1]
            out |= (ga >= 0) & (gb >= 0) & (ga != gb)
        return out

    along_b = leaves_minimum(a, b - 1) & leaves_minimum(a, b + 1)
    along_a = leaves_minimum(a - 1, b) & leaves_minimum(a + 1, b)
    chosen = np.flatnonzero(along_a | along_b)
    chosen = chosen[np.argsort(dist[chosen], kind="stable")]
    return [((int(a[i]), int(b[i])), float(dist[i])) for i in chosen]


def closest_distance(points: np.ndarray, geometry: ContactGeometry) -> float:
    """Return the closest approach [m] of two strands (inf when none are within reach).

    The closest approach [m] of two strands: the smallest candidate pair's distance
    (``candidate_pairs``: not a pair of neighbours on one strand), inf when no two strands are
    within reach.
    """
    candidates = candidate_pairs(points, geometry)
    return min((d for _, d in candidates), default=float("inf"))


def penetrations(
    candidates: list[tuple[tuple[int, int], float]], geometry: ContactGeometry, slack: float
) -> list[tuple[int, int]]:
    """Return the candidate pairs closer than D − slack [m], nearest first.

    The candidate pairs (``candidate_pairs``) closer than D − slack [m], nearest first.  When
    none is, no sample pair the exclusion arc apart is: from any pair closer than D, stepping along
    one strand while the distance falls ends on a candidate closer still.
    """
    return [pair for pair, d in candidates if d < geometry.distance - slack]


def assign(
    slots: list[tuple[int, int] | None],
    wanted: list[tuple[int, int]],
    keep: set[int],
    capacity: int,
) -> tuple[list[tuple[int, int] | None], list[tuple[int, int]]]:
    """Return new slot contents: the kept slots stay, the wanted pairs fill the rest.

    New slot contents: the slots in ``keep`` (carrying a force) stay; the rest of the capacity
    goes to the ``wanted`` pairs in their order (a chosen pair already in a slot keeps that slot,
    so its multiplier stays with it).  Returns the slots and the wanted pairs that found no
    slot.
    """
    slots = list(slots) + [None] * (capacity - len(slots))
    kept = {slots[k] for k in keep if slots[k] is not None}
    chosen: list[tuple[int, int]] = []
    left: list[tuple[int, int]] = []
    for pair in dict.fromkeys(wanted):  # in order, without repeats
        if pair in kept:
            continue
        (chosen if len(chosen) < capacity - len(kept) else left).append(pair)
    chosen_set = set(chosen)
    new: list[tuple[int, int] | None] = [
        slots[k] if (k in keep or slots[k] in chosen_set) else None for k in range(capacity)
    ]
    held = {pair for pair in new if pair is not None}
    free = [k for k in range(capacity) if new[k] is None]
    for pair in chosen:
        if pair not in held:
            new[free.pop(0)] = pair
    return new, left


def fill(p: np.ndarray, slots: ContactSlots, nlp, length: float) -> np.ndarray:
    """Return p with every slot's q_k and b_k set, scaled so that the row reads a distance.

    p with every slot's q_k and b_k set (module docstring), scaled so that the row reads a
    distance:
    q_k = (W(σ_a) − W(σ_b)) / √(2D) and b_k = D/2, so that the NLP row (b_k − |T q_k|²)/L equals
    (D² − |x_a − x_b|²)/(2 D L) ≈ (D − |x_a − x_b|)/L near contact, whatever the radius (a row in
    D² would hold the distance only to 1e-10 L²/D).  An empty slot: q_k = 0, b_k = −L (the row
    reads −1).

    A slot held at closest points (``slots.at``) reads the same with 2r for D at its σ_a, σ_b.
    """
    lay, w = nlp.params, nlp.model.position_matrix(slots.geometry.s)
    for k, pair in enumerate(slots.pairs):
        sl = lay[f"self:{k}"]
        if pair is None:
            p[sl] = 0.0
            p[sl.stop - 1] = -length
            continue
        d = slots.distance(k)
        if k in slots.at:
            wa, wb = nlp.model.position_matrix(np.array(slots.at[k]))
        else:
            wa, wb = w[pair[0]], w[pair[1]]
        p[sl.start : sl.stop - 1] = (wa - wb) / np.sqrt(2.0 * d)
        p[sl.stop - 1] = d / 2
    return p


def slot_multiplier(lam_row_si: float, distance: float) -> float:
    """Return the SI multiplier λ [N/m] of a slot's distance constraint from its row's λ.

    The SI multiplier λ [N/m] of D² − |x_a − x_b|² ≤ 0 from a slot row's λ / (row_scale σ) [N]
    (``fill``: the row is that constraint divided by 2D; ``distance``: the slot's D [m],
    ``ContactSlots.distance``).
    """
    return lam_row_si / (2.0 * distance)


def crossing_signs(
    points: np.ndarray, tangents: np.ndarray, candidates: list[tuple[tuple[int, int], float]]
) -> dict[tuple[int, int], float]:
    """Return the crossing sign of every candidate pair whose tangents cross.

    Sign of (x_b − x_a)·(t_a × t_b) for every candidate pair (``candidate_pairs``) whose
    tangents cross and that lie over one another along the normal (module docstring).
    """
    out = {}
    for (a, b), _ in candidates:
        normal = np.cross(tangents[a], tangents[b])
        size = np.linalg.norm(normal)
        if size >= CROSSING_SINE:
            gap = points[b] - points[a]
            along = np.dot(gap, normal) / size
            if abs(along) >= CROSSING_OVERLAP * np.linalg.norm(gap):
                out[(a, b)] = float(np.sign(along))
    return out


def crossing_flips(
    before: dict[tuple[int, int], float], after: dict[tuple[int, int], float]
) -> list[tuple[int, int]]:
    """Pairs whose crossing sign changed between two shapes of a stream (both within reach)."""
    return [pair for pair, sign in after.items() if pair in before and before[pair] * sign < 0]


def swept_crossing(
    before: np.ndarray, after: np.ndarray, geometry: ContactGeometry
) -> tuple[int, int] | None:
    """Return a sample pair that meets when the samples move straight from ``before`` to ``after``.

    A pair of samples (exclusion arc apart) that meet when every sample moves straight from
    ``before`` to ``after`` (N, 3): its distance min_τ |Δ0 + τ (Δ1 − Δ0)| falls below half of
    min(D, h/√2), the resolution at which the sample polyline can tell two centrelines apart; None
    when no pair does. If the straight motion keeps every pair apart, the two shapes are isotopic
    (the string did not pass through itself); if it does not, it may have. Only pairs that can meet
    are tested: a k-d tree over ``before`` with the radius D plus twice the largest displacement.
    """
    move = float(np.max(np.linalg.norm(after - before, axis=1), initial=0.0))
    pairs, _ = _far_pairs(before, geometry, geometry.distance + 2 * move)
    if not len(pairs):
        return None
    a, b = pairs[:, 0], pairs[:, 1]
    d0, d1 = before[a] - before[b], after[a] - after[b]
    e = d1 - d0
    ee = np.sum(e * e, axis=1)
    tau = np.clip(-np.sum(d0 * e, axis=1) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    closest = np.linalg.norm(d0 + tau[:, None] * e, axis=1)
    limit = 0.5 * min(geometry.distance, geometry.spacing / np.sqrt(2.0))
    hit = np.flatnonzero(closest < limit)
    if not hit.size:
        return None
    i = hit[np.argmin(closest[hit])]
    return int(a[i]), int(b[i])
