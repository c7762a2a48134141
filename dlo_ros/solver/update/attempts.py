"""The attempts every stage is made of: a parameter vector, a Newton or IPOPT solve, a result.

Contract: each function takes the ``UpdateContext`` of the call (``context.py``) and reads from it
only what its docstring names; none changes the context.

* ``pack_parameters`` / ``pack``: the NLP parameter vector of a scene, with a round's obstacle
  slots (``ctx.slot_override``) and self-contact pairs (``ctx.contact``) written in;
* ``newton_to``: ``newton.newton`` from a state to a parameter vector;
* ``ipopt_call`` / ``cold_ipopt``: one IPOPT solve, none once ``ctx.deadline`` has passed;
* ``result``: the ``ShapeResult`` of a state, its wrenches anchored on ``ctx.scene``'s grips.

The stages call these through this module's attributes (``attempts.newton_to``), so a test may
replace one to inject a failure.
"""

from __future__ import annotations

import time

import numpy as np

from ...model.problem import Problem
from ..build.initial_guess import initial_guess
from ..build.parameters import ProblemParameters
from ..contact import self_contact as SC
from ..contact.self_contact import ContactSlots
from ..results.result import ShapeResult
from ..state import SolverState
from .context import UpdateContext
from .ipopt import TIME_LIMIT, Attempt, call
from .newton import newton

#: what a Newton solve gives: (converged, state, steps, constraint violation [m or rad])
NewtonAttempt = tuple[bool, SolverState, int, float]


def pack_parameters(
    parameters: ProblemParameters,
    problem: Problem,
    z_reference: np.ndarray,
    keep: np.ndarray | None = None,
    slot_override: list | None = None,
    contact: ContactSlots | None = None,
) -> np.ndarray:
    """Return the NLP parameter vector for ``problem``.

    Angles are unwrapped to, and obstacle contact slots placed on, the shape ``z_reference``
    (``keep``: a vector whose slots stay while still placed well); ``slot_override``: the slots of
    a repeated solve (``slot_rounds.py``); ``contact``: the self-contact pairs of a round.
    """
    # the slots of a round are given: no placement on the reference shape
    p = parameters.pack(problem, z_reference, keep, slots=not slot_override)
    for i, placement in enumerate(slot_override or ()):
        parameters.write_slots(p, i, placement)
    if contact is not None:
        SC.fill(p, contact, parameters.nlp, problem.string.length)
    return p


def pack(
    ctx: UpdateContext, problem: Problem, z_reference: np.ndarray, keep: np.ndarray | None = None
) -> np.ndarray:
    """``pack_parameters`` with the context's slot override and self-contact pairs."""
    return pack_parameters(
        ctx.parts.parameters, problem, z_reference, keep, ctx.slot_override, ctx.contact
    )


def newton_to(
    ctx: UpdateContext, start: SolverState, p: np.ndarray, problem: Problem | None = None
) -> NewtonAttempt:
    """Run ``newton.newton`` from ``start`` to ``p``.

    Given ``problem`` (what p packs), a compiled loop also evaluates the answer's outputs in its
    call.
    """
    parts = ctx.parts
    plan = parts.functions.output_function
    prof = plan.profiles(problem.string) if problem is not None and plan is not None else None
    return newton(parts.nlp, parts.functions, start, p, fused=parts.fused_newton, prof=prof)


def ipopt_call(
    ctx: UpdateContext,
    warm: bool,
    z0: np.ndarray,
    p: np.ndarray,
    start: SolverState | None = None,
    escape: bool = False,
) -> Attempt:
    """Run one IPOPT solve from z0 (warm: with ``start``'s multipliers; escape: off a saddle).

    Within a streamed update past its ``solver.update_time_limit`` (``ctx.deadline``) none starts:
    a failed attempt, with IPOPT's own status for a call stopped by that limit.
    """
    nlp, solvers = ctx.parts.nlp, ctx.parts.ipopt
    deadline = ctx.deadline
    in_update = deadline is not None
    if deadline is not None and time.perf_counter() >= deadline:
        m, n = nlp.lbg.size, z0.size
        return False, SolverState(z0, np.zeros(m), np.zeros(n), p), TIME_LIMIT, 0, np.inf
    if start is None:
        return call(nlp, solvers.get(warm, escape, in_update), z0, p)
    return call(nlp, solvers.get(warm, in_update=in_update), z0, p, start.lam_g, start.lam_x)


def cold_ipopt(ctx: UpdateContext, problem: Problem) -> Attempt:
    """Run IPOPT cold from the initial guess (``initial_guess``)."""
    z0 = initial_guess(ctx.parts.nlp, ctx.parts.parameters, problem)
    return ipopt_call(ctx, False, z0, pack(ctx, problem, z0))


def result(
    ctx: UpdateContext,
    problem: Problem,
    state: SolverState,
    ipopt_status: str,
    iterations: int,
    violation: float,
    warm: bool,
    steps: int,
) -> ShapeResult:
    """Return the result of ``state`` solving ``problem`` (``ShapeOutputs.result``).

    Its wrenches' frames are anchored on ``ctx.scene``, the scene the update moves from.
    """
    parts = ctx.parts
    return parts.outputs.result(
        problem,
        ctx.scene,
        state,
        ipopt_status,
        iterations,
        violation,
        warm,
        steps,
        parts.summary(),
    )
