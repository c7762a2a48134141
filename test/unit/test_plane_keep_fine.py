"""``solver.plane: keep`` on the paper's Fig. 3 floor to finer tolerances (1e-5 and 1e-6 L).

The cases of test_plane_keep.py (its scene, references and ``floor_answer``) at δ below the
default 1e-3 L, in a file of their own so that the test runners share them out (each takes
10–40 s: the refinement reaches hundreds of nodes).
"""

from __future__ import annotations

from dataclasses import replace

import pytest
from test_plane_keep import SCENE, L, floor_answer, floor_references, nearest

#: the cases over ~15 s each: the whole suite's run (CI) leaves them out (pytest.ini); the
#: cheapest case of each tolerance and the streamed 1e-6 L one stay in it
SLOW = pytest.mark.slow


def answer_and_references(rho: float, delta: float, how: str):
    """(the default's answer at weight ρ and tolerance δ [m], 'cold' or 'streamed'; the floor
    reference's two curled equilibria at ρ)."""
    refs = floor_references(rho)[1]
    options = replace(
        SCENE.options, output_points=401, update_time_limit=0.0, error_tolerance=delta
    )
    return floor_answer(rho, options, how), refs


@pytest.mark.parametrize(
    "rho, tol, how",
    [
        (1000.0, 1e-5, "cold"),
        pytest.param(2000.0, 1e-5, "cold", marks=SLOW),
        pytest.param(3000.0, 1e-5, "cold", marks=SLOW),
        pytest.param(3000.0, 1e-5, "streamed", marks=SLOW),
        (1000.0, 1e-6, "cold"),
    ],
)
def test_fig3_floor_to_a_finer_tolerance(rho, tol, how):
    """δ = 1e-5 L at each weight (ρ = 3000 also streamed, ``floor_answer``) and 1e-6 L at
    ρ = 1000: the default meets it against the floor reference, stable, with an estimate
    that bounds the true error by at most 10x.

    Measured (true error / estimate / nodes): 1e-5 L ρ = 1000 2.0e-6 / 3.5e-6 m / 123, 2000
    2.1e-7 / 7.9e-7 m / 176, 3000 6.8e-7 / 1.7e-6 m / 211; 1e-6 L ρ = 1000 1.9e-7 / 3.8e-7 m / 267.
    Before the residual's grid was split at the obstacle rows (solver/results/residual.py) these
    answers were 'unverified' (the residual aliased the contact forces' sawtooth to 2.5e-5 m), and
    before the refinement's cap grew below 1e-4 L (auto/mesh_check.py) ρ = 3000 stalled at 160
    nodes.  Not met, and said so: 1e-6 L at ρ = 2000 and 3000 (below).
    """
    delta = tol * L
    result, refs = answer_and_references(rho, delta, how)
    assert result.status == "ok" and result.stable is True, result.message
    assert result.equilibrium_residual_m <= delta
    assert result.model.as_dict()["tolerance_met"] is True
    error, ref = nearest(result, refs)
    estimate = result.model.estimated_error_m
    assert error <= delta and error <= estimate <= 10 * error, (error, estimate)
    assert result.energy["total"] == pytest.approx(ref.energy, abs=1e-6 * abs(ref.energy))


@pytest.mark.parametrize(
    "rho, how",
    [
        (1000.0, "streamed"),
        pytest.param(2000.0, "cold", marks=SLOW),
        pytest.param(3000.0, "cold", marks=SLOW),
    ],
)
def test_fig3_floor_to_1e6_reports_an_estimate_that_bounds_its_error(rho, how):
    """At 1e-6 L (ρ = 1000 streamed, 2000 and 3000 cold) the refinement reaches its cap (320 nodes
    per field, auto/mesh_check.py) before or at the tolerance: whatever the answer says of the
    tolerance is true, and the estimate it reports bounds its true error by at most 10x.

    Measured: not met; ρ = 1000 streamed true error 2.7e-5 m, estimate 5.2e-5 m; ρ = 2000 cold
    4.4e-6 m, 1.2e-5 m; ρ = 3000 cold 5.1e-7 m, 1.2e-6 m.  At ρ = 3000 the tolerance was met
    at the cap until 2026-12-08 (1.2e-7 / 6.2e-7 m, later 9.3e-7 m, at 320 nodes), and is not
    since a line contact's forces are carried onto a refined mesh as a line load
    (contact/obstacle_points.carried_forces): the passes take another path to the cap, where the
    last ones only move breakpoints (1.1e-6 m at 319 nodes).  Before the step from the answer
    to its run end moved to the lift-off
    (contact_shift.py) the estimate at ρ = 1000 was 5.2e-6 m, five times below the true error: a
    run end pressing 0.8 mm past the lift-off, on a strip lying flat, along which the pinned
    family barely moves.  Before a run's end was the row of its lift-off's concentrated force
    (contact_shift.END_SHARE) the estimate at ρ = 2000 was 2.1e-3 m for 2.8e-6 m: pinned at a
    row crowded past the lift-off, pressing 1.4e-3 of that force.
    """
    delta = 1e-6 * L
    result, refs = answer_and_references(rho, delta, how)
    assert result.status == "ok" and result.stable is True, result.message
    error, _ = nearest(result, refs)
    estimate = result.model.estimated_error_m
    if result.model.tolerance_met:
        assert error <= delta
    assert error <= estimate <= 10 * error, (error, estimate)
