"""The node's parameters: names, types, ranges, which are read-only, and their checks (pure, no
ROS).

The scene file (parameter ``scene``) defines the problem.  The node's command line
(``--params-file``, ``--scene``, ``--ros-args ...``) is parsed and checked here too, before rclpy
sees it (:func:`prepare_node_args`): every params file (given, shipped default, or inside
``--ros-args``) and every ``-p name:=value`` that applies to this node is read with the scene
loader's bounded YAML reader and checked against the table below, so a syntax error, a file that is
not a ROS parameters file, a misspelt name or an unusable value stops start-up with a message
naming the file and the parameter.
  The string's properties, the output
resolution and a few presentation settings are parameters that may change at run time; everything
that names a file or changes the model's structure is read-only.  :func:`check_live` is what the
node's on-set-parameters callback runs: it returns the reason a value is refused ('' if accepted)
and changes nothing.
"""

from __future__ import annotations

import argparse
import difflib
import math
import os
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

from ..model.problem import Problem, StringProperties
from ..model.profile import Profile
from .validation import FRAME_ID_LIMIT, normalise_frame, safe_text

DEFAULT_SCENE = (
    "default_cable"  # = dlo_ros.scene.DEFAULT_SCENE (not imported: keep this module light)
)


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
    ParamSpec(
        "scene",
        "string",
        DEFAULT_SCENE,
        "Scene name (config/scenes/<name>.yaml) or path of a scene YAML file.",
        read_only=True,
    ),
    ParamSpec(
        "frame_id",
        "string",
        "",
        "Frame of all inputs and outputs; empty: the scene's frame_id (default_cable: 'world').",
        read_only=True,
    ),
    ParamSpec(
        "compile",
        "string",
        "background",
        "How the solver gets compiled (C) derivatives, cached per machine in ~/.cache/dlo_ros: 'background' "
        "(solve at once, interpreted, switch to C when gcc is done: seconds for a new scene structure or "
        "after a solver change), 'blocking' (compile before the first solve), 'cached' (only a library "
        "compiled earlier), 'off' (interpreted only; also false, as `-p compile:=off` reads as one).",
        read_only=True,
        constraints="one of: background, blocking, cached, off (or false)",
        dynamic=True,
    ),
    ParamSpec(
        "solver.model",
        "string",
        "",
        "Override the scene's solver.model: 'auto' (the solver picks the smallest model the scene needs), "
        "'full' (3D) or 'planar'; empty: the scene's value.",
        read_only=True,
        constraints="empty, auto, full or planar",
    ),
    ParamSpec(
        "use_tf",
        "bool",
        True,
        "Transform targets from other frames with tf2 when tf2_ros is importable (else they are rejected).",
        read_only=True,
    ),
    ParamSpec(
        "diagnostics_period",
        "double",
        1.0,
        "Period [s] of /diagnostics.",
        read_only=True,
        low=0.05,
        high=60.0,
    ),
    ParamSpec(
        "markers_period",
        "double",
        0.1,
        "Period [s] of ~/markers (the newest shape); building and publishing a MarkerArray in Python "
        "holds the GIL the solver needs for about 2 ms.",
        read_only=True,
        low=0.02,
        high=60.0,
    ),
    ParamSpec(
        "record.rrd",
        "string",
        "",
        "Save a rerun recording of every solve, target and rejected input to this .rrd file (dlo replay "
        "FILE opens it); empty: no file.",
        read_only=True,
    ),
    ParamSpec(
        "record.connect",
        "string",
        "",
        "Stream the rerun recording to a running viewer at HOST[:PORT] or a rerun+http://HOST:PORT/proxy "
        "URL; empty: no streaming.",
        read_only=True,
    ),
    ParamSpec(
        "query_workers",
        "integer",
        1,
        "Worker processes that answer ~/query_shape beside the stream, each with its own solver of the "
        "scene (they take the other cores); 0: queries are solved in the solver thread between stream "
        "updates.",
        read_only=True,
        low=0,
        high=16,
    ),
    ParamSpec(
        "query_timeout",
        "double",
        30.0,
        "Longest a query worker may take for one ~/query_shape [s]; past it the call answers an empty plan "
        "(timeout) and the worker is killed and replaced. 0 = no limit.",
        read_only=True,
        low=0.0,
        high=3600.0,
    ),
    ParamSpec(
        "grip_names",
        "string_array",
        [],
        "Informational: the scene's grips in configuration order (the order of ~/grips/targets poses).",
        read_only=True,
        from_scene=True,
    ),
)

#: String properties: parameter name -> StringProperties field.  A table-valued (s-dependent)
# property : is represented by its maximum; setting the parameter scales the whole table.
STRING_FIELDS = {
    "string.bend_stiffness": "bend_stiffness",
    "string.twist_stiffness": "twist_stiffness",
    "string.weight_per_length": "weight_per_length",
    "string.stretch_stiffness": "stretch_stiffness",
    "string.radius": "radius",
}

#: Parameters that may change at run time.
LIVE = (
    ParamSpec(
        "string.bend_stiffness",
        "double",
        None,
        "Bending stiffness Rf [N m^2] (> 0). For an s-dependent table: its maximum; setting it scales the table.",
        low=0.0,
        high=1.0e6,
        from_scene=True,
    ),
    ParamSpec(
        "string.twist_stiffness",
        "double",
        None,
        "Torsional stiffness Rt [N m^2] (>= 0). Cannot switch between 0 and > 0 at run time.",
        low=0.0,
        high=1.0e6,
        from_scene=True,
    ),
    ParamSpec(
        "string.weight_per_length",
        "double",
        None,
        "Weight per length D [N/m] (>= 0).",
        low=0.0,
        high=1.0e6,
        from_scene=True,
    ),
    ParamSpec(
        "string.stretch_stiffness",
        "double",
        None,
        "Extensional stiffness Re [N]; 0 = inextensible. Cannot switch between 0 and > 0 at run time.",
        low=0.0,
        high=1.0e12,
        from_scene=True,
    ),
    ParamSpec(
        "string.radius",
        "double",
        None,
        "Clearance kept from obstacles [m] (>= 0).",
        low=0.0,
        high=10.0,
        from_scene=True,
    ),
    ParamSpec(
        "output_points",
        "integer",
        None,
        "Centreline samples in ~/centerline and the markers (a change rebuilds the solver: next solve is cold).",
        low=2,
        high=10000,
        from_scene=True,
    ),
    ParamSpec(
        "markers.force_scale",
        "double",
        0.1,
        "Length of the grip-force arrows per newton [m/N].",
        low=0.0,
        high=100.0,
    ),
    ParamSpec(
        "markers.energy_scale",
        "double",
        0.0,
        "Bending energy density [J/m] shown in full red; 0 = the maximum of each shape.",
        low=0.0,
        high=1.0e9,
    ),
    ParamSpec(
        "warn_throttle",
        "double",
        1.0,
        "Minimum interval [s] between warnings of the same kind.",
        low=0.0,
        high=3600.0,
    ),
)

#: Identification from an observed point cloud (~/observed, ~/fit; msg_docs/node.md "Fitting").
FIT_PARAMETERS = (
    "Rf",
    "Rt",
    "D",
    "Re",
)  # = dlo_ros.identify.observations.PARAMETERS (kept light here)
FIT = (
    ParamSpec(
        "fit.enabled",
        "bool",
        False,
        "Subscribe to ~/observed (sensor_msgs/PointCloud2) and serve ~/fit: identify the string's properties "
        "from the observed shape in a worker process beside the stream.",
        read_only=True,
    ),
    ParamSpec(
        "fit.period_s",
        "double",
        0.0,
        "Fit continuously: every period_s [s], when a cloud arrived since the last fit; 0 = only on ~/fit.",
        read_only=True,
        low=0.0,
        high=3600.0,
    ),
    ParamSpec(
        "fit.max_points",
        "integer",
        20000,
        "Largest ~/observed cloud [points] accepted; a larger one is refused by its size before it is read.",
        read_only=True,
        low=3,
        high=200000,
    ),
    ParamSpec(
        "fit.parameters",
        "string_array",
        ["Rf", "D"],
        "What to identify, among Rf, Rt, D, Re (shapes alone determine only ratios such as D/Rf; "
        "fit.total_mass makes them absolute).",
        constraints="a non-empty subset of Rf, Rt, D, Re",
    ),
    ParamSpec(
        "fit.point_sigma",
        "double",
        0.002,
        "Noise of the observed points [m], standard deviation per coordinate (the stated sigma).",
        low=1.0e-6,
        high=1.0,
    ),
    ParamSpec(
        "fit.total_mass",
        "double",
        0.0,
        "Known total mass of the string [kg] (sigma 0.1 %); 0 = unknown.",
        low=0.0,
        high=1.0e6,
    ),
    ParamSpec(
        "fit.apply_max_rel_sigma",
        "double",
        0.1,
        "Apply an estimate to the string.* parameters only when the relative standard deviation of every "
        "value it changes is at most this; 0 = never apply (report only).",
        low=0.0,
        high=10.0,
    ),
    ParamSpec(
        "fit.max_iterations",
        "integer",
        30,
        "Outer Levenberg-Marquardt iterations of one fit.",
        low=1,
        high=200,
    ),
)

SPECS = {p.name: p for p in STATIC + LIVE + FIT}


def fit_parameters_reason(value: Any) -> str:
    """Why ``value`` cannot be ``fit.parameters`` ('' if it can)."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        return f"expected a list of strings, got {_kind(value)}"
    if not value:
        return f"must name at least one of {', '.join(FIT_PARAMETERS)}"
    for v in value:
        if v not in FIT_PARAMETERS:
            return f"'{safe_text(v, 40)}' is not one of {', '.join(FIT_PARAMETERS)}"
    if len(set(value)) != len(value):
        return "names a parameter twice"
    return ""


#: Values of the ``compile`` parameter (= dlo_ros.solver.shape_solver.COMPILE_MODES).
COMPILE_MODES = ("background", "blocking", "cached", "off")


def compile_mode(value: Any) -> str:
    """The solver's compile mode for a ``compile`` parameter value.

    ROS reads ``-p compile:=off`` (and an unquoted ``off`` / ``no`` in YAML) as the boolean false,
    so false means 'off'; true means the default, 'background'.  Raises ValueError for anything
    else.
    """
    if isinstance(value, bool):
        return "background" if value else "off"
    if isinstance(value, str) and value in COMPILE_MODES:
        return value
    raise ValueError(
        f"compile: must be one of {', '.join(COMPILE_MODES)} (or false), got {value!r}"
    )


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
    """``string`` with the given ``string.*`` parameter values (unchanged values keep their
    tables).

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
    """Why ``name = value`` is refused at run time ('' if it is accepted).  Pure: changes
    nothing.
    """
    if not name or not name.strip():
        return "a parameter name must not be empty"
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
    if name == "fit.parameters":
        reason = fit_parameters_reason(value)
        return f"{name}: {reason}" if reason else ""
    if name in STRING_FIELDS:
        try:
            replace(problem, string=apply_string(problem.string, {name: value})).validate()
        except ValueError as exc:
            return str(exc)
    return ""


# ---- start-up: the command line, params files and -p values (pure; no rclpy) ------------------------------
#: Parameters rclpy declares on every node (accepted in params files and -p without a warning).
ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")
ROS_PARAMETER_PREFIXES = ("qos_overrides.",)
#: Longest ``scene`` / ``record.*`` value (a path).
PATH_CHARS = 4096
#: ROS arguments (inside --ros-args) that take a value: the value is skipped when looking for
# parameters.
_ROS_ARGS_WITH_VALUE = (
    "-r",
    "--remap",
    "-e",
    "--enclave",
    "--log-level",
    "--log-config-file",
    "--log-file-name",
)
_MODELS = ("", "auto", "full", "planar")


class ParamsError(ValueError):
    """The node's arguments, a params file or a parameter value is unusable (the message says
    which).
    """


@dataclass
class NodeArgs:
    """What :func:`prepare_node_args` made of the node's command line."""

    ros_args: list[str]  # for rclpy.init(args=...): program name first
    params_files: list[str]  # every params file rcl will read, in order
    values: dict[str, Any]  # this node's parameters from those files and -p (later wins)
    check: bool = False  # --check: validate and exit

    @property
    def scene(self) -> str:
        return str(self.values.get("scene") or DEFAULT_SCENE)


def node_argument_parser(prog: str = "dlo node") -> argparse.ArgumentParser:
    """The node's own options (everything after ``--ros-args`` goes to rclpy)."""
    ap = argparse.ArgumentParser(
        prog=prog,
        description="Run the dlo node (static cable shape for grip targets). ROS arguments go after --ros-args, "
        "e.g. --ros-args -r __ns:=/left_cell -p scene:=my_scene. Every params file and -p value is "
        "checked before the node starts (msg_docs/node.md).",
    )
    ap.add_argument(
        "--params-file",
        metavar="FILE",
        help="ROS parameters YAML (default: the shipped config/dlo_node.yaml when it exists)",
    )
    ap.add_argument(
        "--scene", metavar="NAME_OR_PATH", help="shorthand for --ros-args -p scene:=NAME_OR_PATH"
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="check the arguments, the params files, the parameters and the scene, then exit "
        "(0: the node would start) without starting ROS",
    )
    return ap


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(the program's own arguments, the tokens of every ``--ros-args`` section), as rcl splits
    them: a section runs from ``--ros-args`` to ``--`` or the end.
    """
    own: list[str] = []
    ros: list[str] = []
    inside = False
    for token in argv:
        if token == "--ros-args":
            inside = True
        elif inside and token == "--":
            inside = False
        elif inside:
            ros.append(token)
        else:
            own.append(token)
    return own, ros


def _yaml_value(text: str, where: str) -> Any:
    """A ``-p name:=value`` value as rcl reads it (YAML)."""
    import yaml

    try:
        return yaml.safe_load(text) if text.strip() else ""
    except yaml.YAMLError:
        return text  # rcl keeps it as a string


def check_value(name: str, value: Any) -> str:
    """Why ``name = value`` cannot be a start-up value of this node's parameter ('' if it can)."""
    spec = SPECS.get(name)
    if spec is None:
        return ""
    if spec.kind == "string":
        if name == "compile":
            try:
                compile_mode(value)
            except ValueError as exc:
                return str(exc).split(": ", 1)[1]
            return ""
        if not isinstance(value, str):
            return f"expected a string, got {_kind(value)}"
        limit = FRAME_ID_LIMIT if name == "frame_id" else PATH_CHARS
        if len(value) > limit:
            return f"{len(value)} characters, at most {limit}"
        if not value.isprintable():
            return f"must be printable text (no control characters, newlines or escape sequences): '{safe_text(value, 60)}'"
        if name == "frame_id" and value:
            if any(c.isspace() for c in value) or not normalise_frame(value).strip("/"):
                return (
                    f"'{safe_text(value, 60)}' is not a usable frame id (no spaces; not only '/'; empty means "
                    "the scene's frame_id)"
                )
        if name == "scene" and not value.strip():
            return "must name a scene (a shipped scene's name or a scene file's path)"
        if name == "solver.model" and value not in _MODELS:
            return f"must be empty, auto, full or planar, got '{safe_text(value, 40)}'"
        return ""
    if spec.kind == "bool":
        return "" if isinstance(value, bool) else f"expected true or false, got {_kind(value)}"
    if spec.kind == "string_array":
        if name == "fit.parameters":
            return fit_parameters_reason(value)
        ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
        return "" if ok else f"expected a list of strings, got {_kind(value)}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"expected {'an integer' if spec.kind == 'integer' else 'a number'}, got {_kind(value)}"
    if spec.kind == "integer" and not isinstance(value, int):
        return f"expected an integer, got {_kind(value)}"
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be finite, got {value}"
    if spec.low is not None and value < spec.low:
        return f"must be >= {spec.low:g}, got {safe_text(value, 40)}"
    if spec.high is not None and value > spec.high:
        return f"must be <= {spec.high:g}, got {safe_text(value, 40)}"
    return ""


def _kind(value: Any) -> str:
    if isinstance(value, (bool, int, float)) or value is None:
        return f"{type(value).__name__} {safe_text(repr(value), 40)}"
    if isinstance(value, str):
        return f"the string '{safe_text(value, 40)}'"
    return f"a {type(value).__name__}"


def unknown_reason(name: str) -> str:
    """Why ``name`` is not a parameter of this node ('' if it is one, or one of rclpy's own)."""
    if not name or not name.strip():
        return "a parameter name must not be empty"
    if name in SPECS or name in ROS_PARAMETERS or name.startswith(ROS_PARAMETER_PREFIXES):
        return ""
    close = difflib.get_close_matches(name, list(SPECS), n=1, cutoff=0.6)
    hint = f"; did you mean '{close[0]}'?" if close else f" (parameters: {', '.join(SPECS)})"
    return f"not a parameter of the dlo node{hint}"


def _applies(key: str, node_name: str) -> bool:
    """Whether a params file's node key (``/**``, ``dlo``, ``/cell1/dlo``, ``/**/dlo``) names this
    node.
    """
    last = key.rstrip("/").rsplit("/", 1)[-1]
    return last in ("*", "**", node_name) or key in ("/**", "**")


def _flatten(d: Mapping, prefix: str, out: dict[str, tuple[Any, str]], where: str) -> None:
    for k, v in d.items():
        if not isinstance(k, str):
            raise ParamsError(f"{where}: parameter names must be strings, got {_kind(k)}")
        name = f"{prefix}.{k}" if prefix else k
        if isinstance(v, dict):
            _flatten(v, name, out, where)
        else:
            out[name] = (v, where)


def read_params_file(path: str, node_name: str = "dlo") -> dict[str, tuple[Any, str]]:
    """This node's parameters in a ROS 2 params file: name -> (value, 'file:line' where it is set).

    Raises ParamsError naming the file (and line, key or parameter) for anything rcl would refuse
    or silently misread: not a regular file, over 1 MiB or the scene loader's YAML limits, a syntax
    error, not a mapping of node names to ``{ros__parameters: {...}}``, an empty or unknown
    parameter name, a value of the wrong type or out of range.
    """
    from ..scene import (
        FileLimitError,
        SceneError,
        compose_bounded_yaml,
        key_lines,  # LIMITS apply
        read_scene_text,
    )

    shown = safe_text(path, 4096)
    try:
        text = read_scene_text(path, shown)
    except SceneError as exc:
        raise ParamsError(
            f"params file {str(exc).replace('scene file', 'parameters file')}"
        ) from None
    try:
        data, root = compose_bounded_yaml(text, shown)
    except FileLimitError as exc:
        raise ParamsError(f"params file {exc}") from None
    lines = key_lines(root)
    shape = "a mapping of node names to {ros__parameters: {name: value, ...}} (e.g. '/**: {ros__parameters: ...}')"
    if not isinstance(data, dict) or not data:
        got = "an empty file" if data is None else f"a {type(data).__name__}"
        raise ParamsError(f"params file {shown}: a ROS parameters file must be {shape}, got {got}")
    found: dict[str, tuple[Any, str]] = {}
    for key, entry in data.items():
        key_text = safe_text(key, 60)
        at = f"{shown}:{lines.get(str(key), 1)}"
        if (
            not isinstance(key, str)
            or not isinstance(entry, dict)
            or "ros__parameters" not in entry
        ):
            raise ParamsError(
                f"params file {at}: node entry '{key_text}' must be {{ros__parameters: {{...}}}}: the "
                f"file must be {shape}"
            )
        extra = [k for k in entry if k != "ros__parameters"]
        if extra:
            raise ParamsError(
                f"params file {at}: node entry '{key_text}' has '{safe_text(extra[0], 40)}' next to "
                "ros__parameters (only ros__parameters is read)"
            )
        params = entry["ros__parameters"]
        if params is None:
            continue
        if not isinstance(params, dict):
            raise ParamsError(
                f"params file {at}: '{key_text}.ros__parameters' must be a mapping of parameter "
                f"names to values, got {_kind(params)}"
            )
        if not _applies(key, node_name):
            continue
        flat: dict[str, tuple[Any, str]] = {}
        _flatten(params, "", flat, shown)
        for name, (value, _) in flat.items():
            line = _line_of_param(lines, str(key), name)
            where = f"params file {shown}:{line}" if line else f"params file {shown}"
            found[name] = (value, where)
    return found


def _line_of_param(lines: Mapping[str, int], key: str, name: str) -> int | None:
    path = f"{key}.ros__parameters.{name}"
    while path:
        if path in lines:
            return lines[path]
        if "." not in path:
            return None
        path = path.rsplit(".", 1)[0]
    return None


def _check_all(values: Mapping[str, tuple[Any, str]]) -> list[str]:
    """The errors in this node's parameter values (name -> (value, where))."""
    errors: list[str] = []
    for name, (value, where) in values.items():
        reason = unknown_reason(name)
        if not reason and name in SPECS:
            reason = check_value(name, value)
        if reason:
            shown = (
                name
                if name and all(c.isalnum() or c in "_." for c in name)
                else f"'{safe_text(name, 60)}'"
            )
            errors.append(f"{where}: parameter {shown}: {reason}")
    return errors


def prepare_node_args(
    argv: Sequence[str], default_params_file: str | None = None, prog: str = "dlo node"
) -> NodeArgs:
    """Parse and check the node's command line before rclpy sees it.

    argv: the arguments after the program name (own options and ``--ros-args`` sections, in any
    order). Returns the arguments for ``rclpy.init`` (program name first; ``--params-file`` and
    ``--scene`` turned into a leading ``--ros-args`` section, so that later ``--ros-args`` values
    win, as before) and this node's effective parameter values.  Raises ParamsError naming the
    file/parameter; argparse exits (code 2) on an unknown own option, and prints help for
    ``--help``.
    """
    argv = list(argv)
    own, ros = split_ros_args(argv)
    args = node_argument_parser(prog).parse_args(own)
    if args.params_file is not None and not os.path.exists(args.params_file):
        raise ParamsError(f"--params-file {safe_text(args.params_file)}: no such file")
    params_file = args.params_file or default_params_file
    if args.scene is not None:
        reason = check_value("scene", args.scene)
        if reason:
            raise ParamsError(f"--scene: {reason}")

    # the node's name, as -r __node:=NAME (or dlo:__node:=NAME) sets it
    node_name = "dlo"
    tokens = iter(ros)
    for t in tokens:
        if t in ("-r", "--remap"):
            rule = next(tokens, "")
            lhs, _, rhs = rule.partition(":=")
            if lhs.rsplit(":", 1)[-1] == "__node" and rhs:
                node_name = rhs

    files: list[str] = [params_file] if params_file else []
    values: dict[str, tuple[Any, str]] = {}
    if params_file:
        values.update(read_params_file(params_file, node_name))
    if args.scene is not None:
        values["scene"] = (args.scene, "--scene")
    tokens = iter(ros)
    for t in tokens:
        if t in _ROS_ARGS_WITH_VALUE:
            next(tokens, None)
        elif t == "--params-file":
            f = next(tokens, None)
            if f is None:
                raise ParamsError("--ros-args --params-file: needs a file")
            if not os.path.exists(f):
                raise ParamsError(f"--ros-args --params-file {safe_text(f)}: no such file")
            files.append(f)
            values.update(read_params_file(f, node_name))
        elif t in ("-p", "--param"):
            rule = next(tokens, None)
            if rule is None or ":=" not in rule:
                raise ParamsError(f"--ros-args {t} {safe_text(rule or '')}: expected NAME:=VALUE")
            lhs, _, raw = rule.partition(":=")
            target, _, name = lhs.rpartition(":")
            if target and target != node_name:
                continue  # a parameter of another node (NODE:name:=value)
            values[name] = (_yaml_value(raw, name), f"--ros-args {t}")
    errors = _check_all(values)
    if errors:
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        raise ParamsError(errors[0] + more)

    ros_args = ["dlo_node"]
    if params_file or args.scene:
        ros_args.append("--ros-args")
        if params_file:
            ros_args += ["--params-file", params_file]
        if args.scene:
            ros_args += ["-p", f"scene:={args.scene}"]
        ros_args.append("--")
    ros_args += argv  # rcl takes the --ros-args sections (later ones win) and ignores the rest
    return NodeArgs(
        ros_args=ros_args,
        params_files=files,
        values={k: v for k, (v, _) in values.items()},
        check=args.check,
    )
