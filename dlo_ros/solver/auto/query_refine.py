"""A query's unverified answer refined as a cold solve's is, on pooled copies of the models.

:func:`refine_query` runs the a-posteriori checks (:mod:`.checks`) on the query's own shape and
escalates until they pass or a model fails, to its end: ``solver.update_time_limit`` bounds a
streamed update only, never a query (``update/time_limit.py``; the node's ``query_timeout``
bounds how long its caller waits).  The stream's model is never touched.
:func:`.query_verify.verified_answer` decides the final status.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...model.problem import Problem
from ..results.result import ShapeResult
from ..shape_solver import ShapeSolver
from ..state import SolverState
from .choice import ModelChoice
from .escalate import contact_for_query
from .query_verify import verified_answer
from .reach import touches_obstacle
from .stream_checks import Escalations, checks_answer, moves_breakpoints, snapshot

if TYPE_CHECKING:  # the solver calls this function (auto_solver.py imports this module)
    from .auto_solver import AutoShapeSolver


def refine_query(
    auto: AutoShapeSolver,
    problem: Problem,
    result: ShapeResult,
    t0: float,
    choice: ModelChoice | None = None,
    solver: ShapeSolver | None = None,
) -> ShapeResult:
    """Return a query's finished answer (``commit=False``), refined when it is 'unverified'.

    ``result`` is the answer of the model ``choice`` on ``solver`` (by default the stream's).  One
    whose residual is over the tolerance ('unverified'), or that presses on an obstacle whose rows
    sit on the mesh nodes (where between them the contact is, only the mesh check sees:
    ``contact/penetration.py``), is refined as a cold solve's is
    (``check_now``): the checks run on the query's own shape and escalate (3D when the planar
    shape is unstable in 3D, the next order, more obstacle samples) until they pass, on pooled
    copies, never the streaming model.  Not limited by ``solver.update_time_limit`` (its re-solves
    and checks neither); 'ok' only when the checks passed (``query_verify.verified_answer``).  An
    answer that passes through itself is first solved again on the self-contact model
    (``escalate``).
    """
    if result.passes_through_itself and not (choice or auto.choice).self_contact:
        result, answered_by = contact_for_query(auto, problem, result, solver or auto.inner)
        if answered_by is not None:
            choice, solver = answered_by
    rows_on_nodes = (solver or auto.inner).options.obstacle_points == "nodes"
    if result.status != "unverified" and not (rows_on_nodes and touches_obstacle(result)):
        return auto.finish(result, t0, [], choice=choice, solver=solver)
    auto.worker.wait()  # a running check may hold the pooled models the refinement uses
    base = choice or auto.choice
    choice = replace(base, reasons=list(base.reasons))
    # the answer on a copy that keeps its state (the checks start from it); the copy is tagged
    # apart from the stream's model, which a query never touches
    source = solver or auto.inner
    held = _held_answer(source, result)
    solver = auto.pool.solver_for(
        choice, problem, stream=False, source=source if held is None else None, tag="query"
    )
    poses = auto.reduced.poses(choice, problem)
    if held is not None and (solver.nlp.director or np.array_equal(solver.nlp.r0, source.nlp.r0)):
        solver.install_warm_start(held.copy())  # solved again, it would give this very answer
        answer = result
    else:
        if held is not None and not solver.adopt_warm_start(source):  # (another frame R0)
            solver.reset()  # as solver_for does
        answer = solver.solve(poses, warm=True, commit=True, checked=True, limited=False)
    estimate, stopped, escalations = None, "", Escalations()
    while True:
        if answer.status not in ("ok", "unverified"):
            stopped = f"the model {choice.order}/{choice.samples} failed ({answer.message})"
            answer = result  # the previous model's shape stays the answer
            break
        result = answer
        verdict = auto.model_checks.evaluate(
            snapshot(auto, problem, poses, answer, solver, choice, limited=False),
            False,
            lower=False,
        )
        if verdict.choice is None:
            estimate = verdict.estimate
            break
        if escalations.spent(verdict.estimate, moves_breakpoints(choice, verdict.choice)):
            stopped = "the model checks kept escalating"
            break
        choice = replace(
            verdict.choice, reasons=list(choice.reasons) + [f"query: {verdict.reason}"]
        )
        same = choice.key() == auto.choice.key()  # never the stream's own model
        solver = auto.pool.solver_for(
            choice, problem, stream=False, source=solver, tag="query" if same else ""
        )
        poses = auto.reduced.poses(choice, problem)
        taken = None if same else checks_answer(solver, verdict)  # solved there: not again
        answer = taken or solver.solve(poses, warm=True, commit=True, checked=True, limited=False)
    answer = verified_answer(answer, estimate, auto.tolerance, stopped)
    return auto.finish(answer, t0, [], choice=choice, solver=solver, estimate=estimate)


def _held_answer(solver: ShapeSolver, result: ShapeResult) -> SolverState | None:
    """Return the state of ``result`` if it is ``solver``'s last query answer (else None).

    The copy that refines it would otherwise solve the same poses again from the same start
    (``test_refined_query_answer.py``: one solve fewer per refined query, the same answers).
    """
    held = solver.query_answer
    return held[1] if held is not None and held[0] is result else None
