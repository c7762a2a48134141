"""A result's outputs from one CasADi call (solver/build/output_function.py) against the numpy path it replaces.

Both paths evaluate the same committed state: the centreline and orientations at the output points, each
grip's reaction, each obstacle's contact force, the equilibrium residual and the flip test.  The numpy
path (wrenches.py, residual.py, frames.py) is written term by term from the equations; the function is
the same equations as one matrix expression.  They must agree to rounding for every update of a stream
and for the cold solve, with contacts on and off, point loads with moments, interior grips (several
elements), stretch, and compiled or interpreted.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from support.problems import clamped_pair, quat_about

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.model.problem import RelativePosition
from dlo_ros.model.obstacles import Obstacle
from dlo_ros.scene import load_scene
from dlo_ros.solver.build.compiled import InterpretedFunction, NativeFunction, compiler
from dlo_ros.solver.native.newton import WithNodePart
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.build.output_function import OutputFunction
from dlo_ros.solver.results.residual import PointAction
from dlo_ros.solver.shape_solver import ShapeSolver

TOL = 1e-10


def numpy_result(solver: ShapeSolver):
    """The committed state's result through the numpy path."""
    fns = solver.functions
    saved, fns.outputs = fns.outputs, None
    try:
        return solver.outputs.result(solver.problem, solver.problem, solver.committed_state, "", 0, 0.0, True, 0, None)
    finally:
        fns.outputs = saved


def assert_same(a, b) -> None:
    assert a.status == b.status and a.stable == b.stable, (a.message, b.message)
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=TOL)
    np.testing.assert_allclose(a.orientations, b.orientations, rtol=0, atol=TOL)
    assert a.grips.keys() == b.grips.keys()
    for name in a.grips:
        np.testing.assert_allclose(a.grips[name].force, b.grips[name].force, rtol=0, atol=TOL)
        np.testing.assert_allclose(a.grips[name].torque, b.grips[name].torque, rtol=0, atol=TOL)
    assert a.contact_forces.keys() == b.contact_forces.keys()
    for i in a.contact_forces:
        np.testing.assert_allclose(a.contact_forces[i], b.contact_forces[i], rtol=0, atol=TOL)
    assert a.equilibrium_residual_m == pytest.approx(b.equilibrium_residual_m, rel=1e-9, abs=1e-13)


def three_clamps() -> Problem:
    """An extensible, heavy cable held by three clamps (one interior: two elements) over a sphere."""
    string = StringProperties(1.0, Profile.constant(0.02), Profile.constant(0.015), Profile.constant(2.0),
                              stretch_stiffness=Profile.constant(40.0))
    ident = [0.0, 0.0, 0.0, 1.0]
    grips = (Grip("left", 0.0, "clamp", GripPose.checked([0.0, 0.0, 0.3], ident, "left")),
             Grip("middle", 0.45, "clamp", GripPose.checked([0.4, 0.0, 0.32], quat_about("z", 0.2), "middle")),
             Grip("right", 1.0, "clamp", GripPose.checked([0.85, 0.05, 0.3], ident, "right")))
    ball = Obstacle("sphere", np.array([0.65, 0.02, 0.2, 0.08]), "ball")
    return Problem(string, grips, gravity=np.array([0.0, 0.0, -9.81]), obstacles=(ball,))


def loaded_cantilever() -> Problem:
    """A clamped cantilever with a point force and a skew point moment at s = 0.6 m."""
    string = StringProperties(1.0, Profile.constant(0.05), Profile.constant(0.04), Profile.constant(0.5))
    grip = Grip("clamp", 0.0, "clamp", GripPose.checked([0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0], "clamp"))
    load = Load(0.6, force=np.array([0.1, 0.2, 0.0]), moment=np.array([0.02, 0.01, 0.03]))
    return Problem(string, (grip,), gravity=np.array([0.0, 0.0, -1.0]), loads=(load,))


def default_cable() -> tuple[Problem, SolverOptions]:
    scene = load_scene("default_cable")
    return scene.problem, replace(scene.options, model="full")


def tied_cable() -> tuple[Problem, SolverOptions]:
    """default_cable with the points at 0.3 m and 0.7 m held 15 cm apart along x (paper eq. 6)."""
    problem, options = default_cable()
    return replace(problem, relative_positions=(RelativePosition(0.3, 0.7, np.array([0.15, 0.0, 0.0])),)), options


def planar(make):
    """The same scene with the planar model (order 24): its outputs function (φ in the x–z plane)."""
    def build():
        problem, options = make()
        return problem, replace(options, model="planar", order=24)
    return build


def planar_loads() -> tuple[Problem, SolverOptions]:
    """A cantilever in the x–z plane with an in-plane point force and a point moment about the plane's
    normal (the only moments the planar model takes), stretchable."""
    string = StringProperties(1.0, Profile.constant(0.05), Profile.constant(0.04), Profile.constant(0.5),
                              stretch_stiffness=Profile.constant(30.0))
    grip = Grip("clamp", 0.0, "clamp", GripPose.checked([0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0], "clamp"))
    load = Load(0.6, force=np.array([0.1, 0.0, 0.05]), moment=np.array([0.0, 0.02, 0.0]))
    return Problem(string, (grip,), gravity=np.array([0.0, 0.0, -1.0]), loads=(load,)), \
        SolverOptions(model="planar", order=24)


#: case → (problem and options, how far the stream lowers the last grip [m], whether it presses on an obstacle)
CASES = {
    "default_cable": (default_cable, 0.3, True),
    "three_clamps": (lambda: (three_clamps(), SolverOptions(model="full", order=12, obstacle_slots=2)), 0.04, True),
    "loaded_cantilever": (lambda: (loaded_cantilever(), SolverOptions(model="full", order=12)), 0.04, False),
    "tied_cable": (tied_cable, 0.3, False),  # the tie holds it off the table
    "planar_default_cable": (planar(default_cable), 0.3, True),
    "planar_tied_cable": (planar(tied_cable), 0.3, False),
    "planar_loads": (planar_loads, 0.04, False),
}


def stream(problem: Problem, drop: float, steps: int = 8, axis: str = "x"):
    """Targets that lower the last grip by ``drop`` and turn it by 0.3 rad about ``axis`` (y: in the
    x–z plane of the planar cases), step by step."""
    grip = problem.grips[-1]
    for k in range(1, steps + 1):
        f = k / steps
        position = grip.pose.position + np.array([0.0, 0.0, -drop * f])
        q = quat_about(axis, 0.3 * f) if axis == "x" else _times(quat_about(axis, 0.3 * f), grip.pose.orientation)
        yield {grip.name: (position, q)}


def _times(a, b):
    """The quaternion product a ⊗ b (x, y, z, w)."""
    from dlo_ros.model.rotations import quat_multiply_matrices

    return quat_multiply_matrices(a, b)[0] @ np.asarray(b, dtype=float)


def test_the_published_quaternion_is_the_unit_quaternion_of_the_rotation_with_frame_to_quats_sign():
    """The outputs' orientation of an interpolated (non-unit) nodal quaternion v: v / |v| with the sign
    Shepperd's method gives the rotation matrix of v (``director.frame_to_quat``), for v of every size
    and each of the four components largest."""
    from dlo_ros.model.director import frame_to_quat
    from dlo_ros.model.rotations import quat_to_matrix
    from dlo_ros.solver.build.output_function import _unit_quaternion

    rng = np.random.default_rng(3)
    v = rng.normal(size=(400, 4)) * rng.uniform(0.2, 3.0, size=(400, 1))
    v[:4] = np.diag([5.0, -5.0, 5.0, -5.0]) + 0.1  # x, y, z and w by far the largest, either sign
    q = np.asarray(_unit_quaternion().map(len(v))(v.T)).T
    expected = frame_to_quat(np.array([quat_to_matrix(u / np.linalg.norm(u)) for u in v]))
    np.testing.assert_allclose(q, expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_outputs_function_equals_the_numpy_path_cold_and_streaming(case):
    make, drop, presses = CASES[case]
    problem, options = make()
    solver = ShapeSolver(problem, options, compile="off")
    assert OutputFunction.applies(solver.nlp) and solver.functions.outputs is not None  # the premise
    first = solver.solve()
    assert first.ok, first.message
    assert_same(first, numpy_result(solver))
    touched = slotted = False
    for targets in stream(problem, drop, axis="y" if options.model == "planar" else "x"):
        r = solver.solve(targets)
        assert r.ok, r.message
        assert_same(r, numpy_result(solver))
        touched |= any(np.linalg.norm(f) > 1e-6 for f in r.contact_forces.values())
        slotted |= any(np.any(solver.committed_state.lam_g[rows] > 1e-8) for rows in solver.nlp.slot_rows)
    assert touched == presses, "the stream was meant to press onto an obstacle: the contact terms went untested" \
        if presses else "a stream meant to stay clear touched"
    # a curved obstacle pressed on: a contact slot (obstacle_slots.py) carried force, so its terms were compared
    assert slotted == (presses and options.obstacle_slots > 0 and any(ob.type != "halfspace" for ob in problem.obstacles))


@pytest.mark.skipif(compiler() is None, reason="needs a C compiler")
@pytest.mark.parametrize("make", [default_cable, planar(default_cable)], ids=["full", "planar"])
def test_compiled_and_interpreted_outputs_agree(make, tmp_path, monkeypatch):
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)  # conftest turns compiling off
    problem, options = make()
    solver = ShapeSolver(problem, options, compile="blocking")
    assert isinstance(solver.functions.outputs, NativeFunction)
    interpreted = InterpretedFunction(solver.functions.output_function.function)
    for targets in [None, *stream(problem, 0.3, 4, axis="y" if options.model == "planar" else "x")]:
        r = solver.solve(targets) if targets else solver.solve()
        assert r.ok, r.message
        state, nlp = solver.committed_state, solver.nlp
        args = (state.z, state.p, state.lam_g / (nlp.row_scale * nlp.sigma),
                solver.functions.output_function.profiles(solver.problem.string))
        for native, plain in zip(solver.functions.outputs(*args), interpreted(*args)):
            np.testing.assert_allclose(native, plain, rtol=0, atol=1e-12)
        assert_same(r, numpy_result(solver))


def test_models_the_function_does_not_cover_keep_the_numpy_path():
    """A clamp and a tangent grip leave the twist free: the tangent model, whose frames are transported
    along s (no closed form): its outputs stay with numpy."""
    problem = clamped_pair(right=(0.8, 0.0, 0.0), modes=("clamp", "tangent"), weight=0.5)
    solver = ShapeSolver(problem, SolverOptions(model="full", order=12), compile="off")
    assert not OutputFunction.applies(solver.nlp) and solver.functions.outputs is None
    for targets in [None, *stream(problem, 0.04, 4)]:
        r = solver.solve(targets) if targets else solver.solve()
        assert r.ok and r.equilibrium_residual_m < 1e-3, r.message


def test_a_relative_positions_reaction_enters_the_residual():
    """The rows x(s_b) − x(s_a) = offset act on the string as a force F_b at s_b and −F_b at s_a.  Without
    them in the residual a tied cable's equilibrium read as 2.7 m off (`unverified`); with them it is
    verified and holds the offset, and both paths agree (the parametrised test).  Cold and streaming."""
    problem, options = tied_cable()
    rel = problem.relative_positions[0]
    solver = ShapeSolver(problem, options, compile="off")
    for targets in [None, *stream(problem, 0.3, 4)]:
        r = solver.solve(targets) if targets else solver.solve()
        assert r.ok, r.message  # verified: the residual is within the tolerance (1e-3 L)
        x_a, x_b = solver.nlp.model.positions(solver.committed_state.z, np.array([rel.s_a, rel.s_b]))
        np.testing.assert_allclose(x_b - x_a, rel.offset, atol=1e-9)
        # the tie pulls: without its reaction the strong-form balance is far off
        untied = solver.equilibrium(solver.problem, solver.committed_state.z, r.grips, contact_actions(solver))
        assert untied.metres > 100 * r.equilibrium_residual_m


def contact_actions(solver: ShapeSolver) -> list[PointAction]:
    """Every touching obstacle sample's force on the committed state, as a point action."""
    nlp, state = solver.nlp, solver.committed_state
    return solver.outputs._contacts(solver.problem, state.z, state.p, state.lam_g / (nlp.row_scale * nlp.sigma))[1]


@pytest.mark.skipif(compiler() is None, reason="needs a C compiler")
def test_kkt_compiled_speaks_of_the_derivatives_alone(tmp_path, monkeypatch):
    """A cache that holds the derivatives' libraries but not the outputs' (e.g. filled before the outputs
    were compiled): a 'cached' solver runs compiled derivatives and says so, with interpreted outputs."""
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    problem, options = default_cable()
    first = ShapeSolver(problem, options, compile="blocking")
    assert first.kkt_compiled and first.functions.outputs_compiled
    removed = list(tmp_path.glob("dlo_outputs_*.so"))
    assert len(removed) == 1
    removed[0].unlink()
    solver = ShapeSolver(problem, options, compile="cached")
    assert solver.kkt_compiled and isinstance(solver.functions.kkt_free, (NativeFunction, WithNodePart))
    assert not solver.functions.outputs_compiled and isinstance(solver.functions.outputs, InterpretedFunction)
    r = solver.solve()
    assert r.ok and r.derivatives == "compiled", r.message
    assert_same(r, numpy_result(solver))


@pytest.mark.parametrize("make", [default_cable, planar(default_cable)], ids=["full", "planar"])
def test_a_model_solved_once_answers_through_numpy_and_builds_the_function_when_solved_again(make):
    """``lazy_outputs`` (a check's shadow, the model a verdict names: solved once, as a rule) builds no
    outputs' function for its first answer, which numpy gives, equal to the function's; solved again,
    the function is built and answers, as an eager solver's does.  A compile builds it too."""
    problem, options = make()
    lazy = ShapeSolver(problem, options, compile="off", lazy_outputs=True)
    eager = ShapeSolver(problem, options, compile="off")
    assert lazy.functions.output_function is None and lazy.functions.outputs is None
    assert eager.functions.outputs is not None
    a, b = lazy.solve(), eager.solve()
    assert lazy.functions.outputs is None  # one answer: numpy
    assert_same(a, b)
    for targets in stream(problem, 0.3, 3, axis="y" if options.model == "planar" else "x"):
        a, b = lazy.solve(targets), eager.solve(targets)
        assert isinstance(lazy.functions.outputs, InterpretedFunction)  # solved again: the function
        assert_same(a, b)
        np.testing.assert_array_equal(a.points, b.points)  # the same path from the second answer on
    other = ShapeSolver(problem, options, compile="off", lazy_outputs=True)
    other.start_compile("background")  # a model that compiles streams: its outputs compile with it
    assert other.functions.outputs is not None
