"""Warm Newton updates across a change of the active set (newton.py): a contact that appears or leaves
between two updates no longer sends the update to IPOPT.

The default cable's planar model, both grips lowered until the sag meets the table and raised again:
the update where the first obstacle sample becomes active, and the one where it leaves, are Newton
updates, and each equals the cold IPOPT solve of the same targets (an independent path to the same
equilibrium) and is a verified, stable equilibrium with the contact force that statics requires (the
grip reactions, the weight and the contact force balance)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver

SCENE = load_scene(Path(__file__).resolve().parents[2] / "config" / "scenes" / "default_cable.yaml")
Q = SCENE.problem.grip("right").pose.orientation
L = SCENE.problem.string.length


def targets(drop: float) -> dict:
    """Both grips lowered by ``drop`` [m] from the scene's 0.4 m."""
    return {"left": ((0.0, 0.0, 0.4 - drop), Q), "right": ((0.6, 0.0, 0.4 - drop), Q)}


def table_force(result) -> np.ndarray:
    """The table's contact force on the string [N] (zero when it does not touch)."""
    (force,) = result.contact_forces.values()
    return force


def touches(result) -> bool:
    """The sag rests on the table (IPOPT leaves ~1e-10 N of barrier multipliers on free samples)."""
    return bool(np.linalg.norm(table_force(result)) > 1e-6)


def balance(result) -> float:
    """|Σ grip forces + Σ contact forces + weight| [N] (the resultant of every force on the string)."""
    weight = SCENE.problem.string.weight_per_length.maximum * L  # uniform: D L
    total = sum(w.force for w in result.grips.values()) + sum(result.contact_forces.values(), np.zeros(3))
    return float(np.linalg.norm(total + weight * SCENE.problem.gravity))


@pytest.fixture(scope="module")
def stream():
    """(drop, result) of every update of the lowering and raising stream, on the planar model."""
    solver = ShapeSolver(SCENE.problem, replace(SCENE.options, model="planar"), compile="off")
    assert solver.solve(targets(0.035)).ok
    out = []
    for drop in np.round(np.concatenate([np.arange(0.04, 0.0551, 0.005), np.arange(0.05, 0.0349, -0.005)]), 6):
        out.append((float(drop), solver.solve(targets(drop))))
    return out


def test_contact_appears_and_leaves_on_the_newton_path(stream):
    touching = [touches(r) for _, r in stream]
    assert not touching[0] and touching[-1] is False and any(touching), touching
    changes = [k for k in range(1, len(stream)) if touching[k] != touching[k - 1]]
    assert len(changes) == 2, changes  # the sag meets the table, and leaves it on the way back
    for k in changes:
        drop, r = stream[k]
        assert r.ok and r.stable and r.warm_started, (drop, r.message)
        assert r.ipopt_status == "Newton", (drop, r.ipopt_status, r.message)


def test_newton_across_the_change_equals_the_cold_solve(stream):
    for drop, r in stream:
        if not touches(r):
            continue
        cold = ShapeSolver(SCENE.problem, replace(SCENE.options, model="planar"), compile="off").solve(targets(drop))
        assert cold.ok and not cold.warm_started and cold.ipopt_status != "Newton", cold.message
        assert np.max(np.linalg.norm(r.points - cold.points, axis=1)) < 1e-6 * L, drop
        assert r.energy["total"] == pytest.approx(cold.energy["total"], rel=1e-8)
        f_warm, f_cold = table_force(r), table_force(cold)
        assert np.linalg.norm(f_warm - f_cold) < 1e-5 * np.linalg.norm(f_cold), (f_warm, f_cold)
        assert f_warm[2] > 0 and balance(r) < 1e-8 * (1 + np.linalg.norm(f_warm)), balance(r)


@pytest.mark.parametrize("drop", [0.045, 0.04])
def test_a_contact_leaves_between_steps(drop):
    """Raising the grips off the table from a shape resting on it, with the table's rows held: with row
    switches (``active_set.active_steps``) the rows leave between steps and the same call ends at the contact-free
    equilibrium, which the solver's own update reaches too; without switches the call ends with the
    rows held and a negative multiplier (the table pulling), which is left to the outer loop."""
    from dlo_ros.model.problem import GripPose
    from dlo_ros.solver.update.active_set import active_steps
    from dlo_ros.solver.update.kkt import active_rows
    from dlo_ros.solver.native.settings import NEWTON_STEP_SWITCHES

    solver = ShapeSolver(SCENE.problem, replace(SCENE.options, model="planar"), compile="off")
    assert touches(solver.solve(targets(0.055)))
    state, nlp = solver.snapshot(), solver.nlp
    g0 = np.asarray(nlp.g_fn(state.z, state.p)).ravel()
    active = active_rows(nlp, state.lam_g, g0)
    contact = nlp.contact_row & ~nlp.equality
    assert np.any(active & contact)
    raised = SCENE.problem.with_grip_poses({k: GripPose(np.array(x), q) for k, (x, q) in targets(drop).items()})
    p = solver.pack_parameters(raised, state.z)
    lam = np.where(active, state.lam_g, 0.0)

    def kkt(*a):
        return [np.asarray(v) for v in nlp.kkt_fn(*a)]

    held = active_steps(kkt, state.z.copy(), lam.copy(), p, active, nlp.ubg, contact, 0, 30, None)
    assert held[0] is not None and np.array_equal(held[-1], active)
    assert held[1][active & contact].min() < 0  # the table would have to pull
    switched = active_steps(kkt, state.z.copy(), lam.copy(), p, active, nlp.ubg, contact, NEWTON_STEP_SWITCHES, 30,
                             None)
    assert switched[0] is not None and not np.any(switched[-1] & contact)
    assert np.all(switched[3][contact] <= nlp.ubg[contact] + 1e-9)  # free of the table everywhere
    update = solver.solve(targets(drop))
    assert update.ok and update.ipopt_status == "Newton" and not touches(update)
    np.testing.assert_allclose(switched[0], solver.snapshot().z, atol=1e-9)
