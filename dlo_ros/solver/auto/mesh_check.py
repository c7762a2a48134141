"""Check 4 on an element model: the shape's own error estimate, and the next element mesh.

For a model on spectral elements (the director model, and the planar one of basis 'elements';
see ``results/element_error.py``) the
a-posteriori estimate comes from the committed shape itself — the strong-form equilibrium residual
per element and each element's coefficient decay — so no second model is solved.  The verdict:

* estimate > δ/2: the mesh ``adapt/rule.py`` proposes (split where an element is not smooth or
  holds a known contact point, more nodes where it is smooth), with δ/2 as the rule's tolerance;
  with the obstacle rows on the nodes (``solver.obstacle_points: nodes``, auto's element models)
  the estimate adds CUT_SAFETY × the deepest cut between the rows and SAFETY × the error of
  each point contact (and each end of a line contact) pushing at its row rather than where the
  shape touches the obstacle (``adapt/contact_shift.py``, charged to the element holding it),
  and the known contact points include that cut and the ends of each run of active rows
  (``contact/penetration.py``), and where each point contact touches
  along the family of equilibria pinned at it (``adapt/contact_shift.py``, when that step stays
  within the rows about the contact): the split puts a node where the contact is, and an element
  holding one gets the kink safety factor;
* in a stream's check, estimate < δ/50 and the rule coarsens (hysteresis: refined elements land
  at a fifth of their share, so they are not coarsened back): the coarser mesh;
* else keep the mesh, with the estimate — also when the estimate is at its floor (1e-10·L, the
  accuracy a converged solve can be held to): a tolerance below it is reported as not met.

A model without an element mesh (a planar or Euler-angle model in another basis than 'elements')
keeps the order ladder (``checks.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...model.elements import element_mesh_of
from ..adapt.contact_shift import ContactShift, contact_shift_error
from ..adapt.moved_breakpoints import moved_onto
from ..adapt.rule import ElementEstimates, RefinementRule, next_mesh, unknowns
from ..adapt.smoothness import contact_kinks, pressing_inside, row_survey
from ..build.mesh import MeshSpec, mesh_spec
from ..build.structure import breakpoints
from ..results.element_error import SAFETY, element_errors
from ..results.residual import FLOOR
from .choice import ModelChoice

#: the most nodes per field a refinement may reach at δ ≥ 1e-4 L (the order ladder stopped at 32
#: in one polynomial; local refinement spends them where the error is); doubled below 1e-4 L
#: (:func:`max_unknowns`: the paper's Fig. 3 floor at 1e-5 L needs about 210), never more: a
#: planar element model of 640 nodes has a parameter vector of 230,000 entries and its build ran
#: a 24 GiB machine out of memory (Fig. 3 streamed at 1e-6 L)
MAX_UNKNOWNS = 160
#: below this fraction of δ the rule may coarsen (it coarsens an element under its own share)
COARSEN_BELOW = 0.02
#: the fewest nodes of an element auto keeps (the lowest order of the single-polynomial ladder):
#: the estimate bounds the shape's error, not the stability threshold's, which a coarser mesh
#: moves (Greenhill's twisted rod stayed straight 0.01 Φ_c past the threshold on 4 nodes)
MIN_NODES = 8
#: the centreline error a cut of depth d between the obstacle rows stands for, over d: the
#: contact sits at a row next to the true one, and the shape around it is off by more than the
#: cut (measured: 4.3 d on the heavy strip on a post of test_contact_auto.py, the true contact
#: 2 mm from the active row)
CUT_SAFETY = 8.0
#: grid points of a point contact's misplacement error δx(s) (``adapt/contact_shift.py``)
SHIFT_GRID = 401


@dataclass(frozen=True)
class MeshVerdict:
    """The mesh check's outcome: ``choice`` to switch to (None: keep), why, and the estimate."""

    choice: ModelChoice | None
    reason: str
    estimate: float


def max_unknowns(tolerance: float, length: float) -> int:
    """Return the refinement's cap on nodes per field at tolerance δ [m] on a string of L [m]."""
    return 2 * MAX_UNKNOWNS if tolerance < 1e-4 * length * (1 - 1e-9) else MAX_UNKNOWNS


def has_elements(solver) -> bool:
    """Tell whether ``solver``'s model is on an element mesh (director, or basis 'elements')."""
    return element_mesh_of(solver.nlp.model) is not None


def contact_points(solver, survey, state, shift: ContactShift) -> tuple[float, ...]:
    """Return where the contacts are [m], on a breakpoint or not.

    The first and last row of each run of contact rows, where each point contact touches, and
    the held points (slots, self-contact).
    """
    ends = () if survey is None else tuple(s for run in survey.intervals for s in run)
    held = contact_kinks(solver, None, state)
    return tuple(sorted({float(s) for s in ends + shift.touches + held}))


def contact_parts(shift: ContactShift, spec) -> np.ndarray:
    """Return each element's share of the point contacts' error [m]: the contact's own element."""
    bounds = np.asarray(spec.breakpoints, dtype=float)
    out = np.zeros(bounds.size + 1)
    for s, error in shift.parts:
        out[min(int(np.searchsorted(bounds, s)), bounds.size)] += error
    return out


def _reason(inside: tuple[float, ...], estimate: float, tolerance: float, fewer: bool) -> str:
    """Return why the proposed mesh is taken ('' : it is not).

    ``inside``: slots pressing inside an element (split there); ``fewer``: the proposal has fewer
    nodes and may coarsen (a stream's check).
    """
    if inside:
        at = ", ".join(f"{s:.4g}" for s in inside)
        return f"a contact inside an element (s = {at} m): split there"
    if estimate > tolerance / 2:
        return f"error estimate {estimate:.3g} m > {tolerance / 2:.3g} m"
    if fewer and estimate < COARSEN_BELOW * tolerance:
        return f"error estimate {estimate:.3g} m < {COARSEN_BELOW * tolerance:.3g} m"
    return ""


def _splits(spec, points: tuple[float, ...], within: float) -> bool:
    """Tell whether ``spec`` has a breakpoint within ``within`` [m] of each of ``points``."""
    placed = np.asarray(spec.breakpoints, dtype=float)
    return all(placed.size and np.min(np.abs(placed - s)) <= within for s in points)


def mesh_verdict(
    solver,
    state,
    choice: ModelChoice,
    problem,
    tolerance: float,
    coarsen: bool,
    moved_shadow: Callable[[MeshSpec], tuple[Any, Any]] | None = None,
) -> MeshVerdict:
    """Return the verdict on ``state``, committed by ``solver`` (a model of ``choice``).

    ``problem``: the scene the state solves as the model sees it (auto's reduced problem);
    ``tolerance``: δ [m]; ``coarsen``: a coarser mesh may be proposed (a stream's check: its later
    updates get cheaper; a cold solve's answer is final, so a coarser rebuild would only cost).
    In a stream's check the contact points are the rule's anchors: a breakpoint no contact holds
    any more (the lift-off slid on) merges away between two calm elements (``adapt/rule.py``).
    ``moved_shadow``: solves the checked shape on another mesh, for a slot pressing inside an
    element (:func:`moved_verdict`; None: split there, with no estimate).
    """
    length = problem.string.length
    survey = row_survey(solver, state)
    # a point contact pushing at a row, not where the shape touches: the error that carries
    shift = (
        contact_shift_error(solver.nlp, problem, state, np.linspace(0.0, length, SHIFT_GRID))
        if survey is not None
        else ContactShift(0.0, ())
    )
    kinks = contact_kinks(solver, survey, state)
    errors = element_errors(solver.outputs, problem, state, contacts=kinks)
    # a cut of depth d between the rows: the contact sits at the wrong node, an error of the
    # centreline of a few d (CUT_SAFETY)
    cuts = CUT_SAFETY * np.maximum(survey.depth_m, 0.0) if survey is not None else 0.0
    estimate = float(errors.estimate_m) + float(np.max(cuts, initial=0.0)) + SAFETY * shift.error_m
    spec = choice.mesh or mesh_spec(solver.nlp.model.mesh)
    rule = RefinementRule(
        tolerance=tolerance / 2,
        min_nodes=MIN_NODES,
        max_unknowns=max_unknowns(tolerance, length),
        max_removed=2,
    )
    # the per-element estimates carry the residual's safety factor, and each element the cut
    # between its rows and the error of the point contacts it holds, so that their sum bounds
    # the estimate as the rule's share of δ/2 assumes (and the rule refines where they are)
    scale = float(errors.estimate_m) / max(float(np.sum(errors.per_element_m)), 1e-300)
    # a slot pressing inside an element: its error unbounded by the estimate, split there
    inside = pressing_inside(solver, state, rule.min_size)
    estimates = ElementEstimates(
        np.maximum(errors.per_element_m * max(scale, 1.0), 0.0)
        + cuts
        + SAFETY * contact_parts(shift, spec),
        np.asarray(errors.smoothness, dtype=float),
        tuple(sorted(set(kinks) | set(shift.touches))),
        shift.touches,
        anchors=contact_points(solver, survey, state, shift) if coarsen else None,
        unresolved=inside,
    )
    following = next_mesh(spec, problem.string.length, estimates, rule, fixed=breakpoints(problem))
    check = (choice, problem, tolerance, coarsen)
    moved = _moved_check(
        solver, state, check, inside, spec, following, rule.min_size, moved_shadow
    )
    if moved is not None:
        return moved
    if inside:
        estimate = float("inf")
    if following is None or not _splits(following, inside, rule.min_size):
        # (a contact inside an element that the unknowns cap left unsplit: kept, no estimate)
        return MeshVerdict(None, "", estimate)
    before, after = unknowns(spec.counts or ()), unknowns(following.counts or ())
    if estimate <= FLOOR * problem.string.length * (1 + 1e-9):
        # at the accuracy a converged solve can be held to: no mesh lowers it (a tolerance below
        # it is reported as not met)
        return MeshVerdict(None, "", estimate)
    why = _reason(inside, estimate, tolerance, coarsen and after < before)
    if not why:
        return MeshVerdict(None, "", estimate)
    return _switch(choice, spec, following, why, estimate)


def _switch(choice: ModelChoice, spec, following, why: str, estimate: float) -> MeshVerdict:
    """Return the verdict that switches from mesh ``spec`` to ``following``, saying ``why``."""
    before, after = unknowns(spec.counts or ()), unknowns(following.counts or ())
    nan = float("nan")
    refined = replace(
        choice,
        mesh=following,
        estimated_error_m=nan,
        order_error_m=nan,
        reasons=list(choice.reasons),
    )
    sizes = f"{len(following.counts or ())} elements, {after} nodes"
    was = f"{len(spec.counts or ())}, {before}"
    return MeshVerdict(refined, f"{why}: mesh of {sizes} (was {was})", estimate)


def _moved_check(solver, state, check, inside, spec, following, min_size, moved_shadow):
    """Return :func:`moved_verdict` on a mesh with a breakpoint at each slot ``inside``, or None.

    The same counts with a breakpoint moved onto each, else the rule's ``following`` mesh where
    it splits at them; None without ``moved_shadow`` or either mesh.
    """
    if not inside or moved_shadow is None:
        return None
    length, fixed = check[1].string.length, breakpoints(check[1])
    moved = moved_onto(spec, length, inside, fixed, min_size)
    if moved is None and following is not None and _splits(following, inside, min_size):
        moved = following
    if moved is None:
        return None
    return moved_verdict(solver, state, check, inside, (spec, moved), moved_shadow)


def moved_verdict(
    solver, state, check: tuple, inside, meshes: tuple[MeshSpec, MeshSpec],
    moved_shadow: Callable[[MeshSpec], tuple[Any, Any]],
) -> MeshVerdict | None:  # fmt: skip
    """Return the verdict on a shape with slots pressing ``inside`` elements, by a mesh ``moved``.

    ``meshes``: (the checked mesh, ``moved``), ``moved`` a mesh with a breakpoint at each such
    slot, the same counts with a breakpoint moved onto it (``adapt/moved_breakpoints.py``: a
    clone of the NLP, no build) or the rule's split there; solved from the shape
    (``moved_shadow``), its own check (:func:`mesh_verdict`) holds no slot inside an element.
    The shape's error is bounded by the triangle inequality, max_s |x(s) − x_moved(s)| + the
    moved mesh's estimate: kept when that is within δ/2, else the moved mesh (or the refinement
    its check proposes) is taken.  None where the moved solve fails or its own estimate is
    unknown (the caller splits at the slot, with no estimate).
    ``check``: :func:`mesh_verdict`'s (choice, problem, tolerance δ [m], coarsen).
    """
    choice, problem, tolerance, coarsen = check
    spec, moved = meshes
    length = problem.string.length
    other, result = moved_shadow(moved)
    other_state = other.committed_state
    if not result.ok or other_state is None:
        return None
    on_moved = replace(choice, mesh=moved, reasons=list(choice.reasons))
    sub = mesh_verdict(other, other_state, on_moved, problem, tolerance, coarsen)
    if not np.isfinite(sub.estimate):
        return None
    s = np.linspace(0.0, length, SHIFT_GRID)
    x, x_moved = (
        solver.nlp.model.positions(state.z, s),
        other.nlp.model.positions(other_state.z, s),
    )
    estimate = float(np.max(np.linalg.norm(x - x_moved, axis=1))) + sub.estimate
    if estimate <= tolerance / 2:
        return MeshVerdict(None, "", estimate)
    at = ", ".join(f"{c:.4g}" for c in inside)
    why = f"a contact inside an element (s = {at} m), error estimate {estimate:.3g} m"
    how = "moved onto it" if moved.counts == spec.counts else "split there"
    if sub.choice is not None:
        return MeshVerdict(sub.choice, f"{why}: {how}; {sub.reason}", estimate)
    return _switch(choice, spec, moved, f"{why}: {how}", estimate)
