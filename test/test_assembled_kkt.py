"""The assembled contact-free KKT function (dlo_ros.solver.assembled, #14) equals the KKT system
differentiated from the whole flattened Lagrangian (CasADi SX AD of ``StringNLP``'s objective and
rows: ``hessian_fn``, ``jac_g_fn``, ``g_fn``, ``energy_fn``), and its compiled C equals it too."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dlo_ros.model.problem import Load, RelativePosition
from dlo_ros.model.profile import Profile
from dlo_ros.scene import load_scene
from dlo_ros.solver.compiled import NativeFunction, compiled, compiler
from dlo_ros.solver.nlp import StringNLP
from dlo_ros.solver.options import SolverOptions
from random_scenes import random_scene


def reference_kkt(nlp: StringNLP, z, p, lam_free):
    """[K, r, ∇f, energies] from the flattened functions (obstacle and other inequality rows' λ = 0)."""
    nf, n = nlp.n_free_rows, z.size
    lam = np.zeros(nlp.g_sym.shape[0])
    lam[:nf] = lam_free
    hess = np.asarray(nlp.hessian_fn(z, p, lam))
    jac = np.asarray(nlp.jac_g_fn(z, p))[:nf]
    g = np.asarray(nlp.g_fn(z, p)).ravel()[:nf]
    grad_f = np.asarray(nlp.kkt_fn(z, p, lam)[0]).ravel()
    kkt = np.block([[hess, jac.T], [jac, np.zeros((nf, nf))]])
    residual = np.concatenate([grad_f + jac.T @ lam_free, g])
    energies = np.asarray(nlp.energy_fn(z, p), dtype=float).ravel()
    assert n == hess.shape[0]
    return [kkt, residual, grad_f, energies]


def assert_equal_systems(fn, nlp: StringNLP, trials: int = 2, rtol: float = 1e-12) -> None:
    rng = np.random.default_rng(7)
    n, n_p, nf = nlp.z_sym.shape[0], nlp.p_sym.shape[0], nlp.n_free_rows
    for _ in range(trials):
        z, p, lam = rng.normal(size=n), rng.uniform(0.5, 1.5, n_p), rng.normal(size=nf)
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


@pytest.mark.skipif(compiler() is None, reason="no C compiler")
def test_the_compiled_assembled_system_equals_the_interpreted_one(tmp_path, monkeypatch):
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    scene = load_scene("default_cable")
    nlp = StringNLP(scene.problem, dataclasses.replace(scene.options, model="full"))
    native, ok = compiled(nlp.kkt_free_fn)
    assert ok and isinstance(native, NativeFunction)
    rng = np.random.default_rng(3)
    args = [rng.normal(size=nlp.z_sym.shape[0]), rng.uniform(0.5, 1.5, nlp.p_sym.shape[0]),
            rng.normal(size=nlp.n_free_rows)]
    for got, want in zip(native(*args), nlp.kkt_free_fn(*args)):
        want = np.asarray(want)
        assert np.max(np.abs(got - want)) <= 1e-10 * (1.0 + np.max(np.abs(want)))
