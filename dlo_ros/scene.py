"""Scene files: YAML (or a dict) -> a validated :class:`Problem` plus :class:`SolverOptions`.

A *scene* is everything one solve needs: the string's properties, the grips and their poses, loads,
obstacles, relative-position constraints, the gravity direction and the solver options.  The format
is documented in ``msg_docs/scene_format.md``; every quantity is SI and quaternions are (x, y, z,
w) of a pose whose x-axis is the string's tangent, pointing toward increasing s.

Every malformed input raises :class:`SceneError` whose message starts with the offending key path
(``grips[1].orientation: quaternion norm is 1.3, not 1 ...``).  Errors found while loading a file
add where the key is, `` (in path/to/scene.yaml:12)``; YAML syntax errors start with
``file:line:column``. Messages never quote the file beyond the scene format's own keys and short
values: a file that is not a scene (``scene:=/etc/passwd``) is named, not echoed.

What a scene may cost is bounded before anything is built (:data:`LIMITS`, msg_docs/scene_format.md
"Limits"): the file's size and kind are checked before it is read, the YAML composer counts
aliases, nesting depth, scalar sizes and the nodes the document would have with every alias
expanded while it composes (no alias is ever expanded to count it), and the sections' list lengths
are checked before their items are parsed.

No ROS here: only the model and solver layers are imported.
"""

from __future__ import annotations

import math
import os
import re
import stat
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .model.obstacles import OBSTACLE_TYPES, Obstacle
from .model.problem import (
    GRIP_MODES,
    Grip,
    GripPose,
    Load,
    Problem,
    RelativePosition,
    StringProperties,
)
from .model.profile import Profile
from .model.rotations import check_quaternion
from .text import safe_text
from .paths import scene_path
from .solver.options import SolverOptions

__all__ = [
    "DEFAULT_SCENE",
    "Scene",
    "SceneError",
    "scene_from_dict",
    "load_scene",
    "scene_to_dict",
    "TOP_LEVEL_KEYS",
    "STRING_KEYS",
    "GRIP_KEYS",
    "LOAD_KEYS",
    "RELATIVE_KEYS",
    "OBSTACLE_KEYS",
    "LIMITS",
    "FileLimitError",
    "read_regular_file",
    "parse_bounded_yaml",
]

DEFAULT_SCENE = "default_cable"

#: Relative tolerance on a quaternion's norm (passed to model.rotations.check_quaternion).
QUATERNION_TOLERANCE = 1e-3

TOP_LEVEL_KEYS = (
    "name",
    "description",
    "frame_id",
    "string",
    "gravity",
    "grips",
    "loads",
    "obstacles",
    "relative_positions",
    "solver",
)
STRING_KEYS = (
    "length",
    "bend_stiffness",
    "twist_stiffness",
    "stretch_stiffness",
    "weight_per_length",
    "radius",
)
GRAVITY_KEYS = ("direction",)
GRIP_KEYS = ("name", "s", "mode", "position", "orientation")
LOAD_KEYS = ("s", "force", "moment")
RELATIVE_KEYS = ("s_a", "s_b", "offset")
#: Keys of each obstacle type (besides ``type`` and ``name``) and which of them are required (each
#: type's ``keys`` in ``model.obstacle_types``).
OBSTACLE_KEYS: dict[str, dict[str, bool]] = {
    name: {k: key.required for k, key in kind.keys.items()}
    for name, kind in OBSTACLE_TYPES.items()
}

#: What a scene may cost (documented in msg_docs/scene_format.md, "Limits").  File and YAML limits
# are : checked while reading and composing, before any alias is expanded or any object is
# constructed; list : and string limits before the items are parsed (for dicts too).
LIMITS: dict[str, int] = {
    "file_bytes": 1 << 20,  # size of a scene file (1 MiB; the shipped ones are < 3 KB)
    "depth": 16,  # nesting of mappings and lists (a valid scene needs 4)
    "aliases": 64,  # YAML aliases (*name) in one file
    "nodes": 100_000,  # YAML nodes, counting an aliased subtree at every alias
    "scalar_chars": 10_000,  # characters of one YAML scalar (key or value)
    "integer_digits": 30,  # digits of an integer in the file (larger ones are no physical value)
    "grips": 16,
    "loads": 100,  # each load adds a breakpoint (an element) and parameters: bounds the build
    "obstacles": 32,  # each adds obstacle_samples constraints: bounds the build's time and memory
    "relative_positions": 32,
    "profile_rows": 1000,  # rows of a string.* profile table
    "name_chars": 128,  # name, grips[].name, obstacles[].name
    "frame_id_chars": 256,  # = dlo_ros.node.validation.FRAME_ID_LIMIT
    "description_chars": 10_000,
}


class SceneError(ValueError):
    """A malformed scene.  ``str(err)`` starts with the offending key path (``key``).

    ``source`` is the file (or ``"<dict>"``) the scene came from; ``line`` the 1-based line of the
    key in that file when known.
    """

    def __init__(self, message: str, key: str = "", source: str = "", line: int | None = None):
        super().__init__(message)
        self.key = key
        self.source = source
        self.line = line


def _fail(key: str, message: str) -> SceneError:
    return SceneError(f"{key}: {message}", key=key)


@dataclass(frozen=True)
class Scene:
    """A validated scene: the problem, how to solve it and where it is expressed."""

    name: str
    problem: Problem
    options: SolverOptions
    frame_id: str = "world"
    source: str = ""
    description: str = ""


# ---- primitive readers (each names its key path) -----------------------------------------------------
def _describe(value: object) -> str:
    """A short, safe description of a value for an error message: numbers and short one-line
    strings as they are; longer strings and containers by their size only (never their content).
    """
    if isinstance(value, str):
        if len(value) <= 40 and value.isprintable():
            return repr(value)
        return f"of {len(value)} characters"
    if isinstance(value, (list, tuple)):
        return f"of {len(value)} items"
    if isinstance(value, dict):
        return f"of {len(value)} keys"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**15:
        return f"with {len(str(abs(value)))} digits"
    return safe_text(repr(value), 60)


def _key_text(k: object) -> str:
    """A key for a key path: itself when it looks like a scene key, else a placeholder (an unknown
    key of a file that is not a scene must not be echoed).
    """
    if isinstance(k, str) and _KEY_TEXT_RE.fullmatch(k):
        return k
    return "<unknown key>"


_KEY_TEXT_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,39}")


def _mapping(value: object, key: str) -> dict:
    if not isinstance(value, dict):
        raise _fail(key, f"expected a mapping, got {type(value).__name__} {_describe(value)}")
    for k in value:
        if not isinstance(k, str):
            raise _fail(key, f"keys must be strings, got {_describe(k)}")
    return value


def _no_unknown(d: dict, allowed: tuple[str, ...] | list[str], key: str) -> None:
    for k in d:
        if k not in allowed:
            prefix = f"{key}.{_key_text(k)}" if key else _key_text(k)
            raise _fail(prefix, f"unknown key (allowed: {', '.join(allowed)})")


def _list(value: object, key: str, limit: str | None = None) -> list:
    """A list; ``limit`` names the entry of :data:`LIMITS` bounding its length (checked first)."""
    if not isinstance(value, (list, tuple)):
        raise _fail(key, f"expected a list, got {type(value).__name__} {_describe(value)}")
    if limit is not None and len(value) > LIMITS[limit]:
        raise _fail(key, f"{len(value)} items, at most {LIMITS[limit]} are allowed")
    return list(value)


def _number(value: object, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise _fail(key, f"expected a number, got {type(value).__name__} {_describe(value)}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond 1.8e308
        raise _fail(key, f"out of range: an integer {_describe(value)}") from None
    if not math.isfinite(v):
        raise _fail(key, f"must be finite, got {v}")
    return v


def _vector(value: object, n: int, key: str) -> np.ndarray:
    items = _list(value, key)
    if len(items) != n:
        raise _fail(key, f"expected {n} numbers, got {len(items)}")
    return np.array([_number(v, f"{key}[{i}]") for i, v in enumerate(items)], dtype=float)


def _string(value: object, key: str, allow_empty: bool = True, limit: str = "name_chars") -> str:
    """A string of at most ``LIMITS[limit]`` characters, without control characters unless it is
    the description.
    """
    if not isinstance(value, str):
        raise _fail(key, f"expected a string, got {type(value).__name__} {_describe(value)}")
    if len(value) > LIMITS[limit]:
        raise _fail(key, f"{len(value)} characters, at most {LIMITS[limit]} are allowed")
    if limit != "description_chars" and not value.isprintable():
        raise _fail(
            key, f"must be printable text without control characters, got {_describe(value)}"
        )
    if not allow_empty and not value.strip():
        raise _fail(key, "must not be empty")
    return value


def _arc_length(value: object, key: str, length: float) -> float:
    s = _number(value, key)
    if not 0.0 <= s <= length:
        raise _fail(key, f"must lie in [0, string.length = {length:g}], got {s:g}")
    return s


def _quaternion(value: object, key: str) -> np.ndarray:
    q = _vector(value, 4, key)
    try:
        return check_quaternion(q, key, QUATERNION_TOLERANCE)
    except ValueError as exc:
        raise SceneError(str(exc), key=key) from None


def _profile(value: object, key: str, length: float, minimum: float, strict: bool) -> Profile:
    """A number, or {table: [[s, value], ...]} piecewise linear in s; every value >= / >
    minimum.
    """
    bound = "> 0" if strict else ">= 0"

    def check(v: float, where: str) -> None:
        if v < minimum or (strict and v <= minimum):
            raise _fail(where, f"must be {bound}, got {v:g}")

    if isinstance(value, dict):
        _no_unknown(value, ("table",), key)
        if "table" not in value:
            raise _fail(key, "a profile mapping needs 'table: [[s, value], ...]'")
        rows = _list(value["table"], f"{key}.table", "profile_rows")
        if not rows:
            raise _fail(f"{key}.table", "needs at least one [s, value] row")
        table = []
        for i, row in enumerate(rows):
            where = f"{key}.table[{i}]"
            pair = _vector(row, 2, where)
            if not 0.0 <= pair[0] <= length:
                raise _fail(
                    f"{where}[0]",
                    f"s must lie in [0, string.length = {length:g}], got {pair[0]:g}",
                )
            if table and pair[0] <= table[-1][0]:
                raise _fail(
                    f"{where}[0]",
                    f"s values must be strictly increasing, got {pair[0]:g} after {table[-1][0]:g}",
                )
            check(float(pair[1]), f"{where}[1]")
            table.append((float(pair[0]), float(pair[1])))
        return Profile.table(table)
    v = _number(value, key)
    check(v, key)
    return Profile.constant(v)


# ---- sections ---------------------------------------------------------------------------------------
def _parse_string(value: object) -> StringProperties:
    d = _mapping(value, "string")
    _no_unknown(d, STRING_KEYS, "string")
    if "length" not in d:
        raise _fail("string.length", "required (the string's length in m)")
    length = _number(d["length"], "string.length")
    if length <= 0:
        raise _fail("string.length", f"must be > 0, got {length:g}")
    if "bend_stiffness" not in d or d["bend_stiffness"] is None:
        raise _fail("string.bend_stiffness", "required (Rf in N m^2, > 0)")
    bend = _profile(d["bend_stiffness"], "string.bend_stiffness", length, 0.0, strict=True)

    def optional(name: str, default: float) -> Profile:
        v = d.get(name)
        return (
            Profile.constant(default)
            if v is None
            else _profile(v, f"string.{name}", length, 0.0, strict=False)
        )

    twist = optional("twist_stiffness", 0.0)
    weight = optional("weight_per_length", 0.0)
    stretch_value = d.get("stretch_stiffness")
    stretch = (
        None
        if stretch_value is None
        else _profile(stretch_value, "string.stretch_stiffness", length, 0.0, strict=True)
    )
    radius = 0.0 if d.get("radius") is None else _number(d["radius"], "string.radius")
    if radius < 0:
        raise _fail("string.radius", f"must be >= 0, got {radius:g}")
    return StringProperties(
        length=length,
        bend_stiffness=bend,
        twist_stiffness=twist,
        weight_per_length=weight,
        stretch_stiffness=stretch,
        radius=radius,
    )


def _parse_gravity(value: object) -> np.ndarray:
    if value is None:
        return np.array([0.0, 0.0, -1.0])
    d = _mapping(value, "gravity")
    _no_unknown(d, GRAVITY_KEYS, "gravity")
    if "direction" not in d:
        raise _fail("gravity.direction", "required (unit direction of weight, e.g. [0, 0, -1])")
    g = _vector(d["direction"], 3, "gravity.direction")
    norm = float(np.linalg.norm(g))
    if norm < 1e-12:
        raise _fail("gravity.direction", "must be non-zero")
    return g / norm


def _parse_grips(value: object, length: float) -> tuple[Grip, ...]:
    if value is None:
        raise _fail("grips", "required: at least one grip must hold the string")
    items = _list(value, "grips", "grips")
    if not items:
        raise _fail("grips", "at least one grip is needed to hold the string")
    grips: list[Grip] = []
    names: dict[str, int] = {}
    arc: dict[float, int] = {}
    for i, item in enumerate(items):
        key = f"grips[{i}]"
        d = _mapping(item, key)
        _no_unknown(d, GRIP_KEYS, key)
        name = _string(d.get("name", f"grip{i}"), f"{key}.name", allow_empty=False)
        if name in names:
            raise _fail(f"{key}.name", f"duplicate grip name {name!r} (also grips[{names[name]}])")
        names[name] = i
        if "s" not in d:
            raise _fail(f"{key}.s", "required (arc length where the grip holds the string, m)")
        s = _arc_length(d["s"], f"{key}.s", length)
        if s in arc:
            raise _fail(f"{key}.s", f"grips[{arc[s]}] already holds the string at s = {s:g}")
        arc[s] = i
        mode = _string(d.get("mode", "clamp"), f"{key}.mode")
        if mode not in GRIP_MODES:
            raise _fail(f"{key}.mode", f"must be one of {', '.join(GRIP_MODES)}, got {mode!r}")
        if "position" not in d:
            raise _fail(f"{key}.position", "required ([x, y, z] in m)")
        position = _vector(d["position"], 3, f"{key}.position")
        orientation = _quaternion(d.get("orientation", [0.0, 0.0, 0.0, 1.0]), f"{key}.orientation")
        grips.append(Grip(name=name, s=s, mode=mode, pose=GripPose(position, orientation)))
    return tuple(grips)


def _parse_loads(value: object, length: float) -> tuple[Load, ...]:
    if value is None:
        return ()
    loads = []
    for i, item in enumerate(_list(value, "loads", "loads")):
        key = f"loads[{i}]"
        d = _mapping(item, key)
        _no_unknown(d, LOAD_KEYS, key)
        if "s" not in d:
            raise _fail(f"{key}.s", "required (arc length where the load acts, m)")
        s = _arc_length(d["s"], f"{key}.s", length)
        force = np.zeros(3) if d.get("force") is None else _vector(d["force"], 3, f"{key}.force")
        moment = (
            np.zeros(3) if d.get("moment") is None else _vector(d["moment"], 3, f"{key}.moment")
        )
        loads.append(Load(s=s, force=force, moment=moment))
    return tuple(loads)


#: how a value of each kind of obstacle key (``obstacle_types.Key.kind``) is checked
_OBSTACLE_VALUE: dict[str, Any] = {
    "number": _number,
    "quaternion": lambda raw, where: _quaternion(raw, where).tolist(),
    "vector": lambda raw, where: _vector(raw, 3, where).tolist(),
}


def _parse_obstacles(value: object) -> tuple[Obstacle, ...]:
    if value is None:
        return ()
    obstacles = []
    names: dict[str, int] = {}
    for i, item in enumerate(_list(value, "obstacles", "obstacles")):
        key = f"obstacles[{i}]"
        d = _mapping(item, key)
        if "type" not in d:
            raise _fail(f"{key}.type", f"required (one of {', '.join(OBSTACLE_TYPES)})")
        kind = _string(d["type"], f"{key}.type")
        if kind not in OBSTACLE_TYPES:
            raise _fail(f"{key}.type", f"must be one of {', '.join(OBSTACLE_TYPES)}, got {kind!r}")
        spec = OBSTACLE_TYPES[kind].keys
        _no_unknown(d, ("type", "name", *spec), key)
        name = _string(d.get("name", ""), f"{key}.name")
        if name and name in names:
            raise _fail(
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
                    raise _fail(where, "required")
                continue
            clean[field_name] = _OBSTACLE_VALUE[field_spec.kind](raw, where)
        try:
            obstacles.append(Obstacle.from_dict(clean, key))
        except ValueError as exc:
            raise _wrap(exc, key) from None
    return tuple(obstacles)


def _parse_relative(value: object, length: float) -> tuple[RelativePosition, ...]:
    if value is None:
        return ()
    rels = []
    for i, item in enumerate(_list(value, "relative_positions", "relative_positions")):
        key = f"relative_positions[{i}]"
        d = _mapping(item, key)
        _no_unknown(d, RELATIVE_KEYS, key)
        for name in RELATIVE_KEYS:
            if name not in d:
                raise _fail(f"{key}.{name}", "required")
        s_a = _arc_length(d["s_a"], f"{key}.s_a", length)
        s_b = _arc_length(d["s_b"], f"{key}.s_b", length)
        if s_a == s_b:
            raise _fail(f"{key}.s_b", f"must differ from s_a = {s_a:g}")
        rels.append(
            RelativePosition(s_a=s_a, s_b=s_b, offset=_vector(d["offset"], 3, f"{key}.offset"))
        )
    return tuple(rels)


def _parse_solver(value: object) -> SolverOptions:
    if value is None:
        options = SolverOptions()
    else:
        d = _mapping(value, "solver")
        known = [f.name for f in fields(SolverOptions)]
        _no_unknown(d, known, "solver")
        for k, v in d.items():
            # from_dict converts with str()/int()/float(): reject what would be silently coerced.
            default = getattr(SolverOptions, k)
            if isinstance(default, str):
                _string(v, f"solver.{k}")
            elif isinstance(v, bool) or not isinstance(v, (int, float)):
                raise _fail(
                    f"solver.{k}",
                    f"expected a {type(default).__name__}, got {type(v).__name__} {_describe(v)}",
                )
            elif isinstance(v, int) and abs(v) >= 10**15:
                raise _fail(f"solver.{k}", f"out of range: an integer {_describe(v)}")
        try:
            options = SolverOptions.from_dict(dict(d))
        except ValueError as exc:
            raise _wrap(exc, "solver") from None
    try:
        options.validate()
    except ValueError as exc:
        raise _wrap(exc, "solver") from None
    return options


_KEY_RE = re.compile(r"^([A-Za-z_][\w.\[\]]*):")


def _wrap(exc: ValueError, fallback_key: str) -> SceneError:
    """A model/solver ValueError (which already starts with its field) as a SceneError."""
    text = str(exc).strip("'\"")
    m = _KEY_RE.match(text)
    if m:
        return SceneError(text, key=m.group(1))
    return SceneError(f"{fallback_key}: {text}", key=fallback_key)


def _check_moments(problem: Problem, options: SolverOptions) -> None:
    """The solver models point moments about the working-plane normal only; say so at load time."""
    if not any(np.any(ld.moment != 0) for ld in problem.loads):
        return
    from .solver.build.nlp import choose_reference_frame

    n = choose_reference_frame(problem, options.frame)[:, 2]
    for i, ld in enumerate(problem.loads):
        m = np.asarray(ld.moment, dtype=float)
        if np.linalg.norm(m - np.dot(m, n) * n) > 1e-9 * max(1.0, float(np.linalg.norm(m))):
            raise _fail(
                f"loads[{i}].moment",
                "only moments about the working-plane normal n = "
                f"{np.round(n, 6).tolist()} (normal to the grips' chord and gravity) are supported",
            )


# ---- public API -------------------------------------------------------------------------------------
def scene_from_dict(d: dict, source: str = "<dict>") -> Scene:
    """Build and validate a Scene from a mapping in the scene-file format.

    Raises SceneError (a ValueError) whose message starts with the offending key path.
    """
    if not isinstance(d, dict):
        raise SceneError(
            f"{source}: a scene must be a mapping of keys, got {type(d).__name__}", key=""
        )
    d = _mapping(d, "<scene>")
    _no_unknown(d, TOP_LEVEL_KEYS, "")
    default_name = Path(source).stem if source and not source.startswith("<") else "scene"
    if not (default_name.isprintable() and 0 < len(default_name) <= LIMITS["name_chars"]):
        default_name = "scene"
    name = _string(d.get("name", default_name), "name", allow_empty=False)
    description = (
        ""
        if d.get("description") is None
        else _string(d["description"], "description", limit="description_chars")
    )
    frame_id = _string(
        d.get("frame_id", "world"), "frame_id", allow_empty=False, limit="frame_id_chars"
    )
    if "string" not in d:
        raise _fail("string", "required (length, bend_stiffness, ...)")
    string = _parse_string(d["string"])
    gravity = _parse_gravity(d.get("gravity"))
    grips = _parse_grips(d.get("grips"), string.length)
    loads = _parse_loads(d.get("loads"), string.length)
    obstacles = _parse_obstacles(d.get("obstacles"))
    relative = _parse_relative(d.get("relative_positions"), string.length)
    options = _parse_solver(d.get("solver"))
    problem = Problem(
        string=string,
        grips=grips,
        gravity=gravity,
        loads=loads,
        obstacles=obstacles,
        relative_positions=relative,
    )
    try:
        problem.validate()
    except ValueError as exc:
        raise _wrap(exc, "<scene>") from None
    _check_moments(problem, options)
    return Scene(
        name=name,
        problem=problem,
        options=options,
        frame_id=frame_id,
        source=source,
        description=description.strip(),
    )


class _LimitError(yaml.composer.ComposerError):
    """A scene file exceeds one of :data:`LIMITS` (raised while composing, before anything is
    expanded).
    """

    def __init__(self, key: str, problem: str, mark):
        super().__init__(problem=problem, problem_mark=mark)
        self.key = key


class _SceneLoader(yaml.SafeLoader):
    """SafeLoader that reads YAML 1.2 floats (``1e-3`` is a number, not a string), rejects
    duplicate keys, and bounds what the document may cost while composing it (:data:`LIMITS`):
    nesting depth, aliases, scalar sizes, and the number of nodes with every alias expanded —
    computed from the node counts of the anchored subtrees, so a "billion laughs" file is rejected
    without expanding anything.
    """

    def __init__(self, stream):
        super().__init__(stream)
        self._paths: list[str] = []  # key path of every node being composed (innermost last)
        self._weights: dict[int, int] = {}  # id(node) -> nodes in its subtree, aliases expanded
        self.node_paths: dict[int, str] = {}  # id(node) -> its key path (first occurrence)
        self._aliases = 0

    def _limit(self, problem: str, mark) -> _LimitError:
        key = self._paths[-1] if self._paths else ""
        return _LimitError(key or "<scene>", problem, mark)

    def compose_node(self, parent, index):  # noqa: D401 - yaml.composer.Composer API
        where = self._paths[-1] if self._paths else ""
        if isinstance(index, yaml.ScalarNode):  # the value of a key
            part = _key_text(index.value)
            where = f"{where}.{part}" if where else part
        elif isinstance(index, int):
            where = f"{where}[{index}]"
        self._paths.append(where)
        try:
            event = self.peek_event()
            if len(self._paths) > LIMITS["depth"]:
                raise self._limit(
                    f"nested more than {LIMITS['depth']} levels deep", event.start_mark
                )
            if isinstance(event, yaml.AliasEvent):
                self._aliases += 1
                if self._aliases > LIMITS["aliases"]:
                    raise self._limit(
                        f"more than {LIMITS['aliases']} YAML aliases", event.start_mark
                    )
            node = super().compose_node(parent, index)
            if isinstance(event, yaml.AliasEvent):
                weight = self._weights.get(id(node))
                if weight is None:
                    raise self._limit(
                        "an alias refers to a node that contains it (a recursive structure)",
                        event.start_mark,
                    )
            else:
                if isinstance(node, yaml.ScalarNode):
                    if len(node.value) > LIMITS["scalar_chars"]:
                        raise self._limit(
                            f"a value of {len(node.value)} characters (at most "
                            f"{LIMITS['scalar_chars']})",
                            node.start_mark,
                        )
                    weight = 1
                elif isinstance(node, yaml.SequenceNode):
                    weight = 1 + sum(self._weights[id(item)] for item in node.value)
                else:
                    weight = 1 + sum(
                        self._weights[id(k)] + self._weights[id(v)] for k, v in node.value
                    )
                self._weights[id(node)] = weight
                self.node_paths[id(node)] = where
            # the whole document so far, aliases expanded: the root's weight bounds every subtree's
            if weight > LIMITS["nodes"]:
                raise self._limit(
                    f"more than {LIMITS['nodes']} YAML nodes with aliases expanded",
                    event.start_mark,
                )
            return node
        finally:
            self._paths.pop()


_SceneLoader.yaml_implicit_resolvers = {
    k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def _construct_mapping(loader: _SceneLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: dict[object, yaml.Node] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            continue  # SafeLoader reports unhashable keys itself
        if key in seen:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping",
                node.start_mark,
                f"found duplicate key {key!r} (first at line {seen[key].start_mark.line + 1})",
                key_node.start_mark,
            )
        seen[key] = key_node
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_SceneLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _construct_int(loader: _SceneLoader, node: yaml.ScalarNode) -> int:
    """SafeLoader's int, refusing more than LIMITS['integer_digits'] digits (int() of a 5000-digit
    string raises a ValueError outside YAML's errors, and no physical value of a scene needs 30
    digits).
    """
    digits = sum(c.isalnum() for c in node.value)
    if digits > LIMITS["integer_digits"]:
        raise _LimitError(
            loader.node_paths.get(id(node)) or "<scene>",
            f"an integer with {digits} digits (at most {LIMITS['integer_digits']})",
            node.start_mark,
        )
    return yaml.SafeLoader.construct_yaml_int(loader, node)


_SceneLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def key_lines(
    node: yaml.Node | None, path: str = "", out: dict[str, int] | None = None
) -> dict[str, int]:
    """Map every key path of a composed YAML document ("grips[1].orientation") to its 1-based
    line.
    """
    out = {} if out is None else out
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                continue
            sub = f"{path}.{key_node.value}" if path else str(key_node.value)
            out.setdefault(sub, key_node.start_mark.line + 1)
            key_lines(value_node, sub, out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            sub = f"{path}[{i}]"
            out.setdefault(sub, item.start_mark.line + 1)
            key_lines(item, sub, out)
    return out


def _line_of(key: str, lines: dict[str, int]) -> int | None:
    """Line of ``key`` or of its nearest enclosing key present in the file."""
    while key:
        if key in lines:
            return lines[key]
        cut = max(key.rfind("."), key.rfind("["))
        if cut <= 0:
            break
        key = key[:cut]
    return lines.get(key) if key else None


class FileLimitError(ValueError):
    """A file refused by :func:`read_regular_file`: one line starting with its source name."""


def open_regular_file(
    path: Path,
    source: str,
    limit: int,
    what: str = "scene file",
    doc: str = "msg_docs/scene_format.md, Limits",
) -> int:
    """A read-only descriptor on a regular file of at most ``limit`` bytes, or FileLimitError
    naming ``source``; the caller closes it.

    Opened without blocking (a FIFO without a writer would hang a plain open) and checked with
    fstat on the open descriptor before a byte is read, so a directory, a FIFO or a device
    (/dev/zero) is refused by kind, and a huge file by size, whatever happens to the path
    meanwhile.  ``what`` names the kind of file in the messages, ``doc`` where its limits are
    documented.
    """
    a = "an" if what[:1] in "aeiou" else "a"
    try:
        fd = os.open(
            path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
        )
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise FileLimitError(f"{source}: cannot open the {what}: {reason}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise FileLimitError(f"{source}: is a directory, not {a} {what}")
        if not stat.S_ISREG(info.st_mode):
            raise FileLimitError(
                f"{source}: not a regular file (a FIFO, socket or device); {a} "
                f"{what} must be a regular file"
            )
        if info.st_size > limit:
            raise FileLimitError(
                f"{source}: the file has {info.st_size} bytes, {a} {what} at most {limit} ({doc})"
            )
    except BaseException:
        os.close(fd)
        raise
    return fd


def read_regular_file(
    path: Path,
    source: str,
    limit: int,
    what: str = "scene file",
    doc: str = "msg_docs/scene_format.md, Limits",
) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (:func:`open_regular_file`), or
    FileLimitError naming ``source``; a file that grew past ``limit`` after the check is refused
    too.
    """
    a = "an" if what[:1] in "aeiou" else "a"
    fd = open_regular_file(path, source, limit, what, doc)
    try:
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 16, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > limit:  # it grew after fstat
            raise FileLimitError(
                f"{source}: the file has more than {limit} bytes, {a} {what} at "
                f"most {limit} ({doc})"
            )
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise FileLimitError(f"{source}: cannot read the {what}: {reason}") from None
    finally:
        os.close(fd)
    return b"".join(chunks)


def read_scene_text(path: Path, source: str) -> str:
    """The text of a scene (or parameters) file, or SceneError naming ``source``: a regular file of
    at most LIMITS['file_bytes'] bytes, UTF-8 (:func:`read_regular_file`).
    """
    try:
        data = read_regular_file(path, source, LIMITS["file_bytes"])
    except FileLimitError as exc:
        message = str(exc).replace(
            "a scene file must be a regular file", "a scene must be a YAML file"
        )
        raise SceneError(message, source=source) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(
            f"{source}: not a UTF-8 text file ({exc.reason} at byte {exc.start})", source=source
        ) from None


def _compose(text: str) -> tuple[object, yaml.Node | None]:
    """(the constructed document, its node tree) with one pass of the bounded composer."""
    loader = _SceneLoader(text)
    try:
        node = loader.get_single_node()
        data = None if node is None else loader.construct_document(node)
        return data, node
    finally:
        loader.dispose()


def parse_bounded_yaml(text: str, source: str) -> object:
    """The document of YAML (or JSON) ``text`` read with the scene reader's bounds
    (:func:`compose_bounded_yaml`).
    """
    return compose_bounded_yaml(text, source)[0]


def compose_bounded_yaml(text: str, source: str) -> tuple[object, yaml.Node | None]:
    """(the document, its YAML node tree) of YAML (or JSON) ``text`` read with the scene reader's
    bounds (:data:`LIMITS`: nesting depth, aliases, nodes with aliases expanded, scalar characters,
    integer digits; YAML 1.2 floats, duplicate keys refused).  The node tree gives each key its
    line (:func:`key_lines`).  Raises FileLimitError with one line: ``<source>:<line>: <key path>:
    over a limit: ...`` or ``<source>:<line>:<column>: YAML syntax error: ...`` (never the
    offending text).
    """
    try:
        return _compose(text)
    except _LimitError as exc:
        line = f":{exc.problem_mark.line + 1}" if exc.problem_mark else ""
        raise FileLimitError(f"{source}{line}: {exc.key}: over a limit: {exc.problem}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        detail = safe_text(": ".join(p for p in (exc.context, exc.problem) if p))
        raise FileLimitError(f"{where}: YAML syntax error: {detail}") from None
    except yaml.YAMLError as exc:
        reason = safe_text(getattr(exc, "reason", "") or type(exc).__name__)
        raise FileLimitError(f"{source}: YAML error: {reason}") from None


def load_scene(path_or_name: str | Path) -> Scene:
    """Load a scene from a file path or the name of a shipped scene
    (``config/scenes/<name>.yaml``).

    Raises:
        FileNotFoundError: neither a file nor a shipped scene (the message lists the shipped
        scenes). SceneError: a path that is not a readable regular file, or one over the size
        limit; malformed YAML
            (message ``<file>:<line>:<column>: ...``); a file over one of :data:`LIMITS` (``<key
            path>: ... (in <file>:<line>)``); or a malformed scene (message ``<key path>: ... (in
            <file>:<line>)``).
    """
    given = Path(path_or_name)
    try:
        exists_as_other = given.exists() and not given.is_file()  # a directory, FIFO, device, ...
    except OSError:
        exists_as_other = False
    path = given if exists_as_other else scene_path(path_or_name)
    source = safe_text(
        str(path), 4096
    )  # control characters escaped; a path is never cut (PATH_MAX)
    text = read_scene_text(path, source)
    try:
        data, root = _compose(text)
        lines = key_lines(root)
    except _LimitError as exc:
        mark = exc.problem_mark
        line = mark.line + 1 if mark else None
        where = f"{source}:{line}" if line else source
        raise SceneError(
            f"{exc.key}: over a limit: {exc.problem} (in {where}; msg_docs/scene_format.md, "
            "Limits)",
            key=exc.key,
            source=source,
            line=line,
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        where = f"{source}:{line}:{mark.column + 1}" if mark else source
        context = exc.context or ""
        cm = exc.context_mark
        if context and cm is not None and mark is not None and cm.line != mark.line:
            context += f" (started at line {cm.line + 1}, column {cm.column + 1})"
        # context and problem only: str(exc) would quote the offending line of the file
        detail = safe_text(": ".join(p for p in (context, exc.problem) if p))
        raise SceneError(
            f"{where}: YAML syntax error: {detail}", source=source, line=line
        ) from None
    except yaml.YAMLError as exc:  # e.g. ReaderError: a control character in the file
        reason = getattr(exc, "reason", "") or type(exc).__name__
        position = getattr(exc, "position", None)
        at = f" at character {position}" if isinstance(position, int) else ""
        raise SceneError(f"{source}: YAML error: {safe_text(reason)}{at}", source=source) from None
    if data is None:
        raise SceneError(f"{source}: the scene file is empty", source=source)
    if not isinstance(data, dict):
        raise SceneError(
            f"{source}: a scene file must be a mapping of keys, got a {type(data).__name__}",
            source=source,
            line=1,
        )
    if not any(isinstance(k, str) and k in TOP_LEVEL_KEYS for k in data):
        raise SceneError(
            f"{source}: not a scene file: none of its top-level keys is a scene key "
            f"({', '.join(TOP_LEVEL_KEYS)})",
            source=source,
            line=1,
        )
    try:
        return scene_from_dict(data, source=source)
    except SceneError as exc:
        line = _line_of(exc.key, lines)
        where = f"{source}:{line}" if line else source
        raise SceneError(f"{exc} (in {where})", key=exc.key, source=source, line=line) from None


def _profile_to_yaml(p: Profile) -> float | dict:
    if len(p.s) == 1:
        return float(p.values[0])
    return {"table": [[float(s), float(v)] for s, v in zip(p.s, p.values)]}


def _floats(a: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def scene_to_dict(scene: Scene) -> dict:
    """The scene in the scene-file format (every key explicit); ``scene_from_dict`` of it is
    equal.
    """
    pr, st = scene.problem, scene.problem.string
    out: dict[str, Any] = {"name": scene.name}
    if scene.description:
        out["description"] = scene.description
    out["frame_id"] = scene.frame_id
    out["string"] = {
        "length": float(st.length),
        "bend_stiffness": _profile_to_yaml(st.bend_stiffness),
        "twist_stiffness": _profile_to_yaml(st.twist_stiffness),
        "stretch_stiffness": None
        if st.stretch_stiffness is None
        else _profile_to_yaml(st.stretch_stiffness),
        "weight_per_length": _profile_to_yaml(st.weight_per_length),
        "radius": float(st.radius),
    }
    out["gravity"] = {"direction": _floats(pr.gravity_unit)}
    out["grips"] = [
        {
            "name": g.name,
            "s": float(g.s),
            "mode": g.mode,
            "position": _floats(g.pose.position),
            "orientation": _floats(g.pose.orientation),
        }
        for g in pr.grips
    ]
    out["loads"] = [
        {"s": float(ld.s), "force": _floats(ld.force), "moment": _floats(ld.moment)}
        for ld in pr.loads
    ]
    out["obstacles"] = [ob.to_dict() for ob in pr.obstacles]
    out["relative_positions"] = [
        {"s_a": float(r.s_a), "s_b": float(r.s_b), "offset": _floats(r.offset)}
        for r in pr.relative_positions
    ]
    out["solver"] = {f.name: getattr(scene.options, f.name) for f in fields(SolverOptions)}
    return out
