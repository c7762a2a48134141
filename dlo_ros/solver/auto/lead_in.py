"""A mesh switch's lead-in: the new mesh follows the stream's targets before it takes over.

A stream's check of update k that names another element mesh takes effect just before update
a = k + CHECK_LAG + BUILD_LAG (:mod:`.check_schedule`).  Mapped at a from the streaming mesh's
last shape, the new mesh's first update started from rows on other nodes than the mapped
multipliers held, and Newton walked the contact's active set one row at a time: 10–34 steps
and an IPOPT fallback now and then (the switches were most of the #37 table stream's updates over
20 ms).  Instead the new mesh leads in:

* once built (on the worker, or inline with checks 'sync'), it is solved at update k's poses from
  the check's snapshot mapped onto it (``checks.ModelChecks.evaluate`` built it warm from there);
* streamed updates j = k + STRIDE, k + 2·STRIDE, … and the last FOLLOW before the switch
  (a − FOLLOW … a − 1) then queue a solve of it at j's poses (the worker runs its jobs in order;
  'sync' solves it inline after j is committed), each a warm update on its own mesh from the one
  before.  Not every update: the worker is still checking and building during the first ten or so,
  and following each of them made the switch wait for the queue; nor only the last few: one jump
  over the whole lag took the solve 0.1–0.25 s (the contact slid far);
* at a the switch takes the new mesh's own equilibrium of update a − 1's targets: its first update
  is an ordinary warm update.

The lead-in's solves depend on the targets only (not on when the worker runs them), so both
check modes stream the same shapes.  A lead-in solve that is not ``ok`` ends it: the switch then
maps the streaming shape as before.  Only a change of mesh leads in (the physics and the poses the
model is solved at are the same on both meshes).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..shape_solver import ShapeSolver
from .checks import CheckVerdict

if TYPE_CHECKING:
    from .pool import ModelPool

#: the new mesh is solved at every STRIDE-th update after the checked one (a step of that many
#: updates' motion: the contact slides on), and at each of the FOLLOW updates before the switch
STRIDE, FOLLOW = 4, 3


def mesh_only(before, after) -> bool:
    """Tell whether two ``ModelChoice`` differ in their element mesh alone (the key's last)."""
    return after.mesh != before.mesh and after.key()[:-1] == before.key()[:-1]


@dataclass
class LeadIn:
    """The lead-in of one held check's switch (module docstring).

    ``first``: the checked update (the first it solves at); ``last``: the last update it follows
    (a − 1); ``generation``: the stream's switch count when its check started (a later one ends
    it: the verdict is stale).  ``solver``: the new mesh (None until a verdict names one, and once
    a solve was not ``ok``: ``failed`` says why); ``through``: the last update solved on it.
    """

    first: int
    last: int
    generation: int
    solver: ShapeSolver | None = None
    through: int = -1
    failed: str = ""
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def begin(self, pool: ModelPool, verdict: CheckVerdict) -> None:
        """Start on the model ``verdict`` names, solved at its snapshot's poses (a mesh change).

        Called where the check ran, right after the build of that model.
        """
        snap = verdict.snapshot
        solver = pool.pooled(verdict.choice) if verdict.choice is not None else None
        if solver is None or not mesh_only(snap.choice, verdict.choice):
            return
        if not solver.has_warm_start:  # (the build maps the snapshot: nothing to start from)
            return
        with self._lock:
            self.solver = solver
            self._solve(self.first, snap.poses)

    def follows(self, update: int) -> bool:
        """Tell whether the lead-in solves at streamed update ``update`` (module docstring)."""
        return self.first <= update <= self.last and (
            (update - self.first) % STRIDE == 0 or update > self.last - FOLLOW
        )

    def step(self, update: int, poses: dict, generation: int) -> None:
        """Solve the new mesh at streamed update ``update``'s (inner) ``poses`` if it follows it.

        A no-op for the other updates and before :meth:`begin` named a mesh.  One it follows out
        of order (one before it never came), or after the stream's ``generation`` moved on, ends
        the lead-in.
        """
        with self._lock:
            if self.solver is None or not self.follows(update):
                return
            expected = next(u for u in range(self.through + 1, self.last + 1) if self.follows(u))
            if generation != self.generation or update != expected:
                self.solver, self.failed = None, f"update {update}: out of order or stale"
                return
            self._solve(update, poses)

    def _solve(self, update: int, poses: dict) -> None:
        """Solve the new mesh at ``poses`` (lock held); a result not ``ok`` ends the lead-in."""
        solver = self.solver
        assert solver is not None
        try:
            result = solver.solve(poses, checked=True, limited=True)
        except Exception as exc:  # noqa: BLE001 - the switch maps instead, as without it
            self.solver, self.failed = None, f"update {update}: {type(exc).__name__}: {exc}"
            return
        if result.status != "ok":
            self.solver, self.failed = None, f"update {update}: {result.status}"
            return
        self.through = update

    def ready(self, update: int) -> ShapeSolver | None:
        """Return the new mesh when it holds update ``update − 1``'s equilibrium, else None."""
        with self._lock:
            return self.solver if self.solver is not None and self.through == update - 1 else None
