"""The cable as a chain of capsules (dlo_ros/node/capsules.py): containment and tightness.

Each curve is known in closed form (a straight line, a circular arc, a helix, a catenary, a
prolate cycloid with a tight loop) or is a solved default_cable.  The chain is built from N samples
of it; the checks use an independent sampling 20 times finer (the coarse samples are every 20th
fine sample), so they see the curve between the samples the chain was built from:

* containment: points of the tube (on its surface, halfway in, and on the centreline) around every
  fine sample lie within R of some capsule's axis;
* tightness: points on every capsule's surface (cylinder and both end spheres) lie within r + p
  (+1e-12) of the fine polyline of the capsule's own stretch of cable (an upper bound of the
  distance to the whole curve);
* the chain's deviation bound holds: every fine sample is within ``deviation`` of its chord.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest

from dlo_ros.node.capsules import (
    MAX_TURN,
    CapsuleChain,
    CapsuleLimitError,
    capsule_chain,
)

FINE = 20  # fine samples per coarse interval
TOL = 1e-12


# ---- curves -------------------------------------------------------------------------------------


def line(t: np.ndarray) -> np.ndarray:
    """A straight 0.8 m cable along (1, 2, -0.5)."""
    d = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    return np.array([0.1, -0.2, 0.3]) + 0.8 * t[:, None] * d


def arc(t: np.ndarray) -> np.ndarray:
    """Three quarters of a circle of radius 0.15 m, tilted out of the x-y plane."""
    a = 1.5 * np.pi * t
    return np.stack([0.15 * np.cos(a), 0.15 * np.sin(a) * 0.8, 0.15 * np.sin(a) * 0.6], axis=1)


def helix(t: np.ndarray) -> np.ndarray:
    """Three turns of a helix, radius 0.05 m, pitch 0.04 m."""
    a = 6 * np.pi * t
    return np.stack([0.05 * np.cos(a), 0.05 * np.sin(a), 0.04 * a / (2 * np.pi)], axis=1)


def catenary(t: np.ndarray) -> np.ndarray:
    """A catenary z = a cosh(x/a) over x in [-0.3, 0.3] m, a = 0.12 m (a deep sag)."""
    x = 0.6 * t - 0.3
    return np.stack([x, 0.0 * x, 0.12 * np.cosh(x / 0.12)], axis=1)


def loop(t: np.ndarray) -> np.ndarray:
    """A prolate cycloid with one tight loop (least radius of curvature about 11 mm)."""
    a = -0.5 * np.pi + 3 * np.pi * t
    c, b = 0.05, 1.6
    return np.stack([c * (a - b * np.sin(a)), c * (1 - b * np.cos(a)), 0.01 * a], axis=1)


@dataclass(frozen=True)
class Case:
    """A curve sampled at n points, the string radius r and the padding p [m]."""

    curve: object
    n: int
    r: float
    p: float


CASES = {
    "line": Case(line, 51, 0.005, 0.002),
    "arc": Case(arc, 61, 0.005, 0.002),
    "arc_thin_padding": Case(arc, 201, 0.004, 0.0004),
    "helix": Case(helix, 301, 0.003, 0.002),
    "catenary": Case(catenary, 51, 0.005, 0.002),
    "loop": Case(loop, 301, 0.002, 0.002),
    "loop_no_radius": Case(loop, 301, 0.0, 0.003),
}


def sampled(case: Case) -> tuple[np.ndarray, np.ndarray]:
    """(coarse (n, 3), fine (20 (n - 1) + 1, 3)) samples; coarse = fine[::20]."""
    fine = case.curve(np.linspace(0.0, 1.0, FINE * (case.n - 1) + 1))
    return fine[::FINE], fine


# ---- independent geometry -----------------------------------------------------------------------


def segment_distance(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (len(x), len(a)) from points x to the segments a_k b_k."""
    ab = b - a
    ax = x[:, None, :] - a[None, :, :]
    den = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(np.sum(ax * ab[None], axis=2) / den[None], 0.0, 1.0)
    return np.linalg.norm(ax - t[..., None] * ab[None], axis=2)


def directions(count: int, seed: int) -> np.ndarray:
    """Unit vectors, seeded."""
    u = np.random.default_rng(seed).normal(size=(count, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def normal_ring(tangent: np.ndarray, count: int) -> np.ndarray:
    """Unit vectors (len(tangent), count, 3) around each tangent, in its normal plane."""
    t = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
    helper = np.where(np.abs(t[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(t, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(t, e1)
    ang = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    return np.cos(ang)[None, :, None] * e1[:, None] + np.sin(ang)[None, :, None] * e2[:, None]


def tube_points(fine: np.ndarray, r: float) -> np.ndarray:
    """Points of the tube of radius r: on its surface and halfway in, and the centreline."""
    tangent = np.gradient(fine, axis=0)
    ring = normal_ring(tangent, 16)  # the tube's surface across the string
    rand = np.broadcast_to(directions(8, 1)[None], (len(fine), 8, 3))  # any other direction
    dirs = np.concatenate([ring, rand], axis=1)
    out = [fine]
    for rho in (r, 0.5 * r):
        out.append((fine[:, None, :] + rho * dirs).reshape(-1, 3))
    return np.concatenate(out)


def capsule_surface(a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Points on the surface of the capsule a-b: its cylinder and both end spheres."""
    axis = b - a
    n = np.linalg.norm(axis)
    ring = (
        normal_ring(axis[None], 24)[0]
        if n > 0
        else directions(24, 2)  # a sphere: any ring will do
    )
    t = np.linspace(0.0, 1.0, 41)
    side = a + t[:, None, None] * axis + radius * ring[None]
    caps = np.concatenate([a + radius * directions(300, 3), b + radius * directions(300, 4)])
    return np.concatenate([side.reshape(-1, 3), caps])


# ---- the checks ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Margins:
    """Worst margins [m] of one chain against its fine curve (all ≥ 0 when it is right)."""

    containment: float  # min over tube points of R - distance to the nearest capsule axis
    tightness: float  # min over capsule-surface points of r + p - distance to the curve
    deviation: float  # min over fine samples of the claimed deviation - distance to the chord
    true_deviation: float  # the largest distance of a fine sample from its chord [m]


def margins(chain: CapsuleChain, fine: np.ndarray, r: float, p: float) -> Margins:
    """Measure containment, tightness and the deviation bound against the fine samples."""
    a, b = chain.starts, chain.ends
    tube = tube_points(fine, r)
    chunks = range(0, len(tube), 20000)  # bounded memory: points × capsules distances
    nearest = np.concatenate([segment_distance(tube[k : k + 20000], a, b).min(1) for k in chunks])
    tight, dev = np.inf, 0.0
    for k in range(chain.count):
        lo, hi = FINE * chain.indices[k], FINE * chain.indices[k + 1]
        stretch = fine[lo : hi + 1]
        surface = capsule_surface(a[k], b[k], chain.radius)
        to_curve = segment_distance(surface, stretch[:-1], stretch[1:]).min(axis=1)
        tight = min(tight, r + p - float(to_curve.max()))
        dev = max(dev, float(segment_distance(stretch, a[k : k + 1], b[k : k + 1]).max()))
    return Margins(chain.radius - float(nearest.max()), tight, chain.deviation - dev, dev)


@pytest.mark.parametrize("name", list(CASES))
def test_the_capsules_contain_the_tube_and_stay_within_the_padding(name):
    case = CASES[name]
    coarse, fine = sampled(case)
    chain = capsule_chain(coarse, case.r, case.p)
    assert chain.radius == pytest.approx(case.r + case.p / 2, abs=0)
    assert 0.0 <= chain.deviation <= case.p / 2
    assert chain.reach <= case.r + case.p
    np.testing.assert_array_equal(chain.joints, coarse[chain.indices])
    np.testing.assert_array_equal(chain.joints[[0, -1]], coarse[[0, -1]])
    m = margins(chain, fine, case.r, case.p)
    assert m.containment >= -TOL, m
    assert m.tightness >= -TOL, m
    assert m.deviation >= -TOL, m


# ---- counts -------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 3, 51, 1000])
def test_a_straight_cable_is_one_capsule(n):
    chain = capsule_chain(line(np.linspace(0.0, 1.0, n)), 0.005, 0.001)
    assert chain.count == 1
    assert chain.deviation == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(chain.lengths, [0.8], rtol=1e-12)


def optimal_arc_count(radius: float, angle: float, bound: float) -> int:
    """The fewest chords of a circular arc that stay within ``bound`` of it."""
    return math.ceil(angle / (2 * math.acos(1 - bound / radius)))


@pytest.mark.parametrize("p", [0.008, 0.004, 0.002, 0.001, 0.0005])
def test_an_arc_gets_close_to_the_fewest_chords(p):
    """The chords of an arc held within p/2 number at least the optimum (the bound is real) and
    at most 30 % more (the allowance for the curve between samples is not wasteful)."""
    chain = capsule_chain(arc(np.linspace(0.0, 1.0, 601)), 0.005, p)
    best = optimal_arc_count(0.15, 1.5 * np.pi, p / 2)
    assert best <= chain.count <= math.ceil(1.3 * best), (chain.count, best)


def test_more_capsules_where_it_bends():
    """A straight run, a quarter circle of radius 0.1 m, a straight run: the capsules' joints
    crowd in the bend; each straight run is (most of) one capsule."""
    a = np.linspace(0.0, np.pi / 2, 61)
    bend = np.stack([0.1 * np.sin(a), 0.1 * (1 - np.cos(a)), 0 * a], axis=1)
    run_in = np.stack([np.linspace(-0.5, 0.0, 51)[:-1], np.zeros(50), np.zeros(50)], axis=1)
    run_out = np.stack([np.full(50, 0.1), np.linspace(0.1, 0.6, 51)[1:], np.zeros(50)], axis=1)
    chain = capsule_chain(np.concatenate([run_in, bend, run_out]), 0.005, 0.002)
    lengths = chain.lengths
    assert lengths[0] >= 0.45 and lengths[-1] >= 0.45, lengths
    assert chain.count >= 5 and np.all(lengths[1:-1] < 0.05), lengths


# ---- the solver's shape -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def default_cable_fine():
    """n -> default_cable solved cold (full model, interpreted) at 20 (n - 1) + 1 output points."""
    from dlo_ros.scene import load_scene
    from dlo_ros.solver import make_solver

    scene = load_scene("default_cable")
    solved: dict[int, np.ndarray] = {}

    def fine(n: int) -> np.ndarray:
        if n not in solved:
            options = replace(scene.options, model="full", output_points=FINE * (n - 1) + 1)
            solver = make_solver(scene.problem, options, compile="off")
            try:
                result = solver.solve()
            finally:
                solver.close()
            assert result.status == "ok", result.message
            solved[n] = result.points
        return solved[n]

    return fine, float(scene.problem.string.radius)


@pytest.mark.parametrize(
    "n, p", [(51, 0.01), (51, 0.004), (51, 0.002), (201, 0.001), (201, 0.0004)]
)
def test_the_solved_default_cable(default_cable_fine, n, p):
    """The node's case: the chain from the n published points of a solved cable, checked on the
    solver's own centreline 20 times finer.  At the default 51 points the arcs next to the grips
    stray up to 0.47 mm from their samples' segment (0.91 mm with the safety factor): a padding
    under about 1.8 mm needs more output points."""
    solve, r = default_cable_fine
    fine = solve(n)
    chain = capsule_chain(fine[::FINE], r, p)
    m = margins(chain, fine, r, p)
    assert m.containment >= -TOL and m.tightness >= -TOL and m.deviation >= -TOL, m
    assert 1 < chain.count < n - 1
    if n == 51:
        with pytest.raises(ValueError, match="^padding: .* too small for the sampling"):
            capsule_chain(fine[::FINE], r, 0.0015)


# ---- inputs, the cap, the dataclass -------------------------------------------------------------


@pytest.mark.parametrize(
    "points, radius, padding, word",
    [
        (np.zeros((1, 3)), 0.005, 0.002, "points"),
        (np.zeros((5, 2)), 0.005, 0.002, "points"),
        (np.zeros(6), 0.005, 0.002, "points"),
        (np.zeros((4, 3)), 0.005, 0.002, "points"),  # one distinct point
        (np.array([[0, 0, 0], [np.nan, 0, 0], [1, 0, 0]]), 0.005, 0.002, "points"),
        (np.array([[0, 0, 0], [1, np.inf, 0]]), 0.005, 0.002, "points"),
        (np.array([[0, 0, 0], [1, 0, 0]]), 0.005, 0.0, "padding"),
        (np.array([[0, 0, 0], [1, 0, 0]]), 0.005, -0.001, "padding"),
        (np.array([[0, 0, 0], [1, 0, 0]]), 0.005, np.nan, "padding"),
        (np.array([[0, 0, 0], [1, 0, 0]]), -0.001, 0.002, "radius"),
        (np.array([[0, 0, 0], [1, 0, 0]]), np.nan, 0.002, "radius"),
    ],
)
def test_bad_inputs_are_refused_naming_the_argument(points, radius, padding, word):
    with pytest.raises(ValueError, match=f"^{word}:"):
        capsule_chain(points, radius, padding)


@pytest.mark.parametrize("cap", [0, -1, 2.5])
def test_a_bad_cap_is_refused(cap):
    with pytest.raises(ValueError, match="^max_capsules:"):
        capsule_chain(line(np.linspace(0, 1, 5)), 0.005, 0.002, max_capsules=cap)


def test_a_corner_is_too_coarse_to_bound():
    """A turn over MAX_TURN between samples: the curve between them is unknown."""
    corner = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.05, 0.01, 0.0]])
    assert MAX_TURN < np.pi * 0.95
    with pytest.raises(ValueError, match="^points: .*turns by .* at point 1"):
        capsule_chain(corner, 0.005, 0.002)


def test_a_padding_below_the_sampling_is_refused():
    """Samples 0.1 rad apart on a 0.15 m circle: the arc between two strays about 0.19 mm (0.38
    mm with the safety factor) from their segment, more than a 0.2 mm padding's half."""
    with pytest.raises(ValueError, match="^padding: .* too small for the sampling"):
        capsule_chain(arc(np.linspace(0.0, 1.0, 48)), 0.005, 0.0002)


def test_the_cap_refuses_and_names_a_padding_that_fits():
    points = arc(np.linspace(0.0, 1.0, 201))
    full = capsule_chain(points, 0.005, 0.001)
    with pytest.raises(CapsuleLimitError, match="^max_capsules: .* needs") as caught:
        capsule_chain(points, 0.005, 0.001, max_capsules=5)
    err = caught.value
    assert isinstance(err, ValueError)
    assert err.needed == full.count and err.max_capsules == 5 and err.min_padding > 0.001
    fitted = capsule_chain(points, 0.005, err.min_padding, max_capsules=5)
    assert fitted.count <= 5
    # near the smallest: the optimum for 5 chords of the arc needs a padding of 2 ρ (1 - cos(θ/10))
    assert err.min_padding <= 1.3 * 2 * 0.15 * (1 - math.cos(1.5 * np.pi / 10))
    assert capsule_chain(points, 0.005, 0.001, max_capsules=full.count).count == full.count


def test_repeated_points_are_dropped_and_indices_refer_to_the_input():
    pts = line(np.linspace(0.0, 1.0, 4))
    doubled = np.repeat(pts, 2, axis=0)
    chain = capsule_chain(doubled, 0.005, 0.002)
    assert chain.count == 1 and list(chain.indices) == [0, 6]


def test_the_chain_is_read_only():
    chain = capsule_chain(arc(np.linspace(0, 1, 61)), 0.005, 0.002)
    with pytest.raises(ValueError):
        chain.joints[0, 0] = 1.0
    with pytest.raises(AttributeError):
        chain.radius = 1.0  # type: ignore[misc]
    assert chain.starts.shape == chain.ends.shape == (chain.count, 3)
    np.testing.assert_array_equal(chain.starts[1:], chain.ends[:-1])
