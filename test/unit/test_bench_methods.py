"""Correctness of the benchmark's own method implementations (bench/), against the exact elastica.

No timing is asserted.  The dynamic peers are tested only when their optional packages
(requirements-bench.txt) are installed.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import (S_OUT, elastica_case, heavy_case, loads_case, max_error, rotation_about_x,  # noqa: E402
                          twist_case)
from bench.methods.nlp_tools import augmented_lagrangian_nm  # noqa: E402
from bench.methods.peers import initial_polyline  # noqa: E402
from bench.methods.planar import PlanarRitz, PlanarRod  # noqa: E402
from bench.methods.rod3d import Rod3D  # noqa: E402
from bench.methods.runners import twisted_problem  # noqa: E402
from bench.suite.references import elastica_points  # noqa: E402


def test_planar_rod_reproduces_the_elastica_to_second_order():
    case = elastica_case(0.5)
    ref = elastica_points(0.5)
    errors = []
    for n in (40, 80):
        out, _ = PlanarRod(case.problem, n).cold(case.problem)
        assert out.ok and out.stable
        errors.append(max_error(out.points, ref, True))
    assert errors[1] < 1e-3  # measured 1.5e-4 at N = 80
    assert errors[0] / errors[1] > 3.0  # second order: ≈ 4 per halving of h


def test_paper_method_nelder_mead_reproduces_the_elastica():
    """The paper's method (Fourier 10, multiplier method + Nelder–Mead) at chord 0.7L: within 1e-3 L."""
    case = elastica_case(0.7)
    model = PlanarRitz(case.problem, "fourier", 10)
    out, z, lam, p = model.solve_nelder_mead(case.problem, time_limit=60.0)
    assert out.ok, out.message
    assert max_error(out.points, elastica_points(0.7), True) < 1e-3  # measured ≈ 1e-5
    assert out.stable


def test_planar_fourier_ipopt_matches_the_elastica_at_order_16():
    case = elastica_case(0.3)
    out, _ = PlanarRitz(case.problem, "fourier", 16).cold(case.problem)
    assert out.ok and max_error(out.points, elastica_points(0.3), True) < 1e-5  # measured 1.2e-7


def test_quaternion_rod_reproduces_the_elastica_in_3d():
    case = elastica_case(0.5)
    out, _ = Rod3D(case.problem, 40).cold(case.problem)
    assert out.ok and out.stable
    assert max_error(out.points, elastica_points(0.5), True) < 2e-3  # measured 7.4e-4


def test_quaternion_rod_keeps_the_turns_of_a_twisted_end():
    """Continuation in τ: a full turn of the end is stored in the chain of frames, not lost."""
    case = twist_case(0.0)
    rod = Rod3D(case.problem, 30)
    out, sol = rod.cold(case.problem, check=False)
    for k in range(1, 9):
        out, sol = rod.warm(twisted_problem(case, 2 * np.pi * k / 8), sol, check=(k == 8))
    assert out.ok
    twist_plus_writhe = rod.twist_turns(sol.z)
    assert twist_plus_writhe > 0.5  # the rod holds twist (a lost turn would read ≈ 0 energy of twist)
    out0, _ = rod.cold(case.problem)
    assert out.energy > out0.energy + 1.0  # the turned end costs energy


def test_augmented_lagrangian_nelder_mead_small_problem():
    # min x² + 2y²  s.t.  x + y = 1,  x ≤ 0.5  →  (0.5, 0.5)
    def fg(z):
        return z[0] ** 2 + 2 * z[1] ** 2, np.array([z[0] + z[1] - 1.0, z[0] - 0.5])

    z, lam, info = augmented_lagrangian_nm(fg, np.zeros(2), np.array([0.0, -np.inf]), np.array([0.0, 0.0]))
    assert info["ok"]
    assert np.allclose(z, [0.5, 0.5], atol=1e-5)


def test_error_metric_aligns_about_the_chord():
    pts = elastica_points(0.6)
    rotated = pts @ rotation_about_x(1.1).T
    assert max_error(rotated, pts, align_about_chord=True) < 1e-12
    assert max_error(rotated, pts) > 0.1


def test_initial_polyline_is_feasible():
    case = elastica_case(0.4)
    nodes, frames = initial_polyline(case.problem, 20)
    seg = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    assert np.allclose(seg, 1.0 / 20, atol=1e-12)
    assert np.allclose(nodes[-1], [0.4, 0.0, 0.0], atol=1e-10)
    assert np.allclose(frames[0][:, 0], [1, 0, 0]) and np.allclose(frames[-1][:, 0], [1, 0, 0])


def test_mujoco_cable_settles_near_the_elastica():
    pytest.importorskip("mujoco")
    from bench.methods.peers import MuJoCoRunner

    case = elastica_case(0.6)
    out = MuJoCoRunner(case, 20, settle=1e-4, max_time=30).cold(case.problem)
    assert out.ok, out.message
    assert max_error(out.points, elastica_points(0.6), True) < 0.05  # first order in L/N: measured ≈ 2.5e-2


def test_mujoco4_rod_settles_near_the_elastica_and_converges():
    from bench.methods.peers import MUJOCO4_DIR, MuJoCoRodRunner

    if not (MUJOCO4_DIR / "mujoco").is_dir():
        pytest.skip("mujoco-core 4 is not installed (requirements-bench-mujoco4.txt)")
    case = elastica_case(0.6)
    errors = []
    for n in (20, 80):
        out = MuJoCoRodRunner(case, n, settle=1e-4, max_time=30).cold(case.problem)
        assert out.ok, out.message
        errors.append(max_error(out.points, elastica_points(0.6), True))
    assert errors[0] < 0.05 and errors[1] < errors[0] / 3  # first order in L/N (a clamped end segment)


@pytest.mark.parametrize("make_case", [loads_case, heavy_case], ids=["point_loads", "heavy_table"])
def test_mujoco4_rod_carries_loads_weight_and_table_contact(make_case):
    """Against the bench's discretised rod with IPOPT (N = 160, second order): a lost load or a couple of the
    wrong sign moves the shape by far more than the peer's first-order error (a couple's sign: caught)."""
    from bench.methods.peers import MUJOCO4_DIR, MuJoCoRodRunner

    if not (MUJOCO4_DIR / "mujoco").is_dir():
        pytest.skip("mujoco-core 4 is not installed (requirements-bench-mujoco4.txt)")
    case = make_case()
    reference, _ = PlanarRod(case.problem, 160).cold(case.problem)
    out = MuJoCoRodRunner(case, 80, settle=1e-4, max_time=30).cold(case.problem)
    assert reference.ok and out.ok, out.message
    assert max_error(out.points, reference.points, mirror=True) < 0.015  # measured 4.8e-3 / 9.2e-3 at N = 80


def test_pyelastica_settles_near_the_elastica():
    pytest.importorskip("elastica")
    from bench.methods.peers import PyElasticaRunner

    case = elastica_case(0.6)
    out = PyElasticaRunner(case, 20, settle=1e-4, max_time=60).cold(case.problem)
    assert out.ok, out.message
    assert max_error(out.points, elastica_points(0.6), True) < 0.05
    assert out.extra["strain"] < 1e-3  # nearly inextensible at radius 2 mm (EA/EI = 4/r²)


assert S_OUT[0] == 0.0


def test_the_euler_rows_run_the_papers_model_and_the_default_rows_the_director_model():
    """SolverOptions' defaults are the director model, which has no basis and no frame: the Fourier rows
    must ask for Euler angles, or they silently run the default (as they did until the 2026-12-03 run)."""
    from dlo_ros.model.director import DirectorModel
    from dlo_ros.model.ritz import RitzModel

    from bench.methods.runners import make_runner

    for method in ("fourier-3d", "fourier-3d-z"):
        runner = make_runner(method, 8, elastica_case(0.6))
        solver = getattr(runner, "solver", None) or runner.inner.solver
        assert isinstance(solver.nlp.model, RitzModel) and solver.nlp.model.basis.name == "fourier", method
    assert isinstance(make_runner("fourier", 8, twist_case()).solver.nlp.model, RitzModel)
    assert isinstance(make_runner("paper", 10, twist_case()).helper.nlp.model, RitzModel)
    assert isinstance(make_runner("default", 8, elastica_case(0.6)).solver.nlp.model, DirectorModel)
