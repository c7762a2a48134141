"""Contact slots: an obstacle row at the string's closest approach between the samples.

The NLP imposes h_i(x(σ)) + r ≤ 0 at ``obstacle_samples`` uniform samples, spacing h_s (or at the
element mesh's nodes, ``obstacle_points.py``: then h_s is their widest gap).  Where a
string rests on a curved obstacle that converges only to first order in h_s: the contact can only
sit at a sample, the string cuts in by about d²/2R at a distance d from it (R the obstacle's radius
of curvature), and a string lying over a sphere or post slides along it into wells one spacing
apart (``bench/results/contact_slots.md``).  Rows much closer together than the samples do not cure
it: a smooth Ritz field cannot tell rows a few millimetres apart, their Jacobians become nearly
equal, and Newton's active set then fails on the near-singular system (measured: the uniform 161-
and 641-sample models fall back to IPOPT on most contact updates).  So each obstacle has
``obstacle_slots`` = K rows whose arc lengths are parameters (``StringNLP.slot_rows``):

    on_k v*_k − (1 − on_k) L ≤ 0,    x(σ_k) = x0 + T W(σ_k)ᵀ,

with v*_k the obstacle's reach h_i + r at the closest approach near σ_k, to second order
(``build/slot_envelope.py``; h_i(x(σ_k)) + r where the string is tangent there), W(σ) the row of
the centreline's integration matrix (T: the quadrature-node tangents) and on_k ∈ {0, 1}: an empty
slot reads −1 ≤ 0 and has no derivative.  Each uniform sample has such a switch too.

``place`` measures the clearance c(s) = −h_i(x(s)) − r of a shape on a grid FINE times finer than
the samples and puts a slot at each of its K deepest local minima (refined by parabolas through
evaluated points) that lie within ``band`` of the obstacle and at least ``DIP`` · L below the
clearance half a sample spacing to either side: a point contact, or the deepest cut of a contact
along an arc.  A string lying flat along a table gets none (it sags between the samples by far
less; they resolve it).  On an obstacle without curvature (``FLAT``: a half-space) a slot goes
only where the string touches at an isolated point, its clearance rising by ``FLAT_DIP`` · L half
a spacing to either side (the bottom of a cable sagging onto a table), and not where it passes
through the plane: a short flat contact has two symmetric dips about µm deep, and a slot in one of
them would pick the side by rounding; a heavy strip's cold guess through its floor (the paper's
Fig. 3), slotted where it dips deepest, arched over onto another equilibrium.  The
sample nearest each slot is switched off, and every row closer to it than ``CLEAR`` · L
(``rows_on``): a row a fraction of a spacing from another nearly repeats it.

A slot is kept while its minimum moves less than ``slot_tolerance``: ``TOLERANCE`` · L, at most
``SLOT_SHARE`` of the error tolerance δ (the parameters then change only in the grip targets, the
case Newton reuses its stored matrix for).  After a solve the slots are placed on the answer; when
a minimum that touches (c < ``TOUCH`` · L) is further than that from its slot, the solve is
repeated warm from the answer with the slot there (``update/slot_rounds.py``).  A slot's row is
the obstacle's reach at the closest approach near it, not at σ alone (``build/slot_envelope.py``):
a string held at one material point slides along a post until it cuts in beside the slot.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...model.obstacle_types import OBSTACLE_TYPES
from .obstacle_points import nearest_row, row_spacing

#: a slot is kept, and a solve is not repeated, while its minimum moved less than this × L (and
#: than SLOT_SHARE × the error tolerance: ``slot_tolerance``)
TOLERANCE = 3e-4

#: a slot of a shape mapped onto another model or mesh takes the force of the source's slot
#: nearest it within this × L (``carried_slot``): the mapped shape's minimum moves by the
#: mapping's error (0.3 mm at one of the main job's mesh switches, where TOLERANCE·L dropped the
#: post's force and the first solve on the new mesh cut 5 cm into the post)
CARRIED = 1e-2

#: a slot may sit this fraction of the error tolerance δ from its fixed point
SLOT_SHARE = 0.04

#: a closest approach touches when its clearance is below this × L
TOUCH = 1e-6

#: a closest approach gets a slot when it lies this × L below the clearance half a sample spacing
#: to each side
DIP = 1e-6

#: obstacle types without curvature: a slot only at an isolated touch (a string on a plane does not
#: cut in between the samples beyond its own sag, and a flat contact has no point to slide to)
FLAT = tuple(name for name, kind in OBSTACLE_TYPES.items() if kind.flat)
#: the types each ``solver.slotted_obstacles`` value slots (None: every type)
SLOTTED: dict[str, tuple[str, ...] | None] = {
    "all": None,
    "flat": FLAT,
    "points": FLAT + tuple(name for name, kind in OBSTACLE_TYPES.items() if kind.points),
}


def slotted(kind: str, which: str) -> bool:
    """Tell whether ``solver.slotted_obstacles: which`` slots an obstacle of type ``kind``."""
    types = SLOTTED[which]
    return types is None or kind in types


#: on a ``FLAT`` obstacle a closest approach gets a slot when it lies this × L below the clearance
#: half a sample spacing to each side: a point where a sagging string touches the plane, not the
#: sag between two rows of a string lying on it
FLAT_DIP = 1e-4

#: rows closer than this × L to a filled slot are switched off (``rows_on``): the clearance rises
#: off a touching point by d²/2R, 2.5e-5 m at d = 2 mm on the demo's post
CLEAR = 2e-3

#: the clearance is measured on FINE points per sample interval (at most 4096 intervals in all)
FINE = 16


@dataclass(frozen=True)
class SlotPlacement:
    """One obstacle's slots on a shape.

    One obstacle's slots on a shape: arc lengths σ [m] (0 where empty), on (1.0 or 0.0), the
    samples' switches, the clearance of the shape at each filled slot's minimum [m] (inf where
    empty), and whether every slot of a previous placement was kept.
    """

    s: np.ndarray
    on: np.ndarray
    samples_on: np.ndarray
    clearance: np.ndarray
    kept: bool = False


@dataclass(frozen=True)
class SlotMotion:
    """How a stream's slots moved over one update (arrays of obstacles × slots).

    fixed: each slot's fixed point σ = s*(σ) as estimated on the update's answer (its minimum
    there) [m]; drift: its move over the update [m] (0 where not filled before and after);
    steady: the drift within half of itself of the update before's (a contact sliding steadily,
    whose next place the drift predicts); on: the slots filled for the next update (1.0).
    """

    fixed: np.ndarray
    drift: np.ndarray
    steady: np.ndarray
    on: np.ndarray


@functools.lru_cache(maxsize=16)
def fine_grid(length: float, samples: int) -> np.ndarray:
    """Arc lengths [m] where the clearance is measured (FINE intervals per sample interval).

    Read-only, one array per (length, samples): every slot placement of a solver asks for it.
    """
    out = np.linspace(0.0, length, min(FINE * (samples - 1), 4096) + 1)
    out.flags.writeable = False
    return out


def band(length: float, radius: float) -> float:
    """Return the clearance [m] within which a minimum gets a slot.

    The clearance [m] within which a minimum gets a slot: the string's diameter, at least
    L/200.
    """
    return max(2.0 * radius, length / 200.0)


def clip(x: float, lo: float, hi: float) -> float:
    """Return x clipped to [lo, hi] in floats as numpy clips: max, then min, keeping a NaN x."""
    if x == x:
        x = x if x > lo else lo
    if x == x:
        x = x if x < hi else hi
    return x


def _vertex(s: list[float], c: list[float]) -> float:
    """Return the vertex of the parabola through three equally spaced points, clipped to them.

    ``s``, ``c``: the points' arc lengths and values; the middle point where the parabola does
    not curve up.  numpy's operations of the vectorised form, in its order, on floats.
    """
    curvature = c[0] - 2 * c[1] + c[2]
    shift = 0.5 * (s[2] - s[1]) * (c[0] - c[2]) / curvature if curvature > 0 else 0.0
    return clip(s[1] + shift, s[0], s[2])


def _triples(values: list[float]) -> list[list[float]]:
    """Return ``values`` in consecutive threes."""
    return [values[j : j + 3] for j in range(0, len(values), 3)]


def minima(
    s_fine: np.ndarray,
    clearance: np.ndarray,
    h_s: float,
    width_band: float,
    length: float,
    clearance_at: Callable[[np.ndarray], np.ndarray],
    flat: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the clearance's local minima that are deep enough, deepest first.

    Each is (s*, c(s*)): the local minima of the clearance within ``width_band`` that dip DIP·L
    below the clearance half a sample spacing to either side, deepest first (``clearance_at(s)``:
    c at any arc lengths; each minimum is refined by two parabola steps through evaluated points).
    ``flat`` (an obstacle without curvature): FLAT_DIP·L instead of DIP·L, and only minima not
    more than FLAT_DIP·L through the plane (a shape through it, such as a cold solve's first
    guess, says nothing of where it will touch).  The few minima are refined in Python floats
    (the same operations numpy would do on their arrays), ``clearance_at`` asked once per step for
    all of them.
    """
    dip = FLAT_DIP if flat else DIP
    inner = clearance[1:-1]
    k = (
        np.flatnonzero((inner <= clearance[:-2]) & (inner < clearance[2:]) & (inner < width_band))
        + 1
    )
    if not k.size:
        return np.zeros(0), np.zeros(0)
    h = float(s_fine[1] - s_fine[0])
    s = [
        _vertex(s_fine[j - 1 : j + 2].tolist(), clearance[j - 1 : j + 2].tolist())
        for j in k.tolist()
    ]
    for r in (h / 4, h / 16):
        pts = [clip(x, 0.0, length) for sj in s for x in (sj - r, sj, sj + r)]
        values = clearance_at(np.array(pts)).tolist()
        s = [_vertex(p, v) for p, v in zip(_triples(pts), _triples(values))]
    half = 0.5 * h_s
    ends = [clip(sj - half, 0.0, length) for sj in s] + [clip(sj + half, 0.0, length) for sj in s]
    both = clearance_at(np.array(s + ends)).tolist()
    n, floor = len(s), dip * length
    found = []
    for j, (sj, c, left, right) in enumerate(zip(s, both, both[n:], both[2 * n :])):
        lower = left if (left < right or left != left) else right  # np.minimum: NaN wins
        if lower - c >= floor and (not flat or c >= -floor):
            found.append((c, j, sj))
    found.sort()  # by depth, then as found (argsort, stable; a NaN depth is not deep)
    places, depths = [f[2] for f in found], [f[0] for f in found]
    return np.array(places, dtype=float), np.array(depths, dtype=float)


def assign(
    found: tuple[np.ndarray, np.ndarray],
    samples: np.ndarray,
    slots: int,
    previous: "SlotPlacement | None",
    length: float,
    within: float | None = None,
) -> SlotPlacement:
    """Place the deepest minima found in the slots, keeping each near its previous slot.

    The deepest ``slots`` minima ``found`` in slots, each kept at the index of the previous slot
    nearest to it (within two sample spacings), and kept exactly when it moved less than
    ``within`` [m] (default TOLERANCE·L; a solver's ``slot_tolerance``).  ``samples``: the
    obstacle rows' arc lengths (uniform samples or mesh nodes, ``obstacle_points.py``); the rows
    about each filled slot are switched off (``rows_on``).
    """
    h_s = row_spacing(samples)
    keep = TOLERANCE * length if within is None else within
    s, on, c = [0.0] * slots, [0.0] * slots, [np.inf] * slots
    free = list(range(slots))
    pending = []
    old_s = previous.s.tolist() if previous is not None else []
    old_on = previous.on.tolist() if previous is not None else []
    for sj, cj in zip(found[0][:slots].tolist(), found[1][:slots].tolist()):
        k = _nearest_slot(old_s, old_on, free, sj, 2 * h_s)
        if k is None:
            pending.append((sj, cj))
            continue
        free.remove(k)
        s[k], on[k], c[k] = (old_s[k] if abs(old_s[k] - sj) <= keep else sj), 1.0, cj
    if previous is not None:
        # free indices: those empty before first (a slot that lost its minimum holds no force)
        free.sort(key=lambda k: old_on[k] > 0)
    for (sj, cj), k in zip(pending, free):
        s[k], on[k], c[k] = sj, 1.0, cj
    # np.array_equal of the arrays: the lists equal and no NaN (a list compares a NaN to itself)
    kept = previous is not None and on == old_on and s == old_s and all(x == x for x in s)
    filled = np.array([x for x, o in zip(s, on) if o > 0], dtype=float)
    return SlotPlacement(
        np.array(s), np.array(on), rows_on(samples, filled, length), np.array(c), kept
    )


def _nearest_slot(
    old_s: list[float], old_on: list[float], free: list[int], s: float, within: float
) -> int | None:
    """Return the free filled slot of a previous placement nearest to ``s`` (within ``within``).

    The first of equals; None where there is none that near (or a distance is NaN).
    """
    d = [abs(old_s[k] - s) if (old_on[k] > 0 and k in free) else np.inf for k in range(len(old_s))]
    if not d or any(x != x for x in d):
        return None
    best = min(range(len(d)), key=d.__getitem__)
    return best if d[best] <= within else None


def carried_slot(source_s: np.ndarray, s: float, length: float) -> int | None:
    """Return the index of the source slot whose force a slot at ``s`` [m] takes, or None.

    ``source_s``: the source's filled slots' arc lengths [m]; the nearest, within CARRIED·L (the
    first of equals).
    """
    if not source_s.size:
        return None
    j = int(np.argmin(np.abs(source_s - s)))
    return j if abs(source_s[j] - s) <= CARRIED * length else None


def slot_tolerance(length: float, error_tolerance: float) -> float:
    """Return how far [m] a slot may sit from its fixed point: TOLERANCE·L, at most SLOT_SHARE·δ.

    δ: ``solver.error_tolerance`` [m] (0: 1e-3·L).  The centreline moves by about 1.3× a point
    contact's shift (``adapt/contact_shift.py``), so a slot within SLOT_SHARE·δ of its fixed point
    keeps that error, twice over in auto's estimate, well under δ/2.
    """
    return min(TOLERANCE * length, SLOT_SHARE * (error_tolerance or 1e-3 * length))


def rows_on(samples: np.ndarray, filled: np.ndarray, length: float) -> np.ndarray:
    """Return the rows' switches (1.0 on) with slots at ``filled`` [m].

    Off: the row nearest each slot, and every row closer to one than CLEAR·L (rows that a
    refinement crowded about a contact shared its force with the slot, each pushing off the
    place it touches: on the post, the error estimate 13× the true error).
    """
    samples = np.asarray(samples, dtype=float)
    if not filled.size:
        return np.ones(len(samples))
    points, slots = samples.tolist(), filled.tolist()
    if any(x != x for x in points + slots):  # NaN: numpy's argmin and min as they treat it
        out = np.ones(len(samples))
        out[nearest_row(samples, filled)] = 0.0
        near = np.min(np.abs(samples[:, None] - filled[None, :]), axis=1) < CLEAR * length
        out[near] = 0.0
        return out
    # in floats: the nearest row (the first of equals), and the rows nearer than CLEAR·L
    reach = CLEAR * length
    off = {min(range(len(points)), key=lambda j: abs(points[j] - sigma)) for sigma in slots}
    return np.array(
        [
            0.0 if j in off or any(abs(x - sigma) < reach for sigma in slots) else 1.0
            for j, x in enumerate(points)
        ]
    )
