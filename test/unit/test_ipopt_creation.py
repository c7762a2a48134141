"""IPOPT's solvers are created without the problem's reverse derivative, and answer as before.

``StringNLP.make_solver`` asks nlpsol for no λ_p and so no "nlp_grad" (the reverse derivative of
the whole problem, which nlpsol builds at each new NLP's first solver: 30-40 ms of the 40-45 ms a
mesh of the paper's Fig. 3 took).  Each solver here must (a) hold no such function and (b) give,
from the same start, the answers of a solver made with nlpsol's defaults to the bit: x, λ_g, λ_x,
g and f, the statuses and iteration counts, cold and warm, on a planar model with a floor and a 3D
element model with an obstacle.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver.build.ipopt_functions import ipopt_options
from dlo_ros.solver.shape_solver import ShapeSolver


def _solver(case: str) -> ShapeSolver:
    """A solved fixed model of ``case`` (its committed state: the warm start)."""
    if case == "planar floor":
        scene = load_scene("bench_fig3_floor")
        options = replace(scene.options, model="planar")
    else:
        scene = load_scene("default_cable")
        options = replace(scene.options, model="full", order=12)
    solver = ShapeSolver(scene.problem, options, compile="off")
    assert solver.solve().status in ("ok", "unverified")
    return solver


def _defaults_solver(nlp, warm: bool):
    """nlpsol with its own defaults and the same IPOPT options and derivatives."""
    ipopt = ipopt_options(nlp.options, warm, None, 0.0)
    opts = {"ipopt": ipopt, "print_time": False, "error_on_fail": False}
    return ca.nlpsol("defaults", "ipopt", nlp.ipopt_nlp, {**opts, **nlp.ipopt_derivatives()})


@pytest.mark.parametrize("case", ["planar floor", "3D cable over its table"])
@pytest.mark.parametrize("warm", [False, True])
def test_the_solver_answers_as_nlpsols_defaults_without_the_reverse_derivative(case, warm):
    shape = _solver(case)
    nlp, state = shape.nlp, shape.committed_state
    ours, theirs = nlp.make_solver(warm), _defaults_solver(nlp, warm)
    assert not ours.has_function("nlp_grad") and theirs.has_function("nlp_grad")
    # from a start off the answer, so that IPOPT iterates
    args = {"x0": state.z * 1.001, "p": state.p, "lbg": nlp.lbg, "ubg": nlp.ubg}
    if warm:
        args.update(lam_g0=state.lam_g, lam_x0=state.lam_x)
    a, b = ours(**args), theirs(**args)
    assert ours.stats()["return_status"] == theirs.stats()["return_status"]
    assert ours.stats()["iter_count"] == theirs.stats()["iter_count"] > 0
    for key in ("x", "lam_g", "lam_x", "g", "f"):
        assert np.array_equal(np.asarray(a[key]), np.asarray(b[key])), key
