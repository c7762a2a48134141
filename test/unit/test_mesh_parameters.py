"""A director model's assembled KKT functions read the element mesh's geometry from p.

``model/mesh_geometry.py`` splits every matrix of an element mesh into a part its topology fixes
(the node counts per element) and the geometry vectors j = 2/h and w at the quadrature nodes;
``solver/build/mesh_parameters.py`` has the assembled KKT functions take (j, w) from p.  So the
functions built for mesh A, evaluated with the p of mesh B (same counts, other breakpoints), must
be mesh B's own functions: compared here with the functions built for B the way they always were
(the node map, weights and integration rows as B's constants: ``geometry = None``), at B's
solved equilibrium and at a perturbed point, to 1e-12 relative.  Scenes: a hanging cable with a
point load and a relative position; the cable on its table and beside a sphere (obstacle rows on
the nodes and contact slots); an extensible strip.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from dlo_ros.model.elements import ElementMesh
from dlo_ros.model.mesh_geometry import MeshTopology, ReferenceGeometry, geometry_vectors
from dlo_ros.model.obstacles import Obstacle
from dlo_ros.model.problem import Load, RelativePosition
from dlo_ros.model.profile import Profile
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build import mesh_parameters
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.options import SolverOptions

FULL = SolverOptions(model="full", order=8, output_points=51)


@pytest.mark.parametrize("extra", [0, 8])
def test_matrices_split_into_topology_and_geometry(extra):
    a = ElementMesh(1.3, [0.3, 0.5, 0.9], 12, extra, counts=[8, 6, 10, 7])
    b = ElementMesh(1.3, [0.2, 0.7, 0.75], 12, extra, counts=[8, 6, 10, 7])
    ref = ReferenceGeometry(a)
    assert ref.matches(b) and MeshTopology.of(a) == MeshTopology.of(b)
    assert not ref.matches(ElementMesh(1.3, [0.2, 0.7, 0.75], 12, extra, counts=[8, 6, 10, 8]))
    j, w = geometry_vectors(b)
    assert np.abs(b.B - ref.value).max() < 1e-13
    assert np.abs(b.dB - j[:, None] * ref.rate).max() < 1e-13 * np.abs(b.dB).max()
    assert np.abs(b.weights - ref.reference_weights / j).max() < 1e-15
    for points_a, points_b in ((a.nodes, b.nodes), (a.breakpoints, b.breakpoints)):
        A, R = ref.integration_rows(points_a)
        W = b.integration_matrix(points_b)
        assert np.abs(W - (A * w[None, :] + R / j[None, :])).max() < 1e-14
    with pytest.raises(ValueError, match="no node or breakpoint"):
        ref.integration_rows(np.array([0.31]))


def scenes():
    """(name, problem, options, mesh A, mesh B) with the same counts, other breakpoints."""
    cable = load_scene("default_cable").problem
    L = cable.string.length
    hanging = replace(
        cable,
        obstacles=(),
        loads=(Load(s=0.4 * L, force=np.array([0.0, 0.01, -0.05])),),
        relative_positions=(
            RelativePosition(s_a=0.2 * L, s_b=0.8 * L, offset=np.array([0.45, 0.0, 0.0]) * L),
        ),
    )
    fixed = (0.2 * L, 0.4 * L, 0.8 * L)  # the scene's own breakpoints stay
    yield (
        "hanging",
        hanging,
        FULL,
        MeshSpec((0.1 * L, *fixed), (6, 6, 7, 8, 6)),
        MeshSpec((0.15 * L, *fixed), (6, 6, 7, 8, 6)),
    )
    ball = Obstacle("sphere", np.array([0.2, 0.0, 0.05, 0.06]), name="ball")
    on_table = replace(cable, obstacles=(*cable.obstacles, ball))
    nodes = replace(FULL, obstacle_points="nodes")
    yield (
        "table and ball",
        on_table,
        nodes,
        MeshSpec((0.45 * L,), (8, 9)),
        MeshSpec((0.6 * L,), (8, 9)),
    )
    strip = replace(
        cable,
        obstacles=(),
        string=replace(
            cable.string,
            stretch_stiffness=Profile((0.0,), (2e3,)),
            lateral_bend_stiffness=Profile((0.0,), (0.5,)),
        ),
    )
    yield (
        "extensible strip",
        strip,
        FULL,
        MeshSpec((0.3 * L, 0.7 * L), (7, 7, 7)),
        MeshSpec((0.35 * L, 0.5 * L), (7, 7, 7)),
    )


def objective(nlp):
    """(z, p) → [f, ∇f] and (z, p) → f: the assembled ones, or the flattened expression's."""
    if nlp.value_fns is not None:
        return nlp.value_fns[0], nlp.value_fns[1]
    x, p, f = nlp.nlp["x"], nlp.nlp["p"], nlp.nlp["f"]
    return ca.Function("f", [x, p], [f, ca.gradient(f, x)]), ca.Function("e", [x, p], [f])


def functions(solver):
    nlp = solver.nlp
    out = {
        "objective": objective(nlp)[0],
        "energy": objective(nlp)[1],
        "g": nlp.g_fn,
        "kkt_free": nlp.kkt_free_fn,
        "residual_free": nlp.residual_free_fn,
        "kkt": nlp.kkt_fn,
        "residual": nlp.residual_fn,
        "jacobian": nlp.jac_g_fn,
        "kkt_free_split": nlp.kkt_free_split_fn,
        "kkt_split": nlp.kkt_split_fn,
    }
    if nlp.obstacle_g_fn is not None:
        out["obstacle_g"] = nlp.obstacle_g_fn
    return out


@pytest.mark.parametrize("scene", list(scenes()), ids=lambda s: s[0])
def test_functions_of_mesh_a_with_mesh_b_geometry_are_mesh_b_functions(scene, monkeypatch):
    name, problem, options, spec_a, spec_b = scene
    a = ShapeSolver(problem, options, compile="off", mesh=spec_a, lazy_ipopt=True)
    b_new = ShapeSolver(problem, options, compile="off", mesh=spec_b, lazy_ipopt=True)
    # mesh B built as before: its geometry as constants
    monkeypatch.setattr(mesh_parameters, "J_NAME", "no such slice")
    b_old = ShapeSolver(problem, options, compile="off", mesh=spec_b, lazy_ipopt=True)
    monkeypatch.undo()
    assert a.nlp._assembled.geometry.params is not None
    assert b_old.nlp._assembled.geometry.params is None
    result = b_new.solve()
    assert result.ok, result.message
    state = b_new.committed_state
    rng = np.random.default_rng(7)
    z0, lam0, p = state.z, state.lam_g, state.p
    # the geometry really differs
    assert np.abs(a.nlp.model.mesh.weights - b_new.nlp.model.mesh.weights).max() > 1e-3
    for z, lam in (
        (z0, lam0),
        (z0 + 1e-3 * rng.standard_normal(z0.size), lam0 + 1e-2 * rng.standard_normal(lam0.size)),
    ):
        fa, fb = functions(a), functions(b_old)
        assert fa.keys() == fb.keys()
        for key in fa:
            n_in = fa[key].n_in()
            args = [
                z,
                p,
                lam if key in ("kkt", "residual", "kkt_split") else lam[: a.nlp.n_free_rows],
            ][:n_in]
            out_a = fa[key](*args)
            out_b = fb[key](*args)
            out_a = out_a if isinstance(out_a, (list, tuple)) else [out_a]
            out_b = out_b if isinstance(out_b, (list, tuple)) else [out_b]
            for i, (x, y) in enumerate(zip(out_a, out_b)):
                x, y = np.asarray(x), np.asarray(y)
                scale = max(np.abs(y).max(initial=0.0), 1.0)
                assert np.abs(x - y).max(initial=0.0) <= 1e-12 * scale, (name, key, i)


@pytest.mark.parametrize("scene", list(scenes())[1:], ids=lambda s: s[0])
def test_ipopt_on_mesh_a_with_mesh_b_geometry_finds_mesh_b_equilibrium(scene):
    """IPOPT's problem (objective, rows and derivatives) of mesh A, given mesh B's p and started
    near mesh B's equilibrium, converges to that equilibrium."""
    name, problem, options, spec_a, spec_b = scene
    a = ShapeSolver(problem, options, compile="off", mesh=spec_a, lazy_ipopt=True)
    b = ShapeSolver(problem, options, compile="off", mesh=spec_b, lazy_ipopt=True)
    assert b.solve().ok
    state = b.committed_state
    nlp = a.nlp
    start = state.z + 1e-4 * np.random.default_rng(3).standard_normal(state.z.size)
    sol = nlp.make_solver(False)(x0=start, p=state.p, lbg=nlp.lbg, ubg=nlp.ubg)
    z = np.asarray(sol["x"]).ravel()
    assert np.abs(z - state.z).max() < 1e-7, name
    # and not mesh A's own equilibrium
    assert a.solve().ok
    assert np.abs(a.committed_state.z - state.z).max() > 1e-5
