"""When a streamed update's check takes effect: CHECK_LAG updates later, in both modes (#37).

The rule.  Streamed updates are numbered 0, 1, 2, ... (every ``solve(commit=True)``: the stream's
update index).  When update k's committed shape is due for a check (its model is unchecked, or
``recheck_every`` updates have passed), the check of that shape is started at k and its verdict
(keep the model, or switch to a richer one) is applied just before update k + CHECK_LAG is
solved; no other check starts meanwhile.

* ``checks='background'``: the check runs on the worker thread beside updates k+1 ... k+LAG−1;
  if it has not finished when update k + CHECK_LAG starts, that update waits for it.  The wait is
  bounded as the check is: each of its re-solves stops at ``solver.update_time_limit``
  (``update/time_limit.py``).  An answer never depends on whether the check had finished.
* ``checks='sync'``: the check runs inline at k and its verdict is held until k + CHECK_LAG.

So both modes, on a fast or a loaded machine, switch models at the same updates and solve the
same shapes.  A verdict about a model the stream has left meanwhile (an escalation inside an
update, a reset, a scene change) is dropped in both.  Solves that are not streamed updates (a
cold solve, ``check_now``) are checked before they return, in both modes (``AutoShapeSolver``).
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from .checks import CheckSnapshot, CheckVerdict
from .choice import ORDERS, full_choice

if TYPE_CHECKING:  # the solver calls these functions (auto_solver.py imports this module)
    from .auto_solver import AutoShapeSolver

#: A check started at update k takes effect just before update k + CHECK_LAG.  Large enough that a
#: background check (one or two shadow solves and a 3D eigenvalue: about the cost of 1–3 updates)
#: usually finishes beside the stream without holding it up; small enough that an escalation
#: follows within a few updates, and below the default ``recheck_every`` (10), so that the checks
#: still run every ``recheck_every`` updates.
CHECK_LAG = 4


@dataclass
class PendingCheck:
    """A started check whose verdict is held until update ``apply_at``.

    ``job``: the background check's future; ``verdict`` / ``error``: an inline check's outcome.
    """

    apply_at: int
    job: Future | None = None
    verdict: CheckVerdict | None = None
    error: Exception | None = None

    def outcome(self) -> CheckVerdict | None:
        """Return the verdict, waiting for a background check; raise what the check raised."""
        if self.job is not None:
            return self.job.result()
        if self.error is not None:
            raise self.error
        return self.verdict


def start_check(auto: AutoShapeSolver, snap: CheckSnapshot) -> PendingCheck:
    """Start the check of ``snap`` (update ``snap.update``): on the worker, or run it now.

    Its verdict is held until update ``snap.update + CHECK_LAG`` (module docstring).
    """
    apply_at = snap.update + CHECK_LAG
    if auto.worker.background:
        i = ORDERS.index(snap.choice.order)
        keys = {("",) + replace(snap.choice, order=o).key() for o in ORDERS[max(i - 1, 0) : i + 2]}
        if not snap.choice.plane_kept:  # the 3D checker of a planar shape (shadows.py)
            keys.add(("checker",) + full_choice(snap.choice, snap.problem).key())
        job = auto.worker.submit(auto.model_checks.evaluate, keys, snap, True)
        return PendingCheck(apply_at, job=job)
    try:
        return PendingCheck(apply_at, verdict=auto.model_checks.evaluate(snap, False))
    except Exception as exc:  # noqa: BLE001 - reported when applied, as a background one is
        return PendingCheck(apply_at, error=exc)
