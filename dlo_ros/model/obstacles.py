"""Obstacles as inequality constraints h(x) ≤ 0 (paper eq. 8): h > 0 inside, h < 0 outside.

Each obstacle type has a fixed-size parameter vector (its pose and size), so moving an obstacle
changes parameter values of the NLP, never its structure.  Every h is a signed distance [m] (exact
for half-space, sphere and capsule; for the box a smooth inscribed approximation, see
``obstacle_types.Box``), which lets the string's radius be added as a clearance: h(x) + radius ≤ 0.

What differs between types lives in ``obstacle_types`` (one class per type, registered in
``OBSTACLE_TYPES``); ``Obstacle`` is one obstacle: its type's name, parameter vector and name.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .obstacle_types import BOX_EXPONENT, NUMPY, OBSTACLE_TYPES, ROWS, ObstacleType, Primitive

__all__ = [
    "BOX_EXPONENT",
    "NUMPY",
    "OBSTACLE_FIELDS",
    "OBSTACLE_TYPES",
    "ROWS",
    "Obstacle",
    "ObstacleType",
    "Primitive",
]

#: where each named field of an obstacle type sits in its parameter vector (the NLP's layout)
OBSTACLE_FIELDS: dict[str, dict[str, slice | int]] = {
    k: t.fields for k, t in OBSTACLE_TYPES.items()
}


@dataclass(frozen=True)
class Obstacle:
    """A rigid obstacle the string must stay outside of, with its parameter vector (pose and size).

    Read its geometry through the named accessors (``point``, ``normal``, ``centre``, ``radius``,
    ``a``, ``b``, ``rotation``, ``half_extents``; each exists for the types whose ``fields`` list
    it): only the type's class in ``obstacle_types`` knows the parameter vector's layout.  What
    differs between types is asked of ``obstacle_type``.
    """

    type: str
    params: np.ndarray = field(compare=False)
    name: str = ""

    def _field(self, name: str):
        where = OBSTACLE_TYPES[self.type].fields.get(name)
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

    @property
    def obstacle_type(self) -> ObstacleType:
        """The behaviour of this obstacle's type (``obstacle_types.OBSTACLE_TYPES[self.type]``)."""
        return OBSTACLE_TYPES[self.type]

    @staticmethod
    def from_dict(d: dict, where: str = "obstacles[0]") -> "Obstacle":
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be a mapping with a 'type'")
        kind = d.get("type")
        if kind not in OBSTACLE_TYPES:
            raise ValueError(
                f"{where}.type: must be one of {sorted(OBSTACLE_TYPES)}, got {kind!r}"
            )
        return Obstacle(kind, OBSTACLE_TYPES[kind].parse(d, where), str(d.get("name", "")))

    def to_dict(self) -> dict:
        """Return the scene-file form of the obstacle.

        The scene-file form: type, name (when set) and the type's keys (``from_dict`` of it is
        equal).
        """
        out: dict = {"type": self.type}
        if self.name:
            out["name"] = self.name
        out.update(self.obstacle_type.to_dict(np.asarray(self.params, dtype=float)))
        return out

    def h(self, x: np.ndarray) -> float:
        """Return the signed distance [m] at x, positive inside.

        Numerical h(x) [m] (positive inside): the NLP's formula, in numpy where the type allows
        (a streaming solver asks every update).
        """
        return self.obstacle_type.h_at(x, self.params)

    def h_many(self, points: np.ndarray) -> np.ndarray:
        """Return h at many points (N, 3) [m] (positive inside)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if points.shape[0] == 0:
            return np.zeros(0)
        return self.obstacle_type.h_many(points, self.params)

    def primitive(self) -> Primitive:
        """Return the shape to draw (markers, recording)."""
        return self.obstacle_type.primitive(np.asarray(self.params, dtype=float))
