"""auto's a-posteriori decision rule: keep the model of a committed shape, or which model next.

:func:`decide` is the whole rule, in the order it is applied: first the physics (planar stability
in 3D, stretch, the Euler-angle pole), then the refinement (the element mesh, or the order ladder
of a basis the scene names), then the obstacle samples of a model whose obstacle rows are not on
its mesh nodes.  The first rule that fires decides; the error estimate is measured regardless.

The measurements are not taken here: :class:`Evidence` hands them over when the rule asks for one
(:class:`.checks.ShapeEvidence` takes them on a snapshot of the solve: :mod:`.shadows`,
:mod:`.mesh_check`), so a measurement that the rule does not reach is never paid for.  This module
only decides.  The triggers decided inside an update (targets leaving the plane, obstacles
coming within reach, grips pulled taut: :mod:`.follow`; self-contact, a refused or unstable
answer: :mod:`.escalate`) and the whole policy are on one page of ``msg_docs/model_and_solver.md``
("auto's policy").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from ...model.problem import Problem
from .choice import MAX_SAMPLES, ORDERS, POLE_MIN_DEG, ModelChoice, full_choice
from .mesh_check import MeshVerdict

NAN = float("nan")
#: the pole turns only to a direction at least this much farther from every tangent [degrees]
POLE_GAIN_DEG = 10.0


class Evidence(Protocol):
    """The measurements of one committed shape, each taken when :func:`decide` asks for it.

    ``problem``: the scene of the shape; ``touching``: it presses on an obstacle;
    ``residual_m``: its strong-form equilibrium residual [m] (inf when unknown); ``on_elements``:
    its model is on an element mesh (and the state is known); ``node_rows``: its obstacle rows sit
    on the mesh nodes (the mesh estimate counts the cut between them).
    """

    problem: Problem
    touching: bool
    residual_m: float
    on_elements: bool
    node_rows: bool

    def planar_instability(self) -> float | None:
        """Return the 3D model's negative eigenvalue at the planar shape (None: stable)."""
        ...

    def elongation_bound(self) -> float | None:
        """Return max|F_grip|·L / min Re [m] (None: the string has no stretch stiffness)."""
        ...

    def pole_angle(self) -> float | None:
        """Return the Euler-angle pole's angle to the nearest tangent [°] (None: no pole)."""
        ...

    def farthest_pole(self) -> tuple[np.ndarray, float]:
        """Return the direction farthest from every tangent, and its angle to them [°]."""
        ...

    def turned(self, normal: np.ndarray) -> ModelChoice:
        """Return the model with its pole turned to ``normal``, built and warm-started."""
        ...

    def mesh(self, coarsen: bool) -> MeshVerdict:
        """Return the mesh check's estimate and the mesh it proposes (``mesh_check.py``)."""
        ...

    def order_change(self, order: int) -> float:
        """Return the centreline change [m] to basis ``order`` (nan: that solve failed)."""
        ...

    def lower_order_change(self, order: int) -> float | None:
        """Return the change to the lower ``order``; None when not to be tried (once per model)."""
        ...

    def penetration(self) -> tuple[float, str]:
        """Return the deepest cut into an obstacle between the samples [m], and its name."""
        ...

    def samples_change(self, finer: ModelChoice) -> float:
        """Return the centreline change [m] to ``finer``'s obstacle samples (nan: failed)."""
        ...


@dataclass(frozen=True)
class Decision:
    """What :func:`decide` concluded: the model to switch to (None: keep), why, the estimates.

    ``estimate`` [m]: the error estimate of the checked model (its discretisation part
    ``order_error`` plus the sampling part; ``sampling_error``: the samples shadow's, nan when not
    measured); ``build``: ``choice`` was not built by the measurement that named it, so build and
    warm-start it before the stream may switch to it.
    """

    choice: ModelChoice | None = None
    reason: str = ""
    estimate: float = NAN
    order_error: float = NAN
    sampling_error: float = NAN
    build: bool = False


def decide(ev: Evidence, choice: ModelChoice, tolerance: float, coarsen: bool) -> Decision:
    """Return the decision on a committed shape of ``choice``, against δ = ``tolerance`` [m].

    ``coarsen``: the mesh may coarsen (a streamed update's check; a cold answer's never does).
    The physics decided before a shape exists, or inside its update, is not here: targets leaving
    the plane, obstacles within reach and grips pulled taut (:mod:`.follow`); self-contact when
    the shape reaches or passes through itself, the next order for a refused or unstable answer
    (:mod:`.escalate`).
    """
    tol, why, build = tolerance, "", False
    to: ModelChoice | None = None
    # -- the physics --------------------------------------------------------------------------
    # a planar shape unstable in 3D leaves its plane (a twist-free strip under compression),
    # unless the scene holds it there (solver.plane: keep)
    if choice.may_leave_plane and (eig := ev.planar_instability()) is not None:
        to = replace(full_choice(choice, ev.problem), estimated_error_m=NAN, order_error_m=NAN)
        why = f"planar shape unstable in 3D (eigenvalue {eig:.3g}): full model"
    # the string stretches by more than δ/2 under its grip forces
    elongation = None if to is not None or choice.stretch else ev.elongation_bound()
    if elongation is not None and elongation > tol / 2:
        to, why = _escalated(choice, stretch=True), _stretch_reason(elongation, tol)
    # a tangent within POLE_MIN_DEG of the Euler-angle pole (the director model has none), and a
    # direction POLE_GAIN_DEG farther from every tangent: the frame turned there
    angle = ev.pole_angle() if to is None and not choice.planar else None
    if angle is not None and angle < POLE_MIN_DEG:
        normal, best = ev.farthest_pole()
        if best >= angle + POLE_GAIN_DEG:
            to, why = ev.turned(normal), _pole_reason(angle, normal, best)
    # -- the refinement -----------------------------------------------------------------------
    order_error = choice.order_error_m
    if to is None and ev.on_elements:
        # the element mesh: its own estimate; refined over δ/2, in a stream coarsened under δ/50
        # (mesh_check.mesh_verdict applies both bounds to the mesh adapt/rule.py proposes)
        mesh = ev.mesh(coarsen=coarsen)
        order_error, to, why = mesh.estimate, mesh.choice, mesh.reason
        build = to is not None
    elif to is None:
        # the order ladder (a basis the scene names): the next order's change, or the residual
        i = ORDERS.index(choice.order)
        if i + 1 < len(ORDERS):
            change, res = ev.order_change(ORDERS[i + 1]), ev.residual_m
            order_error = change if np.isfinite(change) else order_error
            error = max(change, res) if np.isfinite(change) else res
            if np.isfinite(res):
                order_error = max(order_error, res) if np.isfinite(order_error) else res
            if error > tol / 2 and np.isfinite(error):
                to = _escalated(choice, order=ORDERS[i + 1], estimated_error_m=error)
                why = _order_reason(choice.order, error, tol / 2, ">", ORDERS[i + 1])
        # once per model the next lower order, taken within δ/4 (hysteresis)
        down = ORDERS[i - 1] if to is None and i > 0 else None
        lowered = ev.lower_order_change(down) if down is not None else None
        if down is not None and lowered is not None and lowered <= tol / 4:
            to = _escalated(choice, order=down, estimated_error_m=lowered)
            why = _order_reason(down, lowered, tol / 4, "≤", down)
    if ev.node_rows:  # the mesh estimate counted the cut between the rows on the nodes
        return Decision(to, why, order_error, order_error, build=build)
    # -- the obstacle samples: the cut between them, and while touching the finer samples' change
    depth, name = ev.penetration()
    finer = replace(
        choice,
        samples=min(2 * choice.samples - 1, MAX_SAMPLES),
        estimated_error_m=NAN,
        order_error_m=order_error,
        reasons=list(choice.reasons),
    )
    at_most = choice.samples >= MAX_SAMPLES
    change = ev.samples_change(finer) if ev.touching and not at_most else NAN
    # first order in the spacing: twice the change; at MAX_SAMPLES the last measured one stays
    sampling_error = (choice.sampling_error_m if ev.touching else NAN) if at_most else 2 * change
    sampling = max(depth, np.nan_to_num(sampling_error, nan=0.0))
    estimate = order_error + sampling if np.isfinite(order_error) else choice.estimated_error_m
    if to is None and sampling > tol / 2 and not at_most:
        why = _samples_reason(choice, finer, (depth, name), change, sampling, tol)
        to = replace(finer, sampling_error_m=change)
        return Decision(to, why, estimate, order_error, sampling_error, not np.isfinite(change))
    return Decision(to, why, estimate, order_error, sampling_error, build=build)


def _escalated(choice: ModelChoice, **changes) -> ModelChoice:
    """Return ``choice`` changed as given, its estimates unknown and its reasons copied.

    An ``estimated_error_m`` given is the estimate of the order left, kept as the order part too.
    """
    error = changes.get("estimated_error_m", NAN)
    return replace(
        choice,
        **{
            "estimated_error_m": NAN,
            "order_error_m": error,
            "reasons": list(choice.reasons),
            **changes,
        },
    )


def _stretch_reason(elongation: float, tol: float) -> str:
    """Say why the extensible model: the elongation bound over δ/2."""
    return f"elongation bound {elongation:.3g} m > {tol / 2:.3g} m: extensible model"


def _pole_reason(angle: float, normal: np.ndarray, best: float) -> str:
    """Say why the reference frame turns: the pole near a tangent, a direction far from all."""
    return (
        f"Euler-angle pole {angle:.0f}° from the tangent: reference frame turned "
        f"(pole {np.round(normal, 3).tolist()}, {best:.0f}° from every tangent)"
    )


def _order_reason(order: int, error: float, bound: float, sign: str, to: int) -> str:
    """Say why the basis order changes: ``order``'s estimate against ``bound``."""
    return f"order {order} error estimate {error:.3g} m {sign} {bound:.3g} m: order {to}"


def _samples_reason(
    choice: ModelChoice,
    finer: ModelChoice,
    cut: tuple[float, str],
    change: float,
    sampling: float,
    tol: float,
) -> str:
    """Say why more obstacle samples: the cut between them, or the finer samples' change."""
    depth, name = cut
    if depth >= sampling:
        return (
            f"the string cuts into obstacle {name!r} by {depth:.3g} m > {tol / 2:.3g} m "
            f"between its {choice.samples} samples: {finer.samples} samples"
        )
    return (
        f"the shape moves by {change:.3g} m when the obstacle samples go from "
        f"{choice.samples} to {finer.samples} (sampling error about {sampling:.3g} m > "
        f"{tol / 2:.3g} m): {finer.samples} samples"
    )
