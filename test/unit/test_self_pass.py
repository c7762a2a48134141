"""A model without self-contact whose answer passes through itself says so; auto models the contact (#37).

The paper's Fig. 2 loop (clamp at s = 0, the end s = L held by its tangent at (c, 0, 0), Rf/Rt = 100,
no weight) with ``string.radius`` 0.01 L: at chord 0.3 L the stable branch without self-contact
closes its loop through itself (#15).  Checked cold, streamed (warm updates closing the chord from
0.5 L) and as a query, on every result's own output points with a brute-force O(n²) distance written
here (not the package's k-d tree or sampling):

* ``model: full`` (no self-contact rows): the answer whose strands are closer than 2r is
  ``passes_through_itself``, ``unverified``, ``stable`` None, never ``ok``; an answer whose strands
  stay 2r apart is not flagged;
* ``model: auto``: every answer keeps its strands at least 2r − 1e-4 L apart (the tolerance of the
  self-contact rows' sampling, κ h²/4 ≈ 5e-4·2r here, with room), with ``self_contacts`` reported and
  a stability verdict.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from support.problems import clamped_pair

from dlo_ros.solver.auto import AutoShapeSolver
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

L, RF, RT, R = 1.0, 1.0, 0.01, 0.01
STRAIGHT = (0.0, 0.0, 0.0, 1.0)
#: the warm stream's chords after its cold start at 0.5 L
STREAM = (0.46, 0.42, 0.38, 0.34, 0.3)
#: output points (spacing h = L/400): where two strands come closest, the brute-force distance over
#: them exceeds the centreline's by at most h²/(4r) ≈ 1.6e-4 L (each closest point within h/2 of a
#: sample)
POINTS = 401
#: pairs closer along s than this are neighbours on one strand (the loop's bend radius is > 0.05 L)
NEIGHBOURS = 0.05 * L
#: how far below 2r auto's answer may come (the self-contact rows' sampling tolerance, with room)
TOL = 1e-4 * L


def fig2(c: float):
    p = clamped_pair(right=(c, 0.0, 0.0), bend=RF, twist=RT, modes=("clamp", "tangent"))
    return replace(p, string=replace(p.string, radius=R))


def closest(result) -> float:
    """Smallest distance [m] between two output points at least NEIGHBOURS apart along s."""
    x, s = np.asarray(result.points), np.asarray(result.s)
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=-1))
    return float(d[np.abs(s[:, None] - s[None, :]) >= NEIGHBOURS].min())


def at(c: float) -> dict:
    return {"right": ((c, 0.0, 0.0), STRAIGHT)}


def full_solver(c: float) -> ShapeSolver:
    return ShapeSolver(fig2(c), SolverOptions(model="full", output_points=POINTS), compile="off")


def auto_solver(c: float) -> AutoShapeSolver:
    return AutoShapeSolver(
        fig2(c), SolverOptions(output_points=POINTS), compile="off", checks="sync"
    )


def check_flagged(r) -> None:
    """``r`` (a full-model answer) is flagged exactly when its own points pass through each other."""
    d = closest(r)
    if d < 2 * R * 0.99:  # passes through itself, by more than the output sampling can hide
        assert r.passes_through_itself and r.to_dict()["passes_through_itself"], (d, r.message)
        assert r.status == "unverified" and r.stable is None and not r.ok, r.status
        assert r.message.startswith("passes through itself") and "2·radius = 0.02 m" in r.message
        assert r.min_self_distance < 2 * R and r.to_dict()["min_self_distance"] is not None
        assert len(r.points) == len(r.s) > 0  # the shape is kept for inspection
    elif d > 2 * R * 1.01:
        assert not r.passes_through_itself and r.status == "ok", (d, r.message)


def check_apart(r) -> None:
    """``r`` (an auto answer) keeps its strands 2r apart and says whether it is stable."""
    assert closest(r) >= 2 * R - TOL, (closest(r), r.model.self_contact_pairs)
    assert r.status == "ok" and r.stable is not None, (r.status, r.message)
    assert not r.passes_through_itself


def test_full_cold_passes_through_itself_is_flagged():
    r = full_solver(0.3).solve()
    assert closest(r) < R  # measured 6.5 mm on a 20 mm thick cable: it does pass through
    check_flagged(r)


def test_full_streamed_and_query_are_flagged():
    sol = full_solver(0.5)
    r = sol.solve()
    check_flagged(r)
    assert r.ok  # the open loop at 0.5 L
    for c in STREAM:
        r = sol.solve(at(c))
        check_flagged(r)
    assert r.passes_through_itself and closest(r) < R
    q = sol.solve(at(0.3), commit=False)
    check_flagged(q)
    assert q.passes_through_itself


def test_auto_cold_models_self_contact():
    r = auto_solver(0.3).solve()
    check_apart(r)
    assert r.self_contacts and r.model.self_contact_pairs > 0
    assert any(reason.startswith("self-contact:") for reason in r.model.changed)


def test_auto_streamed_keeps_two_radii():
    sol = auto_solver(0.5)
    check_apart(sol.solve())
    for c in STREAM:
        r = sol.solve(at(c))
        check_apart(r)
    assert r.self_contacts and r.model.self_contact_pairs > 0


def test_auto_reads_the_streams_self_approach_from_the_solves_own_measure(monkeypatch):
    """auto's self-approach test takes the committed result's ``min_self_distance`` (measured by
    the solve on the same samples) instead of measuring the shape again: on the stream that closes
    the loop, each answer is the one measured afresh, and the stream does meet its shape."""
    from dlo_ros.solver.auto import escalate

    measured, answers = escalate.self_approach, []

    def both(auto, problem, committed):
        answer = measured(auto, problem, committed)
        assert np.isfinite(committed.min_self_distance) or committed.min_self_distance == np.inf
        afresh = measured(auto, problem, replace(committed, min_self_distance=float("nan")))
        assert answer == afresh
        answers.append(answer)
        return answer

    monkeypatch.setattr(escalate, "self_approach", both)
    sol = auto_solver(0.5)
    sol.solve()
    for c in STREAM:
        sol.solve(at(c))
    assert len(answers) >= len(STREAM) and any(answers), answers


def test_auto_query_models_self_contact_and_leaves_the_stream():
    sol = auto_solver(0.5)
    check_apart(sol.solve())
    q = sol.solve(at(0.3), commit=False)
    check_apart(q)
    assert q.self_contacts and q.model.self_contact_pairs > 0
    r = sol.solve(at(0.5))  # the stream's model is untouched by the query
    check_apart(r)
    assert r.model.self_contact_pairs == 0


@pytest.mark.parametrize("model", ["full", "auto"])
def test_radius_zero_is_not_checked(model):
    """Radius 0 (documented limit): nothing to pass through at a thickness of zero, no distance."""
    p = fig2(0.3)
    p = replace(p, string=replace(p.string, radius=0.0))
    sol = (
        ShapeSolver(p, SolverOptions(model="full", output_points=POINTS), compile="off")
        if model == "full"
        else (AutoShapeSolver(p, SolverOptions(), compile="off", checks="sync"))
    )
    r = sol.solve()
    assert r.ok and not r.passes_through_itself and np.isnan(r.min_self_distance)
