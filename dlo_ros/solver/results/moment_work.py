"""The point moments' work W_M in a result's energy, or why a dead moment has none.

A dead moment M (fixed in the world) does the virtual work M·δθ.  While the tangent at its load
stays normal to n = M/|M|, the rotation's component along n is n·(t × δt), the turn of t in the
plane normal to n, so the work is the potential W_M = |M| α + const, α the angle of the tangent
about n.  Off that plane M·δθ is not the variation of any function of the shape: a dead moment in
general 3D is not conservative and U − W has no meaning.

Rule (one for every model): W_M = |M| α(s_k) where the string's tangent from s = 0 to the load
stays within ``PLANE_TOLERANCE`` of the plane normal to n; α is measured from −R0 e_x (the NLP's
reference frame: where the Euler models' φ = 0, so both agree with their −m φ) projected on that
plane, taken in (−π, π] at s = 0 and unwrapped along the string up to the load (its windings).
Otherwise the work and the total are None, and ``MomentWork.reason`` says why.

The director models apply a moment through a pseudo-potential centred on the solution, whose value
there is 0 (``model/director.py``): its value is replaced by W_M.  The Euler models' work already
holds −m φ(s_k) (exact in their plane, its windings tracked by the Ritz angle); only the plane is
checked.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...model.problem import Problem
from ..build.nlp import StringNLP

#: largest |t·n| [-] along [0, s_k] for which the string counts as normal to the moment's axis
PLANE_TOLERANCE = 1e-6
#: tangents sampled over [0, s_k] to unwrap the angle (a turn by π between two samples would need
#: a curvature of 100 π / s_k, far past any resolved shape)
UNWRAP_SAMPLES = 201


@dataclass(frozen=True)
class MomentWork:
    """The point moments' part of the external work.

    ``correction`` [J]: what to add to the work the NLP's energy function reports (the director
    models' W_M minus their pseudo-potential's value); None when a dead moment has no potential,
    and then ``reason`` names the load and how far its tangent leaves the plane.
    """

    correction: float | None
    reason: str = ""


def moment_work(nlp: StringNLP, problem: Problem, z: np.ndarray, p: np.ndarray) -> MomentWork:
    """Return the correction of the work for ``problem``'s point moments at state (z, p)."""
    correction = 0.0
    for i, ld in enumerate(problem.loads):
        moment = np.asarray(ld.moment, dtype=float)
        size = float(np.linalg.norm(moment))
        if size == 0.0:
            continue
        n = moment / size
        s = np.linspace(0.0, ld.s, UNWRAP_SAMPLES)
        t = tangents(nlp, z, s)
        off = float(np.max(np.abs(t @ n)))
        if not off <= PLANE_TOLERANCE:
            return MomentWork(
                None,
                f"loads[{i}].moment is a dead moment whose axis is not normal to the string "
                f"between s = 0 and its load (|t·n| up to {off:.3g}): it has no potential, so "
                "external_work and total are not defined",
            )
        if nlp.director:
            angle = unwrapped_angle(t, n, -nlp.r0[:, 0], -nlp.r0[:, 1])
            correction += size * angle - pseudo_potential(nlp, z, p, i, ld.s, moment)
    return MomentWork(correction)


def tangents(nlp: StringNLP, z: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Return the unit tangent vectors (len(s), 3) of state z at arc lengths s, any model."""
    m = nlp.model
    if nlp.director:
        return m.tangents_at(z, s)
    fields = m.fields(z, s, ("phi", "theta"))
    return m.tangents(fields["phi"], fields["theta"], lib=np).T


def unwrapped_angle(t: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Return the angle of the last tangent about n from a, unwrapped along the tangents t.

    a (b where a is along n) projected on the plane normal to n is the zero; the first tangent's
    angle is in (−π, π].
    """
    zero = a - (a @ n) * n
    if np.linalg.norm(zero) < 1e-3:
        zero = b - (b @ n) * n
    zero /= np.linalg.norm(zero)
    other = np.cross(n, zero)
    angles = np.unwrap(np.arctan2(t @ other, t @ zero))
    return float(angles[-1])


def pseudo_potential(
    nlp: StringNLP, z: np.ndarray, p: np.ndarray, i: int, s: float, moment: np.ndarray
) -> float:
    """Return the value of load i's pseudo-potential in the NLP's work at (z, p)."""
    m = nlp.model
    v = m.node_values(z)[m.mesh.node_index(s)]
    reference = p[nlp.params[f"load:{i}:reference"]]
    value = m.moment_work_node_sym(ca.DM(v), ca.DM(moment), ca.DM(reference))
    return float(value)
