"""The checks of the node's parameter values, and the string properties they set (pure, no ROS).

:func:`check_value` is the start-up check of one value (params files, ``-p``); :func:`check_live`
is what the node's on-set-parameters callback runs at run time: it returns the reason a value is
refused ('' if accepted) and changes nothing.  :func:`apply_string` turns ``string.*`` values into
the string's properties (a table-valued property is scaled as a whole).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import replace
from typing import Any, Mapping

from ...model.problem import Problem, StringProperties
from ...model.profile import Profile
from ..validation import FRAME_ID_LIMIT, normalise_frame, safe_text
from .table import (
    COMPILE_MODES,
    FIT_PARAMETERS,
    GRIP_TF_FRAME,
    MODELS,
    PATH_CHARS,
    ROS_PARAMETER_PREFIXES,
    ROS_PARAMETERS,
    SPECS,
    STRING_FIELDS,
)


def fit_parameters_reason(value: Any) -> str:
    """Why ``value`` cannot be ``fit.parameters`` ('' if it can)."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        return f"expected a list of strings, got {describe_value(value)}"
    if not value:
        return f"must name at least one of {', '.join(FIT_PARAMETERS)}"
    for v in value:
        if v not in FIT_PARAMETERS:
            return f"'{safe_text(v, 40)}' is not one of {', '.join(FIT_PARAMETERS)}"
    if len(set(value)) != len(value):
        return "names a parameter twice"
    return ""


def compile_mode(value: Any) -> str:
    """Return the solver's compile mode for a ``compile`` parameter value.

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
    """Return a property's parameter value: the constant, a table's maximum, 0 for None."""
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


def scaled_profile(profile: Profile | None, value: float) -> Profile:
    if profile is None or len(profile.values) == 1:
        return Profile.constant(value)
    top = max(profile.values)
    if top <= 0.0:
        return Profile.constant(value)
    return profile.scaled(value / top)


def apply_string(string: StringProperties, values: Mapping[str, float]) -> StringProperties:
    """Return ``string`` with the given ``string.*`` parameter values applied.

    Values that do not change keep their tables.  Raises ValueError naming the parameter for a
    value the model cannot take at run time.
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
                    f"{name}: cannot switch between inextensible (0) and extensible (> 0) at run "
                    "time: it "
                    "changes the model's unknowns; set it in the scene file"
                )
            changes[field] = None if value == 0.0 else scaled_profile(current, value)
            continue
        if field == "twist_stiffness" and current.is_zero != (value == 0.0):
            raise ValueError(
                f"{name}: cannot switch between 0 and > 0 at run time: it changes the model's "
                "unknowns; "
                "set it in the scene file"
            )
        changes[field] = scaled_profile(current, value)
    return replace(string, **changes) if changes else string


def check_live(name: str, value: Any, problem: Problem) -> str:
    """Return why ``name = value`` is refused at run time ('' if accepted); changes nothing."""
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


def check_value(name: str, value: Any) -> str:
    """Why ``name = value`` cannot be a start-up value of this node's parameter ('' if it can)."""
    if GRIP_TF_FRAME.match(name):  # a frame id, or empty (no tf2 target)
        return check_value("frame_id", value)
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
            return f"expected a string, got {describe_value(value)}"
        limit = FRAME_ID_LIMIT if name == "frame_id" else PATH_CHARS
        if len(value) > limit:
            return f"{len(value)} characters, at most {limit}"
        if not value.isprintable():
            return (
                "must be printable text (no control characters, newlines or escape sequences): "
                f"'{safe_text(value, 60)}'"
            )
        if name == "frame_id" and value:
            if any(c.isspace() for c in value) or not normalise_frame(value).strip("/"):
                return (
                    f"'{safe_text(value, 60)}' is not a usable frame id (no spaces; not only '/'; "
                    "empty means "
                    "the scene's frame_id)"
                )
        if name == "scene" and not value.strip():
            return "must name a scene (a shipped scene's name or a scene file's path)"
        if name == "solver.model" and value not in MODELS:
            return f"must be empty, auto, full or planar, got '{safe_text(value, 40)}'"
        return ""
    if spec.kind == "bool":
        return (
            ""
            if isinstance(value, bool)
            else f"expected true or false, got {describe_value(value)}"
        )
    if spec.kind == "string_array":
        if name == "fit.parameters":
            return fit_parameters_reason(value)
        ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
        return "" if ok else f"expected a list of strings, got {describe_value(value)}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        expected = "an integer" if spec.kind == "integer" else "a number"
        return f"expected {expected}, got {describe_value(value)}"
    if spec.kind == "integer" and not isinstance(value, int):
        return f"expected an integer, got {describe_value(value)}"
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be finite, got {value}"
    if spec.low is not None and value < spec.low:
        return f"must be >= {spec.low:g}, got {safe_text(value, 40)}"
    if spec.high is not None and value > spec.high:
        return f"must be <= {spec.high:g}, got {safe_text(value, 40)}"
    return ""


def describe_value(value: Any) -> str:
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
    if GRIP_TF_FRAME.match(name):  # one per grip: the grip is checked against the scene later
        return ""
    close = difflib.get_close_matches(name, list(SPECS), n=1, cutoff=0.6)
    hint = f"; did you mean '{close[0]}'?" if close else f" (parameters: {', '.join(SPECS)})"
    return f"not a parameter of the dlo node{hint}"
