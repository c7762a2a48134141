"""The node's parameters: names, types, ranges, which are read-only, and their checks (pure, no ROS).

The scene file (parameter ``scene``) defines the problem.  The string's properties, the output
resolution and a few presentation settings are parameters that may change at run time; everything
that names a file or changes the model's structure is read-only.  :func:`check_live` is what the
node's on-set-parameters callback runs: it returns the reason a value is refused ('' if accepted) and
changes nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping

from ..model.problem import Problem, StringProperties
from ..model.profile import Profile

DEFAULT_SCENE = "default_cable"  # = dlo_ros.scene.DEFAULT_SCENE (not imported: keep this module light)


@dataclass(frozen=True)
class ParamSpec:
    """One parameter.  ``kind``: 'string', 'bool', 'integer', 'double' or 'string_array'."""

    name: str
    kind: str
    default: Any
    description: str
    read_only: bool = False
    low: float | None = None  # inclusive range for numbers (also published in the descriptor)
    high: float | None = None
    constraints: str = ""
    from_scene: bool = False  # the default comes from the scene file
    dynamic: bool = False  # other types accepted too (see compile_mode)


#: Parameters fixed at start-up.
STATIC = (
    ParamSpec("scene", "string", DEFAULT_SCENE,
              "Scene name (config/scenes/<name>.yaml) or path of a scene YAML file.", read_only=True),
    ParamSpec("frame_id", "string", "",
              "Frame of all inputs and outputs; empty: the scene's frame_id (default_cable: 'world').",
              read_only=True),
    ParamSpec("compile", "string", "background",
              "How the solver gets compiled (C) derivatives, cached per machine in ~/.cache/dlo_ros: 'background' "
              "(solve at once, interpreted, switch to C when gcc is done: minutes for a new scene structure or "
              "after a solver change), 'blocking' (compile before the first solve), 'cached' (only a library "
              "compiled earlier), 'off' (interpreted only; also false, as `-p compile:=off` reads as one).",
              read_only=True, constraints="one of: background, blocking, cached, off (or false)", dynamic=True),
    ParamSpec("solver.model", "string", "",
              "Override the scene's solver.model: 'auto' (the solver picks the smallest model the scene needs), "
              "'full' (3D) or 'planar'; empty: the scene's value.", read_only=True,
              constraints="empty, auto, full or planar"),
    ParamSpec("use_tf", "bool", True,
              "Transform targets from other frames with tf2 when tf2_ros is importable (else they are rejected).",
              read_only=True),
    ParamSpec("diagnostics_period", "double", 1.0, "Period [s] of /diagnostics.", read_only=True,
              low=0.05, high=60.0),
    ParamSpec("record.rrd", "string", "",
              "Save a rerun recording of every solve, target and rejected input to this .rrd file (dlo replay "
              "FILE opens it); empty: no file.", read_only=True),
    ParamSpec("record.connect", "string", "",
              "Stream the rerun recording to a running viewer at HOST[:PORT] or a rerun+http://HOST:PORT/proxy "
              "URL; empty: no streaming.", read_only=True),
    ParamSpec("grip_names", "string_array", [],
              "Informational: the scene's grips in configuration order (the order of ~/grips/targets poses).",
              read_only=True, from_scene=True),
)

#: String properties: parameter name -> StringProperties field.  A table-valued (s-dependent) property
#: is represented by its maximum; setting the parameter scales the whole table.
STRING_FIELDS = {
    "string.bend_stiffness": "bend_stiffness",
    "string.twist_stiffness": "twist_stiffness",
    "string.weight_per_length": "weight_per_length",
    "string.stretch_stiffness": "stretch_stiffness",
    "string.radius": "radius",
}

#: Parameters that may change at run time.
LIVE = (
    ParamSpec("string.bend_stiffness", "double", None,
              "Bending stiffness Rf [N m^2] (> 0). For an s-dependent table: its maximum; setting it scales the table.",
              low=0.0, high=1.0e6, from_scene=True),
    ParamSpec("string.twist_stiffness", "double", None,
              "Torsional stiffness Rt [N m^2] (>= 0). Cannot switch between 0 and > 0 at run time.",
              low=0.0, high=1.0e6, from_scene=True),
    ParamSpec("string.weight_per_length", "double", None, "Weight per length D [N/m] (>= 0).",
              low=0.0, high=1.0e6, from_scene=True),
    ParamSpec("string.stretch_stiffness", "double", None,
              "Extensional stiffness Re [N]; 0 = inextensible. Cannot switch between 0 and > 0 at run time.",
              low=0.0, high=1.0e12, from_scene=True),
    ParamSpec("string.radius", "double", None, "Clearance kept from obstacles [m] (>= 0).",
              low=0.0, high=10.0, from_scene=True),
    ParamSpec("output_points", "integer", None,
              "Centreline samples in ~/centerline and the markers (a change rebuilds the solver: next solve is cold).",
              low=2, high=10000, from_scene=True),
    ParamSpec("markers.force_scale", "double", 0.1, "Length of the grip-force arrows per newton [m/N].",
              low=0.0, high=100.0),
    ParamSpec("markers.energy_scale", "double", 0.0,
              "Bending energy density [J/m] shown in full red; 0 = the maximum of each shape.", low=0.0, high=1.0e9),
    ParamSpec("warn_throttle", "double", 1.0, "Minimum interval [s] between warnings of the same kind.",
              low=0.0, high=3600.0),
)

SPECS = {p.name: p for p in STATIC + LIVE}

#: Values of the ``compile`` parameter (= dlo_ros.solver.shape_solver.COMPILE_MODES).
COMPILE_MODES = ("background", "blocking", "cached", "off")


def compile_mode(value: Any) -> str:
    """The solver's compile mode for a ``compile`` parameter value.

    ROS reads ``-p compile:=off`` (and an unquoted ``off`` / ``no`` in YAML) as the boolean false, so
    false means 'off'; true means the default, 'background'.  Raises ValueError for anything else.
    """
    if isinstance(value, bool):
        return "background" if value else "off"
    if isinstance(value, str) and value in COMPILE_MODES:
        return value
    raise ValueError(f"compile: must be one of {', '.join(COMPILE_MODES)} (or false), got {value!r}")


def profile_value(profile: Profile | None) -> float:
    """The parameter value of a property: the constant, the maximum of a table, 0 for None."""
    if profile is None:
        return 0.0
    return float(max(profile.values))


def scene_values(problem: Problem, output_points: int) -> dict[str, Any]:
    """Defaults of the ``from_scene`` parameters."""
    st = problem.string
    return {
        "grip_names": [g.name for g in problem.grips],
        "string.bend_stiffness": profile_value(st.bend_stiffness),
        "string.twist_stiffness": profile_value(st.twist_stiffness),
        "string.weight_per_length": profile_value(st.weight_per_length),
        "string.stretch_stiffness": profile_value(st.stretch_stiffness),
        "string.radius": float(st.radius),
        "output_points": int(output_points),
    }


def _scaled(profile: Profile | None, value: float) -> Profile:
    if profile is None or len(profile.values) == 1:
        return Profile.constant(value)
    top = max(profile.values)
    if top <= 0.0:
        return Profile.constant(value)
    return profile.scaled(value / top)


def apply_string(string: StringProperties, values: Mapping[str, float]) -> StringProperties:
    """``string`` with the given ``string.*`` parameter values (unchanged values keep their tables).

    Raises ValueError naming the parameter for a value the model cannot take at run time.
    """
    changes: dict[str, Any] = {}
    for name, value in values.items():
        field = STRING_FIELDS[name]
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value}")
        if field == "radius":
            if value < 0:
                raise ValueError(f"{name}: must be >= 0, got {value}")
            if value != string.radius:
                changes[field] = value
            continue
        current = getattr(string, field)
        if value == profile_value(current):
            continue
        if field == "bend_stiffness" and value <= 0:
            raise ValueError(f"{name}: must be > 0, got {value}")
        if value < 0:
            raise ValueError(f"{name}: must be >= 0, got {value}")
        if field == "stretch_stiffness":
            if (current is None) != (value == 0.0):
                raise ValueError(
                    f"{name}: cannot switch between inextensible (0) and extensible (> 0) at run time: it "
                    "changes the model's unknowns; set it in the scene file"
                )
            changes[field] = None if value == 0.0 else _scaled(current, value)
            continue
        if field == "twist_stiffness" and current.is_zero != (value == 0.0):
            raise ValueError(
                f"{name}: cannot switch between 0 and > 0 at run time: it changes the model's unknowns; "
                "set it in the scene file"
            )
        changes[field] = _scaled(current, value)
    return replace(string, **changes) if changes else string


def check_live(name: str, value: Any, problem: Problem) -> str:
    """Why ``name = value`` is refused at run time ('' if it is accepted).  Pure: changes nothing."""
    spec = SPECS.get(name)
    if spec is None:
        return ""  # not one of ours (e.g. use_sim_time): rclpy's own checks apply
    if spec.read_only:
        return f"{name} is read-only at run time"
    if spec.kind == "double" and not math.isfinite(float(value)):
        return f"{name}: must be finite, got {value}"
    if spec.low is not None and value < spec.low:
        return f"{name}: must be >= {spec.low}, got {value}"
    if spec.high is not None and value > spec.high:
        return f"{name}: must be <= {spec.high}, got {value}"
    if name in STRING_FIELDS:
        try:
            replace(problem, string=apply_string(problem.string, {name: value})).validate()
        except ValueError as exc:
            return str(exc)
    return ""
