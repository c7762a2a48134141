"""The planar (and Euler-angle 3D) Ritz model on spectral elements: ``solver.basis: 'elements'``.

Against answers that know nothing of the discretisation:

* the mid-moment cantilever (test_moment_energy.py's docstring): an arc of curvature m/EI on
  [0, L/2] and a straight part beyond, tip in closed form (test_mesh_spec.exact_tip).  Its
  curvature jumps at the load, so one polynomial over [0, L] converges only algebraically there;
  elements split at the load are exact for any order.
* a tip-loaded and a heavy cantilever in the x–z plane: shooting on the Kirchhoff rod equations
  (test/reference/kirchhoff.py, loads raised from zero), sampled at the result's arc lengths.

Each case is solved cold and streamed (the clamp moves 2 cm in the plane and comes back in warm
updates; the shape translates with it), interpreted (compile 'off') and compiled
(compile 'blocking': warm updates are one compiled Newton call).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from reference.kirchhoff import continuation, solve_clamped

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.solver import make_solver
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

from test_mesh_spec import exact_tip
from test_moment_energy import MOMENT, cantilever

LENGTH, EI = 1.0, 0.05
TIP_FORCE = np.array([0.0, 0.0, -0.1])  # F L² / EI = 2
WEIGHT = 0.25  # N/m: D L³ / EI = 5
IDENTITY = [0.0, 0.0, 0.0, 1.0]
STREAM = ([0.02, 0.0, 0.0], [0.0, 0.0, 0.02], [0.0, 0.0, 0.0])  # clamp offsets, back at the end


def plane_cantilever(kind: str) -> Problem:
    """1 m cantilever clamped at the origin, tangent +x: a tip force −z, or its weight along −z."""
    weight = WEIGHT if kind == "heavy" else 0.0
    string = StringProperties(
        LENGTH, Profile.constant(EI), Profile.constant(0.04), Profile.constant(weight)
    )
    grip = Grip("clamp", 0.0, "clamp", GripPose.checked(np.zeros(3), IDENTITY, "clamp"))
    loads = (Load(LENGTH, force=TIP_FORCE),) if kind == "tip" else ()
    return Problem(string, (grip,), gravity=np.array([0.0, 0.0, -1.0]), loads=loads)


@lru_cache(maxsize=None)
def shooting(kind: str):
    """The Kirchhoff equilibrium of ``plane_cantilever(kind)`` (loads raised from zero)."""
    problem = plane_cantilever(kind)
    st, grip = problem.string, problem.grips[0]

    def at(fraction, guess):
        return solve_clamped(
            LENGTH,
            EI,
            0.04,
            np.zeros(3),
            np.eye(3),
            mode_end="free",
            D=fraction * st.weight_per_length.maximum,
            g=problem.gravity,
            loads=[(LENGTH, fraction * TIP_FORCE, None)] if kind == "tip" else [],
            guess=guess,
            tol=1e-11,
        )

    solution = continuation(at, np.linspace(0.0, 1.0, 11), guess=(np.zeros(3), np.zeros(3)))
    solution = solution[-1][1]
    assert solution.residual < 1e-10
    return solution


def reference_error(kind: str, result, offset=(0.0, 0.0, 0.0)) -> float:
    """Largest distance [m] of the result's centreline from the shooting reference's."""
    x = shooting(kind).position(result.s) + np.asarray(offset)
    return float(np.abs(result.points - x).max())


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    """One compiled-function cache for this module's compiled solvers."""
    return str(tmp_path_factory.mktemp("cache"))


@pytest.fixture
def compiling(monkeypatch, cache_dir):
    """Let 'blocking' compile (test/conftest.py turns compiling off), into ``cache_dir``."""
    monkeypatch.setenv("DLO_CACHE_DIR", cache_dir)
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)


def planar(order: int, basis: str = "elements") -> SolverOptions:
    return SolverOptions(model="planar", basis=basis, order=order)


def streamed(solver: ShapeSolver, error, compiled: bool) -> list[float]:
    """Errors of the warm updates of ``STREAM`` (``error(result, offset)``); each must be ok."""
    errors = []
    for offset in STREAM:
        warm = solver.solve({"clamp": (offset, IDENTITY)})
        assert warm.status == "ok", warm.message
        assert warm.warm_started
        assert warm.derivatives == ("compiled" if compiled else "interpreted")
        errors.append(error(warm, offset))
    return errors


# ---- the mid-moment cantilever: a kink at the load ------------------------------------------------
def moment_tip_error(result, offset=(0.0, 0.0, 0.0)) -> float:
    return float(np.abs(result.points[-1] - exact_tip() - np.asarray(offset)).max())


@pytest.mark.parametrize("compile", ["off", "blocking"])
@pytest.mark.parametrize(
    "options",
    [planar(16), SolverOptions(model="full", rotation="euler", basis="elements", order=16)],
    ids=["planar", "euler3d"],
)
def test_mid_moment_cantilever_is_exact_on_elements(options, compile, compiling):
    solver = ShapeSolver(cantilever([0.0, MOMENT, 0.0]), options, compile=compile)
    cold = solver.solve()
    assert cold.status == "ok", cold.message
    assert cold.basis == "elements"
    assert moment_tip_error(cold) < 1e-9 * LENGTH
    assert cold.equilibrium_residual_m < 1e-9 * LENGTH
    assert max(streamed(solver, moment_tip_error, compile == "blocking")) < 1e-9 * LENGTH


def test_one_polynomial_does_not_follow_the_kink():
    """The same scene with basis 'chebyshev' at order 16 and 32 stays off by more than 1e-7 L."""
    for order in (16, 32):
        result = ShapeSolver(
            cantilever([0.0, MOMENT, 0.0]), planar(order, "chebyshev"), compile="off"
        ).solve()
        assert result.status == "ok"
        assert moment_tip_error(result) > 1e-7 * LENGTH


# ---- smooth cantilevers against shooting ----------------------------------------------------------
@pytest.mark.parametrize("kind", ["tip", "heavy"])
def test_error_falls_with_order(kind):
    errors = []
    for order in (8, 16, 24):
        result = ShapeSolver(plane_cantilever(kind), planar(order), compile="off").solve()
        assert result.status == "ok", result.message
        errors.append(reference_error(kind, result))
    assert errors[0] > errors[1] > errors[2] or errors[2] < 1e-11 * LENGTH, errors
    assert errors[2] < 1e-8 * LENGTH, errors


@pytest.mark.parametrize("compile", ["off", "blocking"])
@pytest.mark.parametrize("kind", ["tip", "heavy"])
def test_cold_and_streamed_match_shooting(kind, compile, compiling):
    solver = ShapeSolver(plane_cantilever(kind), planar(24), compile=compile)
    cold = solver.solve()
    assert cold.status == "ok", cold.message
    assert reference_error(kind, cold) < 1e-8 * LENGTH

    def error(result, offset):
        return reference_error(kind, result, offset)

    assert max(streamed(solver, error, compile == "blocking")) < 1e-8 * LENGTH


# ---- auto's planar model -------------------------------------------------------------------------
def test_auto_plans_on_elements():
    """model 'auto' (the default) takes the planar model on elements: the kink at the load is exact,
    cold and streamed (before, its single polynomial stayed 1e-6 L off and more)."""
    solver = make_solver(
        cantilever([0.0, MOMENT, 0.0]), SolverOptions(), compile="off", checks="sync"
    )
    cold = solver.solve()
    assert cold.ok and cold.model.planar and cold.basis == "elements", cold.message
    assert moment_tip_error(cold) < 1e-9 * LENGTH
    for offset in STREAM:
        warm = solver.solve({"clamp": (offset, IDENTITY)})
        assert warm.ok and warm.model.planar and warm.basis == "elements", warm.message
        assert moment_tip_error(warm, offset) < 1e-9 * LENGTH


# ---- options ------------------------------------------------------------------------------------
def test_options_name_the_field():
    with pytest.raises(ValueError, match="solver.order: must be at least 3 for solver.basis"):
        SolverOptions(model="planar", basis="elements", order=2).validate()
    with pytest.raises(ValueError, match="solver.basis: must be one of"):
        SolverOptions(basis="spline").validate()
    # the director model is built on elements: naming them is not an ignored Euler option
    SolverOptions(model="full", basis="elements").validate()


def test_cli_solves_on_elements():
    """``dlo solve --basis elements`` (argparse refused it before): the planar model on elements
    agrees with the single polynomial at order 24 on a smooth scene (the clamped elastica)."""
    import json  # only this test runs the CLI
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = {**os.environ, "DLO_NO_COMPILE": "1"}
    out = {}
    for basis in ("elements", "chebyshev"):
        args = ["solve", "elastica_clamped", "--json", "--model", "planar", "--order", "24"]
        done = subprocess.run(
            [sys.executable, "-m", "dlo_ros.cli", *args, "--basis", basis],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=Path(__file__).resolve().parents[2],
            env=env,
        )
        assert done.returncode == 0, done.stderr
        out[basis] = json.loads(done.stdout)
        assert out[basis]["solver"]["basis"] == basis
    gap = np.abs(np.array(out["elements"]["points"]) - out["chebyshev"]["points"]).max()
    assert gap < 1e-6 * LENGTH  # measured: 8.8e-8
