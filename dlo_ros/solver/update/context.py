"""The explicit state of one warm or cold update: what the stages take and give.

``ShapeSolver.solve`` makes one ``UpdateContext`` per call and hands it down the stages
(``pipeline.py``); nothing of a solve in progress is kept on the solver.  The context holds

* ``parts``: the solver's per-structure pieces (NLP, derivatives, parameters, outputs, IPOPT
  instances) and its options, fixed for the call;
* ``scene`` and ``start``: the scene and equilibrium an update moves from (the committed ones, or
  a substep's or a round's start while that stage runs);
* ``clamp_turns`` and ``turns``: the clamps' turns since the committed shape up to ``start``'s
  targets and up to this target (``topology.ClampTurns``, the linking-number check);
* ``deadline``: ``time.perf_counter()`` at which a streamed update stops starting IPOPT calls
  (None for a cold solve or a query: ``time_limit.py``); ``streamed``: whether this is a
  streamed update, time limit or not (the slot rounds it may spend, ``slot_rounds.py``);
* ``contact`` and ``slot_override``: the self-contact pairs and obstacle slots a round fixes in
  the parameter vector (``attempts.pack``);
* ``newton_far``: set by the escalation ladder when its Newton answer went far from ``start``
  (substeps, a saddle left), read by the linking-number check.

A stage that runs a sub-solve from another start or with other slots sets those fields for the
sub-solve only (``UpdateContext.scoped``) and they are restored afterwards, whatever happens.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from ...model.problem import Problem
from ..build.functions import NlpFunctions
from ..build.nlp import StringNLP
from ..build.parameters import ProblemParameters
from ..contact.self_contact import ContactSlots
from ..contact.topology import ClampTurns
from ..options import SolverOptions
from ..results.outputs import ShapeOutputs
from ..results.result import ShapeResult
from ..results.summary import ModelSummary
from ..state import SolverState
from .ipopt import IpoptSolvers

#: what a stage gives: the result, and the state to commit (None when there is none)
Outcome = tuple[ShapeResult, SolverState | None]


@dataclass(frozen=True)
class SolverParts:
    """The solver's pieces a stage uses, fixed during one call (``ShapeSolver`` owns them).

    ``summary`` returns the result's model (``ShapeSolver.model_summary``); ``fused_newton``:
    the first Newton steps in one call of the compiled loop (``newton.newton``'s ``fused``).
    """

    nlp: StringNLP
    functions: NlpFunctions
    parameters: ProblemParameters
    outputs: ShapeOutputs
    ipopt: IpoptSolvers
    options: SolverOptions
    fused_newton: bool
    summary: Callable[[], ModelSummary]


@dataclass
class UpdateContext:
    """What one ``solve`` call carries through its stages (see the module docstring)."""

    parts: SolverParts
    scene: Problem
    start: SolverState | None
    clamp_turns: ClampTurns | None = None
    turns: ClampTurns | None = None
    deadline: float | None = None
    #: a streamed update (``time_limit.is_limited``), whether or not a time limit is set
    streamed: bool = False
    contact: ContactSlots | None = None
    slot_override: list | None = None
    newton_far: bool = False
    #: the first unstable stationary point this solve met and left (``ladder.escape_unstable``)
    unstable_met: ShapeResult | None = None

    def met_unstable(self, result: ShapeResult) -> None:
        """Keep ``result`` as the unstable point met, if it is the first (an escape starts)."""
        if self.unstable_met is None and result.status == "ok" and result.stable is False:
            self.unstable_met = result

    @contextmanager
    def scoped(self, **fields: Any) -> Iterator[UpdateContext]:
        """Set ``fields`` for a sub-solve; the previous values return when it ends or raises."""
        saved = {name: getattr(self, name) for name in fields}
        for name, value in fields.items():
            setattr(self, name, value)
        try:
            yield self
        finally:
            for name, value in saved.items():
                setattr(self, name, value)
