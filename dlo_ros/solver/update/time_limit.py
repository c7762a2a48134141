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
"""

from __future__ import annotations


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
