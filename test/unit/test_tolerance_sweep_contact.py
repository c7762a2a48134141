"""``solver.error_tolerance`` on the issue's harder cases (#37): the default meets 1e-3 … 1e-6 L.

As test_tolerance_sweep.py: the default solver (``make_solver``, ``solver.model: auto``, checks
inline) asked for δ answers ``ok`` with ``tolerance_met: true`` and a centreline within δ of an
independent answer, cold and streamed (warm updates to the case's pose, then held there until the
update's check has taken effect: ``check_schedule.CHECK_LAG`` updates after a change of model):

* Greenhill's rod past its threshold (1.3 Φ_c, test_greenhill_auto.greenhill): the buckle against
  the extensible shooting reference (test/reference/extensible_shooting.py, started from the
  answer's grip wrench), by axial coordinate and distance from the chord;
* the paper's Fig. 2 (clamp and tangent grip, Rf/Rt = 100) with ``string.radius`` 0.01 L:
  - at chord 0.4 L the loop is open (its strands 0.049 L apart): the Kirchhoff shooting solution
    followed down from 0.5 L (test_fig2_reference.branch_references);
  - at chord 0.3 L the loop closes on itself: the exact point contact (test/reference/
    point_contact.py: shooting with equal and opposite forces at the strands' closest points, 2r
    apart).  The sampled contact rows kept the strands D = √((2r)² + h²/2) apart and stopped
    6.5e-4 L from it at every tolerance; auto now holds the contact at the closest points;
  - at both chords no two points more than 0.05 L apart along s come closer than 2r − δ
    (continuous closest approach on a spline through 401 points, test_fig2_reference);
* the paper's copy-paper sheets (config/scenes/paper_rect_paper.yaml, paper_trapezoid_paper.yaml;
  Rf and the weight read from the files, linear tables interpolated here): the planar shooting
  solution (test/reference/planar_sheet.py), the lowest-energy one from compressive starts.

Every answer's reported estimate (``model.estimated_error_m``) bounds its true error, by at most
10x; a stream is held at its last poses until a check of a shape there has taken effect (the
estimate reported is the last check's: before, Greenhill's stream reported the check of its
first pose, 0.1 rad away, 1.1e-8 m against a true 3.8e-8 m).  On the code before this change the
bound failed on Greenhill streamed, Fig. 2 at 0.3 L at 1e-5 and 1e-6 L (the held self-contact
not known as a kink: 3.7e-7 m against 4.8e-7 m) and the trapezoid sheet streamed at 1e-5 L.

The whole grid runs here (about 50 s of CPU, compile off); bench/perf/tolerance_sweep.py tabulates
unknowns, elements and times of the cold solves beside fixed models.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from reference.extensible_shooting import shoot_clamped
from reference.kirchhoff import blas_threads
from reference.planar_sheet import solve_sheet
from reference.point_contact import solve_point_contact
from support.problems import clamped_pair, quat_about
from test_fig2_reference import (
    branch_references,
    closest_self_approach,
    distance_modulo_chord_rotation,
)
from test_greenhill_auto import PHI_C, RE, greenhill

from dlo_ros.scene import load_scene
from dlo_ros.solver.auto import make_solver
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

TOLERANCES = (1e-3, 1e-4, 1e-5, 1e-6)
POINTS = 401
#: the far grip's chord along a stream that closes the Fig. 2 loop (from 0.1 L wider)
CLOSING = (0.07, 0.04, 0.02, 0.0)
#: how many updates at the case's pose a stream may take for a check of a shape at that pose to
#: take effect (``solver.recheck_every`` = 10 updates, then ``check_schedule.CHECK_LAG`` = 4;
#: a stream that coarsens twice at its pose takes 3 + 10 + 3 × 4 updates)
HOLD = 32
ROOT = Path(__file__).resolve().parents[2]


class Case:
    """A scene, its length, the stream to it and the error [m] of an answer (with checks)."""

    def __init__(self, problem, error, stream):
        self.problem, self.error, self.stream = problem, error, stream
        self.length = problem.string.length


def turned_first_grip(solver, problem):
    """Warm updates from the first grip (identity orientation) turned by 0.1 rad about +z back."""
    first = problem.grips[0]
    position = np.asarray(first.pose.position)
    assert np.allclose(first.pose.orientation, (0.0, 0.0, 0.0, 1.0))
    result = None
    for angle in (0.1, 0.05, 0.0):
        result = solver.solve({first.name: (position, quat_about("z", angle))})
    return result, {first.name: (position, quat_about("z", 0.0))}


def closing_chord(solver, problem):
    """Warm updates closing the far grip's chord from 0.07 L wider to the case's own."""
    right = problem.grips[1]
    position, q = np.asarray(right.pose.position), np.asarray(right.pose.orientation)
    result = None
    for extra in CLOSING:
        result = solver.solve({right.name: (position + [extra, 0.0, 0.0], q)})
    return result, {right.name: (position, q)}


# ---- Greenhill ---------------------------------------------------------------------------------


def greenhill_case() -> Case:
    phi = 1.3 * PHI_C
    c, s = np.cos(phi), np.sin(phi)
    r1 = np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])

    def error(r) -> float:
        w = r.grips["a"]  # the clamp's action on the rod: minus the internal n(0), m(0)
        with blas_threads(1):
            ref = shoot_clamped(
                1.0, 1.0, 4.0, RE, np.array([1.0, 0, 0]), r1, -w.force, -w.torque, r.s
            )
        assert ref.residual < 1e-9, ref.residual
        radial = np.hypot(ref.x[:, 1], ref.x[:, 2])
        assert radial.max() > 1e-2  # buckled: not the straight rod
        return max(
            float(np.abs(r.points[:, 0] - ref.x[:, 0]).max()),
            float(np.abs(np.hypot(r.points[:, 1], r.points[:, 2]) - radial).max()),
        )

    return Case(greenhill(phi), error, turned_first_grip)


# ---- Fig. 2 with a radius ----------------------------------------------------------------------

R = 0.01
S = np.linspace(0.0, 1.0, POINTS)


def fig2(c: float):
    p = clamped_pair(right=(c, 0.0, 0.0), bend=1.0, twist=0.01, modes=("clamp", "tangent"))
    return replace(p, string=replace(p.string, radius=R))


def open_loop_case() -> Case:
    with blas_threads(1):
        ref = branch_references((0.4,), step=0.025)[0.4].position(S)
    return Case(fig2(0.4), lambda r: distance_modulo_chord_rotation(r.points, ref), closing_chord)


def closed_loop_case() -> Case:
    """The exact contact, started from a fixed full model's answer with self-contact rows."""
    start = ShapeSolver(
        fig2(0.3), SolverOptions(model="full", order=16, self_contact_pairs=16), compile="off"
    ).solve()
    assert start.ok and start.self_contacts, start.message
    force = sum(c.force for c in start.self_contacts)
    s_a = float(np.mean([c.s_a for c in start.self_contacts]))
    s_b = float(np.mean([c.s_b for c in start.self_contacts]))
    wrench = start.grips["left"]
    rod = dict(L=1.0, Rf=1.0, Rt=0.01, x0=np.zeros(3), R0=np.eye(3), x1=(0.3, 0.0, 0.0),
               R1_or_tangent=(1.0, 0.0, 0.0), mode_end="tangent", s_eval=S)  # fmt: skip
    with blas_threads(1):
        ref = solve_point_contact(rod, R, force, s_a, s_b, (-wrench.force, -wrench.torque))
    assert ref.residual < 1e-9, ref.residual
    xa, xb = ref.rod.position(ref.s_a), ref.rod.position(ref.s_b)
    assert ref.force @ (xa - xb) > 0  # a push
    # nowhere else do the strands come closer than at the contact
    assert closest_self_approach(S, ref.rod.position(S), 0.05)[0] > 2 * R - 1e-7
    points = ref.rod.position(S)
    return Case(
        fig2(0.3), lambda r: distance_modulo_chord_rotation(r.points, points), closing_chord
    )


# ---- the paper's sheets ------------------------------------------------------------------------


def profile(value):
    """s -> value of a scene file's constant or linear table."""
    if isinstance(value, dict):
        table = np.array(value["table"], dtype=float)
        return lambda s: float(np.interp(s, table[:, 0], table[:, 1]))
    return lambda s: float(value)


def sheet_case(name: str):
    def make() -> Case:
        d = yaml.safe_load((ROOT / "config" / "scenes" / f"{name}.yaml").read_text())
        st = d["string"]
        length, rf, w = (
            st["length"],
            profile(st["bend_stiffness"]),
            profile(st["weight_per_length"]),
        )
        end = d["grips"][1]["position"]
        f0, m0 = 4 * np.pi**2 * rf(0.0) / length**2, 4 * rf(0.0) / length
        refs = [
            solve_sheet(length, rf, w, (end[0], end[2]), (-f0, fz, m), S * length)
            for fz in (w(0.0) * length / 2, -w(0.0) * length / 2)
            for m in (m0, -m0)
        ]
        ref = min((r for r in refs if r.residual < 1e-12), key=lambda r: r.energy)
        return Case(
            load_scene(name).problem,
            lambda r: float(np.abs(r.points - ref.x).max()),
            turned_first_grip,
        )

    return make


CASES = {
    "greenhill": greenhill_case,
    "fig2_r_0.4": open_loop_case,
    "fig2_r_0.3": closed_loop_case,
    "rect_paper": sheet_case("paper_rect_paper"),
    "trapezoid_paper": sheet_case("paper_trapezoid_paper"),
}


@pytest.fixture(scope="module")
def cases():
    return {}


def case(cases, name: str) -> Case:
    if name not in cases:
        cases[name] = CASES[name]()
    return cases[name]


def held(solver, result, poses):
    """Hold the stream's last poses until the estimate reported is a check of a shape there.

    ``model.checked_updates_ago`` counts the updates since the checked one; the stream's last
    result is the first at its poses.
    """
    for at_pose in range(1, HOLD + 1):
        if result.model.checked and result.model.checked_updates_ago < at_pose:
            return result
        result = solver.solve(poses)
    raise AssertionError(f"no check at the final poses within {HOLD} updates: {result.model}")


def solve(c: Case, tolerance: float, how: str):
    """The default's answer at δ = ``tolerance`` L, ``how``: 'cold' or 'streamed'."""
    # interpreted here (compile off): the 2 s update limit could stop a streamed update under load,
    # and a test must not depend on timing (a user's compiled update takes milliseconds)
    options = SolverOptions(
        error_tolerance=tolerance * c.length, output_points=POINTS, update_time_limit=0.0
    )
    solver = make_solver(c.problem, options, compile="off", checks="sync")
    try:
        if how == "cold":
            return solver.solve()
        result, poses = c.stream(solver, c.problem)
        return held(solver, result, poses)
    finally:
        solver.close()


@pytest.mark.parametrize("how", ["cold", "streamed"])
@pytest.mark.parametrize("tolerance", TOLERANCES)
@pytest.mark.parametrize("name", list(CASES))
def test_default_meets_the_tolerance(cases, name, tolerance, how):
    c = case(cases, name)
    result = solve(c, tolerance, how)
    assert result.status == "ok", result.message
    assert result.model.tolerance_met is True, result.model
    error = c.error(result)
    assert error <= tolerance * c.length, (error, result.model)
    # the estimate reported bounds the true error, and by at most 10x (issue #37)
    estimate = result.model.estimated_error_m
    assert error <= estimate <= 10 * error, (estimate, error)
    if c.problem.string.radius > 0:  # the loop never passes through itself
        d = closest_self_approach(S, np.asarray(result.points), 0.05)[0]
        assert d >= 2 * R - tolerance * c.length, d
