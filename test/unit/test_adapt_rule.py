"""The refinement decision (dlo_ros.solver.adapt.rule, #37) on synthetic estimates.

Each branch against the count it must give by hand (the geometric-decay extrapolation, the
split point), the caps, and the hysteresis: with estimates that follow a model of the error
(spectral on smooth elements, algebraic on one holding the kink), the rule applied to its own
output reaches a fixed point and never revisits a mesh, also when the estimates sit just at a
threshold; the scene's breakpoints are always kept.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dlo_ros.solver.adapt.rule import ElementEstimates, RefinementRule, next_mesh, unknowns
from dlo_ros.solver.build.mesh import MeshSpec

L = 1.0
DELTA = 1e-5
RULE = RefinementRule(tolerance=DELTA, min_size=0.01, max_nodes=24, max_unknowns=120)


def estimates(errors, decay, kinks=()) -> ElementEstimates:
    return ElementEstimates(np.array(errors, float), np.array(decay, float), tuple(kinks))


def test_a_smooth_element_gets_the_nodes_its_decay_predicts():
    spec = MeshSpec((0.5,), (8, 8))
    # element 0: 100 δ/2 … needs log(0.2 · δ/2 / e) / log 0.5 more nodes; element 1 in its band
    e0 = 100 * DELTA / 2
    out = next_mesh(spec, L, estimates([e0, 0.1 * DELTA / 2], [0.5, 0.5]), RULE)
    more = math.ceil(math.log(0.2 * (DELTA / 2) / e0) / math.log(0.5))
    assert out == MeshSpec((0.5,), (8 + more, 8))
    assert e0 * 0.5**more <= 0.2 * DELTA / 2 < e0 * 0.5 ** (more - 1)


def test_a_rough_element_is_split_at_its_middle_or_at_the_kink():
    spec = MeshSpec((), (12,))
    rough = estimates([DELTA], [0.97])
    assert next_mesh(spec, L, rough, RULE) == MeshSpec((0.5,), (7, 7))
    # a known kink: split there (whatever the decay), nodes shared out by length
    kinked = estimates([DELTA], [0.3], kinks=[0.41])
    assert next_mesh(spec, L, kinked, RULE) == MeshSpec((0.41,), (6, 9))
    # a kink closer than min_size to an end is no split: the decay decides
    near = estimates([DELTA], [0.97], kinks=[0.995])
    assert next_mesh(spec, L, near, RULE) == MeshSpec((0.5,), (7, 7))


def test_an_unresolved_contact_splits_its_element_whatever_its_estimate():
    """A point contact whose error the estimates do not bound (``unresolved``) splits the
    element holding it there, though every estimate sits far below its share, before any other
    element refines, and rather than at a kink nearer the middle; without it nothing changes."""
    spec = MeshSpec((0.3,), (12, 12))
    calm = [0.1 * DELTA / 2, 0.1 * DELTA / 2]
    assert next_mesh(spec, L, estimates(calm, [0.3, 0.3], kinks=[0.62]), RULE) is None
    held = ElementEstimates(np.array(calm), np.array([0.3, 0.3]), (0.62, 0.66), unresolved=(0.66,))
    assert next_mesh(spec, L, held, RULE) == MeshSpec((0.3, 0.66), (12, 8, 7))
    # the unknowns cap leaves room for one split: the unresolved contact's, not the worse element
    tight = RefinementRule(tolerance=DELTA, min_size=0.01, max_nodes=24, max_unknowns=25)
    worse = ElementEstimates(np.array([50 * DELTA, calm[1]]), np.array([0.97, 0.3]), (0.62,),
                             unresolved=(0.62,))  # fmt: skip
    out = next_mesh(spec, L, worse, tight)
    assert out is not None and 0.62 in out.breakpoints and 0.15 not in out.breakpoints, out


def test_a_breakpoint_next_to_a_snap_kink_moves_onto_it():
    """A contact point predicted closer to a breakpoint than min_size cannot be split at: the
    breakpoint moves there, when an element beside it refines; a scene's breakpoint stays."""
    spec = MeshSpec((0.5,), (8, 8))
    e = [DELTA, 0.1 * DELTA / 2]  # element 0 refines (smooth: more nodes), element 1 keeps
    moved = ElementEstimates(np.array(e), np.array([0.5, 0.5]), (0.503,), snap_to=(0.503,))
    out = next_mesh(spec, L, moved, RULE)
    assert out is not None and out.breakpoints == (0.503,), out
    assert out.counts[0] > 8 and out.counts[1] == 8
    # the scene's own breakpoint stays; so does one whose elements are both in their band
    assert next_mesh(spec, L, moved, RULE, fixed=(0.5,)).breakpoints == (0.5,)
    calm = ElementEstimates(np.full(2, 0.1 * DELTA / 2), np.array([0.5, 0.5]), (), (0.503,))
    assert next_mesh(spec, L, calm, RULE) is None
    # never so that an element gets shorter than min_size
    short = MeshSpec((0.5, 0.512), (8, 8, 8))
    far = ElementEstimates(np.array([DELTA, DELTA, 0.0]), np.full(3, 0.5), (), (0.503,))
    assert next_mesh(short, L, far, RULE).breakpoints == (0.5, 0.512)


def test_coarse_elements_lose_nodes_then_merge_but_never_across_the_scenes_breakpoint():
    tiny = 1e-4 * DELTA
    spec = MeshSpec((0.25, 0.5, 0.75), (10, 4, 4, 4))
    out = next_mesh(spec, L, estimates([tiny] * 4, [0.5] * 4), RULE, fixed=[0.75])
    # element 0 drops the nodes that keep it under 0.2 of its share (δ/4):
    # 1e-4 δ · 2^k ≤ 0.05 δ → k = 8, but no fewer than min_nodes (4)
    # elements 1 and 2 (4 nodes each) merge into 7 nodes; 0.75 is the scene's: 3 stays alone
    assert out == MeshSpec((0.25, 0.75), (4, 7, 4))
    # a kink at 0.5 pins that breakpoint as well
    pinned = next_mesh(spec, L, estimates([tiny] * 4, [0.5] * 4, [0.5]), RULE, fixed=[0.75])
    assert pinned == MeshSpec((0.25, 0.5, 0.75), (4, 4, 4, 4))


def test_the_caps():
    # more nodes than max_nodes: split instead
    big = estimates([1e6 * DELTA], [0.5])
    assert next_mesh(MeshSpec((), (20,)), L, big, RULE) == MeshSpec((0.5,), (11, 11))
    # no room for more unknowns: nothing changes
    full = MeshSpec(tuple(np.linspace(0.1, 0.9, 9)), (13,) * 10)
    assert unknowns(full.counts) == 121 > RULE.max_unknowns
    assert next_mesh(full, L, estimates([DELTA] * 10, [0.5] * 10), RULE) is None
    # elements shorter than 2 · min_size are not split; they gain 2 nodes while they may
    short = MeshSpec((0.015,), (6, 6))
    rough = estimates([DELTA, 0.1 * DELTA], [0.97, 0.5])
    assert next_mesh(short, L, rough, RULE) == MeshSpec((0.015,), (8, 6))


@pytest.mark.parametrize("rule", [RULE, RefinementRule(DELTA, share="each", max_unknowns=400)])
def test_bad_inputs_are_refused_with_the_field(rule):
    with pytest.raises(ValueError, match="refinement.errors: need 2 finite"):
        next_mesh(MeshSpec((0.5,), (6, 6)), L, estimates([1.0], [0.5]), rule)
    with pytest.raises(ValueError, match="refinement.decay"):
        next_mesh(MeshSpec((0.5,), (6, 6)), L, estimates([1.0, 1.0], [0.5, np.nan]), rule)
    with pytest.raises(ValueError, match="explicit counts"):
        next_mesh(MeshSpec((0.5,)), L, estimates([1.0, 1.0], [0.5, 0.5]), rule)
    with pytest.raises(ValueError, match="coarsen < target < refine"):
        next_mesh(MeshSpec(), L, estimates([1.0], [0.5]), RefinementRule(DELTA, coarsen=0.6))


KINK, RATE = 0.4123, 0.55


def modelled(spec: MeshSpec, scale: float) -> ElementEstimates:
    """Errors of a solution analytic but for a kink at KINK: scale · h · ρ^n on a smooth element,
    ρ = 0.55 h / L (spectral in h and n), scale · h³ · n⁻³ on the element holding the kink (its
    decay 0.97)."""
    b = np.concatenate([[0.0], spec.breakpoints, [L]])
    errors, decay = [], []
    for lo, hi, n in zip(b[:-1], b[1:], spec.counts):
        if lo + 1e-12 < KINK < hi - 1e-12:
            errors.append(scale * (hi - lo) ** 3 * n**-3.0)
            decay.append(0.97)
        else:
            rate = RATE * (hi - lo) / L
            errors.append(scale * (hi - lo) * rate**n)
            decay.append(rate)
    return estimates(errors, decay, [KINK])


def iterate(spec: MeshSpec, scale: float, fixed=()) -> list[MeshSpec]:
    seen = [spec]
    for _ in range(30):
        nxt = next_mesh(spec, L, modelled(spec, scale), RULE, fixed)
        if nxt is None:
            return seen
        assert nxt not in seen, f"the rule came back to {nxt}"  # a cycle
        seen.append(spec := nxt)
    raise AssertionError(f"no fixed point in 30 steps: {seen[-3:]}")


@pytest.mark.parametrize("scale", [1e-2, 1.0, 1e3])
def test_the_rule_reaches_a_fixed_point_and_keeps_the_scenes_breakpoints(scale):
    meshes = iterate(MeshSpec((0.8,), (10, 6)), scale, fixed=[0.8])
    last = meshes[-1]
    assert all(0.8 in m.breakpoints for m in meshes)
    assert KINK in last.breakpoints  # split at the kink on the way
    est = modelled(last, scale)
    share = DELTA * np.diff(np.concatenate([[0.0], last.breakpoints, [L]]))
    # every element ends in its band: ≤ refine · share, and ≥ coarsen · share unless it cannot
    # lose a node (at min_nodes, or one node fewer would pass the target)
    assert np.all(est.errors <= RULE.refine * share)
    for e, rate, b, n in zip(est.errors, est.decay, share, last.counts):
        assert e >= RULE.coarsen * b or n == RULE.min_nodes or e / rate > RULE.target * b


def test_estimates_just_at_the_thresholds_change_nothing():
    spec = MeshSpec((0.5,), (8, 8))
    share = DELTA * 0.5
    for factor in (RULE.refine, RULE.coarsen):
        at = estimates([factor * share] * 2, [0.5] * 2)
        assert next_mesh(spec, L, at, RULE) is None
    # just above the refine threshold: refined once to the target, then (estimates following
    # the decay) it stays
    e = RULE.refine * share * (1 + 1e-9)
    once = next_mesh(spec, L, estimates([e, e], [0.5] * 2), RULE)
    assert once == MeshSpec((0.5,), (10, 10))
    after = e * 0.5**2
    assert RULE.coarsen * share < after <= RULE.target * share
    assert next_mesh(once, L, estimates([after, after], [0.5] * 2), RULE) is None


def with_anchors(errors, decay, kinks, anchors) -> ElementEstimates:
    return ElementEstimates(
        np.array(errors, float), np.array(decay, float), tuple(kinks), anchors=tuple(anchors)
    )


def test_calm_elements_merge_across_a_breakpoint_that_holds_nothing():
    """Two elements far below their share, split by a breakpoint no kink holds (one left behind
    by a contact that moved on): one element with the nodes of the larger."""
    tiny = 1e-4 * DELTA
    spec = MeshSpec((0.3, 0.45, 0.7), (8, 10, 12, 8))
    calm = with_anchors([tiny, tiny, tiny, DELTA * 0.1], [0.1] * 4, [], [0.7])
    out = next_mesh(spec, L, calm, RULE)
    # 0.3 and 0.45 hold nothing: 0 and 1 merge, then 2 stays (each merges once per pass); 0.7
    # holds an anchor.  Nodes: coarsened by the decay first (down to min_nodes 4), then merged
    assert out is not None and out.breakpoints == (0.45, 0.7), out
    assert unknowns(out.counts) < unknowns(spec.counts)
    # without the contact points (a cold solve's check) only the old merge of fewest nodes
    unknown = estimates([tiny, tiny, tiny, DELTA * 0.1], [0.1] * 4)
    assert next_mesh(spec, L, unknown, RULE).breakpoints == (0.3, 0.45, 0.7)
    held = with_anchors([tiny] * 4, [0.1] * 4, [], [0.3, 0.45, 0.7])
    assert next_mesh(spec, L, held, RULE).breakpoints == (0.3, 0.45, 0.7)
