"""Whether a shape solved without self-contact passes through itself, and how its result says so.

A model whose NLP has no self-contact rows (``solver.self_contact_pairs: 0``, every model but
auto's self-contact one) solves the string as a line: nothing keeps two strands of a string of
radius r apart.  Its answer can pass through itself (measured, #37: the paper's Fig. 2 loop at
chord 0.3 L, radius 0.01 L, strands 6.5 mm apart on a 20 mm thick cable) and still be a converged,
stable equilibrium of that model.  It is not one of the string: such a result is never ``ok``.

The test is the self-contact module's own (``contact/self_contact.py``), on the answer's centreline
sampled as the self-contact rows would sample it (spacing h, pairs at least the exclusion arc apart
along s, pairs placed by two different grips left out): ``candidate_pairs`` (the local minima of
distance, k-d tree), after the exact ``certainly_apart`` shortcut, and ``penetrations`` with the
threshold 2r − ``TOLERANCE``·2r (not the D = √((2r)² + h²/2) the rows keep: a shape whose strands
are between 2r and D apart does not pass through itself).  A flagged pair is certain: the true
centreline distance is at most the samples'.  The limit of the sampling: two strands whose closest
points fall between samples may come to √((2r − tol)² − h²/2) at worst before a sample pair reads
below 2r − tol (the bound of ``self_contact.py``'s docstring).

Radius 0 ("may touch, may not cross") is not checked: a line of no thickness meets itself only
at isolated targets, and telling a crossing made between two answers needs the previous answer's
crossing signs (``self_contact.crossing_flips``), which a model without self-contact does not keep.

A flagged result (``flag``): ``passes_through_itself`` true, status ``unverified`` (the shape kept
for inspection), ``stable`` None, a message naming the closest pair and the radius.  Every checked
result (radius > 0) gets ``min_self_distance``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from ...model.problem import Problem
from ..build.nlp import StringNLP
from ..build.output_function import TANGENTS
from ..contact import self_contact as SC
from ..contact.apart_memo import ApartMemo
from ..native.outputs import ComputedOutputs, same
from ..state import SolverState
from .result import ShapeResult

#: a sample pair closer than 2r (1 − TOLERANCE) passes through itself (rounding and the solver's
#: own tolerance never bring a shape that keeps 2r that far below it)
TOLERANCE = 1e-3


@dataclass(frozen=True)
class SelfPass:
    """The closest approach of an answer to itself, and the pair that passes through, if any.

    closest [m]: the smallest sample-pair distance of two strands (inf when no two are within
    the candidate reach); pair: (s_a, s_b) [m], s_a < s_b, of the closest pair closer than
    ``limit``, or None; limit [m]: 2r (1 − TOLERANCE); radius [m]: r.
    """

    closest: float
    pair: tuple[float, float] | None
    limit: float
    radius: float

    @property
    def passes(self) -> bool:
        """Whether the answer passes through itself (a pair closer than ``limit``)."""
        return self.pair is not None


def geometry_of(problem: Problem, samples: int = 0) -> SC.ContactGeometry:
    """Return the self-contact sampling of ``problem``'s string (``samples``: 0 picks h = r)."""
    st = problem.string
    return SC.contact_geometry(st.length, st.radius, samples, tuple(g.s for g in problem.grips))


def tangents(nlp: StringNLP, state: SolverState) -> np.ndarray:
    """Return (1 + ε) t̂ at a director model's quadrature nodes (3, M) for ``state``.

    Those the converged compiled loop's outputs carry when it evaluated them at ``state.z``
    (``native.outputs.ComputedOutputs``), else ``model.quad_tangents``: equal to rounding.
    """
    computed = cast(ComputedOutputs | None, state.outputs)  # SolverState types it as object
    if computed is not None and len(computed.values) > TANGENTS and same(computed.z, state.z):
        return computed.values[TANGENTS]
    return nlp.model.quad_tangents(state.z)


def centreline(nlp: StringNLP, state: SolverState, s: np.ndarray) -> np.ndarray:
    """Return the centreline points (len(s), 3) [m] of ``state`` at ``s``, the ones to test.

    A director model's from its ``tangents`` (one matrix product,
    ``DirectorModel.positions_with``); else ``model.positions``.  Equal to rounding.
    """
    if nlp.director:
        return nlp.model.positions_with(state.z, s, tangents(nlp, state))
    return nlp.model.positions(state.z, s)


def check(
    nlp: StringNLP,
    state: SolverState,
    geometry: SC.ContactGeometry,
    radius: float,
    memo: ApartMemo | None = None,
) -> SelfPass:
    """Return ``self_pass`` of ``state``'s centreline at ``geometry.s``.

    With the solver's ``memo``, a director model's samples are worked out only where the memo's
    proof does not cover the move of its tangents (``ApartMemo.apart_linear``).
    """
    if memo is None or not nlp.director:
        return self_pass(centreline(nlp, state, geometry.s), geometry, radius, memo)
    held = tangents(nlp, state)
    sampled: list[np.ndarray] = []

    def points() -> np.ndarray:
        if not sampled:
            sampled.append(nlp.model.positions_with(state.z, geometry.s, held))
        return sampled[0]

    def rows() -> np.ndarray:
        return nlp.model.position_matrix(geometry.s)

    if memo.apart_linear(geometry, held, points, rows):
        return SelfPass(float("inf"), None, 2.0 * radius * (1.0 - TOLERANCE), radius)
    return self_pass(points(), geometry, radius)


def self_pass(
    points: np.ndarray,
    geometry: SC.ContactGeometry,
    radius: float,
    memo: ApartMemo | None = None,
) -> SelfPass:
    """Return how close the centreline ``points`` (N, 3) [m] at ``geometry.s`` comes to itself.

    ``radius`` > 0 [m]; see the module docstring for what is tested.  ``memo``: the solver's
    shape proved apart last (``contact/apart_memo.py``), whose proof may cover ``points``.
    """
    limit = 2.0 * radius * (1.0 - TOLERANCE)
    apart = (
        memo.apart(points, geometry) if memo is not None else SC.certainly_apart(points, geometry)
    )
    if apart:  # the usual answer, proved without the k-d tree
        return SelfPass(float("inf"), None, limit, radius)
    candidates = SC.candidate_pairs(points, geometry)
    closest = min((d for _, d in candidates), default=float("inf"))
    through = SC.penetrations(candidates, geometry, geometry.distance - limit)
    pair = None
    if through:
        a, b = through[0]
        pair = (float(geometry.s[a]), float(geometry.s[b]))
    return SelfPass(closest, pair, limit, radius)


def flag(result: ShapeResult, verdict: SelfPass) -> ShapeResult:
    """Report ``verdict`` in ``result`` (in place; returned): distance, and a pass as unverified.

    ``min_self_distance`` is set; a pass sets ``passes_through_itself``, turns an ``ok`` or
    ``unverified`` status into ``unverified`` with ``stable`` None, and puts the pair first in
    the message.
    """
    result.min_self_distance = verdict.closest
    if not verdict.passes or result.status not in ("ok", "unverified"):
        return result
    assert verdict.pair is not None
    s_a, s_b = verdict.pair
    result.passes_through_itself = True
    result.status, result.stable = "unverified", None
    result.message = (
        f"passes through itself: s = {s_a:.4g} m and {s_b:.4g} m are {verdict.closest:.3g} m "
        f"apart centreline to centreline, under 2·radius = {2 * verdict.radius:.3g} m (this "
        f"model has no self-contact rows: solver.self_contact_pairs or model auto keeps strands "
        f"apart); {result.message}"
    )
    return result
