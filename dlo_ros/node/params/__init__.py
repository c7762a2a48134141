"""The node's parameters: their table, the checks of their values and the node's command line.

Pure, no ROS.  The scene file (parameter ``scene``) defines the problem.  The string's properties,
the output resolution and a few presentation settings are parameters that may change at run time;
everything that names a file or changes the model's structure is read-only.

Modules: :mod:`.table` (names, types, defaults, ranges: ``STATIC``, ``LIVE``, ``FIT``,
``SPECS``), :mod:`.values` (``check_value`` at start-up, ``check_live`` at run time,
``apply_string``) and :mod:`.command_line` (``prepare_node_args``: the command line, params files
and ``-p`` values checked before rclpy sees them).  Callers import everything from here.
"""

from __future__ import annotations

from .command_line import (
    NodeArgs,
    ParamsError,
    node_argument_parser,
    prepare_node_args,
    read_params_file,
    split_ros_args,
)
from .table import (
    COMPILE_MODES,
    DEFAULT_SCENE,
    FIT,
    FIT_PARAMETERS,
    GRIP_TF_FRAME,
    LIVE,
    MODELS,
    PATH_CHARS,
    ROS_PARAMETER_PREFIXES,
    ROS_PARAMETERS,
    SPECS,
    STATIC,
    STRING_FIELDS,
    ParamSpec,
    grip_tf_frame,
)
from .values import (
    apply_string,
    check_live,
    check_value,
    compile_mode,
    describe_value,
    fit_parameters_reason,
    profile_value,
    scaled_profile,
    scene_values,
    unknown_reason,
)

__all__ = [
    "COMPILE_MODES",
    "DEFAULT_SCENE",
    "FIT",
    "FIT_PARAMETERS",
    "GRIP_TF_FRAME",
    "LIVE",
    "MODELS",
    "PATH_CHARS",
    "ROS_PARAMETERS",
    "ROS_PARAMETER_PREFIXES",
    "SPECS",
    "STATIC",
    "STRING_FIELDS",
    "NodeArgs",
    "ParamSpec",
    "grip_tf_frame",
    "ParamsError",
    "apply_string",
    "check_live",
    "check_value",
    "compile_mode",
    "describe_value",
    "fit_parameters_reason",
    "node_argument_parser",
    "prepare_node_args",
    "profile_value",
    "read_params_file",
    "scaled_profile",
    "scene_values",
    "split_ros_args",
    "unknown_reason",
]
