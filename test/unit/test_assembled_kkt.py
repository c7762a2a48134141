"""The assembled KKT functions of director models (dlo_ros.solver.build.assembled, #14) equal the KKT
system differentiated here from the whole flattened NLP (CasADi SX AD of ``StringNLP.nlp``'s objective
and rows, with ``energy_fn``), for the contact-free rows and for every row (obstacles of each type with
their contact slots and sample switches, self-contact slots); and their compiled C equals them too."""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from dlo_ros.model.obstacles import Obstacle
from dlo_ros.model.problem import Load, RelativePosition
from dlo_ros.model.profile import Profile
from dlo_ros.scene import load_scene
from dlo_ros.solver.build.compiled import NativeFunction, compiled, compiler
from dlo_ros.solver.native.blocks import add_contact_part
from dlo_ros.model.mesh_geometry import geometry_vectors
from dlo_ros.solver.build.nlp import StringNLP
from dlo_ros.solver.options import SolverOptions
from random_scenes import random_scene


def flattened(nlp: StringNLP) -> ca.Function:
    """(z, p, λ) → [∇f, g, ∂g/∂z, ∇²L] by SX AD of the NLP's whole objective and rows."""
    x, p, f, g = (nlp.nlp[k] for k in ("x", "p", "f", "g"))
    lam = ca.SX.sym("lam", g.shape[0])
    return ca.Function("flat", [x, p, lam], [ca.gradient(f, x), g, ca.jacobian(g, x),
                                             ca.hessian(f + ca.dot(lam, g), x)[0]])


def random_p(nlp: StringNLP, rng) -> np.ndarray:
    """Return a random p in [0.5, 1.5] whose mesh geometry is the built mesh's.

    The assembled functions read the element mesh's geometry from p (j = 2/h, w:
    ``solver/build/mesh_parameters.py``); the flattened reference has the built mesh's.
    """
    p = rng.uniform(0.5, 1.5, nlp.p_sym.shape[0])
    if "mesh:j" in nlp.params.slices:
        p[nlp.params["mesh:j"]], p[nlp.params["mesh:w"]] = geometry_vectors(nlp.model.mesh)
    return p


def reference_kkt(nlp: StringNLP, z, p, lam_free):
    """[K, r, ∇f, energies] of the contact-free rows (the inequality rows' λ = 0)."""
    nf = nlp.n_free_rows
    lam = np.zeros(nlp.g_sym.shape[0])
    lam[:nf] = lam_free
    grad_f, g, jac, hess = (np.asarray(a, dtype=float) for a in flattened(nlp)(z, p, lam))
    grad_f, g, jac = grad_f.ravel(), g.ravel()[:nf], jac[:nf]
    kkt = np.block([[hess, jac.T], [jac, np.zeros((nf, nf))]])
    residual = np.concatenate([grad_f + jac.T @ lam_free, g])
    energies = np.asarray(nlp.energy_fn(z, p), dtype=float).ravel()
    return [kkt, residual, grad_f, energies]


def assert_equal_systems(fn, nlp: StringNLP, trials: int = 2, rtol: float = 1e-12) -> None:
    rng = np.random.default_rng(7)
    n, n_p, nf = nlp.z_sym.shape[0], nlp.p_sym.shape[0], nlp.n_free_rows
    for _ in range(trials):
        z, p, lam = rng.normal(size=n), random_p(nlp, rng), rng.normal(size=nf)
        for name, got, want in zip(["K", "r", "grad f", "energies"], fn(z, p, lam), reference_kkt(nlp, z, p, lam)):
            got = np.asarray(got, dtype=float).reshape(np.shape(want))
            scale = 1.0 + np.max(np.abs(want))
            assert np.max(np.abs(got - want)) <= rtol * scale, name


def stretched_scene(seed: int):
    """A random scene plus stretch, a piecewise-linear Rf, a relative position and a point load with a
    moment about a skew axis (every kind of row and term the assembly has)."""
    problem = random_scene(seed)
    L = problem.string.length
    string = dataclasses.replace(problem.string, stretch_stiffness=Profile.constant(50.0),
                                 bend_stiffness=Profile.table([(0.0, 0.02), (0.5 * L, 0.05), (L, 0.03)]))
    return dataclasses.replace(
        problem, string=string,
        relative_positions=(RelativePosition(0.2 * L, 0.7 * L, np.array([0.1, 0.05, 0.0]) * L),),
        loads=problem.loads + (Load(0.45 * L, np.array([0.1, 0.2, -0.3]), np.array([0.01, -0.02, 0.03])),))


@pytest.mark.parametrize("case", ["default_cable", "paper_fig2_transition", "seed 3", "seed 8", "stretched 2",
                                  "stretched 4"])
def test_the_assembled_system_equals_the_flattened_one(case):
    if case.startswith("seed"):
        problem, options = random_scene(int(case.split()[1])), SolverOptions(model="full")
    elif case.startswith("stretched"):
        problem, options = stretched_scene(int(case.split()[1])), SolverOptions(model="full")
    else:
        scene = load_scene(case)
        problem, options = scene.problem, dataclasses.replace(scene.options, model="full", order=12)
    nlp = StringNLP(problem, options)
    assert nlp.director
    assert_equal_systems(nlp.kkt_free_fn, nlp)


def obstacle_scene():
    """default_cable (its table) plus a turned box and a capsule."""
    scene = load_scene("default_cable")
    extra = (Obstacle.from_dict({"type": "box", "center": [0.2, 0.1, 0.3], "half_extents": [0.1, 0.2, 0.3],
                                 "orientation": [0.1, 0.2, 0.3, 0.927]}),
             Obstacle.from_dict({"type": "capsule", "a": [0.0, 0.1, 0.2], "b": [0.3, 0.1, 0.2], "radius": 0.05}))
    return dataclasses.replace(scene.problem, obstacles=scene.problem.obstacles + extra)


@pytest.mark.parametrize("case", ["obstacles of every type, 3 self-contact slots", "seed 24 (sphere)",
                                  "stretched 7, 2 slots"])
def test_the_assembled_system_of_every_row_equals_the_flattened_one(case):
    if case.startswith("obstacles"):
        problem, options = obstacle_scene(), SolverOptions(model="full", order=12, self_contact_pairs=3, obstacle_slots=2)
    elif case.startswith("seed"):
        problem, options = random_scene(24), SolverOptions(model="full", obstacle_slots=2)
    else:
        problem, options = stretched_scene(7), SolverOptions(model="full", self_contact_pairs=2)
    nlp = StringNLP(problem, options)
    assert nlp.director and nlp.obstacle_g_fn is not None
    reference = flattened(nlp)
    rng = np.random.default_rng(11)
    rows = nlp.g_sym.shape[0]
    for _ in range(2):
        z, p, lam = rng.normal(size=nlp.z_sym.shape[0]), random_p(nlp, rng), rng.normal(size=rows)
        got = nlp.kkt_fn(z, p, lam)
        want = reference(z, p, lam)
        for name, a, b in zip(["grad f", "g", "jacobian", "hessian"], got, want):
            a, b = ca.DM(a).full(), ca.DM(ca.densify(b)).full()
            assert np.max(np.abs(a - b)) <= 1e-12 * (1.0 + np.max(np.abs(b))), name
        energies = ca.DM(got[4]).full().ravel()
        np.testing.assert_allclose(energies, np.asarray(nlp.energy_fn(z, p), dtype=float).ravel(), rtol=1e-12, atol=1e-12)


@pytest.mark.skipif(compiler() is None, reason="no C compiler")
def test_the_compiled_assembled_system_equals_the_interpreted_one(tmp_path, monkeypatch):
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    scene = load_scene("default_cable")
    nlp = StringNLP(scene.problem, dataclasses.replace(scene.options, model="full"))
    native, ok = compiled(nlp.kkt_free_fn)
    assert ok and isinstance(native, NativeFunction)
    rng = np.random.default_rng(3)
    args = [rng.normal(size=nlp.z_sym.shape[0]), random_p(nlp, rng),
            rng.normal(size=nlp.n_free_rows)]
    for got, want in zip(native(*args), nlp.kkt_free_fn(*args)):
        want = np.asarray(want)
        assert np.max(np.abs(got - want)) <= 1e-10 * (1.0 + np.max(np.abs(want)))


@pytest.mark.parametrize("slots", [0, 3])
def test_the_assembled_inequality_rows_equal_the_flattened_ones(slots):
    nlp = StringNLP(obstacle_scene(), SolverOptions(model="full", order=12, self_contact_pairs=slots, obstacle_slots=2))
    values = ca.Function("g", [nlp.z_sym, nlp.p_sym], [nlp.g_sym[nlp.n_free_rows:]])
    rng = np.random.default_rng(5)
    for _ in range(2):
        z, p = rng.normal(size=nlp.z_sym.shape[0]), random_p(nlp, rng)
        got, want = ca.DM(nlp.obstacle_g_fn(z, p)).full(), ca.DM(values(z, p)).full()
        assert np.max(np.abs(got - want)) <= 1e-12 * (1.0 + np.max(np.abs(want)))


def test_the_assembled_constraint_jacobian_equals_the_flattened_one():
    nlp = StringNLP(obstacle_scene(), SolverOptions(model="full", order=12, self_contact_pairs=2, obstacle_slots=2))
    reference = ca.Function("flat_jacobian", [nlp.z_sym, nlp.p_sym], [ca.jacobian(nlp.g_sym, nlp.z_sym)])
    rng = np.random.default_rng(9)
    z, p = rng.normal(size=nlp.z_sym.shape[0]), random_p(nlp, rng)
    got, want = ca.DM(nlp.jac_g_fn(z, p)).full(), ca.DM(ca.densify(reference(z, p))).full()
    assert np.max(np.abs(got - want)) <= 1e-12 * (1.0 + np.max(np.abs(want)))


def _split_cases(case: str) -> StringNLP:
    if case == "default_cable":
        scene = load_scene(case)
        return StringNLP(scene.problem, dataclasses.replace(scene.options, model="full", order=12))
    if case == "stretched 2, 2 self-contact slots":
        return StringNLP(stretched_scene(2), SolverOptions(model="full", self_contact_pairs=2))
    if case == "obstacles of every type, slots":
        return StringNLP(obstacle_scene(), SolverOptions(model="full", order=12, obstacle_slots=2))
    from test_assembled_euler import planar_scene

    model, rotation = ("planar", "director") if case == "planar" else ("full", "euler")
    return StringNLP(planar_scene(), SolverOptions(model=model, rotation=rotation, order=10))


@pytest.mark.parametrize("case", ["default_cable", "stretched 2, 2 self-contact slots",
                                  "obstacles of every type, slots", "planar", "euler"])
def test_the_split_systems_plus_their_node_part_equal_the_flattened_ones(case):
    """What the compiled Newton loops evaluate (native_newton): ``kkt_free_split_fn`` and ``kkt_split_fn``,
    the systems without the Hessian's per-node part, plus Eᵀ W (W their last output, E the node map),
    equal the system differentiated from the flattened NLP, for every model."""
    nlp = _split_cases(case)
    E, n, nf = nlp.node_map, nlp.z_sym.shape[0], nlp.n_free_rows

    def free(z, p, lam):
        outputs = nlp.kkt_free_split_fn(z, p, lam)
        kkt, residual, grad_f, energies, weighted = (np.asarray(a, dtype=float) for a in outputs)
        kkt[:n, :n] += E.T @ weighted
        return kkt, residual, grad_f, energies

    assert_equal_systems(free, nlp)
    reference = flattened(nlp)
    rng = np.random.default_rng(5)
    rows = nlp.g_sym.shape[0]
    z, p, lam = rng.normal(size=n), random_p(nlp, rng), rng.normal(size=rows)
    outputs = (np.asarray(a, dtype=float) for a in nlp.kkt_split_fn(z, p, lam))
    grad_f, g, jac, hess, _, weighted, d, w = outputs
    hess += E.T @ weighted
    add_contact_part(hess, d, w.ravel(), nlp.contact_sizes)  # every row carries a multiplier here
    if case in ("stretched 2, 2 self-contact slots", "obstacles of every type, slots"):
        assert nlp.contact_sizes  # rows nonlinear in the positions: curvature blocks to add
    for name, a, b in zip(["grad f", "g", "jacobian", "hessian"], [grad_f, g, jac, hess],
                          reference(z, p, lam)):
        b = ca.DM(ca.densify(b)).full()
        assert np.max(np.abs(a.reshape(b.shape) - b)) <= 1e-12 * (1.0 + np.max(np.abs(b))), (name, nf)
