"""What the node reports in /diagnostics, and which warnings it logs (pure, thread-safe, no ROS).

The level follows the latest event of the streaming state:
* 'error' while no solver could be built;
* 'warn' while starting (no shape yet), when the newest input was rejected or its solve failed (the
  last
  good shape stays published), when the published equilibrium is unstable, or when the solver's
  model misses its error tolerance (``solver.model: auto``: estimated_error_m > tolerance_m, or
  "tolerance not met" in its reasons);
* 'ok' otherwise.
Counters and the last error (with its kind, see validation.KINDS) stay in the values, and so do the
current model (``ShapeResult.model.as_dict()`` of the newest solve, keys ``model.*``) and its last
change. The model arrives here in that JSON form (solver/results/summary.py), as in the recording.
"""

from __future__ import annotations

import collections
import threading
import time
from typing import Callable, Mapping, Sequence

from ..solver.results.result import ShapeResult
from .validation import KINDS


def resident_mb() -> float | None:
    """Return this process's resident set size [MiB] (VmRSS; None where there is no /proc)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return round(int(line.split()[1]) / 1024, 1)
    except OSError:
        pass
    return None


RATE_WINDOW_S = 2.0
#: ShapeResult.model.as_dict() entries shown in the diagnostics as ``model.<key>`` (in this order).
MODEL_KEYS = (
    "auto",
    "planar",
    "twist",
    "stretch",
    "gravity",
    "order",
    "obstacles",
    "obstacle_samples",
    "variables",
    "estimated_error_m",
    "tolerance_m",
    "tolerance_met",
    "checked",
    "checked_updates_ago",
    "rotation",
)


def model_text(model: Mapping | None) -> str:
    """Describe a ShapeResult.model.as_dict() in one line ('' for an empty model).

    E.g. 'auto: planar, twist, gravity, order 12, 15 unknowns, 1 obstacle(s), estimated error
    4.3e-05 m (tolerance 0.001 m)'.
    """
    if not model:
        return ""
    parts = ["planar" if model.get("planar") else "3D"]
    parts += [name for name in ("twist", "stretch", "gravity") if model.get(name)]
    if model.get("order") is not None:
        parts.append(f"order {model['order']}")
    if model.get("variables") is not None:
        parts.append(f"{model['variables']} unknowns")
    if model.get("obstacles") is not None:
        parts.append(f"{model['obstacles']} obstacle(s)")
    est, tol = model.get("estimated_error_m"), model.get("tolerance_m")
    if isinstance(est, (int, float)):
        parts.append(
            f"estimated error {est:.2g} m"
            + (f" (tolerance {tol:.2g} m)" if isinstance(tol, (int, float)) else "")
        )
    elif isinstance(tol, (int, float)):
        parts.append(f"error not estimated yet (tolerance {tol:.2g} m)")
    return ("auto: " if model.get("auto") else "") + ", ".join(parts)


def new_model_changes(model: Mapping, seen: int) -> tuple[list[str], int]:
    """Return the model changes to report for one solve, and the new ``seen``.

    ``model``: its ShapeResult.model.as_dict(); ``seen``: how many entries of ``model['changes']``
    (the solver's whole history of changes) were already reported (0 after a new solver was built).
    The changes are ``model['changed']`` (made during the solve), after any change the solver made
    between solves (e.g. in set_problem after a parameter change), which only shows as a new entry
    of ``changes``.
    """
    changed = [str(r) for r in model.get("changed") or ()]
    history = model.get("changes")
    if not isinstance(history, (list, tuple)):
        return changed, seen
    if len(history) < seen:  # not the solver seen before
        seen = 0
    during = collections.Counter(changed)
    between = []
    for reason in history[seen:]:  # the history's new entries that 'changed' does not report
        if during[str(reason)] > 0:
            during[str(reason)] -= 1
        else:
            between.append(str(reason))
    return between + changed, len(history)


class Health:
    def __init__(
        self,
        *,
        scene: str = "",
        frame_id: str = "",
        grips: tuple[str, ...] = (),
        throttle_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._lock = threading.Lock()
        self._clock = clock
        self.throttle_s = throttle_s
        self.scene, self.frame_id, self.grips = scene, frame_id, tuple(grips)
        self.state = "starting"
        self.lifecycle = ""  # a managed node's lifecycle state; '' for the plain node
        self.last: ShapeResult | None = None  # last published (converged) streaming solve
        self.last_trigger = ""
        self.last_latency_ms: float | None = None  # target arrival -> solve finished
        self.last_status = ""  # status of the newest streaming event
        self.last_message = ""
        self.newest_is_error = False
        self.updates = self.stable_updates = self.unstable_updates = self.unverified_updates = 0
        self.failures = self.rejected = 0
        self.errors = {k: 0 for k in KINDS}
        self.last_error = self.last_error_kind = ""
        self.last_error_time: float | None = None
        self.queries = self.queries_failed = 0
        self.last_query_error = ""
        self.targets_received = self.targets_coalesced = 0
        self._update_times: collections.deque[float] = collections.deque()
        self._warned: dict[str, float] = {}
        self.model: dict = {}  # ShapeResult.model of the newest streaming solve
        self.model_changes = 0  # model changes seen since start
        self.last_model_change = ""  # the reasons of the newest solve that changed the model
        self.last_model_change_time: float | None = None  # clock() when the node saw it
        self.last_model_change_stamp_ns: int | None = None  # ROS time of the solve that made it
        self.last_model_change_update: int | None = None  # that solve's update number (recording)

    # ---- events ---------------------------------------------------------------------------------
    def set_state(self, state: str) -> None:
        with self._lock:
            self.state = state

    def set_lifecycle(self, state: str) -> None:
        """Set a managed node's lifecycle state ('inactive', 'active', ...).

        Activating clears a newest error that was a refusal for being inactive: it said nothing
        about the shape.
        """
        with self._lock:
            self.lifecycle = state
            if state == "active" and self.last_error_kind == "inactive":
                self.newest_is_error = False

    def update(self, result: ShapeResult, trigger: str, latency_ms: float | None = None) -> None:
        """Count a converged streaming solve that was published."""
        now = self._clock()
        with self._lock:
            self.last, self.last_trigger, self.last_latency_ms = result, trigger, latency_ms
            self.last_status, self.last_message = result.status, result.message
            self.newest_is_error = False
            self.updates += 1
            if result.stable is False:
                self.unstable_updates += 1
            elif result.stable:
                self.stable_updates += 1
            if result.status == "unverified":
                self.unverified_updates += 1
            self._update_times.append(now)
            while self._update_times and now - self._update_times[0] > RATE_WINDOW_S:
                self._update_times.popleft()

    def set_model(
        self,
        model: Mapping | None,
        changes: Sequence[str] = (),
        *,
        stamp_ns: int | None = None,
        update: int | None = None,
    ) -> None:
        """Keep the model of the newest streaming solve (ok or failed) and the changes it made.

        ``model``: its ``ShapeResult.model.as_dict()``; ``changes``: reasons, oldest first; stamped
        with the solve's ROS time and update number.
        """
        now = self._clock()
        with self._lock:
            if model:
                self.model = dict(model)
            if changes:
                self.model_changes += len(changes)
                self.last_model_change = "; ".join(
                    str(c) for c in changes
                )  # one solve may make several
                self.last_model_change_time = now
                self.last_model_change_stamp_ns = stamp_ns
                self.last_model_change_update = update

    def tolerance_problem(self) -> str:
        """'' when the model meets its error tolerance (or says nothing about it); else why not."""
        with self._lock:
            return self._tolerance_problem()

    def tolerance_checked(self) -> bool:
        """Tell whether a check has measured the model's error (met or not, it is known).

        False between a change of model and its first check (``model.checked`` false, no
        estimate): then neither "met" nor "not met" may be said of it.
        """
        with self._lock:
            m = self.model
            if self._tolerance_problem():
                return True
            return m.get("tolerance_met") is True and m.get("checked") is not False

    def _tolerance_problem(self) -> str:  # lock held
        m = self.model
        est, tol = m.get("estimated_error_m"), m.get("tolerance_m")
        over = isinstance(est, (int, float)) and isinstance(tol, (int, float)) and est > tol
        if not (over or m.get("tolerance_met") is False):
            return ""
        size = [f"order {m['order']}"] if m.get("order") is not None else []
        size += [f"{m['variables']} unknowns"] if m.get("variables") is not None else []
        text = "model: tolerance not met" + (f" ({', '.join(size)})" if size else "")
        if isinstance(est, (int, float)) and isinstance(tol, (int, float)):
            text += f"; estimated error {est:.3g} m vs tolerance {tol:.3g} m"
        return text

    def error(self, kind: str, message: str, *, rejected: bool) -> bool:
        """Count a rejected input (rejected=True) or a failed solve; return whether to warn now.

        At most one warning per kind every ``throttle_s``.
        """
        now = self._clock()
        kind = kind if kind in self.errors else "internal"
        with self._lock:
            self.errors[kind] += 1
            if rejected:
                self.rejected += 1
            else:
                self.failures += 1
            self.last_error, self.last_error_kind, self.last_error_time = message, kind, now
            self.last_status = "rejected" if rejected else kind
            self.last_message = message
            self.newest_is_error = True
            last = self._warned.get(kind)
            if last is None or now - last >= self.throttle_s:
                self._warned[kind] = now
                return True
            return False

    def should_warn(self, key: str) -> bool:
        """Return whether to log a warning that is not an error now (e.g. 'unstable').

        True at most every ``throttle_s`` per key.
        """
        now = self._clock()
        with self._lock:
            last = self._warned.get(key)
            if last is None or now - last >= self.throttle_s:
                self._warned[key] = now
                return True
            return False

    def query(self, ok: bool, message: str = "") -> None:
        with self._lock:
            self.queries += 1
            if not ok:
                self.queries_failed += 1
                self.last_query_error = message

    def set_targets(self, received: int, coalesced: int) -> None:
        with self._lock:
            self.targets_received, self.targets_coalesced = received, coalesced

    # ---- report ---------------------------------------------------------------------------------
    def update_rate(self) -> float:
        now = self._clock()
        with self._lock:
            times = [t for t in self._update_times if now - t <= RATE_WINDOW_S]
        return len(times) / RATE_WINDOW_S

    def level_and_message(self) -> tuple[str, str]:
        with self._lock:
            r = self.last
            idle = self.lifecycle not in ("", "active")
            if idle and not self.state.startswith("failed"):
                return "ok", f"lifecycle state '{self.lifecycle}': targets refused"
            if self.state.startswith("failed"):
                return "error", f"no solver: {self.state}"
            if r is None:
                if self.newest_is_error:
                    return "warn", f"no shape yet; {self.last_status}: {self.last_message}"
                return "warn", f"no shape yet ({self.state})"
            if self.newest_is_error:
                what = (
                    "input rejected"
                    if self.last_status == "rejected"
                    else f"solve failed ({self.last_status})"
                )
                return "warn", f"{what}, the last good shape stays published: {self.last_message}"
            if r.status == "unverified":
                tolerance = self._tolerance_problem()
                return "warn", (
                    f"{tolerance}; " if tolerance else ""
                ) + f"published shape is not a verified equilibrium: {r.message}"
            if r.stable is False:
                return (
                    "warn",
                    f"published equilibrium is unstable (min eigenvalue {r.min_eigenvalue:.3g})",
                )
            tolerance = self._tolerance_problem()
            if tolerance:
                return "warn", tolerance
            return "ok", f"shape up to date ({r.solve_time_ms:.1f} ms, {r.iterations} iterations)"

    def values(self) -> dict[str, object]:
        rate = self.update_rate()
        now = self._clock()
        with self._lock:
            r = self.last
            out: dict[str, object] = {
                "state": self.state,
                "lifecycle": self.lifecycle,
                "rss MB": resident_mb(),
                "scene": self.scene,
                "frame_id": self.frame_id,
                "grips": ",".join(self.grips),
                "status": self.last_status,
                "message": self.last_message,
                "stable": None if r is None else r.stable,
                "min eigenvalue": None if r is None else r.min_eigenvalue,
                "equilibrium residual m": None if r is None else r.equilibrium_residual_m,
                "unverified updates": self.unverified_updates,
                "solve time ms": None if r is None else r.solve_time_ms,
                "iterations": None if r is None else r.iterations,
                "warm started": None if r is None else r.warm_started,
                "derivatives": None if r is None else r.derivatives,
                "continuation steps": None if r is None else r.continuation_steps,
                # None (empty) where a dead moment has no potential; the note says why
                "energy total J": None if r is None else r.energy.get("total"),
                "energy note": "" if r is None else r.energy_note,
                "trigger": self.last_trigger,
                "latency ms": self.last_latency_ms,
                "update rate hz": rate,
                "updates": self.updates,
                "stable updates": self.stable_updates,
                "unstable updates": self.unstable_updates,
                "failures": self.failures,
                "rejected inputs": self.rejected,
                "targets received": self.targets_received,
                "targets coalesced": self.targets_coalesced,
                "last error": self.last_error,
                "last error kind": self.last_error_kind,
                "last error age s": None
                if self.last_error_time is None
                else now - self.last_error_time,
                "queries": self.queries,
                "queries failed": self.queries_failed,
                "last query error": self.last_query_error,
            }
            for kind, n in self.errors.items():
                out[f"errors.{kind}"] = n
            m = self.model
            for key in MODEL_KEYS:
                out[f"model.{key}"] = m.get(key)
            if m:
                out["model.auto"] = bool(m.get("auto"))  # a fixed model (ShapeSolver) does not say
            out["model.reasons"] = "; ".join(str(r) for r in m.get("reasons") or ())
            out["model.changes"] = self.model_changes
            out["model.last change"] = self.last_model_change
            out["model.last change time"] = (
                None
                if self.last_model_change_stamp_ns is None
                else f"{self.last_model_change_stamp_ns / 1e9:.3f}"
            )
            out["model.last change update"] = self.last_model_change_update
            out["model.last change age s"] = (
                None if self.last_model_change_time is None else now - self.last_model_change_time
            )
        return out
