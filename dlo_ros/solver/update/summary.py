"""The model a fixed model's results name: its ``ModelSummary``, made once per NLP and scene.

``ShapeSolver.model_summary`` asks ``ModelSummaries.get``; the stages build every result with it
(``SolverParts.summary``).  A summary depends on the NLP, the string and the obstacle count only.
"""

from __future__ import annotations

from typing import Any

from ...model.problem import Problem
from ..build.nlp import StringNLP
from ..results.summary import ModelSummary


class ModelSummaries:
    """The last ``ModelSummary`` made, kept while its NLP, string and obstacle count stay."""

    def __init__(self) -> None:
        # ((NLP, string, obstacle count), its summary); the NLP and string compared by identity
        self._known: tuple[tuple, ModelSummary] | None = None

    def get(self, nlp: StringNLP, problem: Problem) -> ModelSummary:
        """Return the summary of ``nlp`` solving ``problem``, made again only when it changed."""
        key = (nlp, problem.string, len(problem.obstacles))
        known = self._known
        if (
            known is None
            or any(a is not b for a, b in zip(known[0][:2], key))
            or known[0][2] != key[2]
        ):
            known = self._known = (key, describe_model(nlp, problem))
        return known[1]


def describe_model(nlp: StringNLP, problem: Problem) -> ModelSummary:
    """Return what ``nlp`` models for ``problem``: the ``model`` of its results."""
    lay = nlp.model.layout
    common: dict[str, Any] = dict(
        planar=lay.planar,
        twist=lay.twist,
        stretch=lay.stretch,
        gravity=not problem.string.weight_per_length.is_zero,
        order=lay.order,
        obstacles=len(problem.obstacles),
        variables=lay.size,
    )
    if nlp.director:
        return ModelSummary(
            **common,
            rotation="quaternion" if lay.frame else "tangent",
            elements=lay.elements,
            breakpoints=tuple(float(b) for b in nlp.model.mesh.breakpoints),
            self_contact_pairs=nlp.self_contact_slots,
        )
    return ModelSummary(**common, rotation="planar" if lay.planar else "euler")
