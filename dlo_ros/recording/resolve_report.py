"""What ``dlo replay --resolve`` found: each update compared by status, then by shape.

An update is compared by STATUS first: a re-solve whose status differs from the recorded one is a
*status change* (e.g. ``unverified -> ok``), reported with both statuses and no deviation; equal
statuses agree, except ``ok`` against ``ok``, the only pair compared by shape: the largest
centreline distance [m], over the tolerance a *shape deviation* (also when the sampling changed,
which cannot be compared point by point: its deviation is None).  No deviation is ever inf or NaN.

The model history (``ShapeResult.model``: basis order, unknowns, planar) is compared too: the
updates at which the recorded stream changed model (``model/<key>`` series) and those at which the
re-solve did, and the first update at which the two models differ.  It is reported only; it does
not change :attr:`ResolveReport.ok`.

The recording's slowest solves (``timeseries/solve_time_ms``: where a stream stalled, as the
recording machine timed them) are named too, reported only.

``ok`` (exit 0 of ``dlo replay --resolve``) means no status change and no shape deviation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .reading import RecordedResult

#: Verdicts of one update.
AGREE, DEVIATES, STATUS_CHANGED = "agree", "deviates", "status_changed"
#: The ``ShapeResult.model`` entries that identify a model (its estimated error is not one).
MODEL_KEYS = ("order", "variables", "planar")
#: At most this many update numbers per list in the text summary (the JSON has them all).
SHOWN = 20
#: The recording's slowest solves named in the report.
SLOWEST = 5

ModelKey = tuple[float, ...]


@dataclass(frozen=True)
class UpdateComparison:
    """One re-solved update against its recording."""

    update: int
    recorded_status: str
    status: str
    verdict: str  # AGREE, DEVIATES or STATUS_CHANGED
    max_deviation_m: float | None  # ok vs ok only; None otherwise or when the sampling changed
    note: str = ""


@dataclass(frozen=True)
class ModelChange:
    """An update at which a stream's model differs from its previous update's."""

    update: int
    before: str
    after: str


@dataclass(frozen=True)
class ModelHistory:
    """Where the recorded stream and the re-solve changed model, and where they first differ."""

    recorded: list[ModelChange] = field(default_factory=list)
    resolved: list[ModelChange] = field(default_factory=list)
    first_difference: int | None = None  # first update whose two models differ


@dataclass(frozen=True)
class Switches:
    """The model changes each stream made (``ShapeResult.model.changed``), by update.

    ``recorded`` / ``resolved``: (update, reason) in order; ``first_difference``: the first
    update at which the two made different changes (the reasons' timing notes left out).
    """

    recorded: list[tuple[int, str]] = field(default_factory=list)
    resolved: list[tuple[int, str]] = field(default_factory=list)
    first_difference: int | None = None


def switches(recorded: list[tuple[int, str]], resolved: list[tuple[int, str]]) -> Switches:
    """Compare two streams' model changes, (update, reason) each."""

    def by_update(changes: list[tuple[int, str]]) -> dict[int, list[str]]:
        out: dict[int, list[str]] = {}
        for update, reason in changes:
            out.setdefault(update, []).append(reason.split(" [waited ")[0])
        return out

    a, b = by_update(recorded), by_update(resolved)
    first = next((u for u in sorted(set(a) | set(b)) if a.get(u) != b.get(u)), None)
    return Switches(list(recorded), list(resolved), first)


def changed_of(model: Any) -> list[str]:
    """Return the changes of model one solve made (its ``model['changed']``; [] if none)."""
    changed = model.get("changed") if isinstance(model, dict) else None
    return [str(c) for c in changed] if isinstance(changed, (list, tuple)) else []


@dataclass(frozen=True)
class ResolveReport:
    """The result of ``dlo replay --resolve``; :meth:`as_dict` is its ``--json`` form."""

    file: str
    scene: str
    solver: str
    tolerance_m: float
    updates: list[UpdateComparison]
    models: ModelHistory
    switches: Switches = field(default_factory=Switches)
    #: (update, recorded solve time [ms]) of the SLOWEST slowest solves, slowest first
    slowest: list[tuple[int, float]] = field(default_factory=list)

    def of(self, verdict: str) -> list[int]:
        """Return the updates with this verdict, in order."""
        return [u.update for u in self.updates if u.verdict == verdict]

    @property
    def ok(self) -> bool:
        """No status change and no shape deviation over the tolerance."""
        return all(u.verdict == AGREE for u in self.updates)

    def worst(self) -> UpdateComparison | None:
        """Return the ok-vs-ok update with the largest deviation (None: there is none)."""
        measured = [u for u in self.updates if u.max_deviation_m is not None]
        return max(measured, key=lambda u: u.max_deviation_m or 0.0) if measured else None

    def as_dict(self) -> dict[str, Any]:
        """Return the ``--json`` report (every value finite or null)."""
        worst = self.worst()
        measured = [u.max_deviation_m for u in self.updates if u.max_deviation_m is not None]
        return {
            "file": self.file,
            "scene": self.scene,
            "solver": self.solver,
            "tolerance_m": self.tolerance_m,
            "updates": [vars(u).copy() for u in self.updates],
            "count": len(self.updates),
            "agreements": self.of(AGREE),
            "exceeding": self.of(DEVIATES),
            "status_changes": [
                {"update": u.update, "recorded": u.recorded_status, "now": u.status}
                for u in self.updates
                if u.verdict == STATUS_CHANGED
            ],
            "max_deviation_m": None if worst is None else worst.max_deviation_m,
            "worst_update": None if worst is None else worst.update,
            "mean_deviation_m": float(np.mean(measured)) if measured else None,
            "model_changes": {
                "recorded": [vars(c).copy() for c in self.models.recorded],
                "resolved": [vars(c).copy() for c in self.models.resolved],
                "first_difference": self.models.first_difference,
            },
            "switches": {
                "recorded": [list(c) for c in self.switches.recorded],
                "resolved": [list(c) for c in self.switches.resolved],
                "first_difference": self.switches.first_difference,
            },
            "slowest_recorded_solves": [
                {"update": u, "solve_time_ms": ms} for u, ms in self.slowest
            ],
            "ok": self.ok,
        }


def slowest(solve_times: list[tuple[int, float]]) -> list[tuple[int, float]]:
    """Return the SLOWEST (update, ms) of the recorded solve times, slowest first.

    Finite times only; an update recorded twice counts once, at its longest.
    """
    longest: dict[int, float] = {}
    for update, ms in solve_times:
        if np.isfinite(ms):
            longest[update] = max(ms, longest.get(update, ms))
    return sorted(longest.items(), key=lambda t: (-t[1], t[0]))[:SLOWEST]


def compare(recorded: RecordedResult, result: Any, tolerance: float) -> UpdateComparison:
    """Compare one re-solve (a ShapeResult) with its recorded result: status, then shape."""
    base = {"update": recorded.update, "recorded_status": recorded.status, "status": result.status}
    if recorded.status != result.status:
        return UpdateComparison(**base, verdict=STATUS_CHANGED, max_deviation_m=None)
    if recorded.status != "ok":
        return UpdateComparison(**base, verdict=AGREE, max_deviation_m=None)
    now = np.asarray(result.points, dtype=float)
    if now.shape != recorded.points.shape:
        note = f"sampling changed: {len(recorded.points)} -> {len(now)} samples"
        return UpdateComparison(**base, verdict=DEVIATES, max_deviation_m=None, note=note)
    dev = float(np.max(np.linalg.norm(now - recorded.points, axis=1))) if len(now) else 0.0
    verdict = AGREE if dev <= tolerance else DEVIATES
    return UpdateComparison(**base, verdict=verdict, max_deviation_m=dev)


def model_key(model: dict[str, Any]) -> ModelKey | None:
    """Return the model's identity (:data:`MODEL_KEYS`) from its JSON form; None if unknown."""
    values = [model.get(k) for k in MODEL_KEYS]
    if any(not isinstance(v, (bool, int, float)) for v in values):
        return None
    return tuple(float(v) for v in values)  # type: ignore[arg-type]  # checked just above


def recorded_models(series: dict[str, list[tuple[int, float]]]) -> dict[int, ModelKey]:
    """Return update -> model identity from a recording's ``model/<key>`` series."""
    per_key = {k: dict(series.get(k, [])) for k in MODEL_KEYS}
    updates = set.intersection(*(set(v) for v in per_key.values()))
    return {u: tuple(per_key[k][u] for k in MODEL_KEYS) for u in updates}


def describe(key: ModelKey) -> str:
    """Return a model identity as text: ``order 16, 51 unknowns, 3D``."""
    order, variables, planar = key
    return f"order {order:g}, {variables:g} unknowns, {'planar' if planar else '3D'}"


def _changes(models: dict[int, ModelKey]) -> list[ModelChange]:
    changes, last = [], None
    for update in sorted(models):
        if last is not None and models[update] != last:
            changes.append(ModelChange(update, describe(last), describe(models[update])))
        last = models[update]
    return changes


def model_history(recorded: dict[int, ModelKey], resolved: dict[int, ModelKey]) -> ModelHistory:
    """Compare two streams' models (update -> identity; updates without a model left out)."""
    both = sorted(set(recorded) & set(resolved))
    first = next((u for u in both if recorded[u] != resolved[u]), None)
    return ModelHistory(_changes(recorded), _changes(resolved), first)


def _updates(numbers: list[int]) -> str:
    shown = ", ".join(str(n) for n in numbers[:SHOWN])
    return f"[{shown}{', ...' if len(numbers) > SHOWN else ''}]"


def _deviation(u: UpdateComparison) -> str:
    if u.verdict == STATUS_CHANGED:
        return f"status changed: {u.recorded_status} -> {u.status}"
    if u.max_deviation_m is None:
        return u.note or "same status"
    return f"{u.max_deviation_m:.3g}" + ("   > tolerance" if u.verdict == DEVIATES else "")


def _model_lines(models: ModelHistory) -> list[str]:
    if not (models.recorded or models.resolved or models.first_difference is not None):
        return []

    def listed(changes: list[ModelChange]) -> str:
        parts = [f"{c.update} ({c.before} -> {c.after})" for c in changes[:SHOWN]]
        return "; ".join(parts) + ("; ..." if len(changes) > SHOWN else "") or "none"

    first = models.first_difference
    return [
        f"model   changed in the recording at updates: {listed(models.recorded)}",
        f"model   changed in the re-solve at updates:  {listed(models.resolved)}",
        "model   "
        + ("the same at every update" if first is None else f"first differs at update {first}"),
    ]


def format_report(report: ResolveReport) -> str:
    """Return the human-readable report: one line per update, the model history, a summary."""
    lines = [
        f"replay  {report.file}: scene {report.scene}, {len(report.updates)} updates, "
        f"solver {report.solver}",
        f"{'update':>7}  {'recorded':<11} {'now':<11} max deviation [m]",
    ]
    lines += [
        f"{u.update:>7}  {u.recorded_status:<11} {u.status:<11} {_deviation(u)}"
        for u in report.updates
    ]
    lines += _model_lines(report.models)
    sw = report.switches
    if sw.recorded or sw.resolved:
        lines.append(
            f"switch  model changes took effect at updates {[u for u, _ in sw.recorded][:SHOWN]} "
            f"(recorded), {[u for u, _ in sw.resolved][:SHOWN]} (re-solve): "
            + (
                "the same"
                if sw.first_difference is None
                else f"first differs at update {sw.first_difference}"
            )
        )
    if report.slowest:
        lines.append(
            "time    slowest recorded solves: "
            + ", ".join(f"update {u} {ms:.1f} ms" for u, ms in report.slowest)
        )
    agree, deviates, changed = (report.of(v) for v in (AGREE, DEVIATES, STATUS_CHANGED))
    worst = report.worst()
    measured = (
        "no ok-vs-ok update"
        if worst is None or worst.max_deviation_m is None
        else f"max deviation {worst.max_deviation_m:.3g} m (update {worst.update})"
    )
    lines.append(
        f"summary {len(report.updates)} updates re-solved, {measured}: "
        f"{len(agree)} agree; shape deviations: {len(deviates)} above the tolerance "
        f"{report.tolerance_m:.3g} m {_updates(deviates)}; status changes: {len(changed)} "
        f"{_updates(changed)} -> {'OK' if report.ok else 'DIFFERS'}"
    )
    return "\n".join(lines)
