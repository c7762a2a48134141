"""Escalations inside one update: a richer model for a refused, unstable or self-touching answer.

Each function takes the :class:`.auto_solver.AutoShapeSolver` whose update it escalates and uses
only its public members (``choice``, ``inner``, ``pool``, ``reduced``, ``worker``, ``switch``,
``changes``, ``options``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...model.problem import Problem
from ..contact import self_contact as SC
from ..results.result import ShapeResult
from ..shape_solver import ShapeSolver
from ..update import recovery as RC
from ..update.moments import RAISE_ORDER_ADVICE, UNRESOLVED_MESSAGE
from .choice import ORDERS, ModelChoice, full_choice

if TYPE_CHECKING:  # the solver calls these functions (auto_solver.py imports this module)
    from .auto_solver import AutoShapeSolver


def richer_for_topology(
    auto: AutoShapeSolver,
    problem: Problem,
    result: ShapeResult,
    notes: list[str],
    limited: bool = True,
) -> ShapeResult:
    """Retry an update refused by its model (``REFUSALS``) on the next orders; return the answer.

    The clamped string's linking number changed (the model jumped to a branch with whole turns
    released, ``topology.py``): too coarse a basis cannot hold the twist; or the point moments
    turned the string by more than its rotation field's nodes can follow.  The update is tried
    again on the next orders, each warm-started from the committed shape; the first answer that is
    not refused for its topology is returned (the refusal if every order is).  Each switch is
    appended to ``notes``.  ``limited``: the re-solves stop at ``solver.update_time_limit`` (a
    streamed update's; never a cold solve's).
    """
    for order in ORDERS:
        if order <= auto.choice.order:
            continue
        why = REFUSALS.get(refusal(result) or "", "was refused")
        auto.switch(
            replace(auto.choice, order=order, mesh=None, reasons=list(auto.choice.reasons)),
            f"order {order}: the order-{auto.choice.order} model {why}",
        )
        notes.append(auto.changes[-1][1])
        poses = auto.reduced.poses(auto.choice, problem)
        result = auto.inner.solve(poses, warm=True, commit=True, checked=True, limited=limited)
        if refusal(result) is None:
            return result
    if refusal(result) == UNRESOLVED_MESSAGE:  # a fixed model's advice, which auto has followed
        result.message = result.message.replace(
            RAISE_ORDER_ADVICE, f"(auto tried every order up to {auto.choice.order})"
        )
    return result


#: failures that a richer order may not have (message start → why the order is raised): the
#: linking number changed, or the point moments turned the string more than the mesh can follow
#: (``update/moments.py``)
REFUSALS = {
    "topology:": "changed the linking number",
    UNRESOLVED_MESSAGE: "could not follow the point moments' rotation",
}


def refusal(result: ShapeResult) -> str | None:
    """Return the REFUSALS key a failed result's message starts with (None: not one of them)."""
    if result.status != "failed":
        return None
    return next((key for key in REFUSALS if result.message.startswith(key)), None)


def richer_for_stability(
    auto: AutoShapeSolver,
    problem: Problem,
    result: ShapeResult,
    notes: list[str],
    commit: bool = True,
    limited: bool = True,
) -> tuple[ShapeResult, tuple[ModelChoice, ShapeSolver] | None]:
    """Try an unstable equilibrium on the next order; return (answer, the query's model or None).

    The inner solver's own attempts to leave it (its shifted Newton steps, IPOPT's escapes, the
    cold solve) are done.  Where the model is too coarse the smallest eigenvalue of the reduced
    Hessian can be a discretisation error (``paper_rect_paper``'s strip circling: -0.009 at order
    12, +0.012 at order 16 and +0.008 at order 24 at one target), and the shape answered is not
    one the string rests in.  The update is tried on the next order, warm-started from the
    stream's committed shape (for an update: the unstable answer itself), without touching the
    stream; if that answer is stable it is returned, and an update (``commit``) switches the
    stream to that order and answers there.  Else the unstable answer stands.  The second item is
    the next order's (choice, solver) when that answered a query, else None.  ``limited``: the
    re-solves stop at ``solver.update_time_limit`` (a streamed update's; never a cold solve's or a
    query's).
    """
    higher = [order for order in ORDERS if order > auto.choice.order]
    if not higher:
        return result, None
    richer = replace(auto.choice, order=higher[0], mesh=None, reasons=list(auto.choice.reasons))
    poses = auto.reduced.poses(richer, problem)
    # a running check may be using that order as its shadow
    auto.worker.wait_for_model(("",) + richer.key())
    other = auto.pool.solver_for(richer, problem, stream=False, source=auto.inner)
    trial = other.solve(poses, warm=True, commit=False, checked=True, limited=limited and commit)
    if not (trial.status == "ok" and trial.stable):
        return result, None
    if not commit:  # a query: the stream keeps its model
        return trial, (richer, other)
    auto.switch(
        richer,
        f"order {richer.order}: the order-{auto.choice.order} equilibrium is unstable "
        f"(eigenvalue {result.min_eigenvalue:.3g}), the order-{richer.order} one stable",
    )
    notes.append(auto.changes[-1][1])
    return auto.inner.solve(poses, warm=True, commit=True, checked=True, limited=limited), None


def _contact_geometry(auto: AutoShapeSolver, problem: Problem) -> SC.ContactGeometry:
    """Return the self-contact geometry auto tests a shape of ``problem`` with."""
    st = problem.string
    return SC.contact_geometry(
        st.length,
        st.radius,
        auto.options.self_contact_samples,
        tuple(g.s for g in problem.grips),
    )


def self_approach(auto: AutoShapeSolver, problem: Problem, committed: ShapeResult) -> str:
    """Say why self-contact must be modelled now ('' if not).

    It must when the committed shape of a model without it has two samples the exclusion arc apart
    within the candidate reach of each other (k-d tree query).  Never with ``rotation: euler``
    or the plane kept (``solver.plane: keep``).  ``committed``: the result of that shape; its
    ``min_self_distance``, when the solve measured it (a string with a radius: the same samples
    and the same candidate pairs, ``results/self_pass.py``), is that closest approach, not
    measured again.
    """
    if (
        auto.choice.self_contact
        or auto.choice.plane_kept
        or auto.options.rotation != "director"
        or not auto.inner.has_warm_start
    ):
        return ""
    st = problem.string
    geometry = _contact_geometry(auto, problem)
    d = committed.min_self_distance
    if np.isnan(d):  # not measured by the solve (a string of radius 0)
        state = auto.inner.snapshot()
        assert state is not None  # has_warm_start checked above
        points = auto.inner.model.positions(state.z, geometry.s)
        if SC.certainly_apart(points, geometry):  # the usual answer, proved without the k-d tree
            return ""
        d = SC.closest_distance(points, geometry)
    if not d < geometry.reach:
        return ""
    return (
        f"self-contact: the shape comes within {d:.3g} m of itself "
        f"(reach {geometry.reach:.3g} m, "
        f"2·radius {2 * st.radius:.3g} m): full model with self-contact"
    )


def contact_start(
    auto: AutoShapeSolver, problem: Problem, before: tuple
) -> tuple[tuple | None, str]:
    """Return where the self-contact model starts, and the reason added to the change's.

    A committed shape without self-contact came within reach of itself.  The model starts from
    that shape when it is a topology reference (``recovery.why_not_reference``); else from the
    shape committed before this update (the last one apart from itself), or cold when there was
    none.  ``before``: (solver, its state before this update or None, the scene then).  The first
    item is ``AutoShapeSolver.switch``'s ``start``: None for the answer itself.
    """
    solver, state, previous = before
    geometry = _contact_geometry(auto, problem)
    committed = auto.inner.committed_state
    assert committed is not None  # self_approach found this committed shape within reach
    after = auto.inner.model.positions(committed.z, geometry.s)
    earlier = None if state is None else solver.model.positions(state.z, geometry.s)
    why = RC.why_not_reference(earlier, after, geometry, problem.string.length)
    if not why:
        return None, ""
    where = "the shape before this update" if state is not None else "a cold start"
    why = f" (from {where}: the answer without self-contact is no reference, {why})"
    return (solver, state, previous), why


def _contact_choice(auto: AutoShapeSolver, problem: Problem, result: ShapeResult) -> str:
    """Say why ``result`` must be solved again with self-contact ('' if it need not or cannot).

    It must when it passes through itself (``results.self_pass``) and was solved without
    self-contact; it cannot with ``rotation: euler`` (no self-contact model) or with the plane
    kept (``solver.plane: keep``: self-contact is 3D; the result's flag and message say it passes
    through itself).
    """
    if (
        not result.passes_through_itself
        or auto.options.rotation != "director"
        or auto.choice.plane_kept
    ):
        return ""
    return (
        f"self-contact: the answer without it passes through itself "
        f"(closest {result.min_self_distance:.3g} m, 2·radius "
        f"{2 * problem.string.radius:.3g} m): full model with self-contact"
    )


def contact_for_pass(
    auto: AutoShapeSolver, problem: Problem, result: ShapeResult, notes: list[str]
) -> tuple[ShapeResult, dict]:
    """Switch the stream to self-contact when ``result`` passes through itself; solve again.

    For an answer the checks re-solved on another model (``AutoShapeSolver._check_now``: a cold
    solve, a re-solve after a scene change): the self-contact model starts from that answer (a
    start that passes through itself is checked as a cold start is, ``recovery.through_itself``:
    measured on Fig. 2 at chord 0.3 L, a cold start of the self-contact model lands on the
    unstable planar loop instead) and commits.
    Returns (answer, its poses for the new model); ``result`` unchanged (with the stream's poses)
    when it need not or cannot, or when the self-contact solve fails (the message says so).
    """
    why = _contact_choice(auto, problem, result)
    if not why or auto.choice.self_contact:
        return result, auto.reduced.poses(auto.choice, problem)
    contact = replace(full_choice(auto.choice, problem), self_contact=True)
    auto.switch(contact, why)
    notes.append(auto.changes[-1][1])
    poses = auto.reduced.poses(auto.choice, problem)
    answer = auto.inner.solve(poses, warm=True, commit=True, checked=True, limited=False)
    if answer.status in ("ok", "unverified"):
        return answer, poses
    result.message += f"; the self-contact model failed to solve ({answer.message})"
    return result, poses


def contact_for_query(
    auto: AutoShapeSolver, problem: Problem, result: ShapeResult, source: ShapeSolver
) -> tuple[ShapeResult, tuple[ModelChoice, ShapeSolver] | None]:
    """Answer a query that passed through itself with the self-contact model (stream untouched).

    The pooled self-contact model starts from ``source``'s committed shape (a warm start that
    passes through itself is checked as a cold start is, ``recovery.through_itself``).  Returns
    (answer, (its choice, its solver)), or (``result``, None) when it need not or cannot, or when
    the self-contact solve fails (the message says so).
    """
    why = _contact_choice(auto, problem, result)
    if not why:
        return result, None
    base = full_choice(auto.choice, problem)
    contact = replace(base, self_contact=True, reasons=list(base.reasons) + [f"query: {why}"])
    auto.worker.wait_for_model(("",) + contact.key())  # a running check may be using it
    other = auto.pool.solver_for(contact, problem, stream=False, source=source)
    poses = auto.reduced.poses(contact, problem)
    answer = other.solve(poses, warm=True, checked=True, limited=False)
    if answer.status in ("ok", "unverified"):
        return answer, (contact, other)
    result.message += f"; the self-contact model failed to solve ({answer.message})"
    return result, None
