"""Following the scene: a richer model when the targets need one, and models built ahead.

A stream never waits for a build it can foresee: the 3D model of a planar choice and the models
with the obstacles coming within reach are built on the check worker (:func:`prebuild`) before a
change needs them.  Each function takes the :class:`.auto_solver.AutoShapeSolver` it serves and
uses only its public members (``choice``, ``inner``, ``pool``, ``worker``, ``switch``,
``changes``, ``problem``).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING

from ...model.problem import Problem
from ..results.result import ShapeResult
from .check_schedule import held_refinement
from .choice import ORDERS, ModelChoice, full_choice
from .mesh_check import has_elements
from .query_refine import refine_query
from .reach import in_plane_obstacles, not_planar, reachable_obstacles, stretch_needed

if TYPE_CHECKING:  # the solver calls these functions (auto_solver.py imports this module)
    from .auto_solver import AutoShapeSolver


def build_first(auto: AutoShapeSolver, problem: Problem) -> None:
    """Build ahead: the 3D model a stream leaving the plane switches to, then the shadows.

    The order shadows are the ones the first check needs; an element model's check solves none
    (its estimate comes from the shape itself), so none is built for it.  Returns once the 3D
    model is built, so that a stream leaving the plane at its first update never waits for the
    build.
    """
    ahead = [full_choice(auto.choice, problem)] if auto.choice.may_leave_plane else []
    auto.pool.full_key = ("",) + ahead[0].key() if ahead else ()
    if not has_elements(auto.inner):  # an element model's checks solve no shadow
        i = ORDERS.index(auto.choice.order)
        ahead += [
            replace(auto.choice, order=o)
            for o in ORDERS[i + 1 : i + 2] + ORDERS[max(i - 1, 0) : i]
        ]
    auto.worker.submit(prebuild, {("",) + c.key() for c in ahead}, auto, ahead, problem)
    while auto.pool.full_key and auto.worker.busy_with(auto.pool.full_key):
        time.sleep(0.002)


def off_kept_plane(auto: AutoShapeSolver, problem: Problem) -> str:
    """Say why ``problem``'s targets leave the plane ``solver.plane: keep`` holds ('' if not)."""
    if not auto.choice.plane_kept:
        return ""
    why = not_planar(problem, auto.choice.obstacles, auto.inner.nlp.r0, tolerance=1e-7)
    return f"solver.plane 'keep': {why}" if why else ""


def follow_scene(
    auto: AutoShapeSolver, problem: Problem, commit: bool, notes: list[str], t0: float
) -> ShapeResult | None:
    """Switch to a richer model when the targets need one; build an approaching one ahead.

    Out of the plane, an obstacle within reach (L/4), or grips beyond L: an update switches
    to the richer model, a query is answered with it (returned; the stream's model stays).
    The models a coming change needs are built ahead after the update (:func:`build_ahead`).
    """
    reach = reachable_obstacles(problem, problem.string.length / 4)
    if auto.choice.planar:
        reach = in_plane_obstacles(problem, reach, auto.inner.nlp.r0)
    entering = set(reach) - set(auto.choice.obstacles)
    obstacles = tuple(sorted(entering | set(auto.choice.obstacles)))
    # (with the plane kept, ``off_kept_plane`` has refused targets out of it before this)
    why = (
        not_planar(problem, obstacles, auto.inner.nlp.r0, tolerance=1e-7)
        if auto.choice.may_leave_plane
        else ""
    )
    stretch_why = "" if auto.choice.stretch else stretch_needed(problem, auto.tolerance / 2)
    if why or entering or stretch_why:
        richer = (
            full_choice(_refined(auto, wait=commit), problem)
            if why
            else replace(auto.choice, obstacles=obstacles)
        )
        if stretch_why:
            richer = replace(richer, stretch=True, reasons=list(richer.reasons))
        if not commit:  # a query must not change the streaming model: answer with the richer
            auto.worker.wait()
            other = auto.pool.solver_for(richer, problem, stream=False, source=auto.inner)
            auto.pool.compile_ahead(other)  # it answers every such query: compiled
            # the poses are checked, and in the plane if ``other`` is planar (above)
            # a query is never limited by solver.update_time_limit (update/time_limit.py)
            poses = {g.name: g.pose for g in problem.grips}
            answer = other.solve(poses, commit=False, checked=True, limited=False)
            return refine_query(auto, problem, answer, t0, richer, other)
        reasons = (
            ([f"targets left the plane ({why}): full model"] if why else [])
            + ([f"obstacle(s) {sorted(entering)} came within reach"] if entering else [])
            + ([stretch_why] if stretch_why else [])
        )
        auto.problem = problem
        auto.switch(richer, "; ".join(reasons))
        notes.append(auto.changes[-1][1])
    return None


def build_ahead(auto: AutoShapeSolver, problem: Problem) -> None:
    """Submit a build of the model a coming change needs, if it is not pooled yet.

    For a planar stream, the 3D model leaving the plane switches to; else the model with the
    obstacles within L/2 of reach (they enter the NLP at L/4).  Only on an idle worker, and after
    the update has started its check (the solver calls this last): a check is due CHECK_LAG
    updates after it starts, a build only when its change comes, so a check never queues behind
    a build (the main job's first planar mesh switch: its check waited 0.27 s at the update it
    was due at behind the new mesh's 3D build).
    """
    if not (auto.worker.background and auto.worker.idle):
        return
    if auto.choice.may_leave_plane:
        full = full_choice(_refined(auto, wait=False), problem)
        auto.pool.full_key = ("",) + full.key()
        if auto.pool.pooled(full) is None:
            auto.worker.submit(prebuild, {auto.pool.full_key}, auto, [full], problem)
            return
    near = set(reachable_obstacles(problem, problem.string.length / 2))
    if auto.choice.planar:
        near = set(in_plane_obstacles(problem, tuple(near), auto.inner.nlp.r0))
    near -= set(auto.choice.obstacles)
    if near:
        ahead = replace(auto.choice, obstacles=tuple(sorted(near | set(auto.choice.obstacles))))
        if auto.pool.pooled(ahead) is None:
            auto.worker.submit(prebuild, {("",) + ahead.key()}, auto, [ahead], problem)


def _refined(auto: AutoShapeSolver, wait: bool) -> ModelChoice:
    """Return the streaming choice on the finer mesh a held check decided for it, if any.

    (``check_schedule.held_refinement``; ``wait``: for a background decision.)
    """
    book = auto.book
    mesh = held_refinement(book.pending, auto.choice, book.generation, auto.tolerance, wait)
    return auto.choice if mesh is None else replace(auto.choice, mesh=mesh)


def prebuild(auto: AutoShapeSolver, choices: list[ModelChoice], problem: Problem) -> None:
    """Build (worker thread) the models a coming check or switch will need.

    The 3D model and obstacle models get their IPOPT solvers too (a switch to them streams at
    once).
    """
    for choice in choices:
        solver = auto.pool.solver_for(choice, problem, stream=False)
        key = ("",) + choice.key()
        if key == auto.pool.full_key or choice.obstacles != auto.choice.obstacles:
            solver.prepare()
            auto.pool.compile_ahead(solver)
        else:  # its contact-free Newton functions (built on first use): not on the stream's thread
            solver.functions.prepare_newton()
        auto.worker.built(key)  # built: a switch to it need not wait
