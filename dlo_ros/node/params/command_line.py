"""The node's command line, params files and ``-p`` values, checked before rclpy sees them.

The node's command line (``--params-file``, ``--scene``, ``--ros-args ...``) is parsed here
(:func:`prepare_node_args`): every params file (given, shipped default, or inside ``--ros-args``)
and every ``-p name:=value`` that applies to this node is read with the scene loader's bounded YAML
reader and checked against the parameter table, so a syntax error, a file that is not a ROS
parameters file, a misspelt name or an unusable value stops start-up with a message naming the file
and the parameter.  Pure: no rclpy.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import yaml

from ..validation import safe_text
from .table import DEFAULT_SCENE
from .values import check_value, describe_value, unknown_reason

#: ROS arguments (inside --ros-args) that take a value: the value is skipped when looking for
#: parameters.
ROS_ARGS_WITH_VALUE = (
    "-r",
    "--remap",
    "-e",
    "--enclave",
    "--log-level",
    "--log-config-file",
    "--log-file-name",
)


class ParamsError(ValueError):
    """The node's arguments, a params file or a parameter value is unusable (the message says)."""


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

    @property
    def managed(self) -> bool:
        """Return whether the ``managed`` parameter asks for the lifecycle node."""
        return self.values.get("managed") is True


def node_argument_parser(prog: str = "dlo node") -> argparse.ArgumentParser:
    """Build the parser of the node's own options (everything after ``--ros-args`` is rclpy's)."""
    ap = argparse.ArgumentParser(
        prog=prog,
        description="Run the dlo node (static cable shape for grip targets). ROS arguments go "
        "after --ros-args, "
        "e.g. --ros-args -r __ns:=/left_cell -p scene:=my_scene. Every params file and -p value "
        "is "
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
        "--managed",
        action="store_true",
        help="run as a managed (lifecycle) node: shorthand for --ros-args -p managed:=true",
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="check the arguments, the params files, the parameters and the scene, then exit "
        "(0: the node would start) without starting ROS",
    )
    return ap


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """Split ``argv`` into the program's own arguments and the tokens of its ``--ros-args``.

    As rcl splits them: a section runs from ``--ros-args`` to ``--`` or the end.
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
    """Read a ``-p name:=value`` value as rcl reads it (YAML)."""
    try:
        return yaml.safe_load(text) if text.strip() else ""
    except yaml.YAMLError:
        return text  # rcl keeps it as a string


def _applies(key: str, node_name: str) -> bool:
    """Return whether a params file's node key names this node.

    E.g. ``/**``, ``dlo``, ``/cell1/dlo``, ``/**/dlo``.
    """
    last = key.rstrip("/").rsplit("/", 1)[-1]
    return last in ("*", "**", node_name) or key in ("/**", "**")


def _flatten(d: Mapping, prefix: str, out: dict[str, tuple[Any, str]], where: str) -> None:
    for k, v in d.items():
        if not isinstance(k, str):
            raise ParamsError(f"{where}: parameter names must be strings, got {describe_value(k)}")
        name = f"{prefix}.{k}" if prefix else k
        if isinstance(v, dict):
            _flatten(v, name, out, where)
        else:
            out[name] = (v, where)


def read_params_file(path: str, node_name: str = "dlo") -> dict[str, tuple[Any, str]]:
    """Read this node's parameters in a ROS 2 params file: name -> (value, 'file:line').

    Raises ParamsError naming the file (and line, key or parameter) for anything rcl would refuse
    or silently misread: not a regular file, over 1 MiB or the scene loader's YAML limits, a syntax
    error, not a mapping of node names to ``{ros__parameters: {...}}``, an empty or unknown
    parameter name, a value of the wrong type or out of range.
    """
    # start-up: dlo_ros.scene loads dlo_ros.solver (0.8 s of 1.0 s for this package,
    # python -X importtime), which `dlo node --help` and the CLI's parser do not need
    from ...scene import (
        FileLimitError,
        SceneError,
        compose_bounded_yaml,
        key_lines,  # the scene loader's LIMITS apply
        read_scene_text,
    )

    shown = safe_text(path, 4096)
    try:
        text = read_scene_text(Path(path), shown)
    except SceneError as exc:
        raise ParamsError(
            f"params file {str(exc).replace('scene file', 'parameters file')}"
        ) from None
    try:
        data, root = compose_bounded_yaml(text, shown)
    except FileLimitError as exc:
        raise ParamsError(f"params file {exc}") from None
    lines = key_lines(root)
    shape = (
        "a mapping of node names to {ros__parameters: {name: value, ...}} "
        "(e.g. '/**: {ros__parameters: ...}')"
    )
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
                f"params file {at}: node entry '{key_text}' must be {{ros__parameters: {{...}}}}: "
                "the "
                f"file must be {shape}"
            )
        extra = [k for k in entry if k != "ros__parameters"]
        if extra:
            raise ParamsError(
                f"params file {at}: node entry '{key_text}' has '{safe_text(extra[0], 40)}' next "
                "to "
                "ros__parameters (only ros__parameters is read)"
            )
        params = entry["ros__parameters"]
        if params is None:
            continue
        if not isinstance(params, dict):
            raise ParamsError(
                f"params file {at}: '{key_text}.ros__parameters' must be a mapping of parameter "
                f"names to values, got {describe_value(params)}"
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
    """List the errors in this node's parameter values (name -> (value, where))."""
    errors: list[str] = []
    for name, (value, where) in values.items():
        reason = unknown_reason(name)
        if not reason:
            reason = check_value(name, value)
        if reason:
            shown = (
                name
                if name and all(c.isalnum() or c in "_." for c in name)
                else f"'{safe_text(name, 60)}'"
            )
            errors.append(f"{where}: parameter {shown}: {reason}")
    return errors


def remapped_node_name(ros: Sequence[str], default: str = "dlo") -> str:
    """Return the node's name as ``-r __node:=NAME`` (or ``dlo:__node:=NAME``) sets it."""
    node_name = default
    tokens = iter(ros)
    for t in tokens:
        if t in ("-r", "--remap"):
            rule = next(tokens, "")
            lhs, _, rhs = rule.partition(":=")
            if lhs.rsplit(":", 1)[-1] == "__node" and rhs:
                node_name = rhs
    return node_name


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

    node_name = remapped_node_name(ros)
    files: list[str] = [params_file] if params_file else []
    values: dict[str, tuple[Any, str]] = {}
    if params_file:
        values.update(read_params_file(params_file, node_name))
    if args.scene is not None:
        values["scene"] = (args.scene, "--scene")
    if args.managed:
        values["managed"] = (True, "--managed")
    tokens = iter(ros)
    for t in tokens:
        if t in ROS_ARGS_WITH_VALUE:
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
    if params_file or args.scene or args.managed:
        ros_args.append("--ros-args")
        if params_file:
            ros_args += ["--params-file", params_file]
        if args.scene:
            ros_args += ["-p", f"scene:={args.scene}"]
        if args.managed:
            ros_args += ["-p", "managed:=true"]
        ros_args.append("--")
    ros_args += argv  # rcl takes the --ros-args sections (later ones win) and ignores the rest
    return NodeArgs(
        ros_args=ros_args,
        params_files=files,
        values={k: v for k, (v, _) in values.items()},
        check=args.check,
    )
