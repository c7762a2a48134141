"""Self-contact (#15): a plectoneme, streamed, against an independent discrete rod with twist.

The scene: a string (L = 1, Rf = 1, Rt = 0.7, radius r = 0.02 L, no weight) folded into a hairpin.  The
left clamp at the origin points along +y, the right clamp D = 0.06 L from it along x points along −y
(the string arrives going back down), and the middle s = L/2 is pinned (position only, free to turn) at
(D/2, 0.45 L, 0): two legs of 0.5 L over a span of 0.45 L, slack enough to wrap.  The right clamp is
turned about its own tangent in 15° steps to 2.5 turns (60 warm updates).  Up to about one turn the
legs only twist and bow; then they wrap around each other and touch, and the contact line grows with
every further step: a plectoneme, two strands wrapped around each other in contact along a line.
Why this path and not "twist a straight clamped string, then bring its ends together": that path
reaches a fold (chord 0.5 L at 2 turns) where the string must snap into a loop, and the warm update
lands on a branch with whole turns released, which the topology checks rightly refuse (measured; see
test_linking_stream.py).  The pin holds the tip of the hairpin away from the clamps, so the tip cannot
pass around a clamp and unwind the legs (without it, grips 0.1 L apart, the free loop never touched
itself and the stream returned to its first shape after two turns: energy periodic in 720°, the
belt trick).  Every update of this
path is a small continuous step: no snap, no refusal.

Checked: every streamed update ok, stable, warm and non-penetrating (its own minimum sample distance
and a dense spline check, 2r − κh²/4); the linking number Tw + Wr (ray closure) equals the turns applied
all along (nothing passed through anything); at 2.5 turns several contacts along a stretch of the legs,
the vector between the two strands turning more than half a turn about the legs' axis (wrapped), global
force and moment balance over the grip reactions and the contact forces to 1e-8, and the strong-form
equilibrium needing the contact forces.  Against the independent reference
(test/reference/twisted_contact_rod.py: rigid edges carrying quaternion frames, bend and twist joints,
pairwise non-penetration at exactly 2r, IPOPT; N = 40 and 60, Richardson in h²): energy, contact
stretch, total contact force and shape.  The same target solved cold lands on another branch (3 turns
released, no contact), which the reference confirms too.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from reference.kirchhoff import blas_threads
from reference.twisted_contact_rod import solve_twisted_contact_rod
from test_fig2_reference import closest_self_approach
from test_linking_stream import linking

from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties
from dlo_ros.model.director import quat_to_frame
from dlo_ros.solver.contact import self_contact as SC
from dlo_ros.solver.contact import topology as TP
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

L, RF, RT, R = 1.0, 1.0, 0.7, 0.02
D, H = 0.06, 0.45  # clamp spacing and the pin's height [m]
TURNS, STEPS_PER_TURN = 2.5, 24
ORDER, PAIRS = 16, 24
PIN = np.array([D / 2, H, 0.0])
Q_LEFT = tuple(Rotation.from_euler("z", np.pi / 2).as_quat())


def q_right(angle: float) -> tuple:
    """The right clamp: tangent −y, turned by ``angle`` [rad] about that tangent."""
    return tuple((Rotation.from_euler("z", -np.pi / 2) * Rotation.from_euler("x", angle)).as_quat())


def hairpin(angle: float) -> Problem:
    string = StringProperties(L, Profile.constant(RF), Profile.constant(RT), Profile.constant(0.0), radius=R)
    grips = (Grip("left", 0.0, "clamp", GripPose.checked((0.0, 0.0, 0.0), Q_LEFT, "left")),
             Grip("mid", L / 2, "pin", GripPose.checked(tuple(PIN), (0.0, 0.0, 0.0, 1.0), "mid")),
             Grip("right", L, "clamp", GripPose.checked((D, 0.0, 0.0), q_right(angle), "right")))
    return Problem(string, grips, gravity=np.array([0.0, 0.0, -1.0]))


def solver(angle: float) -> ShapeSolver:
    return ShapeSolver(hairpin(angle), SolverOptions(model="full", order=ORDER, self_contact_pairs=PAIRS),
                       compile="off")


GRIP_POINTS = {"left": np.zeros(3), "mid": PIN, "right": np.array([D, 0.0, 0.0])}


def balance(result) -> tuple[float, float]:
    """|Σ F| [N] and |Σ (x × F + T)| [N·m] over the three grips' reactions and both sides of every contact."""
    force, moment = np.zeros(3), np.zeros(3)
    for name, w in result.grips.items():
        force += w.force
        moment += np.cross(GRIP_POINTS[name], w.force) + w.torque
    for c in result.self_contacts:
        moment += np.cross(c.point_a, c.force) - np.cross(c.point_b, c.force)
    return float(np.linalg.norm(force)), float(np.linalg.norm(moment))


def wrap_angle(points_a: np.ndarray, points_b: np.ndarray) -> float:
    """How far [rad] the vector from one leg to the other (points at s and L − s) turns about the legs'
    axis y, from the clamps to the tip."""
    v = points_a - points_b
    angle = np.unwrap(np.arctan2(v[:, 2], v[:, 0]))
    return float(abs(angle[-1] - angle[0]))


@pytest.fixture(scope="module")
def stream():
    """The 60 warm updates: (solver, [(angle, result), …], committed z of the last)."""
    sol = solver(0.0)
    first = sol.solve()
    assert first.ok and first.stable, first.message
    steps = int(round(TURNS * STEPS_PER_TURN))
    results = []
    for k in range(1, steps + 1):
        angle = 2 * np.pi * TURNS * k / steps
        results.append((angle, sol.solve({"right": ((D, 0.0, 0.0), q_right(angle))})))
    return sol, results, sol.snapshot().z


def reference(sol: ShapeSolver, z: np.ndarray, n: int):
    """The discrete rod at the final target with n edges, started from the frames of z at edge midpoints."""
    q0 = Rotation.from_matrix(sol.pose_frames(z, (np.arange(n) + 0.5) * L / n)).as_quat()
    with blas_threads(1):
        return solve_twisted_contact_rod(q0, L, RF, RT, (np.zeros(3), np.array(Q_LEFT)),
                                         (np.array([D, 0.0, 0.0]), np.array(q_right(2 * np.pi * TURNS))), R,
                                         gap=0.08 * L, window=0.1 * L, pins=((n // 2, PIN),), box=0.5)


@pytest.fixture(scope="module")
def references(stream):
    sol, _, z = stream
    return {n: reference(sol, z, n) for n in (40, 60)}


def richardson(e40: float, e60: float) -> float:
    return e60 + (e60 - e40) * 40**2 / (60**2 - 40**2)


def test_streamed_plectoneme(stream):
    """Every update ok, stable, warm, non-penetrating, with Lk = the turns applied (measured within 1e-4);
    contact first near one turn; at 2.5 turns at least 3 contacts along at least 0.08 L of each leg
    (measured 4, s = 0.12–0.23 L against 0.77–0.88 L), the legs wrapped by more than half a turn about
    each other (measured 281° from the clamps to the tip), balance to 1e-8."""
    sol, results, z = stream
    geometry = SC.contact_geometry(L, R)
    first_contact = None
    for angle, r in results:
        assert r.ok and r.stable and r.warm_started, (np.degrees(angle), r.status, r.message)
        # (2r: a point contact is held at the strands' closest points, update/contact_points.py; the
        # contact line, past it, on its sample pairs D apart)
        assert r.min_self_distance >= 2 * R - 1e-8 * L, np.degrees(angle)
        assert linking(r) == pytest.approx(angle / (2 * np.pi), abs=1e-3), (np.degrees(angle), linking(r))
        if r.self_contacts and first_contact is None:
            first_contact = angle
    assert first_contact is not None and 0.75 < first_contact / (2 * np.pi) < 1.25, first_contact
    r = results[-1][1]
    # dense check on the committed shape: every pair of the centreline the exclusion arc apart keeps 2r − κh²/4
    s = np.linspace(0.0, L, 2001)
    d, _, _ = closest_self_approach(s, sol.model.positions(z, s), geometry.exclusion)
    kappa = float(np.max(np.linalg.norm(sol.model.world_curvature(z, s), axis=1)))
    assert d >= 2 * R - geometry.tolerance(kappa) - 1e-9 * L, (d, geometry.tolerance(kappa))
    # a contact line: several contacts, on each leg a stretch of s, each pair one point on either leg
    s_a = np.array([c.s_a for c in r.self_contacts])
    s_b = np.array([c.s_b for c in r.self_contacts])
    assert len(s_a) >= 3 and np.all(s_a < L / 2) and np.all(s_b > L / 2), (s_a, s_b)
    assert np.ptp(s_a) >= 0.08 * L and np.ptp(s_b) >= 0.08 * L, (s_a, s_b)
    legs = np.linspace(0.0, 0.45 * L, 91)
    assert wrap_angle(sol.model.positions(z, legs), sol.model.positions(z, L - legs)) > np.pi
    for c in r.self_contacts:  # pushes the strands apart, along the line between the contact points
        gap = c.point_a - c.point_b
        assert np.dot(c.force, gap) > 0 and np.linalg.norm(np.cross(c.force, gap)) < 1e-9 * np.linalg.norm(c.force)
    f, m = balance(r)
    assert f < 1e-8 and m < 1e-8, (f, m)
    assert r.equilibrium_residual_m < 1e-3 * L
    without = sol.equilibrium(sol.problem, z, r.grips, [])
    assert without.metres > 10 * r.equilibrium_residual_m, (without, r.equilibrium_residual_m)


def test_plectoneme_against_discrete_rod(stream, references):
    """The reference (N = 40, 60, box inactive) stays on the plectoneme: no two points closer than 2r (to IPOPT's constraint tolerance, 1e-6 L).
    Energy: ours (order 16, sample pairs held at D = 0.0406 L, not 2r) corrected to 2r by the contact
    forces' work, E − Σ|f| (D − 2r) (dE/dD = Σ|f|: test_self_contact.py; measured 51.536 → 51.269 J;
    sampling twice as fine gives 51.278 J by Richardson in h), against the reference's Richardson limit
    (measured 50.062, 50.628 → 51.081 J; N = 80 gives 50.836 J, 51.095 J with N = 40): 0.4 %, the Ritz
    order (order 24: 51.403 → 51.131 J corrected, 0.1 %).  The contact stretch on each leg within
    0.02 L of the reference's at both ends (measured s_a 0.12–0.23 against 0.108–0.242), the total
    contact force within 3 % (431.4 N against 423.1, 431.2 → 437.7 N extrapolated; order 24: 438.2 N), the
    shape within 5e-3 L (measured 4.4e-3 at N = 40, 3.3e-3 at N = 80) and the legs wrapped alike."""
    sol, results, z = stream
    r = results[-1][1]
    for n, ref in references.items():
        assert ref.success and not ref.box_active, (n, ref.message)
        assert ref.closest >= 2 * R - 1e-6 * L and len(ref.active) >= 3  # IPOPT: constraint tolerance, (n, ref.closest, ref.active)
    geometry = SC.contact_geometry(L, R)
    forces = sum(np.linalg.norm(c.force) for c in r.self_contacts)
    ours = r.energy["total"] - forces * (geometry.distance - 2 * R)
    limit = richardson(references[40].energy, references[60].energy)
    assert ours == pytest.approx(limit, rel=5e-3), (r.energy["total"], ours, limit)
    ref = references[60]
    ref_a = np.array([ref.s[a] for a, _ in ref.active])
    ref_b = np.array([ref.s[b] for _, b in ref.active])
    s_a = np.array([c.s_a for c in r.self_contacts])
    s_b = np.array([c.s_b for c in r.self_contacts])
    for ours_s, ref_s in ((s_a, ref_a), (s_b, ref_b)):
        assert abs(ours_s.min() - ref_s.min()) < 0.02 * L and abs(ours_s.max() - ref_s.max()) < 0.02 * L, (ours_s, ref_s)
    ref_force = richardson(*(float(np.linalg.norm(references[n].forces, axis=1).sum()) for n in (40, 60)))
    assert forces == pytest.approx(ref_force, rel=3e-2), (forces, ref_force)
    assert np.max(np.linalg.norm(sol.model.positions(z, ref.s) - ref.points, axis=1)) < 5e-3 * L
    tip = ref.s <= 0.45 * L
    assert wrap_angle(ref.points[tip], ref.points[::-1][tip]) > np.pi


def test_cold_solve_is_another_branch(stream):
    """A fresh solver's cold answer at 2.5 turns: the cold guess knows nothing of the turns, and it lands
    on the branch with 3 turns released (Lk −0.5, no contact, energy 19.520 J against 51.536 J), which
    ``link_change`` calls a jump from the plectoneme.  That branch is a true equilibrium as well: the
    reference started from it stays there (energy Richardson 19.517 J from N = 40, 60; agreement 1e-3)."""
    sol, results, z = stream
    plectoneme = results[-1][1]
    cold_solver = solver(2 * np.pi * TURNS)
    cold = cold_solver.solve()
    assert cold.ok and cold.stable, cold.message
    assert linking(cold) == pytest.approx(TURNS - 3, abs=1e-3) and not cold.self_contacts, linking(cold)
    assert cold.energy["total"] < plectoneme.energy["total"] / 2
    change = TP.link_change(plectoneme.points, quat_to_frame(plectoneme.orientations),
                            cold.points, quat_to_frame(cold.orientations))
    # every tangent turned less than 90°: Fuller's writhe, which holds mod 2 only (topology.py): −3 reads −1
    assert change.jumped and change.method == "fuller", change
    assert change.unexplained == pytest.approx(round(change.unexplained), abs=1e-2) and round(change.unexplained) % 2 == 1
    z_cold = cold_solver.snapshot().z
    refs = {n: reference(cold_solver, z_cold, n) for n in (40, 60)}
    for n, ref in refs.items():
        assert ref.success and not ref.box_active and not ref.active, (n, ref.message)
    assert cold.energy["total"] == pytest.approx(richardson(refs[40].energy, refs[60].energy), rel=1e-3)


def test_reference_contact_forces_are_its_energy_sensitivity(references):
    """The reference's contact forces (its IPOPT multipliers) do the work of its energy: raising r by dr
    moves every active pair apart by 2 dr, so dE/dr = 2 Σ|f| (central difference, N = 40, restarted from
    its own answer, the same active pairs; measured 846.162 against 846.160 N)."""
    ref = references[40]
    energies = {}
    for r in (R - 1e-4 * L, R + 1e-4 * L):
        with blas_threads(1):
            moved = solve_twisted_contact_rod(ref.quaternions, L, RF, RT, (np.zeros(3), np.array(Q_LEFT)),
                                              (np.array([D, 0.0, 0.0]), np.array(q_right(2 * np.pi * TURNS))), r,
                                              gap=0.08 * L, window=0.1 * L, pins=((20, PIN),), box=0.5)
        assert moved.success and moved.active == ref.active, (r, moved.message)
        energies[r] = moved.energy
    slope = (energies[R + 1e-4 * L] - energies[R - 1e-4 * L]) / (2e-4 * L)
    assert slope == pytest.approx(2 * np.linalg.norm(ref.forces, axis=1).sum(), rel=1e-4)
