"""Check 4 on an element model: the shape's own error estimate, and the next element mesh.

For a model on spectral elements (the director model, and the planar one of basis 'elements';
see ``results/element_error.py``) the
a-posteriori estimate comes from the committed shape itself — the strong-form equilibrium residual
per element and each element's coefficient decay — so no second model is solved.  The verdict:

* estimate > δ/2: the mesh ``adapt/rule.py`` proposes (split where an element is not smooth or
  holds a known contact point, more nodes where it is smooth), with δ/2 as the rule's tolerance;
* in a stream's check, estimate < δ/50 and the rule coarsens (hysteresis: refined elements land
  at a fifth of their share, so they are not coarsened back): the coarser mesh;
* else keep the mesh, with the estimate — also when the estimate is at its floor (1e-10·L, the
  accuracy a converged solve can be held to): a tolerance below it is reported as not met.

A model without an element mesh (a planar or Euler-angle model in another basis than 'elements')
keeps the order ladder (``checks.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...model.elements import element_mesh_of
from ..adapt.rule import ElementEstimates, RefinementRule, next_mesh, unknowns
from ..adapt.smoothness import contact_kinks
from ..build.mesh import mesh_spec
from ..build.structure import breakpoints
from ..results.element_error import FLOOR, element_errors
from .choice import ModelChoice

#: the most nodes per field a refinement may reach (the order ladder stopped at 32 in one
#: polynomial; local refinement spends them where the error is)
MAX_UNKNOWNS = 160
#: below this fraction of δ the rule may coarsen (it coarsens an element under its own share)
COARSEN_BELOW = 0.02
#: the fewest nodes of an element auto keeps (the lowest order of the single-polynomial ladder):
#: the estimate bounds the shape's error, not the stability threshold's, which a coarser mesh
#: moves (Greenhill's twisted rod stayed straight 0.01 Φ_c past the threshold on 4 nodes)
MIN_NODES = 8


@dataclass(frozen=True)
class MeshVerdict:
    """The mesh check's outcome: ``choice`` to switch to (None: keep), why, and the estimate."""

    choice: ModelChoice | None
    reason: str
    estimate: float


def has_elements(solver) -> bool:
    """Tell whether ``solver``'s model is on an element mesh (director, or basis 'elements')."""
    return element_mesh_of(solver.nlp.model) is not None


def mesh_verdict(
    solver, state, choice: ModelChoice, problem, tolerance: float, coarsen: bool
) -> MeshVerdict:
    """Return the verdict on ``state``, committed by ``solver`` (a model of ``choice``).

    ``problem``: the scene the state solves as the model sees it (auto's reduced problem);
    ``tolerance``: δ [m]; ``coarsen``: a coarser mesh may be proposed (a stream's check: its later
    updates get cheaper; a cold solve's answer is final, so a coarser rebuild would only cost).
    """
    errors = element_errors(solver.outputs, problem, state)
    estimate = float(errors.estimate_m)
    spec = choice.mesh or mesh_spec(solver.nlp.model.mesh)
    rule = RefinementRule(
        tolerance=tolerance / 2, min_nodes=MIN_NODES, max_unknowns=MAX_UNKNOWNS, max_removed=2
    )
    # the per-element estimates carry the global estimate's safety factor, so that their sum
    # bounds it as the rule's share of δ/2 assumes
    scale = estimate / max(float(np.sum(errors.per_element_m)), 1e-300)
    estimates = ElementEstimates(
        np.maximum(errors.per_element_m * max(scale, 1.0), 0.0),
        np.asarray(errors.smoothness, dtype=float),
        contact_kinks(solver),
    )
    following = next_mesh(spec, problem.string.length, estimates, rule, fixed=breakpoints(problem))
    if following is None:
        return MeshVerdict(None, "", estimate)
    before, after = unknowns(spec.counts or ()), unknowns(following.counts or ())
    if estimate <= FLOOR * problem.string.length * (1 + 1e-9):
        # at the accuracy a converged solve can be held to: no mesh lowers it (a tolerance below
        # it is reported as not met)
        return MeshVerdict(None, "", estimate)
    if estimate > tolerance / 2:
        why = f"error estimate {estimate:.3g} m > {tolerance / 2:.3g} m"
    elif coarsen and estimate < COARSEN_BELOW * tolerance and after < before:
        why = f"error estimate {estimate:.3g} m < {COARSEN_BELOW * tolerance:.3g} m"
    else:
        return MeshVerdict(None, "", estimate)
    refined = replace(
        choice,
        mesh=following,
        estimated_error_m=float("nan"),
        order_error_m=float("nan"),
        reasons=list(choice.reasons),
    )
    return MeshVerdict(
        refined,
        f"{why}: mesh of {len(following.counts or ())} elements, {after} nodes (was "
        f"{len(spec.counts or ())}, {before})",
        estimate,
    )
