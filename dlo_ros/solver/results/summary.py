"""What a solver models: ``ModelSummary``, the ``model`` of every ShapeResult.

``as_dict()`` is its JSON form (``dlo solve --json``'s ``model`` object, the node's ``model.*``
diagnostics, the recording's ``model/<key>`` series and ``data/result`` JSON; keys in
msg_docs/cli.md):

* every solver: planar, twist, stretch, gravity (which fields and loads the NLP has), order (basis
  order), obstacles (obstacles in the NLP), estimated_error_m [m] (None for a fixed model),
  variables (unknowns), rotation ('planar', 'euler', 'quaternion' or 'tangent'), and for the
  director models elements and breakpoints [m] (the element layout); self_contact_pairs (the
  capacity of the self-contact pair list, solver/contact/self_contact.py; only when self-contact is
  modelled);
* ``solver.model: auto`` adds obstacle_samples, tolerance_m [m], tolerance_met, auto, checked,
  checked_updates_ago (how many streamed updates before this one the shape the estimate describes
  was solved: 0 when it is this very shape; background checks lag), checks ('sync' or
  'background'), reasons (why this model), changes (every change so far, the newest 50),
  changes_at (the stream's update index at which each of them took effect: updates are numbered
  0, 1, ... by every committing solve) and changed (the changes made during the solve that
  returned it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ModelSummary:
    """The model a result was solved (or attempted) with (see the module docstring)."""

    planar: bool
    twist: bool
    stretch: bool
    gravity: bool
    order: int
    obstacles: int
    variables: int
    rotation: str
    estimated_error_m: float | None = None
    elements: int | None = None  # director models
    breakpoints: tuple[float, ...] | None = None  # director models: element ends [m]
    self_contact_pairs: int = 0  # self-contact slots in the NLP (0: not modelled)
    # solver.model 'auto' only
    auto: bool = False
    obstacle_samples: int | None = None
    tolerance_m: float | None = None
    tolerance_met: bool | None = None
    checked: bool | None = None
    checked_updates_ago: int | None = None
    checks: str | None = None
    reasons: tuple[str, ...] = ()
    changes: tuple[str, ...] = ()
    changes_at: tuple[int, ...] = ()
    changed: tuple[str, ...] | None = None

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form: a fixed model's keys, or auto's, in their fixed order.

        The JSON form: a fixed model's keys, or auto's (see the module docstring), in their
        fixed order.
        """
        out: dict[str, Any] = {
            "planar": self.planar,
            "twist": self.twist,
            "stretch": self.stretch,
            "gravity": self.gravity,
            "order": self.order,
            "obstacles": self.obstacles,
        }
        if self.auto:
            out.update(
                obstacle_samples=self.obstacle_samples,
                estimated_error_m=self.estimated_error_m,
                tolerance_m=self.tolerance_m,
                tolerance_met=self.tolerance_met,
                variables=self.variables,
                auto=True,
                checked=self.checked,
                checked_updates_ago=self.checked_updates_ago,
                checks=self.checks,
                reasons=list(self.reasons),
                changes=list(self.changes),
                changes_at=list(self.changes_at),
            )
        else:
            out.update(estimated_error_m=self.estimated_error_m, variables=self.variables)
        out["rotation"] = self.rotation
        if self.elements is not None:
            out["elements"] = self.elements
        if self.breakpoints is not None:
            out["breakpoints"] = list(self.breakpoints)
        if self.self_contact_pairs:
            out["self_contact_pairs"] = self.self_contact_pairs
        if self.changed is not None:
            out["changed"] = list(self.changed)
        return out
