"""Self-contact (#15): the paper's Fig. 2 loop with a string radius, against an independent discrete rod
with pairwise non-penetration constraints (test/reference/contact_rod.py), the unconstrained solve and
the strong-form equilibrium; the pair selection against brute force; the crossing-sign check.

Fig. 2: clamp at s = 0, the end s = L held by its tangent at (c, 0, 0), Rf/Rt = 100, no weight.  Without
self-contact the stable branch closes its loop through itself at c = 0.3 L (#15)."""
from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pytest
from support.problems import clamped_pair
from reference.contact_rod import solve_contact_rod
from reference.kirchhoff import blas_threads
from test_fig2_reference import closest_self_approach, distance_modulo_chord_rotation

from dlo_ros.solver import self_contact as SC
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

L, RF, RT, R = 1.0, 1.0, 0.01, 0.01 * 1.0
ORDER, PAIRS = 16, 16
STRAIGHT = (0.0, 0.0, 0.0, 1.0)


def fig2(c: float, radius: float):
    p = clamped_pair(right=(c, 0.0, 0.0), bend=RF, twist=RT, modes=("clamp", "tangent"))
    return replace(p, string=replace(p.string, radius=radius))


def solver(c: float, radius: float, pairs: int = PAIRS) -> ShapeSolver:
    return ShapeSolver(fig2(c, radius), SolverOptions(model="full", order=ORDER, self_contact_pairs=pairs),
                       compile="off")


def world_curvature_max(sol: ShapeSolver, z: np.ndarray) -> float:
    s = np.linspace(0.0, L, 2001)
    t = sol.model.tangents_at(z, s)
    return float(np.max(np.linalg.norm(np.gradient(t, s, axis=0), axis=1)))


def global_balance(result) -> tuple[float, float]:
    """|Σ F| [N] and |Σ (x × F + T)| [N·m] over the grip reactions and both sides of every contact."""
    force, moment = np.zeros(3), np.zeros(3)
    for name, w in result.grips.items():
        x = result.points[0] if name == "left" else result.points[-1]
        force += w.force
        moment += np.cross(x, w.force) + w.torque
    for c in result.self_contacts:
        force += c.force - c.force
        moment += np.cross(c.point_a, c.force) - np.cross(c.point_b, c.force)
    return float(np.linalg.norm(force)), float(np.linalg.norm(moment))


@pytest.fixture(scope="module")
def loops():
    """chord → Fig. 2 with radius 0.01 L, cold: (solver, result, committed z), solved on first use."""
    cache = {}

    def get(c):
        if c not in cache:
            sol = solver(c, R)
            result = sol.solve()
            cache[c] = (sol, result, sol.snapshot().z)
        return cache[c]
    return get


@pytest.fixture(scope="module")
def loop(loops):
    return loops(0.3)


@functools.lru_cache(maxsize=None)
def free_energy_at(c: float) -> float:
    """The same scene without self-contact (same order): the unconstrained equilibrium's energy."""
    r = ShapeSolver(fig2(c, R), SolverOptions(model="full", order=ORDER), compile="off").solve()
    assert r.ok and r.stable, r.message
    return r.energy["total"]


@pytest.fixture(scope="module")
def free_energy():
    return free_energy_at(0.3)


@pytest.mark.parametrize("c", [0.3, 0.2])
def test_fig2_loop_keeps_two_radii(c, loops):
    sol, r, z = loops(c)
    free_energy = free_energy_at(c)
    assert r.ok and r.stable, r.message
    assert r.self_contacts, "the loop must touch itself"
    geometry = SC.contact_geometry(L, R)
    # every pair of the centreline (resampled finely, 0.05 L apart along s) keeps 2r − κ h²/4
    s = np.linspace(0.0, L, 2001)
    d, _, _ = closest_self_approach(s, sol.model.positions(z, s), 0.05 * L)
    tol = geometry.tolerance(world_curvature_max(sol, z))
    assert d >= 2 * R - tol - 1e-9 * L, (d, tol)
    assert r.min_self_distance >= geometry.distance - 1e-8 * L
    # a constraint can only raise the energy of the same branch's minimum
    assert r.energy["total"] >= free_energy - 1e-9 * abs(free_energy)
    # the contact forces push the strands apart, along the line between the contact points
    for c in r.self_contacts:
        gap = c.point_a - c.point_b
        assert np.dot(c.force, gap) > 0 and np.linalg.norm(np.cross(c.force, gap)) < 1e-9 * np.linalg.norm(c.force)
    # grip reactions and contact forces balance, and enter the strong-form residual: without them the
    # shape is far off equilibrium
    f, m = global_balance(r)
    assert f < 1e-8 and m < 1e-8, (f, m)
    tolerance = 1e-3 * L
    assert r.equilibrium_residual_m < tolerance
    without = sol.equilibrium(sol.problem, z, r.grips, [])
    assert without.metres > 10 * r.equilibrium_residual_m, (without, r.equilibrium_residual_m)
    as_json = r.to_dict()
    assert len(as_json["self_contacts"]) == len(r.self_contacts) and as_json["model"]["self_contact_pairs"] == PAIRS


def test_self_contacts_in_markers_and_recording(loop):
    """Every self-contact reaches the node's markers (two arrows, equal and opposite, from the contact
    points) and the recording's result message (exact float64 rows)."""
    conv = pytest.importorskip("dlo_ros.node.conversions")
    from dlo_ros.recording.codec import decode, encode_result

    sol, r, _ = loop
    arrows = [m for m in conv.result_markers(r, sol.problem, "world", 1, force_scale=0.1).markers
              if m.ns == "self_contacts"]
    assert len(arrows) == 2 * len(r.self_contacts)
    for k, c in enumerate(r.self_contacts):
        for side, (point, force) in enumerate(((c.point_a, c.force), (c.point_b, -c.force))):
            a, b = (np.array([p.x, p.y, p.z]) for p in arrows[2 * k + side].points)
            assert np.allclose(a, point) and np.allclose(b - a, 0.1 * force)
    snap = decode(encode_result(r, 1, 0, None, None, True)).payload
    expected = [np.concatenate([[c.s_a, c.s_b], c.point_a, c.point_b, c.force]) for c in r.self_contacts]
    assert np.array_equal(snap.self_contacts, np.array(expected))


def test_fig2_loop_against_discrete_rod(loop):
    """The discrete rod (N = 40 and 60 edges, started from the unconstrained shape at 0.31 L, where the
    loop is open) finds the same contact: energy (Richardson-extrapolated in h²), contact arc lengths
    and centreline."""
    sol, r, z = loop
    free = ShapeSolver(fig2(0.31, R), SolverOptions(model="full", order=ORDER), compile="off")
    assert free.solve().ok
    z_open = free.snapshot().z
    e = np.array([1.0, 0.0, 0.0])
    refs = {}
    with blas_threads(1):
        for n in (40, 60):
            t0 = free.model.tangents_at(z_open, (np.arange(n) + 0.5) * L / n)
            refs[n] = solve_contact_rod(t0, L, RF, np.array([0.3, 0.0, 0.0]), e, e, R, 0.05 * L, 0.08 * L)
            assert refs[n].closest >= 2 * R - 1e-8, (n, refs[n].closest)  # pairs outside the window too
            assert refs[n].active, n
    e40, e60 = refs[40].energy, refs[60].energy
    richardson = e60 + (e60 - e40) * 40**2 / (60**2 - 40**2)
    assert r.energy["total"] == pytest.approx(richardson, rel=5e-4), (r.energy["total"], e40, e60, richardson)
    ref = refs[60]
    h = L / 60
    for a, b in ref.active:  # each reference contact lies within a spacing of one of ours
        assert min(abs(c.s_a - ref.s[a]) + abs(c.s_b - ref.s[b]) for c in r.self_contacts) < 2 * h
    assert distance_modulo_chord_rotation(sol.model.positions(z, ref.s), ref.points) < 5e-3 * L


def test_contact_forces_are_the_energy_sensitivity():
    """Statics by virtual work: raising the contact distance D by dD costs the energy Σ|f_i| dD (the
    contact forces do that work).  With the samples fixed (h = L/100), D = √((2r)² + h²/2), so
    dE/dr = Σ|f_i| · 4r/D: a central difference in r against the reported forces."""
    opts = SolverOptions(model="full", order=ORDER, self_contact_pairs=PAIRS, self_contact_samples=101)
    delta = 1e-4 * L
    energies = {}
    for r in (R - delta, R + delta, R):
        result = ShapeSolver(fig2(0.3, r), opts, compile="off").solve()
        assert result.ok and result.stable and result.self_contacts, (r, result.message)
        energies[r] = result.energy["total"]
    h = L / 100
    d = np.sqrt(4 * R**2 + h**2 / 2)
    force = sum(np.linalg.norm(c.force) for c in result.self_contacts)
    slope = (energies[R + delta] - energies[R - delta]) / (2 * delta)
    assert slope == pytest.approx(force * 4 * R / d, rel=5e-4), (slope, force)


def test_fig2_radius_zero_may_touch_not_cross(free_energy):
    """Radius 0: the strands touch at the sample-pair distance D = h/√2 (no crossing of the sampled
    polyline) and the energy stays at the unconstrained one's (the clearance is tiny)."""
    sol = solver(0.3, 0.0)
    r = sol.solve()
    assert r.ok and r.stable, r.message
    geometry = SC.contact_geometry(L, 0.0)
    assert r.self_contacts and r.min_self_distance >= geometry.distance - 1e-8 * L
    assert free_energy - 1e-9 * free_energy <= r.energy["total"] <= free_energy * (1 + 1e-4)
    f, m = global_balance(r)
    assert f < 1e-8 and m < 1e-8 and r.equilibrium_residual_m < 1e-3 * L


def test_fig2_streamed_into_contact(loop):
    """Warm updates from 0.34 L (open loop) to 0.27 L: every update ok, stable, warm and non-penetrating;
    the loop closes onto itself on the way, and at 0.3 L the stream agrees with the cold solve."""
    sol = solver(0.34, R)
    assert sol.solve().ok
    geometry = SC.contact_geometry(L, R)
    touched = False
    for c in np.round(np.arange(0.33, 0.265, -0.01), 10):
        r = sol.solve({"right": ((c, 0.0, 0.0), STRAIGHT)})
        assert r.ok and r.stable and r.warm_started, (c, r.message)
        assert r.min_self_distance >= geometry.distance - 1e-8 * L, c
        touched |= bool(r.self_contacts)
        if c == 0.3:
            assert r.energy["total"] == pytest.approx(loop[1].energy["total"], rel=1e-8)
    assert touched


def test_far_from_itself_is_unchanged():
    """At 0.6 L the shape is nowhere near itself: with self-contact the answers (cold and two warm
    updates) are those without, and the warm updates stay on the contact-free Newton path."""
    on, off = solver(0.6, R), solver(0.6, R, pairs=0)
    for c in (None, 0.59, 0.58):
        poses = None if c is None else {"right": ((c, 0.0, 0.0), STRAIGHT)}
        a, b = on.solve(poses), off.solve(poses)
        assert a.ok and b.ok and a.iterations == b.iterations and not a.self_contacts
        assert a.energy["total"] == pytest.approx(b.energy["total"], rel=1e-12)
        # the cold answer leaves the planar saddle toward one of two mirror images (a neutral choice)
        assert distance_modulo_chord_rotation(a.points, b.points) < 1e-9
        if c is not None:
            assert a.ipopt_status == b.ipopt_status == "Newton"


def test_auto_models_self_contact_once_within_reach():
    """``solver.model: auto`` (sync checks; a loose tolerance keeps the order at 16): no self-contact while
    the loop is open, the full model with self-contact from the update that brings the shape within reach
    of itself, and no published shape closer to itself than 2r (measured on its own output points)."""
    from dlo_ros.solver.auto import AutoShapeSolver

    sol = AutoShapeSolver(fig2(0.33, R), SolverOptions(error_tolerance=0.01 * L), compile="off", checks="sync")
    r = sol.solve()
    assert r.ok and r.model.self_contact_pairs == 0
    for c in (0.32, 0.31, 0.30, 0.29):
        r = sol.solve({"right": ((c, 0.0, 0.0), STRAIGHT)})
        assert r.ok and r.stable, (c, r.message)
        d, _, _ = closest_self_approach(r.s, r.points, 0.05 * L)
        assert d >= 2 * R - 1e-4 * L, (c, d, r.model.self_contact_pairs)
    assert r.model.self_contact_pairs > 0 and r.self_contacts
    assert any(reason.startswith("self-contact:") for reason in r.model.reasons)
    assert r.to_dict()["model"]["self_contact_pairs"] == r.model.self_contact_pairs


# ---- pair selection and topology, on synthetic curves ------------------------------------------------
def random_curve(seed: int, n: int) -> np.ndarray:
    """A smooth random closed-ish curve of length ≈ 1 sampled at n points (sum of a few harmonics)."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, n)
    pts = sum(np.outer(np.sin(2 * np.pi * k * u + rng.uniform(0, 6)), rng.normal(size=3)) / k for k in range(1, 5))
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    return pts / seg


@pytest.mark.parametrize("seed", range(6))
def test_penetration_check_is_complete(seed):
    """``penetrations`` (local minima only) is empty exactly when brute force over every sample pair the
    exclusion arc apart finds none closer than D."""
    geometry = SC.contact_geometry(L, 0.02)
    for scale in (1.0, 0.3, 0.15):
        pts = random_curve(seed, len(geometry.s)) * scale
        i, j = np.triu_indices(len(pts), 1)
        far = (j - i) * geometry.spacing >= geometry.exclusion - 1e-12
        d = np.linalg.norm(pts[i[far]] - pts[j[far]], axis=1)
        brute = bool(np.any(d < geometry.distance - 1e-9))
        found = SC.penetrations(SC.candidate_pairs(pts, geometry), geometry, 1e-9)
        assert bool(found) == brute, (seed, scale)
        if found:
            a, b = found[0]
            assert np.linalg.norm(pts[a] - pts[b]) == pytest.approx(d.min())


def test_crossing_flip_is_detected():
    """Two straight strands crossing at right angles 0.05 L apart: moving one through the other flips the
    crossing sign; moving it further away on the same side does not."""
    geometry = SC.contact_geometry(L, 0.01)
    s = geometry.s

    def shape(offset: float) -> tuple[np.ndarray, np.ndarray]:
        # first half along +x at height 0, second half along +y crossing above or below it
        pts = np.zeros((len(s), 3))
        tangents = np.zeros((len(s), 3))
        first = s <= 0.5
        pts[first] = np.stack([s[first] - 0.25, 0 * s[first], 0 * s[first]], axis=1)
        tangents[first] = [1.0, 0.0, 0.0]
        pts[~first] = np.stack([0 * s[~first], s[~first] - 0.75, offset + 0 * s[~first]], axis=1)
        tangents[~first] = [0.0, 1.0, 0.0]
        return pts, tangents

    above, below, higher = (SC.crossing_signs(*shape(z), SC.candidate_pairs(shape(z)[0], geometry))
                            for z in (0.05, -0.05, 0.06))
    assert above and SC.crossing_flips(above, below) and not SC.crossing_flips(above, higher)


def test_side_by_side_strands_have_no_crossing_sign():
    """The legs of a planar V (s ≤ L/2 up from (−0.02, 0, 0) leaning left, s > L/2 down to (0.02, 0, 0)
    leaning right, 30° between them, within reach near the base) lie side by side, not over one another:
    their tangent lines meet far from the samples, so no pair gets a crossing sign, and lifting one leg
    1e-9 L above or below the plane flips nothing.  (Before: the sign of rounding noise, flipped by the
    first small out-of-plane step of a planar pinned hairpin at order 32, which was refused as a crossing.)"""
    geometry = SC.contact_geometry(L, 0.01)
    s = geometry.s
    phi = np.radians(15)

    def shape(lift: float) -> tuple[np.ndarray, np.ndarray]:
        first = s <= 0.5
        u = np.where(first, s, L - s)  # arc length from the base along each leg
        side = np.where(first, -1.0, 1.0)
        pts = np.stack([side * (0.02 + u * np.sin(phi)), u * np.cos(phi), np.where(first, 0.0, lift)], axis=1)
        tangents = np.stack([-np.sin(phi) + 0 * s, np.cos(phi) + 0 * s, 0 * s], axis=1)
        tangents[~first] = [-np.sin(phi), -np.cos(phi), 0.0]
        return pts, tangents

    assert SC.candidate_pairs(shape(0.0)[0], geometry), "the legs are within reach near the base"
    up, down = (SC.crossing_signs(*shape(z), SC.candidate_pairs(shape(z)[0], geometry)) for z in (1e-9, -1e-9))
    assert not up and not down and not SC.crossing_flips(up, down)


def test_swept_crossing():
    """A strand moved straight through another is caught; moved away from it, or slid along it at
    contact distance, it is not."""
    geometry = SC.contact_geometry(L, 0.01)
    s = geometry.s
    first = s <= 0.5

    def shape(offset: float, slide: float = 0.0) -> np.ndarray:
        pts = np.zeros((len(s), 3))
        pts[first, 0] = s[first] - 0.25
        pts[~first, 0] = slide
        pts[~first, 1] = s[~first] - 0.75
        pts[~first, 2] = offset
        return pts

    d = geometry.distance
    assert SC.swept_crossing(shape(d), shape(-d), geometry) is not None
    assert SC.swept_crossing(shape(d), shape(3 * d), geometry) is None
    assert SC.swept_crossing(shape(d), shape(d, slide=0.05), geometry) is None


def test_assign_keeps_loaded_slots():
    """Loaded slots stay; the rest of the capacity goes to the wanted pairs in order, a chosen pair keeping
    its slot; a nearer wanted pair displaces an unloaded farther one."""
    slots, left = SC.assign([(1, 9), (2, 8), None], [(3, 7), (2, 8)], keep={0}, capacity=3)
    assert slots == [(1, 9), (2, 8), (3, 7)] and not left
    slots, left = SC.assign(slots, [(4, 6), (5, 9), (3, 7)], keep={0}, capacity=3)
    assert slots[0] == (1, 9) and set(slots[1:]) == {(4, 6), (5, 9)} and left == [(3, 7)]
