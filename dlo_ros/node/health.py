"""What the node reports in /diagnostics, and which warnings it logs (pure, thread-safe, no ROS).

The level follows the latest event of the streaming state:
* 'error' while no solver could be built;
* 'warn' while starting (no shape yet), when the newest input was rejected or its solve failed (the last
  good shape stays published), or when the published equilibrium is unstable;
* 'ok' otherwise.
Counters and the last error (with its kind, see validation.KINDS) stay in the values.
"""
from __future__ import annotations

import collections
import threading
import time
from typing import Callable

from ..solver.result import ShapeResult
from .validation import KINDS

RATE_WINDOW_S = 2.0


class Health:
    def __init__(self, *, scene: str = "", frame_id: str = "", grips: tuple[str, ...] = (),
                 throttle_s: float = 1.0, clock: Callable[[], float] = time.monotonic):
        self._lock = threading.Lock()
        self._clock = clock
        self.throttle_s = throttle_s
        self.scene, self.frame_id, self.grips = scene, frame_id, tuple(grips)
        self.state = "starting"
        self.last: ShapeResult | None = None      # last published (converged) streaming solve
        self.last_trigger = ""
        self.last_latency_ms: float | None = None  # target arrival -> solve finished
        self.last_status = ""                      # status of the newest streaming event
        self.last_message = ""
        self.newest_is_error = False
        self.updates = self.stable_updates = self.unstable_updates = 0
        self.failures = self.rejected = 0
        self.errors = {k: 0 for k in KINDS}
        self.last_error = self.last_error_kind = ""
        self.last_error_time: float | None = None
        self.queries = self.queries_failed = 0
        self.last_query_error = ""
        self.targets_received = self.targets_coalesced = 0
        self._update_times: collections.deque[float] = collections.deque()
        self._warned: dict[str, float] = {}

    # ---- events -----------------------------------------------------------------------------------------
    def set_state(self, state: str) -> None:
        with self._lock:
            self.state = state

    def update(self, result: ShapeResult, trigger: str, latency_ms: float | None = None) -> None:
        """A converged streaming solve was published."""
        now = self._clock()
        with self._lock:
            self.last, self.last_trigger, self.last_latency_ms = result, trigger, latency_ms
            self.last_status, self.last_message = result.status, result.message
            self.newest_is_error = False
            self.updates += 1
            if result.stable is False:
                self.unstable_updates += 1
            else:
                self.stable_updates += 1
            self._update_times.append(now)
            while self._update_times and now - self._update_times[0] > RATE_WINDOW_S:
                self._update_times.popleft()

    def error(self, kind: str, message: str, *, rejected: bool) -> bool:
        """A rejected input (rejected=True) or a failed solve; returns whether to log a warning now
        (at most one per kind every ``throttle_s``)."""
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
        """Throttle for warnings that are not errors (e.g. 'unstable'): True at most every ``throttle_s``."""
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

    # ---- report ----------------------------------------------------------------------------------------
    def update_rate(self) -> float:
        now = self._clock()
        with self._lock:
            times = [t for t in self._update_times if now - t <= RATE_WINDOW_S]
        return len(times) / RATE_WINDOW_S

    def level_and_message(self) -> tuple[str, str]:
        with self._lock:
            r = self.last
            if self.state.startswith("failed"):
                return "error", f"no solver: {self.state}"
            if r is None:
                if self.newest_is_error:
                    return "warn", f"no shape yet; {self.last_status}: {self.last_message}"
                return "warn", f"no shape yet ({self.state})"
            if self.newest_is_error:
                what = "input rejected" if self.last_status == "rejected" else f"solve failed ({self.last_status})"
                return "warn", f"{what}: {self.last_message}; the last good shape stays published"
            if r.stable is False:
                return "warn", f"published equilibrium is unstable (min eigenvalue {r.min_eigenvalue:.3g})"
            return "ok", f"shape up to date ({r.solve_time_ms:.1f} ms, {r.iterations} iterations)"

    def values(self) -> dict[str, object]:
        rate = self.update_rate()
        now = self._clock()
        with self._lock:
            r = self.last
            out: dict[str, object] = {
                "state": self.state,
                "scene": self.scene,
                "frame_id": self.frame_id,
                "grips": ",".join(self.grips),
                "status": self.last_status,
                "message": self.last_message,
                "stable": None if r is None else r.stable,
                "min eigenvalue": None if r is None else r.min_eigenvalue,
                "solve time ms": None if r is None else r.solve_time_ms,
                "iterations": None if r is None else r.iterations,
                "warm started": None if r is None else r.warm_started,
                "continuation steps": None if r is None else r.continuation_steps,
                "energy total J": None if r is None else r.energy.get("total"),
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
                "last error age s": None if self.last_error_time is None else now - self.last_error_time,
                "queries": self.queries,
                "queries failed": self.queries_failed,
                "last query error": self.last_query_error,
            }
            for kind, n in self.errors.items():
                out[f"errors.{kind}"] = n
        return out
