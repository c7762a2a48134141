"""The h/p refinement decision: the next element mesh from per-element error estimates.

Each element k of the current ``MeshSpec`` has an error estimate e_k [m] and a smoothness measure
ρ_k, the geometric decay rate of its solution's polynomial coefficients (ρ near 1: not smooth,
e.g. a kink inside; well below 1: smooth, the error falls by about ρ per added node).  Element k's
share of the tolerance δ [m] is b_k = δ · h_k / L when the estimates add up to the global one
(``share='length'``), or δ when the global estimate is their maximum (``share='each'``).

* refine when e_k > ``refine`` · b_k: move a breakpoint of the element onto a ``snap_to`` kink
  closer to it than ``min_size``; split at a kink the caller knows inside the element (e.g. a
  contact point), else split at the middle when ρ_k ≥ ``smooth``, else add the nodes that the
  geometric decay predicts bring e_k to ``target`` · b_k (split at the middle instead when that
  needs more than ``max_nodes``);
* an element holding an ``unresolved`` point contact (one whose error its estimate does not
  bound) is refined whatever e_k, split at that contact;
* coarsen when e_k < ``coarsen`` · b_k: remove the nodes the decay predicts it can spare while
  staying under ``target`` · b_k, at most ``max_removed`` per pass when set (auto sets 2: the
  fitted decay of a solution resolved to rounding predicts far more than it can spare, 12 → 4
  nodes took an estimate of 0.17 mm to 0.17 m); two neighbours both at their fewest nodes and
  both coarse merge into one element with the same unknowns, unless the breakpoint between them
  is one of the scene's (``fixed``) or a known kink;
* when the caller lists the contact points (``anchors``: run ends, touching points, on a
  breakpoint or not), two neighbours below ``coarsen`` · b_k and not refined in the pass merge
  across a breakpoint no contact point holds (not the scene's) into one element with the nodes
  of the larger: a stream's contact that slid on leaves a breakpoint behind at each place a
  split put one (the table stream of #37 grew to 10 elements and 327 unknowns that way).

The gap between ``refine`` and ``coarsen`` (25× by default) is the hysteresis: an element refined
or coarsened lands at ``target`` · b_k, strictly between them, so the rule applied again to its
own output with estimates that follow the prediction changes nothing (a fixed point).  Caps:
``max_nodes`` per element, ``max_unknowns`` nodes of a field in all (Σ (n_k − 1) + 1, refinements
with the largest e_k / b_k first), no element shorter than ``min_size`` [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..build.mesh import MERGE, MeshSpec


@dataclass(frozen=True)
class RefinementRule:
    """The thresholds and caps of ``next_mesh`` (module docstring); tolerance δ [m]."""

    tolerance: float
    refine: float = 0.5
    coarsen: float = 0.02
    target: float = 0.2
    smooth: float = 0.6
    share: str = "length"
    min_nodes: int = 4
    max_nodes: int = 32
    max_removed: int | None = None
    max_unknowns: int = 200
    min_size: float = 1e-3

    def validate(self) -> None:
        """Raise ValueError naming the first field out of range."""
        if not self.tolerance > 0:
            raise ValueError(f"refinement.tolerance: must be > 0 m, got {self.tolerance}")
        if not 0 < self.coarsen < self.target < self.refine:
            raise ValueError(
                "refinement: need 0 < coarsen < target < refine, got "
                f"{self.coarsen}, {self.target}, {self.refine}"
            )
        if not 0 < self.smooth < 1:
            raise ValueError(f"refinement.smooth: must be in (0, 1), got {self.smooth}")
        if self.share not in ("length", "each"):
            raise ValueError(f"refinement.share: 'length' or 'each', got {self.share!r}")
        if not 3 <= self.min_nodes <= self.max_nodes:
            raise ValueError("refinement: need 3 <= min_nodes <= max_nodes")
        if not self.min_size > 0:
            raise ValueError(f"refinement.min_size: must be > 0 m, got {self.min_size}")


@dataclass(frozen=True)
class ElementEstimates:
    """Per-element error estimates [m], coefficient decay rates, and known kinks' s [m].

    snap_to: kinks known best (a point contact's predicted touching point): a breakpoint of an
    element to refine closer to one than ``min_size`` moves onto it.
    """

    errors: np.ndarray
    decay: np.ndarray
    kinks: tuple[float, ...] = ()
    snap_to: tuple[float, ...] = ()
    #: the contact points that hold a breakpoint [m] (run ends, touching points, held points),
    #: also those on one (None: not known, so no breakpoint is taken for one that holds nothing)
    anchors: tuple[float, ...] | None = None
    #: point contacts inside an element whose error the estimates do not bound [m]: each
    #: element holding one is split there, whatever its estimate
    unresolved: tuple[float, ...] = ()


def unknowns(counts) -> int:
    """Return the nodes of one field on a mesh with these per-element counts."""
    return int(sum(n - 1 for n in counts) + 1)


def _nodes_for(error: float, goal: float, rate: float) -> int:
    """Return the nodes to add (> 0) or remove (< 0) to move ``error`` to ``goal``.

    The estimate falls by ``rate`` per node; adding rounds up, removing rounds toward zero, so
    the prediction never overshoots ``goal``.
    """
    rate = min(max(rate, 1e-3), 0.999)
    k = math.log(goal / max(error, 1e-300)) / math.log(rate)
    return math.ceil(k) if k > 0 else -math.floor(-k)


def _split(lo: float, hi: float, n: int, at: float, rule: RefinementRule):
    """Return the two elements [lo, at], [at, hi] with nodes shared out by length."""
    h = hi - lo
    counts = [max(rule.min_nodes, math.ceil(n * (b - a) / h) + 1) for a, b in ((lo, at), (at, hi))]
    return [(lo, at, min(counts[0], rule.max_nodes)), (at, hi, min(counts[1], rule.max_nodes))]


def _kink_inside(lo: float, hi: float, kinks, rule: RefinementRule) -> float | None:
    """Return the known kink nearest the middle of [lo, hi] that leaves both parts long enough."""
    inside = [k for k in kinks if lo + rule.min_size <= k <= hi - rule.min_size]
    return min(inside, key=lambda k: abs(k - 0.5 * (lo + hi))) if inside else None


def _refined(lo, hi, n, error, budget, rate, kinks, rule) -> list[tuple[float, float, int]]:
    """Return what element [lo, hi] with n nodes becomes when refined (itself when it cannot)."""
    kink = _kink_inside(lo, hi, kinks, rule)
    if kink is not None:
        return _split(lo, hi, n, kink, rule)
    if rate < rule.smooth:
        more = _nodes_for(error, rule.target * budget, rate)
        if n + more <= rule.max_nodes:
            return [(lo, hi, n + max(more, 1))]
    if hi - lo >= 2 * rule.min_size:
        return _split(lo, hi, n, 0.5 * (lo + hi), rule)
    return [(lo, hi, min(n + 2, rule.max_nodes))]


def _budgets(bounds: np.ndarray, rule: RefinementRule) -> np.ndarray:
    """Return each element's share b_k of the tolerance [m]."""
    h = np.diff(bounds)
    return rule.tolerance * (h / bounds[-1] if rule.share == "length" else np.ones_like(h))


def _check(spec: MeshSpec, estimates: ElementEstimates, elements: int) -> None:
    if spec.counts is None:
        raise ValueError("refinement: the mesh spec needs explicit counts (build/mesh.mesh_spec)")
    for name, values in (("errors", estimates.errors), ("decay", estimates.decay)):
        if np.shape(values) != (elements,) or not np.all(np.isfinite(values)):
            raise ValueError(f"refinement.{name}: need {elements} finite values per element")


def next_mesh(
    spec: MeshSpec,
    length: float,
    estimates: ElementEstimates,
    rule: RefinementRule,
    fixed=(),
) -> MeshSpec | None:
    """Return the next mesh after ``spec`` (module docstring), or None when nothing changes.

    length: the string's length L [m]; fixed: the scene's own breakpoints [m], never removed.
    """
    rule.validate()
    bounds = np.concatenate([[0.0], np.asarray(spec.breakpoints, dtype=float), [length]])
    _check(spec, estimates, bounds.size - 1)
    counts = list(spec.counts or ())
    errors, rates = np.asarray(estimates.errors), np.asarray(estimates.decay)
    budgets = _budgets(bounds, rule)
    held = _holding(bounds, estimates.unresolved)
    refine = (errors > rule.refine * budgets) | (held > 0)
    moved = _snapped(bounds, refine, estimates.snap_to, fixed, rule)
    plan: list[list[tuple[float, float, int]]] = [
        [(moved[k], moved[k + 1], n)] for k, n in enumerate(counts)
    ]
    total, changed = unknowns(counts), set()
    # the worst first (an unresolved contact's element before all): the unknowns cap may stop it
    for k in np.lexsort((-(errors / budgets), -held)):
        lo, hi, n = plan[k][0]
        if refine[k]:
            kinks = estimates.unresolved if held[k] else estimates.kinks
            new = _refined(lo, hi, n, errors[k], budgets[k], rates[k], kinks, rule)
            grown = total + unknowns(c for _, _, c in new) - n
            if grown <= rule.max_unknowns:
                plan[k], total = new, grown
                changed.add(int(k))
        elif errors[k] < rule.coarsen * budgets[k] and n > rule.min_nodes:
            fewer = -_nodes_for(errors[k], rule.target * budgets[k], rates[k])
            if rule.max_removed is not None:
                fewer = min(fewer, rule.max_removed)
            plan[k] = [(lo, hi, max(rule.min_nodes, n - max(fewer, 0)))]
            changed.add(int(k))
    low = (errors < rule.coarsen * budgets) & (held == 0)
    coarse = [k not in changed and low[k] for k in range(len(plan))]
    calm = [len(plan[k]) == 1 and low[k] for k in range(len(plan))]
    flat = _merged(plan, coarse, calm, rule, fixed, estimates, length)
    out = MeshSpec(tuple(float(b) for b, _, _ in flat[1:]), tuple(int(c) for _, _, c in flat))
    return None if out == MeshSpec(tuple(float(b) for b in bounds[1:-1]), tuple(counts)) else out


def _holding(bounds: np.ndarray, points) -> np.ndarray:
    """Return how many of ``points`` [m] lie inside each element of ``bounds``."""
    inside = np.searchsorted(bounds, np.asarray(points, dtype=float)) - 1
    return np.bincount(np.clip(inside, 0, bounds.size - 2), minlength=bounds.size - 1)


def _snapped(bounds: np.ndarray, refine: np.ndarray, snap_to, fixed, rule) -> np.ndarray:
    """Return ``bounds``, each breakpoint of an element to refine moved onto a near kink.

    A ``snap_to`` kink closer to it than ``min_size`` could not be split at so near it.  Never a
    scene breakpoint (``fixed``) or an end, and never so that an element gets shorter than
    ``min_size``.
    """
    out = np.array(bounds, dtype=float)
    length = float(out[-1])
    for i in range(1, out.size - 1):
        if not (refine[i - 1] or refine[i]):
            continue
        if any(abs(out[i] - s) <= MERGE * length for s in fixed):
            continue
        near = [k for k in snap_to if 0 < abs(k - out[i]) < rule.min_size]
        if not near:
            continue
        k = min(near, key=lambda k: abs(k - out[i]))
        if k - out[i - 1] >= rule.min_size and out[i + 1] - k >= rule.min_size:
            out[i] = k
    return out


def _merged(plan, coarse, calm, rule, fixed, estimates, length) -> list[tuple[float, float, int]]:
    """Return the planned elements with coarse neighbours merged.

    ``coarse[k]``: element k is untouched by this pass and below the coarsening threshold; two
    such neighbours at their fewest nodes merge into one with the same unknowns.  ``calm[k]``:
    element k is below the coarsening threshold and not refined in this pass; two such neighbours
    across a breakpoint that holds no anchor (``estimates.anchors`` known; a kink that is no
    contact point, such as the deepest cut between two rows, does not hold one) merge into one
    with the nodes of the larger, the rule's other coarsening.  Each merges at most once per
    pass; never across a scene breakpoint, nor next to a known kink at their fewest nodes.
    """
    kinks, anchors = estimates.kinks, estimates.anchors
    out: list[tuple[float, float, int]] = []
    k = 0
    while k < len(plan):
        if k + 1 < len(plan) and calm[k] and calm[k + 1]:
            (lo, mid, n1), (_, hi, n2) = plan[k][0], plan[k + 1][0]
            scene = any(abs(mid - s) <= MERGE * length for s in fixed)
            pinned = scene or any(abs(mid - s) <= rule.min_size for s in kinks)
            held = anchors is None or any(abs(mid - s) <= rule.min_size for s in anchors)
            fewest = coarse[k] and coarse[k + 1] and n1 == n2 == rule.min_nodes
            if not scene and not held:
                out.append((lo, hi, max(n1, n2)))
                k += 2
                continue
            if fewest and not pinned and n1 + n2 - 1 <= rule.max_nodes:
                out.append((lo, hi, n1 + n2 - 1))
                k += 2
                continue
        out.extend(plan[k])
        k += 1
    return out
