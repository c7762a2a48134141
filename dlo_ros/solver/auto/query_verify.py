"""What a refined query (``solve(..., commit=False)`` of ``solver.model: auto``) may claim.

A query answer whose equilibrium residual is over the tolerance ('unverified') is refined by
AutoShapeSolver as a cold solve's answer is: its a-posteriori checks run on the query's own shape
(planar stability in 3D, the basis order's shadow, the obstacle samples' shadow) and escalate to a
richer model until they pass.  This module holds the two decisions around that loop:

* :class:`QueryBudget` — the refinement stops when ``solver.update_time_limit`` [s] has passed
  since
  the query started (0: no limit).  The limit bounds how long a caller waits; it never turns an
  answer into a verdict: a refinement cut short leaves the answer 'unverified', and its message
  says why.
* :func:`verified_answer` — the final status: 'ok' only when the checks finished, the residual and
  the checks' error estimate are both within the tolerance; otherwise 'unverified' (the shape kept,
  no stability verdict), with the reason in the message.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from ..results.result import ShapeResult


@dataclass
class QueryBudget:
    """The time budget of a query's refinement.

    The time a query's refinement may take: ``limit`` [s] from ``start``
    (``time.perf_counter``).
    """

    limit: float
    start: float = field(default_factory=time.perf_counter)

    def expired(self) -> bool:
        """Whether no further refinement step may start (never, when ``limit`` is 0)."""
        return self.limit > 0 and time.perf_counter() - self.start >= self.limit

    def reason(self) -> str:
        return (
            f"solver.update_time_limit ({self.limit:g} s) reached before the answer was verified "
            f"(refinement stopped after {time.perf_counter() - self.start:.2f} s)"
        )


def verified_answer(
    result: ShapeResult, estimate: float | None, tolerance: float, stopped: str = ""
) -> ShapeResult:
    """Give ``result`` (the refined answer, changed in place and returned) its final status.

    estimate [m]: the error estimate of the checks that passed on this very shape (None: they did
    not finish). stopped: why the refinement ended before its checks passed ('' when they passed).
    An answer that is not 'ok' or 'unverified' (failed, infeasible, ...) is returned as it is.
    """
    if result.status not in ("ok", "unverified"):
        return result
    why = stopped
    if not why and (estimate is None or not math.isfinite(estimate)):
        why = "the model checks did not finish"
    elif not why and estimate is not None and estimate > tolerance:
        why = f"the error estimate {estimate:.3g} m is over the tolerance {tolerance:.3g} m"
    if not why:
        return result  # the inner solver's 'ok': the residual is within the tolerance too
    if result.status == "ok":
        result.status, result.stable, result.min_eigenvalue = "unverified", None, None
        result.message = f"not a verified equilibrium: {why}; {result.message}"
    else:
        result.message = f"{result.message}; refinement ended: {why}"
    return result
