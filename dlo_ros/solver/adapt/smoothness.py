"""The contact points of a solved shape, which a refinement knows as kinks.

A point contact is a jump of the internal force, so the curvature has a kink there: the rule
(``rule.py``) splits an element at such a point rather than at its middle.  Known contact points:
the filled obstacle slots, the self-contacts held at the closest points of two strands
(``update/contact_points.py``: both points, where the internal force jumps by the contact
force), and with the rows on the mesh nodes (``solver.obstacle_points: nodes``) the deepest cut
between the rows and the ends of each run of active rows (``contact/penetration.py``).  How
smooth a shape is on each element (its Legendre coefficients' decay) is
``results/element_error.coefficient_decay``.
"""

from __future__ import annotations

import numpy as np

from ...model.elements import element_mesh_of
from ..contact.obstacle_slots import FLAT
from ..contact.penetration import ContactSurvey, contact_survey
from ..shape_solver import ShapeSolver
from ..state import SolverState
from ..update.slot_rounds import ACTIVE


def row_survey(solver: ShapeSolver, state: SolverState | None) -> ContactSurvey | None:
    """Return the contact survey of ``state`` (of ``solver``), when its obstacle rows sit on nodes.

    ``state``: the checked shape's (a check's snapshot), never read from ``solver`` here: on the
    worker thread the stream commits later shapes meanwhile, and a survey of one of those made the
    background checks' verdicts depend on when the worker ran them.  None without a state,
    without obstacles, or with the rows on uniform samples (whose cut between samples
    ``auto/checks.py``'s sampling check measures).
    """
    mesh, problem = element_mesh_of(solver.nlp.model), solver.problem
    if state is None or mesh is None or not problem.obstacles:
        return None
    if solver.options.obstacle_points != "nodes":
        return None
    return contact_survey(solver.model, state.z, mesh, problem.obstacles, problem.string.radius)


def contact_kinks(
    solver: ShapeSolver, survey: ContactSurvey | None = None, state: SolverState | None = None
) -> tuple[float, ...]:
    """Return the arc lengths [m] of the known contact points of ``state`` (default: committed).

    The filled obstacle contact slots, both points of each self-contact held at the strands'
    closest points (``state.contact.at``), and the kinks of ``survey`` (the rows' contact survey,
    :func:`row_survey`) inside elements.  A point contact is a jump of the internal force: the
    curvature has a kink there.  (Measured without the held points: Fig. 2 at chord 0.3 L,
    r = 0.01 L, held inside an element whose coefficients still decay fast, estimated
    3.7e-7 m against a true 4.8e-7 m.)
    """
    state = state if state is not None else solver.committed_state
    if state is None:
        return ()
    out: list[float] = []
    for i in range(len(solver.nlp.slot_rows) if solver.nlp.obstacle_slots else 0):
        slots = solver.parameters.slots(state.p, i)
        out += [float(s) for s, on in zip(slots.s, slots.on) if on > 0]
    if state.contact is not None:
        out += [float(s) for pair in state.contact.at.values() for s in pair]
    mesh = element_mesh_of(solver.nlp.model)
    if survey is not None and mesh is not None:
        out += list(survey.kinks(mesh))
    return tuple(sorted(set(out)))


def pressing_inside(solver: ShapeSolver, state: SolverState, margin: float) -> tuple[float, ...]:
    """Return the arc lengths [m] of the obstacle slots of ``state`` that press inside an element.

    A filled slot of a curved obstacle whose row's multiplier exceeds ``slot_rounds.ACTIVE``
    (it carries force), farther than ``margin`` [m] from every breakpoint of the mesh (the
    string's ends included).  The Ritz field cannot kink there, and on a curved obstacle the
    residual integrated from s = 0 does not bound the error that carries: the string's swing
    about the obstacle is soft, and a contact a little off moves the whole shape (the main job's
    post, its contact 13 mm inside a 16-node element: 4.8e-6 m from the reference against an
    estimate of 1.3e-6 m; 8 mm inside: 3.5e-7 m).  On a plane the estimate holds
    (``test_table_touch.py``).
    """
    mesh = element_mesh_of(solver.nlp.model)
    nlp = solver.nlp
    if mesh is None or not nlp.obstacle_slots:
        return ()
    out: list[float] = []
    for i, rows in enumerate(nlp.slot_rows):
        if solver.problem.obstacles[i].type in FLAT:
            continue
        slots = solver.parameters.slots(state.p, i)
        force = state.lam_g[list(rows)] > ACTIVE
        for s, on, pressing in zip(slots.s, slots.on, force):
            if on > 0 and pressing and np.min(np.abs(mesh.breakpoints - s)) > margin:
                out.append(float(s))
    return tuple(sorted(out))
