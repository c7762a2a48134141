"""The result of one solve: what the node, the CLI, rerun and the benchmarks consume."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any, Callable, Generic, TypeVar, overload

import numpy as np

from .summary import ModelSummary

T = TypeVar("T")
V = TypeVar("V", covariant=True)  # a Later of a float is a Later of an optional float

#: 'unverified': the solver converged but the shape fails the equilibrium check
#: (equilibrium_residual_m over the tolerance) or passes through itself (passes_through_itself);
#: it carries the shape for inspection, never a stability verdict
STATUSES = ("ok", "unverified", "unreachable", "infeasible", "failed", "invalid")


def _the(value: T) -> T:
    """Return ``value`` (what a pickled ``Later`` is unpickled as)."""
    return value


class Later(Generic[V]):
    """A value worked out on first read: ``compute()`` once, then remembered.

    What a ``Deferred`` result field holds until a caller reads it (``stability.DeferredEigen``,
    the obstacles' loads of ``outputs.ShapeOutputs``).  Pickled as its value: a result sent to
    another process carries the value, not what it is worked out from.
    """

    def __init__(self, compute: Callable[[], V]) -> None:
        self._compute: Callable[[], V] | None = compute
        self._value: V

    def value(self) -> V:
        """Return the value, worked out on the first call (its inputs then dropped)."""
        if self._compute is not None:
            self._value, self._compute = self._compute(), None
        return self._value

    def __reduce__(self) -> tuple[Callable[[V], V], tuple[V]]:
        return _the, (self.value(),)


class Deferred(Generic[T]):
    """A result field given as its value or as a ``Later`` of it, read into the value once.

    A solve hands over how to work out what most callers of one update do not read
    (``ShapeResult.min_eigenvalue`` where the inertia showed the shape stable, ``contact_loads``),
    so that only a caller who reads it pays; every read sees the value.  A dataclass field with
    this descriptor as its default keeps the constructor, ``replace``, ``to_dict``, equality and
    pickling as with a plain field (the class's default is None; ``empty``: what a None given
    stands for, as a field's default factory).
    """

    def __init__(self, empty: Callable[[], T] | None = None) -> None:
        self._empty = empty

    def __set_name__(self, owner: type, name: str) -> None:
        self._key = f"_{name}_given"

    @overload
    def __get__(self, obj: None, objtype: type | None = None) -> None: ...

    @overload
    def __get__(self, obj: object, objtype: type | None = None) -> T: ...

    def __get__(self, obj: object, objtype: type | None = None) -> T | None:
        if obj is None:  # the class's: the dataclass default
            return None
        given = obj.__dict__.get(self._key)
        if isinstance(given, Later):
            given = obj.__dict__[self._key] = given.value()
        return given

    def __set__(self, obj: object, value: T | Later[T] | None) -> None:
        obj.__dict__[self._key] = self._empty() if value is None and self._empty else value

    def known(self, obj: object) -> T | None:
        """Return ``obj``'s value if it is worked out, else None (a ``Later`` is not run)."""
        given = obj.__dict__.get(self._key)
        return None if isinstance(given, Later) else given


def known(obj: object, name: str) -> Any:
    """Return ``obj``'s :class:`Deferred` field ``name`` if it is worked out, else None.

    None also while it is still a ``Later`` (nothing is computed): for a caller that reports the
    value where the solve had it anyway, and must not pay for it where it did not (the recorder).
    """
    field_ = inspect.getattr_static(type(obj), name)
    assert isinstance(field_, Deferred), f"{name}: not a Deferred field"
    return field_.known(obj)


@dataclass
class GripWrench:
    """Reaction at a grip: the force [N] and torque [N·m] the gripper exerts on the string.

    Reaction at a grip: the force [N] and torque [N·m] the gripper exerts ON the string, world
    frame.

    The torque is about the grip point.  The gripper feels the opposite (−force, −torque).
    """

    force: np.ndarray
    torque: np.ndarray


@dataclass
class SelfContact:
    """A pair of points of the string pressed against each other (solver/contact/self_contact.py).

    s_a < s_b [m] and their centreline points [m]; force [N] acts on the string at s_a, −force at
    s_b (along x(s_a) − x(s_b)); gap [m] is their centreline distance.
    """

    s_a: float
    s_b: float
    point_a: np.ndarray
    point_b: np.ndarray
    force: np.ndarray
    gap: float


@dataclass
class ContactLoad:
    """What one obstacle exerts on the string over one stretch of contact (``contacts.py``).

    kind 'line': consecutive obstacle rows all in contact (a strip lying on a floor): a
    distributed load, ``line_load`` (K, 3) [N/m] at the rows' arc lengths ``s`` (K,) [m] and
    centreline ``points`` (K, 3) [m], each row's multiplier force over its quadrature weight; an
    end row also carries the point force at a lift-off point, lumped on its weight.  kind 'point':
    an isolated contact (one row or a contact slot): ``line_load`` is empty.  ``force`` [N]: the
    stretch's resultant (for 'point' the force itself); the forces of all stretches of obstacle
    ``obstacle`` sum to ``contact_forces[obstacle]``.
    """

    obstacle: int
    kind: str
    s: np.ndarray
    points: np.ndarray
    force: np.ndarray
    line_load: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def s_start(self) -> float:
        """The first arc length [m] of the stretch."""
        return float(self.s[0])

    @property
    def s_end(self) -> float:
        """The last arc length [m] of the stretch."""
        return float(self.s[-1])


@dataclass
class ShapeResult:
    """One equilibrium (or the reason there is none).

    points (N, 3) [m] and orientations (N, 4) (x, y, z, w; pose x-axis along the tangent) at arc
    lengths s (N,).  energy [J]: bend, twist, stretch, gravity, external_work and total = U − W;
    external_work and total are None when a dead point moment has no potential (its axis not
    normal to the string's plane, ``results/moment_work.py``), and energy_note then says why.
    min_eigenvalue: smallest eigenvalue of the Hessian of the Lagrangian reduced to the null space
    of the active constraints, in units of Rf_max/L per (coefficient)² — negative means unstable;
    where the inertia showed the shape stable, worked out when first read (``Deferred``).
    constraint_violation [m or rad]: the largest residual of an equality or violated inequality.
    equilibrium_residual_m [m]: the strong-form force and moment balance of the returned shape, as
    an equivalent centreline error (solver/results/residual.py); NaN when there is no shape.
    self_contacts: the pairs of points pressed together (empty when self-contact is not modelled or
    nothing touches); min_self_distance [m]: the closest approach of two strands at the
    self-contact samples (inf when no two strands are within the candidate reach, NaN when
    self-contact is not modelled and the string has no radius; JSON null for both).
    passes_through_itself: a model without self-contact answered a shape whose strands come closer
    than 2·radius (solver/results/self_pass.py); such a result is 'unverified', never 'ok'.
    contact_loads: the obstacles' contact forces as the physics has them: distributed line loads
    over stretches of contact and point forces (``ContactLoad``); ``contact_forces`` keeps each
    obstacle's total; a solve's are worked out when first read (``Deferred``).
    unstable_met: the first unstable stationary point (status ok, stable False)
    this solve met and left along its negative-curvature mode before reaching this answer, None
    when it met none (its shape, energy and negative eigenvalue: the saddle next to this state).
    """

    status: str
    message: str
    s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    orientations: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    energy: dict[str, float | None] = field(default_factory=dict)
    #: why energy's external_work and total are None ("" when they are numbers)
    energy_note: str = ""
    grips: dict[str, GripWrench] = field(default_factory=dict)
    contact_forces: dict[int, np.ndarray] = field(default_factory=dict)
    stable: bool | None = None
    min_eigenvalue: Deferred[float | None] = Deferred()
    iterations: int = 0
    solve_time_ms: float = 0.0
    constraint_violation: float = float("nan")
    warm_started: bool = False
    #: 'compiled' (the KKT functions as compiled C, warm updates one compiled Newton call) or
    #'interpreted'
    derivatives: str = ""
    continuation_steps: int = 0
    basis: str = ""
    order: int = 0
    ipopt_status: str = ""
    model: ModelSummary | None = None  # the model solved (or attempted) with
    equilibrium_residual_m: float = float("nan")
    self_contacts: list[SelfContact] = field(default_factory=list)
    min_self_distance: float = float("nan")
    passes_through_itself: bool = False
    contact_loads: Deferred[list[ContactLoad]] = Deferred(list)
    unstable_met: ShapeResult | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def model_dict(self) -> dict:
        """Return the model's JSON form (``ModelSummary.as_dict``; {} when there is none)."""
        return self.model.as_dict() if self.model is not None else {}

    def contacts_dict(self) -> dict:
        """Return the JSON form of ``self_contacts`` and ``contact_loads`` (``to_dict``'s keys)."""
        return {
            "self_contacts": [
                {
                    "s_a": c.s_a,
                    "s_b": c.s_b,
                    "point_a": _arr(c.point_a),
                    "point_b": _arr(c.point_b),
                    "force": _arr(c.force),
                    "gap": c.gap,
                }
                for c in self.self_contacts
            ],
            "contact_loads": [
                {
                    "obstacle": c.obstacle,
                    "kind": c.kind,
                    "s": _arr(c.s),
                    "points": _arr(c.points),
                    "force": _arr(c.force),
                    "line_load": _arr(c.line_load),
                }
                for c in self.contact_loads
            ],
        }

    def to_dict(self) -> dict:
        """JSON-ready dictionary (the schema of ``dlo solve --json``, documented in msg_docs/)."""
        arr = _arr
        return {
            "status": self.status,
            "message": self.message,
            "stable": self.stable,
            "min_eigenvalue": self.min_eigenvalue,
            "s": arr(self.s),
            "points": arr(self.points),
            "orientations": arr(self.orientations),
            "energy": {k: None if v is None else float(v) for k, v in self.energy.items()},
            "energy_note": self.energy_note,
            "grips": {
                name: {"force": arr(w.force), "torque": arr(w.torque)}
                for name, w in self.grips.items()
            },
            "contact_forces": {str(i): arr(f) for i, f in self.contact_forces.items()},
            **self.contacts_dict(),
            "min_self_distance": self.min_self_distance
            if np.isfinite(self.min_self_distance)
            else None,
            "passes_through_itself": self.passes_through_itself,
            "unstable_met": None
            if self.unstable_met is None
            else {
                "min_eigenvalue": self.unstable_met.min_eigenvalue,
                "energy_total": self.unstable_met.energy.get("total"),
                "points": arr(self.unstable_met.points),
            },
            "model": self.model_dict(),
            "solver": {
                "iterations": self.iterations,
                "time_ms": self.solve_time_ms,
                "basis": self.basis,
                "order": self.order,
                "constraint_violation": self.constraint_violation,
                "equilibrium_residual_m": self.equilibrium_residual_m,
                "warm_started": self.warm_started,
                "derivatives": self.derivatives,
                "continuation_steps": self.continuation_steps,
                "ipopt_status": self.ipopt_status,
            },
        }


def _arr(a: np.ndarray) -> list:
    """Return ``a`` as nested lists of floats rounded to 1e-12 (the JSON form)."""
    return np.asarray(a, dtype=float).round(12).tolist()
