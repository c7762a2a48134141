"""The physical problem: a string, where it is held, what acts on it, what it must avoid.

Every quantity is SI: lengths in m, stiffnesses Rf, Rt in N·m², Re in N, weight per length D in
N/m, forces in N, moments in N·m.  Orientations are quaternions (x, y, z, w) of a pose whose x-axis
is the string's tangent, pointing toward increasing s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .obstacles import Obstacle
from .profile import Profile

# PoseError is re-exported: callers validating a pose catch it from here
from .rotations import PoseError as PoseError
from .rotations import check_position, check_quaternion

GRIP_MODES = ("clamp", "pin", "tangent")


def finite_vector(value: object, n: int, where: str) -> np.ndarray:
    """``value`` as a float array of n finite numbers, or ValueError naming ``where``."""
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected {n} numbers, got {value!r}") from None
    if arr.size != n:
        raise ValueError(f"{where}: expected {n} numbers, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: contains NaN or infinity")
    return arr


@dataclass(frozen=True)
class StringProperties:
    """Length L and the stiffness / weight profiles of the paper's energy (sec. 2.2).

    stretch_stiffness None means inextensible (‖dx/ds‖ = 1 exactly); radius is the clearance kept
    from obstacles.  lateral_bend_stiffness [N·m²] makes the string a strip with two bending
    stiffnesses (None: an isotropic rod, Rf about every axis): the material frame is (t, d1, d2),
    held at a clamp as the grip orientation's (x, y, z) axes; the strip's width runs along d1
    (the grip's y-axis) and its face normal along d2 (the grip's z-axis).  bend_stiffness Rf is
    then the stiffness about d1 (the strip bends out of its face, the soft way) and
    lateral_bend_stiffness the stiffness about d2 (bending within the strip's own plane, the
    centreline curving along the width): U_bend = ∫ ½ (Rf κ_1² + R_lateral κ_2²) ds.  A strip
    needs a twist stiffness > 0 (with none it would roll freely onto its soft axis) and the
    director frame model.
    """

    length: float
    bend_stiffness: Profile
    twist_stiffness: Profile
    weight_per_length: Profile
    stretch_stiffness: Profile | None = None
    radius: float = 0.0
    lateral_bend_stiffness: Profile | None = None

    def lateral_stiffness(self, s: np.ndarray) -> np.ndarray:
        """Return the stiffness about d2 at s [N·m²]: lateral_bend_stiffness, or Rf (a rod)."""
        prof = self.lateral_bend_stiffness
        return self.bend_stiffness(s) if prof is None else prof(s)

    def validate(self) -> None:
        if not (np.isfinite(self.length) and self.length > 0):
            raise ValueError(f"string.length: must be > 0, got {self.length}")
        if self.bend_stiffness.minimum <= 0:
            raise ValueError("string.bend_stiffness: must be > 0 everywhere")
        if self.twist_stiffness.minimum < 0:
            raise ValueError("string.twist_stiffness: must be >= 0 everywhere")
        if self.weight_per_length.minimum < 0:
            raise ValueError("string.weight_per_length: must be >= 0 everywhere")
        if self.stretch_stiffness is not None and self.stretch_stiffness.minimum <= 0:
            raise ValueError(
                "string.stretch_stiffness: must be > 0 everywhere (omit it for inextensible)"
            )
        if not (np.isfinite(self.radius) and self.radius >= 0):
            raise ValueError(f"string.radius: must be >= 0, got {self.radius}")
        self._validate_lateral()
        for name in (
            "bend_stiffness",
            "twist_stiffness",
            "weight_per_length",
            "stretch_stiffness",
        ):
            prof = getattr(self, name)
            if prof is not None and not all(np.isfinite(prof.values)):
                raise ValueError(f"string.{name}: contains NaN or infinity")

    def _validate_lateral(self) -> None:
        """Check lateral_bend_stiffness: finite, > 0, and a twist stiffness > 0 beside it."""
        prof = self.lateral_bend_stiffness
        if prof is None:
            return
        if not all(np.isfinite(prof.values)):
            raise ValueError("string.lateral_bend_stiffness: contains NaN or infinity")
        if prof.minimum <= 0:
            raise ValueError(
                "string.lateral_bend_stiffness: must be > 0 everywhere (omit it for a rod)"
            )
        if self.twist_stiffness.minimum <= 0:
            raise ValueError(
                "string.lateral_bend_stiffness: needs twist_stiffness > 0 everywhere (with no "
                "twist stiffness a strip rolls freely onto its soft axis: omit it then)"
            )


def _copied(value, **changes):
    """Return a copy of a frozen dataclass with ``changes``, without calling ``__init__``.

    A copy of the frozen dataclass ``value`` with ``changes``, without ``dataclasses.replace``'s
    call of ``__init__`` (for values that are valid already; a warm update makes several per
    target).
    """
    new = object.__new__(type(value))
    new.__dict__.update(value.__dict__)
    new.__dict__.update(changes)
    return new


@dataclass(frozen=True)
class GripPose:
    """Where a grip holds the string: position [m] and orientation.

    Where a grip holds the string: position [m] and orientation (x, y, z, w), x along the
    tangent.
    """

    position: np.ndarray
    orientation: np.ndarray

    @staticmethod
    def checked(
        position: object, orientation: object, where: str, quat_tolerance: float = 1e-3
    ) -> "GripPose":
        """Return this pose validated: the one check of a grip pose.

        The one validation of a grip pose (scene files, targets, queries, observations): the
        quaternion normalised, or PoseError (a ValueError with a ``kind``) naming
        ``where``.position/.orientation.
        """
        return GripPose(
            check_position(position, f"{where}.position"),
            check_quaternion(orientation, f"{where}.orientation", quat_tolerance),
        )


@dataclass(frozen=True)
class Grip:
    """A gripper holding the string at arc length s.

    mode: 'clamp' fixes position and full orientation; 'pin' position only; 'tangent' position and
    tangent direction, twist free about it.
    """

    name: str
    s: float
    mode: str
    pose: GripPose


@dataclass(frozen=True)
class Load:
    """A point force [N] and/or moment [N·m] applied at arc length s (world frame, constant)."""

    s: float
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    moment: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class RelativePosition:
    """Paper eq. 6: x(s_b) − x(s_a) = offset [m]."""

    s_a: float
    s_b: float
    offset: np.ndarray


@dataclass(frozen=True)
class Problem:
    """Everything the energy and constraints need.  gravity is the unit direction of weight."""

    string: StringProperties
    grips: tuple[Grip, ...]
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -1.0]))
    loads: tuple[Load, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    relative_positions: tuple[RelativePosition, ...] = ()

    def validate(self) -> None:
        """Raise ValueError naming the offending field."""
        self.string.validate()
        L = self.string.length
        g = np.asarray(self.gravity, dtype=float)
        if g.size != 3 or not np.all(np.isfinite(g)) or np.linalg.norm(g) < 1e-12:
            raise ValueError("gravity.direction: must be a non-zero finite 3-vector")
        if not self.grips:
            raise ValueError("grips: at least one grip is needed to hold the string")
        names = set()
        for i, grip in enumerate(self.grips):
            where = f"grips[{i}]"
            if not grip.name or grip.name in names:
                raise ValueError(f"{where}.name: must be a unique, non-empty name")
            names.add(grip.name)
            if grip.mode not in GRIP_MODES:
                raise ValueError(f"{where}.mode: must be one of {GRIP_MODES}, got {grip.mode!r}")
            if not (0.0 <= grip.s <= L):
                raise ValueError(f"{where}.s: must lie in [0, string.length = {L}], got {grip.s}")
        if len({g.s for g in self.grips}) != len(self.grips):
            raise ValueError("grips: two grips hold the same arc length s")
        for i, load in enumerate(self.loads):
            if not (0.0 <= load.s <= L):
                raise ValueError(f"loads[{i}].s: must lie in [0, {L}], got {load.s}")
            finite_vector(load.force, 3, f"loads[{i}].force")
            finite_vector(load.moment, 3, f"loads[{i}].moment")
        for i, rel in enumerate(self.relative_positions):
            for name in ("s_a", "s_b"):
                if not (0.0 <= getattr(rel, name) <= L):
                    raise ValueError(f"relative_positions[{i}].{name}: must lie in [0, {L}]")
            finite_vector(rel.offset, 3, f"relative_positions[{i}].offset")

    @property
    def gravity_unit(self) -> np.ndarray:
        g = np.asarray(self.gravity, dtype=float)
        return g / np.linalg.norm(g)

    def farthest_apart(self, reach: float = 1.0) -> tuple[Grip, Grip, float, float] | None:
        """Return the first pair of grips farther apart than the string between them allows.

        The first pair of grips farther apart than ``reach`` times the string between them, as
        (a, b, distance [m], reach × span [m]); None when every pair is within reach.
        """
        for i, a in enumerate(self.grips):
            for b in self.grips[i + 1 :]:
                d = a.pose.position - b.pose.position
                # np.linalg.norm's own sqrt(d·d) of a vector, without its dispatch
                dist, span = math.sqrt(float(d.dot(d))), abs(a.s - b.s) * reach
                if dist > span + 1e-12:
                    return a, b, dist, span
        return None

    def grip(self, name: str) -> Grip:
        for g in self.grips:
            if g.name == name:
                return g
        raise KeyError(f"no grip named {name!r}; grips are {[g.name for g in self.grips]}")

    def relative_ends(self) -> list[float]:
        """Return s_a, s_b [m] of every relative position, in order.

        s_a, s_b [m] of every relative position, in order: where their reactions act as point
        forces.
        """
        return [s for rel in self.relative_positions for s in (rel.s_a, rel.s_b)]

    def with_grip_poses(self, poses: dict[str, GripPose]) -> "Problem":
        """Return this problem with the grips named in ``poses`` at those poses.

        This problem with the grips named in ``poses`` at those poses (checked ones:
        ``GripPose.checked``).
        """
        return _copied(
            self,
            grips=tuple(
                _copied(g, pose=poses[g.name]) if g.name in poses else g for g in self.grips
            ),
        )
