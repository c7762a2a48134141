"""Self-contact (#15): two strands pressed together by a point load.

The paper's Fig. 2 loop at chord 0.3 L (radius 0.01 L; test_self_contact.py), whose strands touch near
s = 0.16 L and 0.85 L, with a dead force P = 0.3 N along −y applied at s = 0.85 L, on the strand that lies
on the other one.  With one string the contact pair is internal: it cancels from the global balance, so
statics fixes it locally (the strong-form equilibrium of each strand needs it) and the independent discrete
rod (test/reference/contact_rod.py, SLSQP, its contact forces from its own KKT multipliers) gives its size.
Both cold and streamed (P raised in five warm updates from the unloaded loop)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from reference.contact_rod import solve_contact_rod
from reference.kirchhoff import blas_threads
from reference.point_contact import solve_point_contact
from test_fig2_reference import distance_modulo_chord_rotation
from test_self_contact import L, ORDER, PAIRS, R, RF, RT, fig2

from dlo_ros.model.problem import Load
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

P, S_LOAD, CHORD = 0.3, 0.85, 0.3
DIRECTION = np.array([0.0, -1.0, 0.0])


def loaded(p: float):
    return replace(fig2(CHORD, R), loads=(Load(S_LOAD, force=p * DIRECTION),))


def options(samples: int = 0, pairs: int = PAIRS) -> SolverOptions:
    return SolverOptions(model="full", order=ORDER, self_contact_pairs=pairs, self_contact_samples=samples)


def resultant(result) -> np.ndarray:
    """Σ of the contact forces on the strand with the smaller s [N]."""
    return sum((c.force for c in result.self_contacts), np.zeros(3))


def balance(result, x_load: np.ndarray) -> tuple[float, float]:
    """|Σ F| [N] and |Σ x × F + T| [N·m] over the grips, the load (at ``x_load``) and both sides of every
    contact."""
    force, moment = P * DIRECTION, np.cross(x_load, P * DIRECTION)
    for name, w in result.grips.items():
        x = result.points[0] if name == "left" else result.points[-1]
        force = force + w.force
        moment = moment + np.cross(x, w.force) + w.torque
    for c in result.self_contacts:
        moment = moment + np.cross(c.point_a, c.force) - np.cross(c.point_b, c.force)
    return float(np.linalg.norm(force)), float(np.linalg.norm(moment))


@pytest.fixture(scope="module")
def streamed():
    sol = ShapeSolver(loaded(0.0), options(), compile="off")
    assert sol.solve().ok
    results = []
    for p in np.linspace(0.0, P, 6)[1:]:
        sol.set_problem(loaded(p))
        results.append(sol.solve())
    return sol, results


@pytest.fixture(scope="module")
def cold():
    sol = ShapeSolver(loaded(P), options(), compile="off")
    return sol, sol.solve()


def check_statics(sol: ShapeSolver, result) -> None:
    assert result.ok and result.stable, result.message
    assert result.self_contacts, "the load presses the strands together"
    assert result.min_self_distance >= 2 * R - 1e-8 * L  # held at the closest points, 2r apart
    z = sol.snapshot().z
    f, m = balance(result, sol.model.positions(z, np.array([S_LOAD]))[0])
    assert f < 1e-8 and m < 1e-8, (f, m)
    for c in result.self_contacts:  # pushes the strands apart, along the line between the contact points
        gap = c.point_a - c.point_b
        assert np.dot(c.force, gap) > 0 and np.linalg.norm(np.cross(c.force, gap)) < 1e-9 * np.linalg.norm(c.force)
    # local statics: each strand's strong-form balance needs the contact forces (without them it is far off)
    assert result.equilibrium_residual_m < 1e-3 * L
    without = sol.equilibrium(sol.problem, z, result.grips, [])
    assert without.metres > 10 * result.equilibrium_residual_m, (without, result.equilibrium_residual_m)


def test_pressed_strands_streamed(streamed):
    sol, results = streamed
    for r in results:
        assert r.ok and r.warm_started, r.message
    check_statics(sol, results[-1])


def test_pressed_strands_cold(cold, streamed):
    """Cold: the same statics; the loop leaves the plane to either side (a neutral choice): the same
    equilibrium as the stream's up to that mirror image: energy to 1e-8, contact force size to 1e-5 (a
    multiplier: IPOPT's tolerance), shape to 1e-6 L."""
    sol, r = cold
    check_statics(sol, r)
    s = streamed[1][-1]
    assert r.energy["total"] == pytest.approx(s.energy["total"], rel=1e-8)
    assert np.linalg.norm(resultant(r)) == pytest.approx(np.linalg.norm(resultant(s)), rel=1e-5)
    assert distance_modulo_chord_rotation(r.points, s.points) < 1e-6 * L


def test_contact_force_against_discrete_rod(streamed):
    """The contact force against two independent references.

    * The exact point contact (test/reference/point_contact.py: shooting with the load and equal and
      opposite forces at the strands' closest points, 2r apart), started from our contact: 0.3456 N;
      ours, held at the closest points (update/contact_points.py) on one element of order 16, 0.3426 N
      (the sample pairs alone, held at D = √((2r)² + h²/2), gave 0.378 N): within 1 %.
    * The discrete rod (N = 40 and 60 edges, started from the streamed shape, the load at its vertex at
      0.85 L): its contact force at each N within 3 % of ours (0.3451 and 0.3357 N: its multipliers
      scatter with N, test_self_contact.py, so that no extrapolation of them converges: 40/80 gave
      0.3487 N, 30/40 0.352, 50/60 0.303), and its energy, Richardson-extrapolated in h², within 5e-4
      of ours (measured 3.1e-5).  (N = 80 took SLSQP 79 s, N = 60 2 s.)
    """
    sol, results = streamed
    ours = results[-1]
    size_ours = float(np.linalg.norm(resultant(ours)))
    z = sol.snapshot().z
    e = np.array([1.0, 0.0, 0.0])
    wrench = ours.grips["left"]
    rod = dict(L=L, Rf=RF, Rt=RT, x0=np.zeros(3), R0=np.eye(3), x1=(CHORD, 0.0, 0.0), R1_or_tangent=e,
               mode_end="tangent", loads=((S_LOAD, P * DIRECTION, None),))
    first = ours.self_contacts[0]
    with blas_threads(1):
        exact = solve_point_contact(rod, R, resultant(ours), first.s_a, first.s_b, (-wrench.force, -wrench.torque))
    assert exact.residual < 1e-9, exact.residual
    assert size_ours == pytest.approx(float(np.linalg.norm(exact.force)), rel=1e-2), exact.force
    refs = {}
    with blas_threads(1):
        for n in (40, 60):
            t0 = sol.model.tangents_at(z, (np.arange(n) + 0.5) * L / n)
            ref = solve_contact_rod(t0, L, RF, np.array([CHORD, 0.0, 0.0]), e, e, R, 0.05 * L, 0.08 * L,
                                    loads=((int(round(S_LOAD * 2 * n)), P * DIRECTION),), maxiter=3000)
            assert ref.success and ref.active and ref.closest >= 2 * R - 1e-8, (n, ref.message)
            refs[n] = ref
    size = {n: float(np.linalg.norm(ref.forces.sum(axis=0))) for n, ref in refs.items()}
    assert all(v == pytest.approx(size_ours, rel=3e-2) for v in size.values()), (size_ours, size)
    e40, e60 = refs[40].energy, refs[60].energy
    richardson = e60 + (e60 - e40) * 40**2 / (60**2 - 40**2)  # its joints' error is O(h²)
    assert ours.energy["total"] == pytest.approx(richardson, rel=5e-4), (ours.energy["total"], e40, e60)
