"""The rows' curvature added only where a row carries force (``assembled_contact.contact_blocks``).

The compiled split full KKT function (``StringNLP.kkt_split_fn``) leaves the curvature term
Σ_j D_jᵀ λ_j∇²ψ_j D_j of the rows nonlinear in the positions out of ∇²L and outputs its blocks;
the compiled active-set loop and saddle escape (``dlo_add_contact_part``, C) and the Python calls
(``native.blocks.add_contact_part``) add the blocks whose multiplier is not zero.  Asserted on the
main job's cable pressed on its post (a sphere: a curved obstacle's samples, and contact slots):
the compiled function with its parts added equals the interpreted whole one at the answer, a
stream through the landing with the C loop equals the interpreted stream to 1e-9 m, and the C
loop's own Hessian at its answer equals the interpreted one.  (The split's algebra for every model
and random multipliers: test_assembled_kkt.py.)
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
import test_post_last_pose as post

from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.compiled import compiler

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler")

FIRST, LAST = 405, 416  # the cable lands on the post at 409 and slides along it


@pytest.fixture(scope="module")
def solvers(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DLO_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.delenv("DLO_NO_COMPILE", raising=False)
        options = replace(post.scene().options, model="full", order=12, obstacle_slots=2,
                          update_time_limit=0.0)  # fmt: skip
        problem = post.problem_at(FIRST)
        native = ShapeSolver(problem, options, compile="blocking")
        interpreted = ShapeSolver(problem, options, compile="off")
        yield native, interpreted


@pytest.fixture(scope="module")
def streamed(solvers):
    """Both solvers streamed from a cold solve at FIRST to LAST: (native answers, interpreted
    answers, the C loop's calls)."""
    native, interpreted = solvers
    calls = []
    loop = native.functions.newton_active
    native.functions.newton_active = lambda *a: calls.append(1) or loop(*a)
    try:
        answers = [(native.solve(), interpreted.solve())]
        for k in range(FIRST + 1, LAST + 1):
            answers.append((native.solve(post.targets(k)), interpreted.solve(post.targets(k))))
    finally:
        native.functions.newton_active = loop
    return answers, calls


def test_the_stream_onto_the_post_with_the_compiled_loop_equals_the_interpreted_one(solvers, streamed):
    native, _ = solvers
    answers, calls = streamed
    assert native.functions.newton_active is not None
    assert native.nlp.contact_sizes and 9 in native.nlp.contact_sizes  # samples and slots
    for a, b in answers:
        assert a.status == b.status == "ok", (a.message, b.message)
        np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    assert answers[-1][0].contact_loads and calls  # pressed on the post, through the C loop

    # at the answer: the post's rows carry force, and the compiled function with its parts added
    # (the Python path's WithNodePart) equals the interpreted whole one
    state, nlp = native.snapshot(), native.nlp
    lam = state.lam_g
    assert np.any(lam[nlp.n_free_rows:] > 1e-6)
    got = native.functions.kkt(state.z, state.p, lam)
    want = [np.asarray(ca.DM(v).full()) for v in nlp.kkt_fn(state.z, state.p, lam)]
    for x, y in zip(got, want):
        np.testing.assert_allclose(x.reshape(y.shape), y, atol=1e-10 * (1 + np.abs(y).max()))
    # the C loop's own evaluation there (its Hessian with the blocks added in C)
    active = np.abs(lam) > 0
    switchable = nlp.contact_row & ~nlp.equality
    out = native.functions.newton_active(state.z, lam, state.p, active, nlp.ubg, switchable, 4, 10)
    here = [np.asarray(ca.DM(v).full()) for v in nlp.kkt_fn(out.z, state.p, out.lam)]
    np.testing.assert_allclose(out.hessian, here[3], atol=1e-9 * np.abs(here[3]).max())


def test_without_the_blocks_the_hessian_differs(solvers, streamed):
    """The blocks matter: the split function's ∇²L alone misses the post's curvature term."""
    native, _ = solvers
    state, nlp = native.snapshot(), native.nlp
    outputs = [np.asarray(ca.DM(v).full()) for v in nlp.kkt_split_fn(state.z, state.p, state.lam_g)]
    hess, weighted = outputs[3], outputs[5]
    whole = np.asarray(ca.DM(nlp.kkt_fn(state.z, state.p, state.lam_g)[3]).full())
    gap = np.abs(hess + nlp.node_map.T @ weighted - whole).max()
    assert gap > 1e-6 * np.abs(whole).max()
