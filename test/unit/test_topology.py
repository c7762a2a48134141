"""The linking number Lk = Tw + Wr (dlo_ros/solver/contact/topology.py) against closed forms: a circle with k
turns of twist, a helix's twist and Fuller writhe, a flat figure-eight, Călugăreanu's theorem on a
trefoil ribbon (Gauss linking with its push-off, an independent integer), Fuller's formula against the
Gauss writhe on a deformation that does not pass through itself."""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.solver.contact import topology as TP


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def closed(a: np.ndarray) -> np.ndarray:
    """Rows with the first repeated at the end (``twist`` walks a closed ribbon back to its start)."""
    return np.vstack([a, a[:1]])


def circle(n: int = 400):
    u = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    x = np.stack([np.cos(u), np.sin(u), 0 * u], 1)
    t = np.stack([-np.sin(u), np.cos(u), 0 * u], 1)
    return u, x, t, x.copy(), np.cross(t, x)  # u, points, tangent, normal, binormal


@pytest.mark.parametrize("k", [1, -2, 3])
def test_circle_with_k_turns_of_twist(k):
    """Tw = k, Wr = 0 and the ribbon's edge links the centreline k times."""
    u, x, t, nrm, b = circle()
    d1 = np.cos(k * u)[:, None] * nrm + np.sin(k * u)[:, None] * b
    assert TP.twist(closed(t), closed(d1)) == pytest.approx(k, abs=1e-12)
    assert TP.gauss_writhe(x, closed=True) == pytest.approx(0.0, abs=1e-12)
    assert TP.gauss_linking(x, x + 0.01 * d1) == pytest.approx(k, abs=1e-9)


def helix(turns: float, radius: float, pitch: float, n: int = 2001):
    """Points, unit tangents and Frenet normals of x = (a cos φ, a sin φ, b φ), φ ∈ [0, 2π turns]."""
    phi = np.linspace(0.0, 2 * np.pi * turns, n)
    c = np.hypot(radius, pitch)
    x = np.stack([radius * np.cos(phi), radius * np.sin(phi), pitch * phi], 1)
    t = np.stack([-radius * np.sin(phi), radius * np.cos(phi), pitch + 0 * phi], 1) / c
    normal = -np.stack([np.cos(phi), np.sin(phi), 0 * phi], 1)
    return x, t, normal, pitch / c


@pytest.mark.parametrize("turns,pitch", [(3, 0.3), (2.5, 1.5)])
def test_helix_twist_and_writhe(turns, pitch):
    """A helix whose tangent makes the angle θ with its axis: the Frenet ribbon's twist is n cos θ (torsion
    b/(a²+b²) over arc 2π√(a²+b²) per turn), Fuller's writhe from the straight axis n (1 − cos θ) (the
    tangent circle's cap), and their sum n: the normal turns once about the axis per turn."""
    x, t, normal, cos_theta = helix(turns, 1.0, pitch)
    axis = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    tw, wr = TP.twist(t, normal), TP.fuller_writhe_change(axis, t)
    # both O(h²): 2000 samples over ≤ 3 turns leave < 1e-5 turns
    assert tw == pytest.approx(turns * cos_theta, abs=1e-5)
    assert wr == pytest.approx(turns * (1 - cos_theta), abs=1e-5)
    assert tw + wr == pytest.approx(turns, abs=1e-5)
    assert TP.min_alignment(axis, t) > 0  # never antipodal: Fuller's formula holds (mod 2)


@pytest.mark.parametrize("lift", [1e-2, -1e-2])
def test_flat_figure_eight(lift):
    """A figure-eight in the plane with its crossing lifted by ``lift``: Wr → ±1 (every projection but the
    in-plane ones sees one crossing of that sign), a ribbon lying flat has no twist, yet its edge links
    the centreline once: Tw alone is not invariant, Tw + Wr is."""
    u = np.linspace(0.0, 2 * np.pi, 800, endpoint=False)
    x = np.stack([np.sin(2 * u), np.sin(u), lift * np.cos(u)], 1)
    wr = TP.gauss_writhe(x, closed=True)
    assert abs(abs(wr) - 1) < 0.02 and np.sign(wr) == -np.sign(lift)
    t = unit(np.roll(x, -1, 0) - np.roll(x, 1, 0))
    up = np.array([0.0, 0.0, 1.0])
    d1 = unit(np.cross(t, np.cross(up, t)))  # in-plane-normal director: flat ribbon
    tw = TP.twist(closed(t), closed(d1))
    assert abs(tw) < 0.02
    assert TP.gauss_linking(x, x + 1e-3 * d1) == pytest.approx(round(tw + wr), abs=1e-6)
    assert tw + wr == pytest.approx(round(tw + wr), abs=2e-3)


def test_calugareanu_on_a_trefoil_ribbon():
    """Lk of the centreline and its push-off along d1 (Gauss linking integral: an integer) equals Tw + Wr."""
    u = np.linspace(0.0, 2 * np.pi, 1200, endpoint=False)
    x = np.stack([np.sin(u) + 2 * np.sin(2 * u), np.cos(u) - 2 * np.cos(2 * u), -np.sin(3 * u)], 1)
    t = unit(np.roll(x, -1, 0) - np.roll(x, 1, 0))
    ref = np.array([0.3, 0.2, 1.0])
    d1 = unit(ref - np.sum(ref * t, 1)[:, None] * t)
    lk = TP.gauss_linking(x, x + 0.01 * d1)
    assert lk == pytest.approx(round(lk), abs=1e-9) and round(lk) != 0
    assert TP.twist(closed(t), closed(d1)) + TP.gauss_writhe(x, closed=True) == pytest.approx(lk, abs=1e-5)


def coil(r: float, n: int = 800, m: int = 5):
    """A ring of radius 1 wound m times by a coil of radius r: an unknot for r < 1, no self-passage as r
    grows from 0."""
    u = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    rho = 1 + r * np.cos(m * u)
    x = np.stack([rho * np.cos(u), rho * np.sin(u), r * np.sin(m * u)], 1)
    return x, unit(np.roll(x, -1, 0) - np.roll(x, 1, 0))


def test_fuller_against_gauss_writhe():
    """Fuller's formula between two curves, step by step along a deformation that never passes through
    itself, sums to the change of the absolute Gauss writhe."""
    radii = np.linspace(0.0, 0.4, 9)
    shapes = [coil(r) for r in radii]
    fuller = sum(TP.fuller_writhe_change(closed(a[1]), closed(b[1])) for a, b in zip(shapes, shapes[1:]))
    gauss = TP.gauss_writhe(shapes[-1][0], closed=True) - TP.gauss_writhe(shapes[0][0], closed=True)
    assert abs(gauss) > 0.5
    assert fuller == pytest.approx(gauss, abs=2e-3)


def ribbon(points: np.ndarray, turns: float) -> np.ndarray:
    """Frames (n, 3, 3) (columns t, d1, d2) along the polyline ``points``: d1 transported without twist
    from d1 = e_z ⊥ t at the start (``topology.transport``: discrete twist exactly 0), then turned
    uniformly by ``turns`` along the samples (Tw = turns exactly)."""
    seg = unit(np.diff(points, axis=0))
    t = unit(np.vstack([seg[:1], seg[:-1] + seg[1:], seg[-1:]]))
    d = np.empty_like(t)
    d[0] = unit(np.cross(t[0], np.cross([0.0, 0.0, 1.0], t[0])))
    for i in range(1, len(t)):
        d[i] = unit(TP.transport(d[i - 1], t[i - 1], t[i]))
    e = np.cross(t, d)
    a = 2 * np.pi * turns * np.linspace(0.0, 1.0, len(t))[:, None]
    d1 = np.cos(a) * d + np.sin(a) * e
    return np.stack([t, d1, np.cross(t, d1)], axis=2)


def straight_ribbon(turns: float, n: int = 401, bow: float = 0.0):
    """A rod along x of length ≈ 1 with ``turns`` of twist, bowed by ``bow`` in y (a half sine)."""
    s = np.linspace(0.0, 1.0, n)
    x = np.stack([s, bow * np.sin(np.pi * s), 0 * s], 1)
    return x, ribbon(x, turns)


def test_clamp_turns_are_accounted_and_jumps_are_not():
    """A clamp turned 40° (the rod's twist follows): ΔLk explained (0 left); the bow growing: 0 left; the
    twist released by two whole turns while the centreline does not move: −2 left, a jump."""
    x0, f0 = straight_ribbon(3.0)
    x1, f1 = straight_ribbon(3.0 + 40 / 360)
    turned = TP.link_change(x0, f0, x1, f1)
    assert turned.clamps == pytest.approx(40 / 360, abs=1e-12) and not turned.jumped
    assert turned.unexplained == pytest.approx(0.0, abs=1e-9)
    x2, f2 = straight_ribbon(3.0, bow=0.1)
    bowed = TP.link_change(x0, f0, x2, f2)
    assert bowed.method == "fuller" and abs(bowed.unexplained) < 1e-3 and not bowed.jumped
    x3, f3 = straight_ribbon(1.0)
    released = TP.link_change(x0, f0, x3, f3)
    assert released.jumped and released.unexplained == pytest.approx(-2.0, abs=1e-9)


def looped(lift: float, n: int = 801) -> np.ndarray:
    """A straight rod along x with one loop of radius 0.08 in the middle, its second pass lifted by
    ``lift`` over the first: the loop's far side runs along −x, antipodal to the straight rod."""
    rho, a = 0.08, 0.3
    s = np.linspace(0.0, 0.6 + 2 * np.pi * rho, n)
    th = np.clip((s - a) / rho, 0.0, 2 * np.pi)
    x = np.where(s < a, s, np.where(th < 2 * np.pi, a + rho * np.sin(th), s - 2 * np.pi * rho))
    return np.stack([x, rho * (1 - np.cos(th)), lift * th / (2 * np.pi)], 1)


def test_ray_writhe_fallback():
    """A loop formed in a twisted rod (tangents antipodal to the straight rod's on its far side): Fuller's
    formula is not used; the ray-closed Gauss writhes see the loop's writhe ≈ ±1, so twist that went into
    the loop is explained, and a turn lost on top of that is a jump."""
    straight = looped(0.0) * np.array([1.0, 0.0, 0.0])  # same samples, no loop: x only
    straight[:, 0] = np.linspace(0.0, straight[-1, 0] + 2 * np.pi * 0.08, len(straight))
    loop = looped(0.02)
    writhe = TP.ray_writhe(loop, ribbon(loop, 0.0)[:, :, 0])
    assert abs(abs(writhe) - 1) < 0.1
    f0 = ribbon(straight, 2.0)
    kept = TP.link_change(straight, f0, loop, ribbon(loop, 2.0 - writhe))
    assert kept.method == "rays" and abs(kept.unexplained) < 1e-3, kept
    lost = TP.link_change(straight, f0, loop, ribbon(loop, 1.0 - writhe))
    assert lost.method == "rays" and lost.jumped and lost.unexplained == pytest.approx(-1.0, abs=1e-3)


def test_clamp_turns_accumulate_past_half_a_turn():
    """Three requested steps of 100° about the tangent sum to 300° (one comparison would read −60°)."""
    def frame(deg: float) -> np.ndarray:
        a = np.radians(deg)
        return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])

    turns = TP.ClampTurns({"right": frame(0)})
    for deg in (100, 200, 300):
        turns = turns.advanced({"right": frame(deg)})
    assert turns.turns["right"] == pytest.approx(np.radians(300), abs=1e-12)
    assert TP.clamp_turn(frame(0), frame(300)) == pytest.approx(np.radians(-60), abs=1e-12)
    assert turns.committed().turns == {} and TP.ClampTurns(turns.frames).advanced({"right": frame(300)}).turns["right"] == 0.0
