"""Which solve ``solver.update_time_limit`` bounds, and what a solve it stopped says (#37).

Contract: the limit bounds a *streamed* update only: a warm solve that commits its answer (the
stream's next shape).  It never bounds

* a cold solve (no committed shape, after ``reset``, or a new scene structure),
* a query (``commit=False``; the node's ``query_timeout`` bounds the caller's wait instead), nor
* the re-solves and checks ``solver.model: auto`` runs inside a cold solve or a query
  (``AutoShapeSolver`` passes ``limited=False`` down to them),

so that the limit can never change a cold solve's or a query's answer: with any limit they answer
what they answer with the limit off.  A streamed update past the limit starts no IPOPT attempt and
answers ``failed`` (:func:`limit_message`); its background checks are limited as it is, and a check
that cannot finish leaves the estimate unknown until the next update retries it.

One strike (:class:`LimitStrikes`, per solver): the limited solve after one the limit stopped is
not limited, so the work the limit cut short is done then.  Otherwise a stream whose next shape
needs more than the limit (the first update on a finer mesh, on a machine starved of CPU) starts
that work afresh and fails at every update: the main job starved of CPU failed eight updates in a
row and held its last target 40 s without a checked shape.
"""

from __future__ import annotations

import time


def is_limited(warm: bool, commit: bool, limited: bool | None) -> bool:
    """Whether a solve is bounded by ``solver.update_time_limit``.

    ``warm``: it starts from a committed shape (a cold solve never is limited); ``limited``: the
    caller's word (auto's re-solves), None for the default: limited exactly when it commits (a
    streamed update), never a query.
    """
    return warm and (commit if limited is None else limited)


def update_deadline(t0: float, limit: float, limited: bool) -> float | None:
    """Return the ``time.perf_counter()`` a limited solve started at ``t0`` stops at (or None).

    ``limit`` [s]: ``solver.update_time_limit`` (0: no limit).
    """
    return t0 + limit if limited and limit > 0 else None


def limit_message(limit: float, message: str) -> str:
    """Return the message of a streamed update that failed once its limit [s] had passed."""
    return (
        f"no answer within solver.update_time_limit ({limit:g} s): the update stopped; {message}"
    )


class LimitStrikes:
    """One strike of ``solver.update_time_limit``: after a stop the next limited solve is not.

    Per solver (a stream's, or a check's pooled model), so that each one's own cut-short work is
    done by its own next solve.
    """

    def __init__(self) -> None:
        self.struck = False

    def deadline(self, t0: float, limit: float, limited: bool) -> float | None:
        """Return the deadline of a solve started at ``t0`` (``update_deadline``), or None.

        None also for the first limited solve after a stop (which clears the strike).
        """
        if limited and self.struck:
            self.struck = False
            return None
        return update_deadline(t0, limit, limited)

    def stopped(self, deadline: float | None, status: str) -> bool:
        """Tell whether a solve with ``deadline`` that answered ``status`` was stopped by it.

        Record the strike when it was.
        """
        if deadline is None or status != "failed" or time.perf_counter() < deadline:
            return False
        self.struck = True
        return True
