"""The record of the node's stream: the update counter, the recording and the model's changes.

One :class:`StreamLog` per node.  Every streaming solve (ok or failed) is one update: it goes to
the rerun recording with its number, and the model it used goes to the diagnostics; each change of
model is logged (INFO) and recorded as an event, with the scene after it, so that a recording stays
re-solvable (``dlo replay --resolve``) from the next update on.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from ..model.problem import Problem
from ..recording import Recorder
from ..scene import Scene
from ..solver.options import SolverOptions
from ..solver.results.result import ShapeResult
from .engine import Update
from .health import Health, model_text, new_model_changes


class StreamLog:
    """The update counter, the recorded scene and the model bookkeeping of one node.

    ``scene``: the effective scene (parameters applied), which the recording holds.  ``recorder``
    is replaced by the node's own once it is open (the last start-up step).  Called from the
    solver thread (updates, model changes), the target thread and the main executor's (targets,
    rejections read ``update``).
    """

    def __init__(self, scene: Scene, health: Health, logger: Any) -> None:
        self.scene = scene
        self.health = health
        self.logger = logger
        self.recorder = Recorder()  # off (every call a no-op) until the node opens its own
        self.update = 0  # one per streaming solve (ok or failed)
        self._last: Update | None = None
        self._model_changes_seen = 0  # len(ShapeResult.model.changes) of the current solver
        self._tolerance_warned = False

    def new_solver(self) -> None:
        """Start a new history of model changes: the engine built a new solver (solver thread)."""
        self._model_changes_seen = 0

    def record_update(self, u: Update, stamp_ns: int) -> bool:
        """Record one streaming solve and its model; the update counter advances.

        Returns whether the solver changed its model.  The same update twice (on_update raised
        after recording it, and on_failure gets it too) is recorded once.
        """
        if u is self._last:
            return False
        self._last = u
        changes = self.observe_model(u.result, stamp_ns)
        self.recorder.log_update(
            u.result,
            update=self.update,
            problem=u.problem,
            ros_time_ns=stamp_ns,
            warm=u.trigger not in ("initial", "reset", "rebuild"),
        )
        self.update += 1
        return bool(changes)

    def observe_model(self, result: ShapeResult, stamp_ns: int) -> list[str]:
        """Put the model of a streaming solve into the diagnostics; log and record its changes."""
        model = result.model_dict()
        changes: list[str] = []
        if model:
            changes, self._model_changes_seen = new_model_changes(model, self._model_changes_seen)
        now = model_text(model)
        for reason in changes:
            self.logger.info(f"model change (update {self.update}): {reason}")
            self.model_change(f"model change: {reason}", ros_time_ns=stamp_ns)
        if changes:  # the model after all of them
            self.logger.info(f"model now (update {self.update}): {now}")
            self.model_change(f"model now: {now}", ros_time_ns=stamp_ns)
        self.health.set_model(model, changes, stamp_ns=stamp_ns, update=self.update)
        problem = self.health.tolerance_problem()
        if problem and not self._tolerance_warned:
            self._tolerance_warned = True
            self.logger.warning(problem)
        elif not problem and self._tolerance_warned and self.health.tolerance_checked():
            # only a check's estimate says "met": a model not checked yet (just switched to) is
            # neither
            self._tolerance_warned = False
            self.logger.info(f"model meets its error tolerance again: {now}")
        return changes

    def model_change(
        self,
        text: str,
        *,
        problem: Problem | None = None,
        options: SolverOptions | None = None,
        ros_time_ns: int | None = None,
    ) -> None:
        """Record a model event at the current update (solver thread).

        With ``problem`` or ``options``: the solved problem or options changed, and the new scene
        is recorded with it.  With neither: the solver changed its model itself (solver.model:
        auto; the scene is the same).
        """
        scene = None
        if problem is not None:
            self.scene = scene = replace(self.scene, problem=problem)
        if options is not None:
            self.scene = scene = replace(self.scene, options=options)
        self.recorder.log_model_change(
            text, update=self.update, ros_time_ns=ros_time_ns, scene=scene
        )
