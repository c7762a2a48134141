"""Which rows the stability check holds (``results/stability.py``, ``held_rows``).

An interior-point answer leaves λ·slack ≈ μ on every inequality row: a row far from its bound
keeps a multiplier of μ/slack.  On the random scenes that was 1.8e-10/slack, above the 1e-9
multiplier tolerance on every row within 0.18 of its bound, and the check held those rows as if
the string touched there: the reduced Hessian lost the directions they block, up to "no freedom"
(stable by accident).  A row is held when it is at its bound, or its |λ| is above the tolerance
and above its slack.

The default cable hanging above its table (planar model, solved cold by IPOPT): its λ_min with
the table rows given such barrier residue equals its λ_min with those multipliers zeroed, and
differs from the λ_min with those rows held as equalities (what the old rule did), so the test
can tell the two rules apart.  A row at its bound stays held whatever its multiplier.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.results.stability import (
    held_rows,
    lowest_eigenpair,
    min_reduced_eigenvalue,
    null_space,
)
from dlo_ros.solver.state import SolverState
from dlo_ros.solver.update.newton import derivatives

SCENE = load_scene(
    Path(__file__).resolve().parents[2] / "config" / "scenes" / "default_cable.yaml"
)


@pytest.fixture(scope="module")
def hanging():
    solver = ShapeSolver(SCENE.problem, replace(SCENE.options, model="planar"), compile="off")
    result = solver.solve()
    assert result.ok and result.stable, result.message
    return solver, solver.committed_state


def fresh(state: SolverState, lam: np.ndarray) -> SolverState:
    """``state`` with multipliers ``lam`` and no cached derivatives or eigenpair."""
    return SolverState(state.z.copy(), lam, state.lam_x.copy(), state.p.copy())


def test_barrier_residue_is_not_held(hanging):
    solver, state = hanging
    nlp, fns = solver.nlp, solver.functions
    g = np.asarray(nlp.g_fn(state.z, state.p)).ravel()
    table = ~nlp.equality
    slack = nlp.ubg - g
    assert np.all(slack[table] > 1e-3)  # the string hangs clear of the table
    clean = np.where(table, 0.0, state.lam_g)
    residue = np.where(table, 2e-10 / np.maximum(slack, 1e-300), state.lam_g)  # μ/slack, above 1e-9 near the table
    assert np.any(residue[table] > 1e-9)
    assert not np.any(held_rows(nlp.equality, nlp.ubg, residue, g)[table])
    expected = min_reduced_eigenvalue(nlp, fns, fresh(state, clean))
    with_residue = fresh(state, residue)
    assert min_reduced_eigenvalue(nlp, fns, with_residue) == pytest.approx(expected, rel=1e-9)
    # the old rule held every row with |λ| > 1e-9: λ_min on that null space is another number
    old = nlp.equality | (np.abs(residue) > 1e-9) | (g > nlp.ubg - 1e-9)
    _, _, jac, hess, _ = derivatives(nlp, fns, state.z, state.p, residue, old)
    basis = null_space(jac[old])
    if basis.shape[1]:
        value, _ = lowest_eigenpair(basis.T @ hess @ basis)
        assert abs(value - expected) > 1e-3 * abs(expected)


def test_rows_at_their_bound_are_held(hanging):
    solver, state = hanging
    nlp = solver.nlp
    g = nlp.ubg.copy()  # every row at its bound
    lam = np.zeros_like(g)
    assert np.all(held_rows(nlp.equality, nlp.ubg, lam, g))
    g_far = nlp.ubg - 1.0
    lam_big = np.full_like(g, 2.0)  # λ above the slack: an active row of an IPOPT answer
    assert np.all(held_rows(nlp.equality, nlp.ubg, lam_big, g_far))
