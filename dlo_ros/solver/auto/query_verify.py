"""What a refined query (``solve(..., commit=False)`` of ``solver.model: auto``) may claim.

A query answer whose equilibrium residual is over the tolerance ('unverified') is refined by
AutoShapeSolver as a cold solve's answer is: its a-posteriori checks run on the query's own shape
(planar stability in 3D, the basis order's shadow, the obstacle samples' shadow) and escalate to a
richer model until they pass.  It is not bounded by ``solver.update_time_limit`` (that bounds a
streamed update only, ``update/time_limit.py``): a limit cannot change a query's answer; the
node's ``query_timeout`` bounds how long its caller waits.  This module holds the decision after
that loop:

* :func:`verified_answer` — the final status: 'ok' only when the checks finished, the residual and
  the checks' error estimate are both within the tolerance; otherwise 'unverified' (the shape kept,
  no stability verdict), with the reason in the message.
"""

from __future__ import annotations

import math

from ..results.result import ShapeResult


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
