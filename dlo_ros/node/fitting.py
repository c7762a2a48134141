"""Identification in the node: what is fitted, in which process, and when it is applied.

Serves ``~/observed`` and ``~/fit`` (pure: no ROS; msg_docs/node.md "Fitting").

* :class:`CloudSnapshot` is one observation as the node took it: the checked points of a cloud and
  the
  grip poses the node held when the cloud arrived.
* :func:`fit_payload` / :func:`run_fit`: the fit of one snapshot, pickled into and run in a worker
  process (its own equilibrium solvers: a CasADi/IPOPT solver object is never shared between
  threads, and an interpreted CasADi call holds the GIL, so a thread would slow the stream).  The
  worker keeps its solvers from one fit to the next: the first fit of a structure pays for building
  them.
* :func:`plan_application`: which ``string.*`` parameters an estimate changes, whether the fit
  passed the goodness-of-fit gate (status ``ok``, not ``misfit``), and whether every value it
  changes is determined with a relative standard deviation within ``fit.apply_max_rel_sigma``.
* :class:`FitHealth`: the counters and the last estimate for the diagnostics status ``<node>:
  fit``.
"""

from __future__ import annotations

import math
import pickle
import threading
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..identify.fit import fit
from ..identify.objective import FitSettings, SolverCache
from ..identify.observations import MassObservation, Observation, ObservationSet
from ..model.problem import GripPose, Problem
from .params import STRING_FIELDS, profile_value

#: fitted material → the node's parameter that holds it
PARAMETER_OF = {
    "Rf": "string.bend_stiffness",
    "Rt": "string.twist_stiffness",
    "D": "string.weight_per_length",
    "Re": "string.stretch_stiffness",
}
#: relative σ of a known total mass (the observation file's default)
MASS_RELATIVE_SIGMA = 1e-3
#: (fit worker process) the equilibrium solvers of earlier fits: building one takes seconds, a fit
#: of a kept one a few solves (dlo_ros.identify.objective.SolverCache; one fit at a time per
#: worker)
_SOLVERS = None


@dataclass(frozen=True)
class FitConfig:
    """The ``fit.*`` parameters one fit uses.

    parameters: among Rf, Rt, D, Re; point_sigma [m]; total_mass [kg] (0: unknown);
    apply_max_rel_sigma: the bound of :func:`plan_application`; compile: the worker's solvers'
    compile mode ('cached' or 'off': a worker never starts gcc).
    """

    parameters: tuple[str, ...] = ("Rf", "D")
    point_sigma: float = 0.002
    total_mass: float = 0.0
    apply_max_rel_sigma: float = 0.1
    max_iterations: int = 30
    compile: str = "off"


@dataclass(frozen=True)
class CloudSnapshot:
    """One observation: the points of a cloud and the grip poses the node held when it arrived.

    ``points`` (N, 3) [m] in the node's frame, the grip ``poses``, the cloud's header stamp [ns]
    and its number (1, 2, ... in arrival order).
    """

    points: np.ndarray
    poses: dict[str, GripPose]
    stamp_ns: int
    number: int


def observation_set(snapshot: CloudSnapshot, config: FitConfig):
    """Build the ``ObservationSet`` of one snapshot (``dlo_ros.identify``)."""
    obs = Observation(
        f"cloud_{snapshot.number}",
        dict(snapshot.poses),
        snapshot.points,
        float(config.point_sigma),
    )
    mass = None
    if config.total_mass > 0:
        mass = MassObservation(
            float(config.total_mass), MASS_RELATIVE_SIGMA * float(config.total_mass)
        )
    return ObservationSet((obs,), tuple(config.parameters), "", mass, source="~/observed")


def fit_payload(problem: Problem, options, snapshot: CloudSnapshot, config: FitConfig) -> bytes:
    """Pickle the request :func:`run_fit` takes.

    ``problem`` (the node's current values; its grip poses are replaced by the snapshot's),
    ``options``, the observation and the settings.
    """
    settings = FitSettings(max_iterations=int(config.max_iterations), compile=config.compile)
    return pickle.dumps(
        (problem, options, observation_set(snapshot, config), settings),
        protocol=pickle.HIGHEST_PROTOCOL,
    )


def run_fit(payload: bytes):
    """Run the fit of a :func:`fit_payload` request (in the worker process); its ``FitResult``.

    Raises ObservationError for a request the scene cannot support (e.g. Re of an inextensible
    string).
    """
    global _SOLVERS
    if _SOLVERS is None:
        _SOLVERS = SolverCache()
    problem, options, data, settings = pickle.loads(payload)  # noqa: S301 - from our own node
    return fit(problem, options, data, settings, _SOLVERS)


# ---- applying an estimate -----------------------------------------------------------------------
@dataclass(frozen=True)
class Application:
    """What a fit changes, and why.

    ``values``: parameter name → new value (empty when nothing is applied); ``reason``: one line,
    what was applied with which σ, or why nothing was.
    """

    values: dict[str, float]
    reason: str

    @property
    def applied(self) -> bool:
        return bool(self.values)


def _relative(est) -> float:
    return est.std / abs(est.value) if est.value else math.inf


def plan_application(result, current: Mapping[str, float], bound: float) -> Application:
    """Plan which parameters ``result`` (a FitResult) changes from ``current`` (name → value).

    They are applied only when the fit converged, passed the goodness-of-fit gate (status 'ok'; a
    'misfit' does not explain the points, ``identify/gate.py``) and every changed value is
    determined with relative σ ≤ ``bound``.

    A changed material is determined either absolutely (``result.parameters``) or as a ratio to one
    that does not change (``result.ratios``, e.g. D/Rf from shapes alone: the fit keeps Rf and
    moves D, which reproduces the fitted shape); the σ of that estimate is the one compared with
    ``bound``.  The new values are the fitted string's, as the node's parameters read a profile
    (its maximum; setting it scales the table).
    """
    if result.status != "ok" or result.string is None:
        return Application({}, f"not applied: the fit is {result.status} ({result.message})")
    new = {
        m: profile_value(getattr(result.string, STRING_FIELDS[PARAMETER_OF[m]]))
        for m in result.names
        if m in PARAMETER_OF
    }
    changed = {
        m: v
        for m, v in new.items()
        if abs(v - current[PARAMETER_OF[m]]) > 1e-9 * max(abs(current[PARAMETER_OF[m]]), 1e-300)
    }
    if not changed:
        return Application({}, "not applied: the estimate equals the current values")
    evidence = []
    for m in changed:
        est = result.parameters.get(m)
        if est is None:
            est = next(
                (
                    r
                    for label, r in result.ratios.items()
                    if m in label.split("/")
                    and all(x == m or x not in changed for x in label.split("/"))
                ),
                None,
            )
        if est is None:
            why = result.not_identifiable.get(m, "no estimate")
            return Application(
                {}, f"not applied: {m} would change but the data do not determine it: {why}"
            )
        evidence.append((m, est, _relative(est)))
    worst = max(evidence, key=lambda e: e[2])
    summary = ", ".join(
        f"{est.name} = {est.value:.6g} ± {est.std:.2g} {est.unit}" for _, est, _ in evidence
    )
    if bound <= 0:
        return Application(
            {}, f"not applied (fit.apply_max_rel_sigma is 0: report only): {summary}"
        )
    if worst[2] > bound:
        return Application(
            {},
            f"not applied: relative σ of {worst[1].name} is {worst[2]:.3g} > "
            f"fit.apply_max_rel_sigma {bound:g} ({summary})",
        )
    values = {PARAMETER_OF[m]: float(v) for m, v in changed.items()}
    changes = ", ".join(f"{name} {current[name]:.6g} -> {v:.6g}" for name, v in values.items())
    return Application(
        values, f"applied: {changes} ({summary}; largest relative σ {worst[2]:.3g} <= {bound:g})"
    )


# ---- diagnostics --------------------------------------------------------------------------------
@dataclass
class FitHealth:
    """What the diagnostics status ``<node>: fit`` reports.

    Thread-safe: the executor thread writes it, the diagnostics timer reads it.
    """

    clouds_received: int = 0
    clouds_rejected: int = 0
    last_cloud_points: int | None = None
    last_cloud_stamp_ns: int | None = None
    last_cloud_error: str = ""
    newest_is_rejection: bool = False
    fits_started: int = 0
    fits_finished: int = 0
    running: bool = False
    last_fit: dict = field(default_factory=dict)
    estimates: dict = field(default_factory=dict)
    applications: int = 0
    last_application: str = ""
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def cloud(self, points: int, stamp_ns: int) -> None:
        with self._lock:
            self.clouds_received += 1
            self.last_cloud_points, self.last_cloud_stamp_ns = points, stamp_ns
            self.newest_is_rejection = False

    def rejected(self, reason: str) -> None:
        with self._lock:
            self.clouds_rejected += 1
            self.last_cloud_error = reason
            self.newest_is_rejection = True

    def started(self) -> None:
        with self._lock:
            self.fits_started += 1
            self.running = True

    def finished(
        self, result, snapshot: CloudSnapshot, application: Application | None, error: str = ""
    ) -> None:
        """Count a finished fit: its FitResult (None when it raised: ``error``), what applied."""
        with self._lock:
            self.fits_finished += 1
            self.running = False
            if result is None:
                self.last_fit = {"status": "failed", "message": error, "cloud": snapshot.number}
                self.estimates = {}
            else:
                self.last_fit = {
                    "status": result.status,
                    "message": result.message,
                    "cloud": snapshot.number,
                    "time s": result.time_s,
                    "solves": result.equilibrium_solves,
                    "iterations": result.iterations,
                    "chi2 reduced": result.chi2_reduced,
                    "not identifiable": ",".join(result.not_identifiable),
                    "rms m": result.observations[0].rms_m if result.observations else None,
                }
                self.estimates = {
                    name: (est.value, est.std, est.unit)
                    for name, est in {**result.parameters, **result.ratios}.items()
                }
            if application is not None:
                self.last_fit["applied"] = application.applied
                self.last_fit["apply reason"] = application.reason
                if application.applied:
                    self.applications += 1
                    self.last_application = application.reason

    def level_and_message(self) -> tuple[str, str]:
        with self._lock:
            if self.newest_is_rejection:
                return "warn", f"observed cloud rejected: {self.last_cloud_error}"
            status = self.last_fit.get("status")
            if self.running:
                return "ok", f"fitting cloud {self.clouds_received}"
            if status is None:
                return "ok", "no fit yet" + (
                    "" if self.clouds_received else " (no cloud received)"
                )
            if status != "ok":
                return "warn", f"last fit {status}: {self.last_fit.get('message', '')}"
            return "ok", self.last_fit.get("apply reason", "fitted")

    def values(self) -> dict[str, object]:
        with self._lock:
            out: dict[str, object] = {
                "clouds received": self.clouds_received,
                "clouds rejected": self.clouds_rejected,
                "last cloud points": self.last_cloud_points,
                "last cloud stamp": None
                if self.last_cloud_stamp_ns is None
                else f"{self.last_cloud_stamp_ns / 1e9:.3f}",
                "last cloud error": self.last_cloud_error,
                "fits started": self.fits_started,
                "fits finished": self.fits_finished,
                "running": self.running,
                "applications": self.applications,
                "last application": self.last_application,
            }
            for key, value in self.last_fit.items():
                out[f"last fit {key}" if key not in ("applied", "apply reason") else key] = value
            for name, (value, std, unit) in self.estimates.items():
                out[f"estimate.{name}"] = value
                out[f"estimate.{name}.sigma"] = std
                out[f"estimate.{name}.unit"] = unit
        return out
