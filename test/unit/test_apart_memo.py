"""``contact/apart_memo.py``: a proof of "apart" carried to the shapes near the one it was made on.

* a memo's answer is ``certainly_apart``'s statement: never apart where ``candidate_pairs`` finds a
  pair, on arcs moved, bent and folded by growing amounts (most moves small enough to be covered,
  the largest not);
* it is used: a gentle shape moved a little is covered (no new proof), and a shape proved apart is
  kept only when its own proof covers it (the subsample test's inequalities at no move);
* a stream's self-pass check with the solver's memo gives the results it gives without one.
"""

from __future__ import annotations

import numpy as np

from dlo_ros.solver.contact import apart_memo as AM
from dlo_ros.solver.contact import self_contact as SC
from dlo_ros.solver.results import self_pass as SP

L = 1.0


def arc(s: np.ndarray, radius: float) -> np.ndarray:
    """Points of a planar arc of ``radius`` along s."""
    angle = s / radius
    return np.stack([radius * np.sin(angle), radius * (1 - np.cos(angle)), 0 * s], axis=1)


def test_memo_never_claims_apart_where_a_candidate_is():
    geometry = SC.contact_geometry(L, 0.005, grip_s=(0.0, L))
    s = geometry.s
    base = arc(s, 0.4)
    assert SC.certainly_apart(base, geometry)
    apart, proof = AM.prove(base, geometry)
    assert apart and proof is not None and AM.covers(proof, base, geometry)
    covered = refused = 0
    rng = np.random.default_rng(3)
    for amount in (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 0.05, 0.2, 0.5):
        for _ in range(6):
            # a rigid move, a smooth bend and a fold towards closing the arc on itself
            shift = rng.normal(size=3) * amount
            wave = np.sin(np.pi * s / L * rng.integers(1, 4))
            bend = np.outer(wave, rng.normal(size=3)) * amount
            fold = arc(s, 0.4 / (1 + 40 * amount)) - base
            for moved in (base + shift, base + bend, base + fold, base + shift + bend + fold):
                said = AM.covers(proof, moved, geometry)
                assert not (said and SC.candidate_pairs(moved, geometry)), amount
                covered += said
                refused += not said
    assert covered > 0 and refused > 0
    # another sampling, a non-finite point: not covered
    assert not AM.covers(proof, base, SC.contact_geometry(L, 0.004, grip_s=(0.0, L)))
    broken = base.copy()
    broken[7, 1] = np.nan
    assert not AM.covers(proof, broken, geometry)


def test_memo_keeps_its_proof_while_it_covers(monkeypatch):
    geometry = SC.contact_geometry(L, 0.005, grip_s=(0.0, L))
    s = geometry.s
    memo = AM.ApartMemo()
    proofs = []
    prove = AM.prove

    def counted(points, geo):
        proofs.append(1)
        return prove(points, geo)

    monkeypatch.setattr(AM, "prove", counted)
    for k in range(20):  # an arc bending slowly: 20 shapes, a few proofs
        assert memo.apart(arc(s, 0.6 - 0.002 * k) + 1e-4 * k, geometry)
    assert 1 <= len(proofs) < 5
    loop = arc(s, 0.14)  # closes on itself: not apart, and the memo's proof does not cover it
    assert SC.candidate_pairs(loop, geometry) and not memo.apart(loop, geometry)


def test_stream_self_pass_with_memo_as_without():
    geometry = SC.contact_geometry(L, 0.005, grip_s=(0.0, L))
    s = geometry.s
    memo = AM.ApartMemo()
    for k in range(40):  # an arc closing into a loop that passes through itself
        pts = arc(s, 0.5 * (1 - k / 45))
        with_memo = SP.self_pass(pts, geometry, 0.005, memo)
        plain = SP.self_pass(pts, geometry, 0.005)
        assert with_memo == plain, k


def test_linear_bound_never_claims_apart_where_a_candidate_is():
    """Samples as a linear map of tangents (x_i = Σ_j W_ij T_j: piecewise constant tangents on M
    cells, integrated exactly): the tangents' move alone settles most small moves, never one that
    brings a candidate pair, and the samples are worked out only when it does not settle."""
    geometry = SC.contact_geometry(L, 0.005, grip_s=(0.0, L))
    s = geometry.s
    cells = 300
    ds = L / cells

    def rows_at(s: np.ndarray) -> np.ndarray:
        return np.clip((s[:, None] - ds * np.arange(cells)[None, :]) / ds, 0.0, 1.0) * ds

    rows = rows_at(s)
    mid = ds * (np.arange(cells) + 0.5)

    def tangents(curvature: float, wobble: np.ndarray) -> np.ndarray:
        angle = curvature * mid
        t = np.stack([np.cos(angle), np.sin(angle), 0 * mid]) + wobble
        return t / np.linalg.norm(t, axis=0)

    memo = AM.ApartMemo()
    base = tangents(2.5, np.zeros((3, cells)))
    assert memo.apart_linear(geometry, base, lambda: rows @ base.T, lambda: rows)
    rng = np.random.default_rng(5)
    sampled = settled = crossing = 0
    for amount in (1e-5, 1e-4, 1e-3, 1e-2, 0.05, 0.2):
        for k in range(8):
            wobble = np.outer(rng.normal(size=3), np.sin(np.pi * mid * (k % 3 + 1))) * amount
            t = tangents(2.5 + 60 * amount * (k % 2), wobble)
            asked = []

            def points(t=t, asked=asked):
                asked.append(1)
                return rows @ t.T

            said = memo.apart_linear(geometry, t, points, lambda: rows)
            pts = rows @ t.T
            found = SC.candidate_pairs(pts, geometry)
            assert not (said and found), (amount, k)
            assert said or found or not SC.certainly_apart(pts, geometry), (amount, k)
            crossing += bool(found)
            sampled += bool(asked)
            settled += not asked
    assert settled > 0 and sampled > 0 and crossing > 0
    # another sampling: the samples are asked for
    other = SC.contact_geometry(L, 0.004, grip_s=(0.0, L))
    rows_o = rows_at(other.s)
    asked = []
    assert memo.apart_linear(other, base, lambda: asked.append(1) or rows_o @ base.T, lambda: rows_o)
    assert asked
