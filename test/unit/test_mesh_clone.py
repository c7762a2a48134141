"""An NLP cloned onto another mesh of its topology answers as the NLP built for that mesh.

``solver/build/mesh_clone.py``: a director model's functions read the mesh's geometry from p, so
``ShapeSolver(..., mesh=B, template=A's solver)`` shares A's functions and makes only the numpy
parts of mesh B its own.  Compared here with a solver built for B the usual way (its functions
built with B's constants): cold and along a stream of grip targets, the status, centreline, grip
forces, energy, stability and constraint violation agree; the shape sensitivity (the one module that differentiates
the flattened graph, which a clone does not own) agrees; and a mesh whose topology or scene
breakpoints differ is built, not cloned.  Scenes: ``test_mesh_parameters.scenes`` (a hanging cable
with a point load and a relative position; the table and a sphere on node rows with slots; an
extensible strip).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_mesh_parameters import FULL, scenes

from dlo_ros.model.problem import GripPose, Load
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.build.mesh_clone import clone_nlp, clone_or_build, symbolic_nlp
from dlo_ros.solver.results.sensitivity import shape_sensitivity

SCENES = list(scenes())


def moved(problem, k: int) -> dict:
    """The right grip's target k of a short stream: 2 cm per step along a diagonal."""
    pose = problem.grip("right").pose
    step = np.array([-0.02, 0.015, 0.01]) * k
    return {"right": GripPose(pose.position + step, pose.orientation)}


def agree(a, b) -> None:
    """Two results of one mesh: the same status and answer, to rounding."""
    assert a.status == b.status == "ok", (a.status, b.status, a.message, b.message)
    assert np.abs(a.points - b.points).max() < 1e-9
    for name, wrench in a.grips.items():
        assert np.abs(wrench.force - b.grips[name].force).max() < 1e-7
    assert abs(a.energy["total"] - b.energy["total"]) < 1e-10
    assert a.stable == b.stable and a.stable is not None
    assert abs(a.constraint_violation - b.constraint_violation) < 1e-9


@pytest.mark.parametrize(
    "name, problem, options, mesh_a, mesh_b", SCENES, ids=[s[0] for s in SCENES]
)
def test_clone_answers_as_the_mesh_built_for_it(name, problem, options, mesh_a, mesh_b):
    template = ShapeSolver(problem, options, compile="off", mesh=mesh_a)
    assert template.solve().status == "ok"
    # the clone's scene has other grip poses: its R0 (the cold start's plane) is its own, as a
    # build's (a clone with the template's answered a data set by the order its samples came in)
    problem = problem.with_grip_poses(moved(problem, 3))
    clone = ShapeSolver(problem, options, compile="off", mesh=mesh_b, template=template)
    built = ShapeSolver(problem, options, compile="off", mesh=mesh_b)
    assert np.array_equal(clone.nlp.r0, built.nlp.r0)
    assert not np.allclose(clone.nlp.r0, template.nlp.r0)
    assert clone.nlp.own_symbols is False and getattr(built.nlp, "own_symbols", True)
    assert clone.nlp.kkt_fn is template.nlp.kkt_fn  # shared, not built
    assert np.array_equal(clone.nlp.model.mesh.breakpoints, built.nlp.model.mesh.breakpoints)
    assert np.abs(clone.nlp.node_map - built.nlp.node_map).max() < 1e-12
    assert np.array_equal(clone.nlp.obstacle_s, built.nlp.obstacle_s)
    agree(clone.solve(), built.solve())  # cold
    for k in range(1, 5):  # streamed: warm updates from each one's own last answer
        agree(clone.solve(moved(problem, k)), built.solve(moved(problem, k)))
    # the template still answers on its own mesh after the clone has solved
    assert template.solve(moved(problem, 1)).status == "ok"


def test_sensitivity_of_a_clone_differentiates_its_own_mesh():
    name, problem, options, mesh_a, mesh_b = SCENES[0]
    template = ShapeSolver(problem, options, compile="off", mesh=mesh_a)
    clone = ShapeSolver(problem, options, compile="off", mesh=mesh_b, template=template)
    built = ShapeSolver(problem, options, compile="off", mesh=mesh_b)
    for solver in (clone, built):
        assert solver.solve().status == "ok"
    s = np.linspace(0.0, problem.string.length, 21)
    a = shape_sensitivity(clone, ("Rf", "D"), s)
    b = shape_sensitivity(built, ("Rf", "D"), s)
    assert np.abs(a.d_points).max() > 1e-3  # the derivatives are not trivially zero
    assert np.abs(a.d_points - b.d_points).max() < 1e-7 * np.abs(b.d_points).max()
    symbolic = symbolic_nlp(clone.nlp)
    assert (
        symbolic is not template.nlp and symbolic.own_symbols
        if hasattr(symbolic, "own_symbols")
        else True
    )
    assert np.array_equal(symbolic.model.mesh.breakpoints, clone.nlp.model.mesh.breakpoints)


def test_a_mesh_that_does_not_fit_the_template_is_built():
    name, problem, options, mesh_a, mesh_b = SCENES[0]
    template = ShapeSolver(problem, options, compile="off", mesh=mesh_a).nlp
    L = problem.string.length
    other_counts = MeshSpec(mesh_b.breakpoints, (6, 6, 7, 8, 7))
    built = clone_or_build(problem, options, None, other_counts, template)
    assert getattr(built, "own_symbols", True) and built.kkt_fn is not template.kkt_fn
    with pytest.raises(ValueError, match="topology"):
        clone_nlp(template, problem, other_counts)
    # the point load at 0.4 L on another breakpoint (the second, not the third)
    shifted = replace(problem, loads=(replace(problem.loads[0], s=0.15 * L),))
    with pytest.raises(ValueError, match="another breakpoint"):
        clone_nlp(
            template, shifted, MeshSpec((0.15 * L, 0.2 * L, 0.4 * L, 0.8 * L), mesh_b.counts)
        )
    # another structure (a second load) through ShapeSolver: built anew, answers
    more = replace(problem, loads=(*problem.loads, Load(s=0.2 * L, force=np.zeros(3))))
    solver = ShapeSolver(
        more,
        options,
        compile="off",
        mesh=mesh_b,
        template=ShapeSolver(problem, options, compile="off", mesh=mesh_a),
    )
    assert getattr(solver.nlp, "own_symbols", True)
    samples = replace(FULL, obstacle_points="samples")
    table = SCENES[1][1]
    with pytest.raises(ValueError, match="uniform samples"):
        clone_nlp(
            ShapeSolver(table, samples, compile="off", mesh=SCENES[1][3]).nlp, table, SCENES[1][4]
        )


def test_a_clone_loads_the_templates_compiled_functions_and_answers_alike(monkeypatch, tmp_path):
    """The compiled drivers add Eᵀ W with the clone's own node map (its blocks), not A's."""
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    name, problem, options, mesh_a, mesh_b = SCENES[0]
    template = ShapeSolver(problem, options, compile="blocking", mesh=mesh_a)
    clone = ShapeSolver(problem, options, compile="cached", mesh=mesh_b, template=template)
    built = ShapeSolver(problem, options, compile="off", mesh=mesh_b)
    assert clone.kkt_compiled  # the template's libraries: one fingerprint for the topology
    for k in range(4):
        a, b = clone.solve(moved(problem, k)), built.solve(moved(problem, k))
        assert a.derivatives == "compiled" and b.derivatives != "compiled"
        agree(a, b)
