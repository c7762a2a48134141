"""A refinement's mesh (``MeshSpec``): extra breakpoints and per-element nodes, or a clear refusal.

The mid-moment cantilever (test_moment_energy.py's docstring) is exact on any mesh with a
breakpoint at the load: an arc of curvature m/EI on [0, L/2], straight beyond.  Its tip is
(R sin θ + (L/2) cos θ, 0, −(R (1 − cos θ) + (L/2) sin θ)), R = EI/m, θ = m (L/2)/EI.
"""

from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.elements import ElementMesh
from dlo_ros.solver.build.mesh import MeshSpec, element_mesh, mesh_spec
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

from test_moment_energy import EI, LENGTH, MOMENT, cantilever


def exact_tip() -> np.ndarray:
    R, th = EI / MOMENT, MOMENT * (LENGTH / 2) / EI
    return np.array(
        [R * np.sin(th) + 0.5 * np.cos(th), 0.0, -(R * (1 - np.cos(th)) + 0.5 * np.sin(th))]
    )


@pytest.mark.parametrize(
    "spec", [MeshSpec((0.25, 0.5), (5, 7, 9)), MeshSpec((0.5, 0.8), (9, 4, 3))]
)
def test_a_chosen_mesh_is_built_and_solves_exactly(spec):
    problem = cantilever([0.0, MOMENT, 0.0])
    solver = ShapeSolver(problem, SolverOptions(model="full"), compile="off", mesh=spec)
    mesh = solver.nlp.model.mesh
    assert list(mesh.counts) == list(spec.counts)
    assert mesh_spec(mesh) == spec
    cold = solver.solve()
    assert cold.status == "ok"
    assert np.abs(cold.points[-1] - exact_tip()).max() < 1e-9
    # streamed: the clamp moves 1 cm along y and back; the shape translates with it
    for dy in (0.01, 0.0):
        warm = solver.solve({"clamp": ([0.0, dy, 0.0], [0.0, 0.0, 0.0, 1.0])})
        assert warm.status == "ok"
        assert np.abs(warm.points[-1] - exact_tip() - [0.0, dy, 0.0]).max() < 1e-9


def test_a_mesh_without_the_scenes_breakpoints_is_refused():
    problem = cantilever([0.0, MOMENT, 0.0])
    with pytest.raises(ValueError, match=r"leave out the scene's at s = \[0.5\]"):
        element_mesh(problem, SolverOptions(), MeshSpec((0.3,), (5, 5)))


def test_counts_must_match_the_elements():
    with pytest.raises(ValueError, match="2 elements need as many node counts"):
        ElementMesh(1.0, [0.5], 8, counts=(5, 5, 5))
    with pytest.raises(ValueError, match="at least 3"):
        ElementMesh(1.0, [0.5], 8, counts=(5, 2))
