"""A saddle's escape by shifted Newton steps as one compiled call (native/saddle_escape.c, #38):
the C loop (native.saddle.NativeSaddle) takes the steps of the Python loop (the reference,
update.saddle.shifted_steps) to the same point, and leave_saddle through it reaches the same
stable state.

Two snap-through updates of the default cable, where a warm Newton answer is the in-plane saddle
on the table: test_leave_saddle.py's grips lowered from 0.045 to 0.05 m below their start (model
full), and the 78th update of solver_speed.py's ellipse stream (the scene's options), where the
sag touches down.  Each escape the update makes is replayed from the same saddle both ways."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.compiled import compiler
from dlo_ros.solver.native.saddle import NativeSaddle
from dlo_ros.solver.update import ladder as LD
from dlo_ros.solver.update import saddle as SD

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler")

SCENE = load_scene("default_cable")
Q = SCENE.problem.grip("right").pose.orientation
L = SCENE.problem.string.length


def lowered(drop: float) -> dict:
    """Both grips lowered by ``drop`` [m] in their vertical plane (test_leave_saddle.py's)."""
    return {"left": ((0.0, 0.0, 0.4 - drop), Q), "right": ((0.6, 0.0, 0.4 - drop), Q)}


def ellipse(updates: int) -> list[dict]:
    """The right grip in steps of 1 % of L around an ellipse of radius 0.08 L in the x–z plane."""
    start = SCENE.problem.grip("right").pose.position
    radius, step = 0.08 * L, 0.01 / 0.08
    return [
        {"right": (start + radius * np.array([np.cos(i * step) - 1.0, 0.0, np.sin(i * step)]), Q)}
        for i in range(1, updates + 1)
    ]


def snap_through(case: str, monkeypatch) -> tuple[ShapeSolver, list[tuple], object]:
    """Solve ``case`` up to its snap-through update, compiled; (the solver, the arguments of each
    leave_saddle call the update made, its result)."""
    if case == "lowered table":
        solver = ShapeSolver(
            SCENE.problem, replace(SCENE.options, model="full"), compile="blocking"
        )
        assert solver.solve(lowered(0.045)).ok
        last = lowered(0.05)
    else:
        solver = ShapeSolver(SCENE.problem, SCENE.options, compile="blocking")
        assert solver.solve().ok
        targets = ellipse(78)
        for poses in targets[:-1]:
            assert solver.solve(poses).ok
        last = targets[-1]
    calls: list[tuple] = []
    original = LD.leave_saddle
    monkeypatch.setattr(
        LD, "leave_saddle", lambda *a, **k: calls.append((a, k)) or original(*a, **k)
    )
    result = solver.solve(last)
    assert calls, "Newton did not land on a saddle: the case no longer tests what it says"
    return solver, calls, result


@pytest.fixture(scope="module", params=["lowered table", "ellipse"])
def case(request, tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DLO_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.delenv("DLO_NO_COMPILE", raising=False)
        yield snap_through(request.param, mp)


def test_the_compiled_escape_is_in_place_and_runs_in_the_update(case, monkeypatch):
    """The full KKT function's library holds the escape, and the update's escape goes through it
    (an escape disabled, or the old code without it, fails here)."""
    solver, calls, result = case
    escape = solver.functions.saddle_escape
    assert isinstance(escape, NativeSaddle)
    ran = []
    monkeypatch.setattr(solver.functions, "saddle_escape", lambda *a: ran.append(1) or escape(*a))
    monkeypatch.setattr(SD, "shifted_steps", lambda *a: pytest.fail("the Python loop ran"))
    args, kwargs = calls[0]
    SD.leave_saddle(*args, **kwargs)
    assert ran


def test_the_c_loop_takes_the_python_loops_steps(case):
    """From each saddle the update left, the compiled loop's last iterate, multipliers and step
    count equal the Python loop's (round-off apart: 1e-10 in scaled unknowns)."""
    solver, calls, _ = case
    nlp, fns = solver.nlp, solver.functions
    for (nlp_arg, fns_arg, saddle, p, eigenvalue, *rest), _ in calls:
        sign = rest[0] if rest else 1.0
        g0 = saddle.g if saddle.g is not None else np.asarray(nlp.g_fn(saddle.z, saddle.p)).ravel()
        active = SD.active_rows(nlp, saddle.lam_g, g0)
        idx = np.flatnonzero(active)
        d = saddle.unstable_direction / np.max(np.abs(saddle.unstable_direction))
        z0 = saddle.z + sign * SD.SADDLE_STEP * d
        lam0 = np.where(active, saddle.lam_g, 0.0)
        rho = 2.0 * float(np.abs(lam0).max(initial=0.0)) + 1.0
        mu = 2.0 * abs(eigenvalue)
        args = (nlp, fns, z0, lam0, p, idx, nlp.ubg[idx], rho, mu)
        ok_c, z_c, lam_c, steps_c = fns.saddle_escape(*args)
        ok_py, z_py, lam_py, steps_py = SD.shifted_steps(*args)
        assert (ok_c, steps_c) == (ok_py, steps_py)
        assert steps_c > 1  # shifted steps were taken, not only the first evaluation
        np.testing.assert_allclose(z_c, z_py, rtol=0.0, atol=1e-10)
        np.testing.assert_allclose(lam_c, lam_py, rtol=0.0, atol=1e-10)


def test_the_escape_reaches_the_same_stable_state_either_way(case, monkeypatch):
    """leave_saddle compiled and interpreted (the escape set to None: the Python loop) from the
    same saddle: the same outcome, and the state polished from there equal to 1e-10; the update's
    answer is stable, Newton's and warm."""
    solver, calls, result = case
    assert result.ok and result.stable and result.warm_started, result.message
    assert result.ipopt_status == "Newton"
    fns = solver.functions
    for args, kwargs in calls:
        ok_c, state_c, steps_c, _ = SD.leave_saddle(*args, **kwargs)
        with monkeypatch.context() as mp:
            mp.setattr(fns, "saddle_escape", None)
            ok_py, state_py, steps_py, _ = SD.leave_saddle(*args, **kwargs)
        assert (ok_c, steps_c) == (ok_py, steps_py)
        if ok_c:
            np.testing.assert_allclose(state_c.z, state_py.z, rtol=0.0, atol=1e-10)
            np.testing.assert_allclose(state_c.lam_g, state_py.lam_g, rtol=0.0, atol=1e-10)


def test_a_compiled_call_leaves_the_callers_floating_point_mode(case):
    """The drivers flush subnormals to zero inside their call only (dlo_fpmode.h): after the
    escape's call this thread still computes a subnormal (numpy's and the Python path's numbers
    are untouched)."""
    solver, calls, _ = case
    (nlp, fns, saddle, p, eigenvalue, *_), _ = calls[0]
    idx = np.flatnonzero(nlp.equality)
    z = saddle.z.copy()
    z[np.abs(z) < 1e-300] = 1e-310  # subnormal inputs: read as zeros inside the call
    fns.saddle_escape(nlp, fns, z, np.zeros(nlp.lbg.size), p, idx, nlp.ubg[idx], 1.0, 1.0)
    tiny = np.array([1e-300]) * np.array([1e-10])
    assert tiny[0] != 0.0 and tiny[0] == pytest.approx(1e-310, rel=1e-3)
