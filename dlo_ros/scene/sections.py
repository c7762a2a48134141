"""Parsers of the scene's sections, each from its raw YAML value to the model's types.

The sections: ``string``, ``gravity``, ``grips``, ``loads``, ``obstacles``,
``relative_positions`` and ``solver``.  Obstacles are read through their type's keys and ``parse``
(``model.obstacle_types.ObstacleType``): nothing here depends on the type.

Every error is a SceneError whose message starts with the offending key path; an error raised by
the model or solver (which starts with its own field) is rewrapped by :func:`wrap_error`.
"""

from __future__ import annotations

import re
from dataclasses import fields
from typing import Any, Callable

import numpy as np

from ..model.obstacle_types import OBSTACLE_TYPES
from ..model.obstacles import Obstacle
from ..model.problem import GRIP_MODES, Grip, GripPose, Load, RelativePosition, StringProperties
from ..model.profile import Profile
from ..solver.options import SolverOptions
from ..solver.results.uncertainty import KEYS as UNCERTAIN_KEYS
from ..solver.results.uncertainty import Uncertainty, UncertaintyError
from .format import (
    GRAVITY_KEYS,
    GRIP_KEYS,
    LOAD_KEYS,
    RELATIVE_KEYS,
    STRING_KEYS,
    SceneError,
    describe_value,
    fail,
)
from .values import (
    check_known_keys,
    read_arc_length,
    read_list,
    read_mapping,
    read_number,
    read_profile,
    read_quaternion,
    read_string,
    read_vector,
)

_KEY_RE = re.compile(r"^([A-Za-z_][\w.\[\]]*):")


def wrap_error(exc: ValueError, fallback_key: str) -> SceneError:
    """Turn a model/solver ValueError (which already starts with its field) into a SceneError."""
    text = str(exc).strip("'\"")
    m = _KEY_RE.match(text)
    if m:
        return SceneError(text, key=m.group(1))
    return SceneError(f"{fallback_key}: {text}", key=fallback_key)


def parse_string(value: object) -> StringProperties:
    """Read the ``string`` section: length, stiffness and weight profiles, radius."""
    d = read_mapping(value, "string")
    check_known_keys(d, STRING_KEYS, "string")
    if "length" not in d:
        raise fail("string.length", "required (the string's length in m)")
    length = read_number(d["length"], "string.length")
    if length <= 0:
        raise fail("string.length", f"must be > 0, got {length:g}")
    if "bend_stiffness" not in d or d["bend_stiffness"] is None:
        raise fail("string.bend_stiffness", "required (Rf in N m^2, > 0)")
    bend = read_profile(d["bend_stiffness"], "string.bend_stiffness", length, 0.0, strict=True)

    def optional(name: str, default: float) -> Profile:
        v = d.get(name)
        return (
            Profile.constant(default)
            if v is None
            else read_profile(v, f"string.{name}", length, 0.0, strict=False)
        )

    twist = optional("twist_stiffness", 0.0)
    weight = optional("weight_per_length", 0.0)
    stretch_value = d.get("stretch_stiffness")
    stretch = (
        None
        if stretch_value is None
        else read_profile(stretch_value, "string.stretch_stiffness", length, 0.0, strict=True)
    )
    lateral_value = d.get("lateral_bend_stiffness")
    lateral = (
        None
        if lateral_value is None
        else read_profile(lateral_value, "string.lateral_bend_stiffness", length, 0.0, strict=True)
    )
    radius = 0.0 if d.get("radius") is None else read_number(d["radius"], "string.radius")
    if radius < 0:
        raise fail("string.radius", f"must be >= 0, got {radius:g}")
    return StringProperties(
        length=length,
        bend_stiffness=bend,
        twist_stiffness=twist,
        weight_per_length=weight,
        stretch_stiffness=stretch,
        radius=radius,
        lateral_bend_stiffness=lateral,
    )


def parse_uncertainty(value: object, string: StringProperties) -> Uncertainty | None:
    """Read ``string.uncertainty``: a standard deviation per material key, in that key's unit.

    Each σ is a number >= 0 of a key that scales a profile (bend_stiffness, twist_stiffness,
    stretch_stiffness, weight_per_length, lateral_bend_stiffness); a σ > 0 needs the string's
    value of that key to be > 0 (the envelope scales the profile: σ_θ = σ / value).  None when
    absent.
    """
    if value is None:
        return None
    where = "string.uncertainty"
    d = read_mapping(value, where)
    check_known_keys(d, tuple(UNCERTAIN_KEYS), where)
    sigmas = {k: read_number(v, f"{where}.{k}") for k, v in d.items()}
    try:
        uncertainty = Uncertainty.from_sigmas(sigmas, where)
        uncertainty.check_string(string, where)
    except UncertaintyError as exc:
        raise SceneError(str(exc), key=exc.key) from None
    return uncertainty


def parse_gravity(value: object) -> np.ndarray:
    """Read the ``gravity`` section: the unit direction of weight (default -z)."""
    if value is None:
        return np.array([0.0, 0.0, -1.0])
    d = read_mapping(value, "gravity")
    check_known_keys(d, GRAVITY_KEYS, "gravity")
    if "direction" not in d:
        raise fail("gravity.direction", "required (unit direction of weight, e.g. [0, 0, -1])")
    g = read_vector(d["direction"], 3, "gravity.direction")
    norm = float(np.linalg.norm(g))
    if norm < 1e-12:
        raise fail("gravity.direction", "must be non-zero")
    return g / norm


def parse_grips(value: object, length: float) -> tuple[Grip, ...]:
    """Read the ``grips`` section: at least one, unique names and unique arc lengths."""
    if value is None:
        raise fail("grips", "required: at least one grip must hold the string")
    items = read_list(value, "grips", "grips")
    if not items:
        raise fail("grips", "at least one grip is needed to hold the string")
    grips: list[Grip] = []
    names: dict[str, int] = {}
    arc: dict[float, int] = {}
    for i, item in enumerate(items):
        key = f"grips[{i}]"
        d = read_mapping(item, key)
        check_known_keys(d, GRIP_KEYS, key)
        name = read_string(d.get("name", f"grip{i}"), f"{key}.name", allow_empty=False)
        if name in names:
            raise fail(f"{key}.name", f"duplicate grip name {name!r} (also grips[{names[name]}])")
        names[name] = i
        if "s" not in d:
            raise fail(f"{key}.s", "required (arc length where the grip holds the string, m)")
        s = read_arc_length(d["s"], f"{key}.s", length)
        if s in arc:
            raise fail(f"{key}.s", f"grips[{arc[s]}] already holds the string at s = {s:g}")
        arc[s] = i
        mode = read_string(d.get("mode", "clamp"), f"{key}.mode")
        if mode not in GRIP_MODES:
            raise fail(f"{key}.mode", f"must be one of {', '.join(GRIP_MODES)}, got {mode!r}")
        if "position" not in d:
            raise fail(f"{key}.position", "required ([x, y, z] in m)")
        position = read_vector(d["position"], 3, f"{key}.position")
        orientation = read_quaternion(
            d.get("orientation", [0.0, 0.0, 0.0, 1.0]), f"{key}.orientation"
        )
        grips.append(Grip(name=name, s=s, mode=mode, pose=GripPose(position, orientation)))
    return tuple(grips)


def parse_loads(value: object, length: float) -> tuple[Load, ...]:
    """Read the ``loads`` section: point forces and moments at arc lengths."""
    if value is None:
        return ()
    loads = []
    for i, item in enumerate(read_list(value, "loads", "loads")):
        key = f"loads[{i}]"
        d = read_mapping(item, key)
        check_known_keys(d, LOAD_KEYS, key)
        if "s" not in d:
            raise fail(f"{key}.s", "required (arc length where the load acts, m)")
        s = read_arc_length(d["s"], f"{key}.s", length)
        force = (
            np.zeros(3) if d.get("force") is None else read_vector(d["force"], 3, f"{key}.force")
        )
        moment = (
            np.zeros(3)
            if d.get("moment") is None
            else read_vector(d["moment"], 3, f"{key}.moment")
        )
        loads.append(Load(s=s, force=force, moment=moment))
    return tuple(loads)


#: how a value of each kind of obstacle key (``obstacle_types.Key.kind``) is checked
OBSTACLE_VALUE_READERS: dict[str, Callable[[object, str], Any]] = {
    "number": read_number,
    "quaternion": lambda raw, where: read_quaternion(raw, where).tolist(),
    "vector": lambda raw, where: read_vector(raw, 3, where).tolist(),
}


def parse_obstacles(value: object) -> tuple[Obstacle, ...]:
    """Read the ``obstacles`` section through each type's keys and ``parse`` (ObstacleType)."""
    if value is None:
        return ()
    obstacles = []
    names: dict[str, int] = {}
    for i, item in enumerate(read_list(value, "obstacles", "obstacles")):
        key = f"obstacles[{i}]"
        d = read_mapping(item, key)
        if "type" not in d:
            raise fail(f"{key}.type", f"required (one of {', '.join(OBSTACLE_TYPES)})")
        kind = read_string(d["type"], f"{key}.type")
        if kind not in OBSTACLE_TYPES:
            raise fail(f"{key}.type", f"must be one of {', '.join(OBSTACLE_TYPES)}, got {kind!r}")
        spec = OBSTACLE_TYPES[kind].keys
        check_known_keys(d, ("type", "name", *spec), key)
        name = read_string(d.get("name", ""), f"{key}.name")
        if name and name in names:
            raise fail(
                f"{key}.name", f"duplicate obstacle name {name!r} (also obstacles[{names[name]}])"
            )
        if name:
            names[name] = i
        clean: dict[str, Any] = {"type": kind, "name": name}
        for field_name, field_spec in spec.items():
            where = f"{key}.{field_name}"
            raw = d.get(field_name)
            if raw is None:
                if field_spec.required:
                    raise fail(where, "required")
                continue
            clean[field_name] = OBSTACLE_VALUE_READERS[field_spec.kind](raw, where)
        try:
            obstacles.append(Obstacle.from_dict(clean, key))
        except ValueError as exc:
            raise wrap_error(exc, key) from None
    return tuple(obstacles)


def parse_relative(value: object, length: float) -> tuple[RelativePosition, ...]:
    """Read the ``relative_positions`` section: offsets between two distinct arc lengths."""
    if value is None:
        return ()
    rels = []
    for i, item in enumerate(read_list(value, "relative_positions", "relative_positions")):
        key = f"relative_positions[{i}]"
        d = read_mapping(item, key)
        check_known_keys(d, RELATIVE_KEYS, key)
        for name in RELATIVE_KEYS:
            if name not in d:
                raise fail(f"{key}.{name}", "required")
        s_a = read_arc_length(d["s_a"], f"{key}.s_a", length)
        s_b = read_arc_length(d["s_b"], f"{key}.s_b", length)
        if s_a == s_b:
            raise fail(f"{key}.s_b", f"must differ from s_a = {s_a:g}")
        rels.append(
            RelativePosition(s_a=s_a, s_b=s_b, offset=read_vector(d["offset"], 3, f"{key}.offset"))
        )
    return tuple(rels)


def parse_solver(value: object) -> SolverOptions:
    """Read the ``solver`` section into validated SolverOptions (defaults when absent)."""
    if value is None:
        options = SolverOptions()
    else:
        d = read_mapping(value, "solver")
        known = [f.name for f in fields(SolverOptions)]
        check_known_keys(d, known, "solver")
        for k, v in d.items():
            # from_dict converts with str()/int()/float(): reject what would be silently coerced.
            default = getattr(SolverOptions, k)
            if isinstance(default, str):
                read_string(v, f"solver.{k}")
            elif isinstance(v, bool) or not isinstance(v, (int, float)):
                raise fail(
                    f"solver.{k}",
                    f"expected a {type(default).__name__}, got {type(v).__name__} "
                    f"{describe_value(v)}",
                )
            elif isinstance(v, int) and abs(v) >= 10**15:
                raise fail(f"solver.{k}", f"out of range: an integer {describe_value(v)}")
        try:
            options = SolverOptions.from_dict(dict(d))
        except ValueError as exc:
            raise wrap_error(exc, "solver") from None
    try:
        options.validate()
    except ValueError as exc:
        raise wrap_error(exc, "solver") from None
    return options
