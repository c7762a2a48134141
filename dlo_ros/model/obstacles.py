"""Obstacles as inequality constraints h(x) ≤ 0 (paper eq. 8): h > 0 inside, h < 0 outside.

Each obstacle type has a fixed-size parameter vector (its pose and size), so moving an obstacle changes
parameter values of the NLP, never its structure.  Every h is a signed distance [m] (exact for
half-space, sphere and capsule; for the box a smooth inscribed approximation, see ``box``), which lets
the string's radius be added as a clearance: h(x) + radius ≤ 0.
"""
from __future__ import annotations

import functools

from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Callable

import casadi as ca
import numpy as np

from .rotations import check_quaternion, quat_to_matrix


def _vec(value: object, n: int, where: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).ravel()
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: expected {n} finite numbers, got {value!r}")
    return arr


#: numpy stand-ins for the CasADi functions the h below use (``lib=NUMPY``: plain arrays, no CasADi call)
NUMPY = SimpleNamespace(dot=np.dot, norm_2=np.linalg.norm, fmin=min, fmax=max)
#: the same over the rows of an (N, 3) array of points (the half-space and the sphere: ``Obstacle.h_many``)
ROWS = SimpleNamespace(dot=lambda a, b: np.sum(a * b, axis=-1), norm_2=lambda v: np.sqrt(np.sum(v * v, axis=-1)))


def _halfspace(x: ca.SX, p: ca.SX, lib=ca) -> ca.SX:
    """p = [point(3), unit outward normal(3)];  h = −n·(x − point) (inside = behind the surface)."""
    return -lib.dot(p[3:6], x - p[0:3])


def _sphere(x: ca.SX, p: ca.SX, lib=ca) -> ca.SX:
    """p = [centre(3), radius];  h = radius − |x − centre|."""
    return p[3] - lib.norm_2(x - p[0:3])


def _capsule(x: ca.SX, p: ca.SX, lib=ca) -> ca.SX:
    """p = [a(3), b(3), radius];  h = radius − distance(x, segment ab)."""
    a, b, r = p[0:3], p[3:6], p[6]
    ab = b - a
    t = lib.fmin(1, lib.fmax(0, lib.dot(x - a, ab) / lib.dot(ab, ab)))
    return r - lib.norm_2(x - (a + t * ab))


BOX_EXPONENT = 8


def _box(x: ca.SX, p: ca.SX) -> ca.SX:
    """p = [centre(3), rotation matrix Rᵀ row-major (9), half extents e(3)].

    q = Rᵀ(x − c) in the box frame; h = min(e) · (1 − ‖q/e‖_8): a superellipsoid of exponent 8,
    inscribed in the box (touches each face centre, rounds the edges), smooth for IPOPT.  Its zero set
    is exact on the faces' centres; near edges and corners the string may cut the box's edge by up to
    1 − 3^(−1/8) ≈ 13 % of the half-diagonal — give the box a margin if that matters.
    """
    c, rt, e = p[0:3], ca.reshape(p[3:12], 3, 3).T, p[12:15]
    q = ca.mtimes(rt, x - c) / e
    return ca.mmin(e) * (1 - ca.sum1(q**BOX_EXPONENT) ** (1.0 / BOX_EXPONENT))


@dataclass(frozen=True)
class ObstacleType:
    size: int
    h: Callable[..., ca.SX]  # h(x, p) in CasADi; half-space, sphere, capsule also h(x, p, NUMPY)
    parse: Callable[[dict, str], np.ndarray]


def _parse_halfspace(d: dict, where: str) -> np.ndarray:
    n = _vec(d.get("normal", [0, 0, 1]), 3, f"{where}.normal")
    if np.linalg.norm(n) < 1e-12:
        raise ValueError(f"{where}.normal: must be non-zero")
    return np.concatenate([_vec(d.get("point", [0, 0, 0]), 3, f"{where}.point"), n / np.linalg.norm(n)])


def _positive(value: object, where: str) -> float:
    v = float(_vec(value, 1, where)[0])
    if v <= 0:
        raise ValueError(f"{where}: must be > 0, got {v}")
    return v


def _parse_sphere(d: dict, where: str) -> np.ndarray:
    return np.concatenate([_vec(d.get("center"), 3, f"{where}.center"), [_positive(d.get("radius"), f"{where}.radius")]])


def _parse_capsule(d: dict, where: str) -> np.ndarray:
    a, b = _vec(d.get("a"), 3, f"{where}.a"), _vec(d.get("b"), 3, f"{where}.b")
    if np.linalg.norm(b - a) < 1e-9:
        raise ValueError(f"{where}: a and b must differ (use a sphere otherwise)")
    return np.concatenate([a, b, [_positive(d.get("radius"), f"{where}.radius")]])


def _parse_box(d: dict, where: str) -> np.ndarray:
    q = check_quaternion(d.get("orientation", [0, 0, 0, 1]), f"{where}.orientation")
    e = _vec(d.get("half_extents"), 3, f"{where}.half_extents")
    if np.any(e <= 0):
        raise ValueError(f"{where}.half_extents: must all be > 0")
    return np.concatenate([_vec(d.get("center"), 3, f"{where}.center"), quat_to_matrix(q).T.ravel(), e])


OBSTACLE_TYPES: dict[str, ObstacleType] = {
    "halfspace": ObstacleType(6, _halfspace, _parse_halfspace),
    "sphere": ObstacleType(4, _sphere, _parse_sphere),
    "capsule": ObstacleType(7, _capsule, _parse_capsule),
    "box": ObstacleType(15, _box, _parse_box),
}


#: where each named field of an obstacle type sits in its parameter vector (the NLP's layout)
OBSTACLE_FIELDS: dict[str, dict[str, slice | int]] = {
    "halfspace": {"point": slice(0, 3), "normal": slice(3, 6)},
    "sphere": {"centre": slice(0, 3), "radius": 3},
    "capsule": {"a": slice(0, 3), "b": slice(3, 6), "radius": 6},
    "box": {"centre": slice(0, 3), "rotation_transposed": slice(3, 12), "half_extents": slice(12, 15)},
}


@dataclass(frozen=True)
class Obstacle:
    """A rigid obstacle the string must stay outside of, with its parameter vector (pose and size).

    Read its geometry through the named accessors (``point``, ``normal``, ``centre``, ``radius``, ``a``,
    ``b``, ``rotation``, ``half_extents``; each exists for the types ``OBSTACLE_FIELDS`` lists): only
    this module knows the parameter vector's layout."""

    type: str
    params: np.ndarray = field(compare=False)
    name: str = ""

    def _field(self, name: str):
        where = OBSTACLE_FIELDS[self.type].get(name)
        if where is None:
            raise AttributeError(f"a {self.type} obstacle has no {name}")
        value = np.asarray(self.params, dtype=float)[where]
        return float(value) if isinstance(where, int) else value.copy()

    @property
    def point(self) -> np.ndarray:
        """A point on a half-space's surface [m]."""
        return self._field("point")

    @property
    def normal(self) -> np.ndarray:
        """A half-space's unit outward normal."""
        return self._field("normal")

    @property
    def centre(self) -> np.ndarray:
        """Centre of a sphere or box [m]."""
        return self._field("centre")

    @property
    def radius(self) -> float:
        """Radius of a sphere or capsule [m]."""
        return self._field("radius")

    @property
    def a(self) -> np.ndarray:
        """First end of a capsule's segment [m]."""
        return self._field("a")

    @property
    def b(self) -> np.ndarray:
        """Second end of a capsule's segment [m]."""
        return self._field("b")

    @property
    def rotation(self) -> np.ndarray:
        """A box's orientation R (3×3, box frame → world)."""
        return self._field("rotation_transposed").reshape(3, 3).T

    @property
    def half_extents(self) -> np.ndarray:
        """A box's half extents along its own axes [m]."""
        return self._field("half_extents")

    @staticmethod
    def from_dict(d: dict, where: str = "obstacles[0]") -> "Obstacle":
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be a mapping with a 'type'")
        kind = d.get("type")
        if kind not in OBSTACLE_TYPES:
            raise ValueError(f"{where}.type: must be one of {sorted(OBSTACLE_TYPES)}, got {kind!r}")
        return Obstacle(kind, OBSTACLE_TYPES[kind].parse(d, where), str(d.get("name", "")))

    def h(self, x: np.ndarray) -> float:
        """Numerical h(x) [m] (positive inside): the NLP's formulas evaluated in numpy for the
        half-space, sphere and capsule (a streaming solver asks every update), through CasADi for the box."""
        if self.type == "box":
            return float(_numeric_h(self.type)(x, self.params))
        return float(OBSTACLE_TYPES[self.type].h(np.asarray(x, dtype=float), self.params, NUMPY))

    def h_many(self, points: np.ndarray) -> np.ndarray:
        """h at many points (N, 3) [m] (positive inside): numpy over the rows for the half-space and the
        sphere, one CasADi call for the others."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if points.shape[0] == 0:
            return np.zeros(0)
        if self.type in ("halfspace", "sphere"):
            return np.asarray(OBSTACLE_TYPES[self.type].h(points, self.params, ROWS), dtype=float)
        fn = _numeric_h_many(self.type, points.shape[0])
        return np.asarray(fn(points.T, self.params)).ravel()


_NUMERIC_H: dict[str, ca.Function] = {}


@functools.lru_cache(maxsize=64)
def _numeric_h_many(kind: str, count: int) -> ca.Function:
    """``_numeric_h`` mapped over ``count`` points, built once per (type, count)."""
    return _numeric_h(kind).map(count)


def _numeric_h(kind: str) -> ca.Function:
    """h of an obstacle type as a CasADi Function, built once per type."""
    if kind not in _NUMERIC_H:
        xs = ca.SX.sym("x", 3)
        ps = ca.SX.sym("p", OBSTACLE_TYPES[kind].size)
        _NUMERIC_H[kind] = ca.Function(f"h_{kind}", [xs, ps], [OBSTACLE_TYPES[kind].h(xs, ps)])
    return _NUMERIC_H[kind]
