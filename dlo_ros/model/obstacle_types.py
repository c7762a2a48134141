"""One class per obstacle type: the single home of everything that differs between types.

Each type (``HalfSpace``, ``Sphere``, ``Capsule``, ``Box``) says, for its fixed-size parameter
vector ``p`` (its pose and size, the NLP's layout in ``fields``):

* how a scene mapping becomes ``p`` (``keys``, ``parse``: errors name the key) and back
  (``to_dict``);
* its signed distance h(x, p) [m], positive inside (``h``: CasADi, and numpy through ``lib=NUMPY``
  where the formula allows), at one point (``h_at``) and at many (``h_many``), and a lower bound of
  the distance (``distance_bound``) that the reach test of ``solver.auto`` uses;
* whether it lies clear of a plane (``clear_of_plane``) or fits in it (``planarity_violation``):
  the planar model's two questions;
* whether it is ``flat`` (no curvature: ``solver.obstacle_slots`` gives it slots only at isolated
  touches), and whether a string lying on it touches it at ``points`` (a sphere) rather than
  along a line (a bar, a box's edge): ``solver.slotted_obstacles: points``;
* a ``Primitive``: the shape the node's markers and the rerun recording draw, without knowing the
  type.

``OBSTACLE_TYPES`` maps the scene's ``type`` string to the type's instance; ``register`` adds one.
Adding a type is one class here plus its tests (CONTRIBUTING.md, "A new obstacle type").  The style
is PyElastica's one class per contact pair: no ``if type == ...`` anywhere else.
"""

from __future__ import annotations

import enum
import functools
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from .rotations import check_quaternion, matrix_to_quat, quat_to_matrix, quat_z_to

#: numpy stand-ins for the CasADi functions the h below use (``lib=NUMPY``: plain arrays, no
#: CasADi)
NUMPY = SimpleNamespace(dot=np.dot, norm_2=np.linalg.norm, fmin=min, fmax=max)
#: the same over the rows of an (N, 3) array of points (``HalfSpace.h_many``, ``Sphere.h_many``)
ROWS = SimpleNamespace(
    dot=lambda a, b: np.add.reduce(a * b, axis=-1),
    norm_2=lambda v: np.sqrt(np.add.reduce(v * v, axis=-1)),
)

BOX_EXPONENT = 8

#: colours (RGB, 0–255) the recording gives the primitives: planes dark, solids light
PLANE_COLOUR = (70, 72, 80)
SOLID_COLOUR = (150, 150, 165)


class PrimitiveKind(enum.StrEnum):
    """The shapes a ``Primitive`` can be: each has one drawing in the node and in the recording.

    A StrEnum, so a kind equals its name as a string (``PrimitiveKind.PLANE == "plane"``).
    """

    PLANE = "plane"
    SPHERE = "sphere"
    CAPSULE = "capsule"
    BOX = "box"


#: the kinds of ``Primitive`` that the drawing code must know
PRIMITIVE_KINDS: tuple[PrimitiveKind, ...] = tuple(PrimitiveKind)


@dataclass(frozen=True)
class Key:
    """A scene-file key of an obstacle type: its kind and whether it is required.

    A scene-file key of an obstacle type: its value's ``kind`` ('vector': 3 numbers, 'number',
    'quaternion': x, y, z, w) and whether it is required (else the type's ``parse`` has a
    default).
    """

    kind: str
    required: bool


@dataclass(frozen=True)
class Primitive:
    """What to draw for an obstacle, in world coordinates [m].

    kind: one of ``PRIMITIVE_KINDS``.  centre: a point on a plane, the centre of a sphere or box,
    the midpoint of a capsule's segment.  orientation: quaternion (x, y, z, w) of the shape's
    frame. axis: that frame's z axis (unit): a plane's outward normal, a capsule's direction a → b.
    half_sizes: a box's half extents, (r, r, r) for a sphere, (r, r, length / 2) for a capsule,
    zeros for a plane (which is unbounded: the drawer picks its size).  radius: sphere or capsule
    (0 otherwise).  colour: RGB 0–255 (the recording's; the node's markers share one translucent
    colour).
    """

    kind: PrimitiveKind
    centre: np.ndarray
    orientation: np.ndarray
    axis: np.ndarray
    half_sizes: np.ndarray
    radius: float = 0.0
    colour: tuple[int, int, int] = SOLID_COLOUR

    @property
    def length(self) -> float:
        """A capsule's segment length [m] (0 for the other kinds)."""
        return 2.0 * float(self.half_sizes[2]) if self.kind == PrimitiveKind.CAPSULE else 0.0

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """Return a capsule's segment ends a, b [m]."""
        half = 0.5 * self.length * self.axis
        return self.centre - half, self.centre + half


def vector(value: object, n: int, where: str) -> np.ndarray:
    """``value`` as n finite floats, else ValueError naming ``where``."""
    arr = np.asarray(value, dtype=float).ravel()
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: expected {n} finite numbers, got {value!r}")
    return arr


def positive(value: object, where: str) -> float:
    """``value`` as one finite float > 0, else ValueError naming ``where``."""
    v = float(vector(value, 1, where)[0])
    if v <= 0:
        raise ValueError(f"{where}: must be > 0, got {v}")
    return v


class ObstacleType(ABC):
    """The behaviour of one obstacle type, on its parameter vector ``p``.

    The behaviour of one obstacle type, on its parameter vector ``p`` (see the module
    docstring).

    Subclasses set the class attributes and implement every abstract method;
    test/unit/test_obstacle_types.py checks each registered type for all of them.
    """

    name: ClassVar[str]  # the scene's ``type`` string
    size: ClassVar[int]  # length of p
    keys: ClassVar[dict[str, Key]]  # scene keys besides ``type`` and ``name``
    #: where each named field sits in p (``Obstacle``'s accessors)
    fields: ClassVar[dict[str, slice | int]]
    flat: ClassVar[bool] = False  # no curvature: slots at isolated touches only (obstacle_slots)
    #: a string resting on it touches at isolated points, never along a line (a sphere; a bar's or
    #: a box's contact may run along the string): 'points' slots it (``solver.slotted_obstacles``)
    points: ClassVar[bool] = False

    @abstractmethod
    def parse(self, d: Mapping[str, Any], where: str) -> np.ndarray:
        """Return p from the scene mapping ``d``; a ValueError names ``where``.<key>."""

    @abstractmethod
    def to_dict(self, p: np.ndarray) -> dict[str, Any]:
        """Return the scene keys of p (plain lists and floats); ``parse`` of it gives p back."""

    @abstractmethod
    def h(self, x: Any, p: Any, lib: Any = ca) -> Any:
        """Return the signed distance [m] from x, positive inside.

        Signed distance [m], positive inside: CasADi with ``lib=ca``; numpy with ``lib=NUMPY``
        (one point) or ``ROWS`` (rows of points) unless ``casadi_only``.
        """

    #: whether ``h`` works only in CasADi (then ``h_at`` calls a CasADi Function)
    casadi_only: ClassVar[bool] = False

    def h_at(self, x: np.ndarray, p: np.ndarray) -> float:
        """Return h at one point [m].

        h at one point [m]: numpy unless ``casadi_only`` (a streaming solver asks every
        update).
        """
        if self.casadi_only:
            return float(numeric_h(self.name)(x, p))
        return float(self.h(np.asarray(x, dtype=float), p, NUMPY))

    def h_many(self, points: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Return h at the rows of ``points`` [m].

        h at the rows of ``points`` (N ≥ 1, 3) [m]: one mapped CasADi call (overridden where
        numpy over rows is exact).
        """
        return np.asarray(numeric_h_many(self.name, points.shape[0])(points.T, p)).ravel()

    @abstractmethod
    def distance_bound(self, x: np.ndarray, p: np.ndarray) -> float:
        """Return a lower bound of the distance [m] from x to the obstacle (≤ 0 inside)."""

    @abstractmethod
    def clear_of_plane(
        self, p: np.ndarray, origin: np.ndarray, normal: np.ndarray, margin: float
    ) -> bool:
        """Say whether the obstacle is more than ``margin`` [m] from a plane.

        Is the obstacle more than ``margin`` [m] from the plane through ``origin`` (unit
        ``normal``)?
        """

    @abstractmethod
    def planarity_violation(
        self,
        p: np.ndarray,
        origin: np.ndarray,
        normal: np.ndarray,
        tolerance: float,
        length: float,
    ) -> str:
        """Say why the obstacle does not fit the planar model of a plane, or "".

        Why the obstacle does not fit the planar model of the plane (``origin``, unit
        ``normal``), or "": directions within ``tolerance``, offsets within ``tolerance`` ·
        ``length``.
        """

    @abstractmethod
    def primitive(self, p: np.ndarray) -> Primitive:
        """Return the shape to draw."""


#: the registry: the scene's type string → its ObstacleType
OBSTACLE_TYPES: dict[str, ObstacleType] = {}


def register(cls: type[ObstacleType]) -> type[ObstacleType]:
    """Class decorator: add one instance of ``cls`` to ``OBSTACLE_TYPES`` under ``cls.name``."""
    if cls.name in OBSTACLE_TYPES:
        raise ValueError(f"obstacle type {cls.name!r} is registered twice")
    OBSTACLE_TYPES[cls.name] = cls()
    return cls


@functools.lru_cache(maxsize=None)
def numeric_h(kind: str) -> ca.Function:
    """Return h of a registered type as a CasADi Function (x, p) → h, built once per type."""
    xs = ca.SX.sym("x", 3)
    ps = ca.SX.sym("p", OBSTACLE_TYPES[kind].size)
    return ca.Function(f"h_{kind}", [xs, ps], [OBSTACLE_TYPES[kind].h(xs, ps)])


@functools.lru_cache(maxsize=64)
def numeric_h_many(kind: str, count: int) -> ca.Function:
    """``numeric_h`` mapped over ``count`` points, built once per (type, count)."""
    return numeric_h(kind).map(count)


def _offset(point: np.ndarray, origin: np.ndarray, normal: np.ndarray) -> float:
    return np.dot(point - origin, normal)


@register
class HalfSpace(ObstacleType):
    """p = [point(3), unit outward normal(3)];  h = −n·(x − point) (inside: behind the surface)."""

    name = "halfspace"
    size = 6
    keys = {"point": Key("vector", False), "normal": Key("vector", False)}
    fields = {"point": slice(0, 3), "normal": slice(3, 6)}
    flat = True

    def parse(self, d, where):
        n = vector(d.get("normal", [0, 0, 1]), 3, f"{where}.normal")
        if np.linalg.norm(n) < 1e-12:
            raise ValueError(f"{where}.normal: must be non-zero")
        point = vector(d.get("point", [0, 0, 0]), 3, f"{where}.point")
        return np.concatenate([point, n / np.linalg.norm(n)])

    def to_dict(self, p):
        return {"point": p[0:3].tolist(), "normal": p[3:6].tolist()}

    def h(self, x, p, lib=ca):
        return -lib.dot(p[3:6], x - p[0:3])

    def h_many(self, points, p):
        return np.asarray(self.h(points, p, ROWS), dtype=float)

    def distance_bound(self, x, p):
        return -self.h_at(x, p)

    def clear_of_plane(self, p, origin, normal, margin):
        # parallel to the plane, with the plane outside it
        return abs(abs(np.dot(p[3:6], normal)) - 1.0) < 1e-12 and self.h_at(origin, p) < -margin

    def planarity_violation(self, p, origin, normal, tolerance, length):
        if abs(np.dot(p[3:6], normal)) > tolerance:
            return "the half-space's normal is not in the plane"
        return ""

    def primitive(self, p):
        return Primitive(
            PrimitiveKind.PLANE,
            p[0:3].copy(),
            quat_z_to(p[3:6]),
            p[3:6].copy(),
            np.zeros(3),
            colour=PLANE_COLOUR,
        )


@register
class Sphere(ObstacleType):
    """p = [centre(3), radius];  h = radius − |x − centre|."""

    name = "sphere"
    size = 4
    points = True
    keys = {"center": Key("vector", True), "radius": Key("number", True)}
    fields = {"centre": slice(0, 3), "radius": 3}

    def parse(self, d, where):
        centre = vector(d.get("center"), 3, f"{where}.center")
        return np.concatenate([centre, [positive(d.get("radius"), f"{where}.radius")]])

    def to_dict(self, p):
        return {"center": p[0:3].tolist(), "radius": float(p[3])}

    def h(self, x, p, lib=ca):
        return p[3] - lib.norm_2(x - p[0:3])

    def h_many(self, points, p):
        return np.asarray(self.h(points, p, ROWS), dtype=float)

    def distance_bound(self, x, p):
        return -self.h_at(x, p)

    def clear_of_plane(self, p, origin, normal, margin):
        return abs(_offset(p[0:3], origin, normal)) - float(p[3]) > margin

    def planarity_violation(self, p, origin, normal, tolerance, length):
        if abs(_offset(p[0:3], origin, normal)) > tolerance * length:
            return "not centred on the plane"
        return ""

    def primitive(self, p):
        r = float(p[3])
        return Primitive(
            PrimitiveKind.SPHERE,
            p[0:3].copy(),
            np.array([0.0, 0.0, 0.0, 1.0]),
            np.array([0.0, 0.0, 1.0]),
            np.full(3, r),
            r,
        )


@register
class Capsule(ObstacleType):
    """p = [a(3), b(3), radius];  h = radius − distance(x, segment ab)."""

    name = "capsule"
    size = 7
    keys = {"a": Key("vector", True), "b": Key("vector", True), "radius": Key("number", True)}
    fields = {"a": slice(0, 3), "b": slice(3, 6), "radius": 6}

    def parse(self, d, where):
        a, b = vector(d.get("a"), 3, f"{where}.a"), vector(d.get("b"), 3, f"{where}.b")
        if np.linalg.norm(b - a) < 1e-9:
            raise ValueError(f"{where}: a and b must differ (use a sphere otherwise)")
        return np.concatenate([a, b, [positive(d.get("radius"), f"{where}.radius")]])

    def to_dict(self, p):
        return {"a": p[0:3].tolist(), "b": p[3:6].tolist(), "radius": float(p[6])}

    def h(self, x, p, lib=ca):
        a, b, r = p[0:3], p[3:6], p[6]
        ab = b - a
        t = lib.fmin(1, lib.fmax(0, lib.dot(x - a, ab) / lib.dot(ab, ab)))
        return r - lib.norm_2(x - (a + t * ab))

    def distance_bound(self, x, p):
        return -self.h_at(x, p)

    def clear_of_plane(self, p, origin, normal, margin):
        da, db = _offset(p[0:3], origin, normal), _offset(p[3:6], origin, normal)
        return da * db > 0 and min(abs(da), abs(db)) - float(p[6]) > margin

    def planarity_violation(self, p, origin, normal, tolerance, length):
        off = max(abs(_offset(p[0:3], origin, normal)), abs(_offset(p[3:6], origin, normal)))
        return "not centred on the plane" if off > tolerance * length else ""

    def primitive(self, p):
        a, b, r = p[0:3], p[3:6], float(p[6])
        length = float(np.linalg.norm(b - a))
        return Primitive(
            PrimitiveKind.CAPSULE,
            (a + b) / 2,
            quat_z_to(b - a),
            (b - a) / length,
            np.array([r, r, 0.5 * length]),
            r,
        )


@register
class Box(ObstacleType):
    """p = [centre(3), rotation matrix Rᵀ row-major (9), half extents e(3)].

    q = Rᵀ(x − c) in the box frame; h = min(e) · (1 − ‖q/e‖_8): a superellipsoid of exponent 8,
    inscribed in the box (touches each face centre, rounds the edges), smooth for IPOPT.  Its zero
    set is exact on the faces' centres; near edges and corners the string may cut the box's edge by
    up to 1 − 3^(−1/8) ≈ 13 % of the half-diagonal — give the box a margin if that matters.  The
    bounds (``distance_bound``, ``clear_of_plane``) use the circumscribed sphere.
    """

    name = "box"
    size = 15
    keys = {
        "center": Key("vector", True),
        "orientation": Key("quaternion", False),
        "half_extents": Key("vector", True),
    }
    fields = {
        "centre": slice(0, 3),
        "rotation_transposed": slice(3, 12),
        "half_extents": slice(12, 15),
    }
    casadi_only = True

    def parse(self, d, where):
        q = check_quaternion(d.get("orientation", [0, 0, 0, 1]), f"{where}.orientation")
        e = vector(d.get("half_extents"), 3, f"{where}.half_extents")
        if np.any(e <= 0):
            raise ValueError(f"{where}.half_extents: must all be > 0")
        centre = vector(d.get("center"), 3, f"{where}.center")
        return np.concatenate([centre, quat_to_matrix(q).T.ravel(), e])

    @staticmethod
    def rotation(p: np.ndarray) -> np.ndarray:
        """R (3×3, box frame → world) from p."""
        return np.asarray(p[3:12], dtype=float).reshape(3, 3).T

    def to_dict(self, p):
        return {
            "center": p[0:3].tolist(),
            "orientation": matrix_to_quat(self.rotation(p)).tolist(),
            "half_extents": p[12:15].tolist(),
        }

    def h(self, x, p, lib=ca):
        c, rt, e = p[0:3], ca.reshape(p[3:12], 3, 3).T, p[12:15]
        q = ca.mtimes(rt, x - c) / e
        return ca.mmin(e) * (1 - ca.sum1(q**BOX_EXPONENT) ** (1.0 / BOX_EXPONENT))

    def distance_bound(self, x, p):
        # the solver's box is inscribed in the box; bound with the circumscribed sphere
        return float(np.linalg.norm(x - p[0:3]) - np.linalg.norm(p[12:15]))

    def clear_of_plane(self, p, origin, normal, margin):
        return abs(_offset(p[0:3], origin, normal)) - np.linalg.norm(p[12:15]) > margin

    def planarity_violation(self, p, origin, normal, tolerance, length):
        if abs(_offset(p[0:3], origin, normal)) > tolerance * length:
            return "not centred on the plane"
        return ""

    def primitive(self, p):
        rotation = self.rotation(p)
        return Primitive(
            PrimitiveKind.BOX,
            p[0:3].copy(),
            matrix_to_quat(rotation),
            rotation[:, 2].copy(),
            p[12:15].copy(),
        )
