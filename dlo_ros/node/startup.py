"""The node's start-up checks: its parameters declared, its scene loaded, its first problem built.

Everything here runs once, in the node's constructor, before any interface exists.  A bad scene or
parameter raises :class:`StartupError` with one line that names it; ``main`` prints that line and
exits with code 2.
"""

from __future__ import annotations

import importlib.util
import os
import re
from pathlib import Path
from dataclasses import dataclass, fields, replace
from typing import Any, Iterable

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.exceptions import InvalidTopicNameException, ParameterException
from rclpy.node import Node
from rclpy.validate_topic_name import validate_topic_name

from ..model.problem import Problem
from ..recording import Recorder, RecordingUnavailable
from ..scene import Scene, SceneError, load_scene
from ..solver.options import SolverOptions
from . import params as P
from .engine import options_with_output_points
from .validation import normalise_frame, safe_text

#: a grip name must be usable inside a topic name
GRIP_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
PARAMETER_TYPES = {
    "string": ParameterType.PARAMETER_STRING,
    "bool": ParameterType.PARAMETER_BOOL,
    "integer": ParameterType.PARAMETER_INTEGER,
    "double": ParameterType.PARAMETER_DOUBLE,
    "string_array": ParameterType.PARAMETER_STRING_ARRAY,
}


class StartupError(Exception):
    """The node cannot start (bad scene or parameters); the message says why.

    ``main`` prints it on one line and exits with code 2.
    """


@dataclass(frozen=True)
class StartSettings:
    """What the node starts with: its scene, frame, grips, first problem and compile mode."""

    scene: Scene
    frame_id: str
    grip_names: list[str]
    problem: Problem  # the scene's problem with the string.* parameters applied
    options: SolverOptions  # the scene's options with output_points and solver.model applied
    compile_mode: str  # params.COMPILE_MODES


def descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    """Build the rclpy descriptor of one parameter of the table (type, range, read-only)."""
    d = ParameterDescriptor(
        name=spec.name,
        type=PARAMETER_TYPES[spec.kind],
        description=spec.description,
        read_only=spec.read_only,
        additional_constraints=spec.constraints,
        dynamic_typing=spec.dynamic,
    )
    if spec.low is not None and spec.high is not None and spec.kind == "double":
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
        ]
    if spec.low is not None and spec.high is not None and spec.kind == "integer":
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    return d


def declare(node: Node, specs: Iterable[P.ParamSpec]) -> None:
    """Declare ``specs`` on ``node``; a value of a wrong type or out of range is a StartupError.

    A parameter declared already (a managed node configured again after ``cleanup``) keeps its
    value.
    """
    for spec in specs:
        if node.has_parameter(spec.name):
            continue
        try:
            node.declare_parameter(spec.name, spec.default, descriptor(spec))
        except ParameterException as exc:  # wrong type or out of range in the params file / -p
            raise StartupError(f"parameter {spec.name}: {safe_text(exc, 500)}") from None


def prepare(node: Node) -> StartSettings:
    """Declare every parameter of ``node``, load its scene and build its first problem.

    Raises StartupError naming the scene or parameter that is unusable.  The checks run in a
    fixed order (scene, frame, grip names, string properties, compile mode), so the first problem
    found is the one reported.
    """
    value = node.get_parameter
    declare(node, P.STATIC[:-1])
    declare(node, P.FIT)
    scene = read_scene(value("scene").value)
    frame_id = frame_of(scene, value("frame_id").value)
    grip_names = [g.name for g in scene.problem.grips]
    for name in grip_names:
        if not GRIP_NAME.match(name):
            raise StartupError(
                f"grip name '{safe_text(name, 60)}' cannot be used in a topic name (letters, "
                "digits, '_'; not starting with a digit)"
            )
    defaults = P.scene_values(scene.problem, scene.options.output_points)
    if not node.has_parameter("grip_names"):
        node.declare_parameter(
            "grip_names",
            defaults["grip_names"],
            descriptor(P.SPECS["grip_names"]),
            ignore_override=True,
        )
    declare(node, [replace(s, default=defaults.get(s.name, s.default)) for s in P.LIVE])
    declare_tf_frames(node, grip_names)
    check_topic(node, "planning_scene.topic")
    problem, options = initial_problem(scene, lambda name: value(name).value)
    try:
        mode = P.compile_mode(value("compile").value)
    except ValueError as exc:
        raise StartupError(f"parameter {exc}") from None
    if mode == "off":
        os.environ["DLO_NO_COMPILE"] = (
            "1"  # read by dlo_ros.solver.build.compiled (this process only)
        )
    return StartSettings(scene, frame_id, grip_names, problem, options, mode)


def declare_tf_frames(node: Node, grip_names: list[str]) -> None:
    """Declare ``grips.<grip>.tf_frame`` per grip; check the values for the scene and for tf2.

    A StartupError names the parameter: a grip the scene does not have, a value that is not a
    frame id, or a frame set where tf2_ros cannot be imported (targets from tf need it).
    """
    # what -p / params files set for this node; rclpy silently drops an override that no
    # declaration reads, so a misspelt grip would otherwise go unnoticed
    overrides = getattr(node, "_parameter_overrides", {})
    for name in overrides:
        match = P.GRIP_TF_FRAME.match(name)
        if match and match.group(1) not in grip_names:
            raise StartupError(
                f"parameter {name}: the scene has no grip '{match.group(1)}' (grips: "
                f"{', '.join(grip_names)})"
            )
    spec = P.ParamSpec(
        "",
        "string",
        "",
        "The tf2 frame whose pose is this grip's target "
        "(empty: targets from the target topics only).",
        read_only=True,
    )
    declare(node, [replace(spec, name=P.grip_tf_frame(g)) for g in grip_names])
    for g in grip_names:
        frame = node.get_parameter(P.grip_tf_frame(g)).value
        reason = P.check_value(P.grip_tf_frame(g), frame)
        if reason:
            raise StartupError(f"parameter {P.grip_tf_frame(g)}: {reason}")
        if frame and not node.get_parameter("use_tf").value:
            raise StartupError(
                f"parameter {P.grip_tf_frame(g)}='{safe_text(frame, 60)}': targets from tf2 need "
                "use_tf: true"
            )
        if frame and not tf_available():
            raise StartupError(
                f"parameter {P.grip_tf_frame(g)}='{safe_text(frame, 60)}': targets from tf2 need "
                "tf2_ros, which cannot be imported here (apt: ros-jazzy-tf2-ros-py; not on PyPI)"
            )


def check_topic(node: Node, name: str) -> None:
    """Raise StartupError naming parameter ``name`` when its value is not a valid topic name."""
    topic = node.get_parameter(name).value
    try:
        validate_topic_name(topic)
    except InvalidTopicNameException as exc:
        first = str(exc).splitlines()[0]
        raise StartupError(f"parameter {name}='{safe_text(topic, 60)}': {first}") from None


def tf_available() -> bool:
    """Return whether tf2_ros can be imported."""
    return importlib.util.find_spec("tf2_ros") is not None


def read_scene(name: str) -> Scene:
    """Load the scene of the ``scene`` parameter; a missing or invalid one is a StartupError."""
    try:
        return load_scene(name)
    except (SceneError, FileNotFoundError, OSError) as exc:
        raise StartupError(
            f"parameter scene='{safe_text(name)}': {safe_text(exc, 1000)}"
        ) from None


def frame_of(scene: Scene, frame_param: str) -> str:
    """Choose the node's frame: the ``frame_id`` parameter, else the scene's, else 'world'.

    Raises StartupError when the parameter or the scene's frame is not a usable frame id.
    """
    reason = P.check_value("frame_id", frame_param)  # also checked before rclpy
    if reason:
        raise StartupError(f"parameter frame_id: {reason}")
    frame_id = normalise_frame(frame_param or scene.frame_id or "world")
    if not frame_id.strip("/") or P.check_value("frame_id", frame_id):
        raise StartupError(
            f"scene frame_id '{safe_text(scene.frame_id, 60)}' ({safe_text(scene.source)}) is "
            "not a usable frame id; set the parameter frame_id"
        )
    return frame_id


def initial_problem(scene: Scene, value: Any) -> tuple[Problem, SolverOptions]:
    """Apply the parameters (``value(name)``) to the scene's problem and options; validate both.

    Raises StartupError when the combination is not a valid problem.
    """
    values = {name: value(name) for name in P.STRING_FIELDS}
    try:
        string = P.apply_string(scene.problem.string, values)
        problem = replace(scene.problem, string=string)
        problem.validate()
        options = options_with_output_points(scene.options, value("output_points"))
        model = value("solver.model")
        if model:
            if "model" not in {f.name for f in fields(options)}:
                raise ValueError("solver.model: this solver has no model option")
            options = replace(options, model=model)
        options.validate()
    except ValueError as exc:
        raise StartupError(f"parameters: {safe_text(exc, 500)}") from None
    return problem, options


def start_recorder(node: Node, scene: Scene, frame_id: str, session: int = 1) -> Recorder:
    """Open the rerun recording of the ``record.*`` parameters and log ``scene`` into it.

    The recorder is off (every call a no-op) when both parameters are empty.  An unusable file or
    address is a StartupError.  ``session`` > 1 (a managed node configured again) records to
    ``<stem>.<session><suffix>`` beside ``record.rrd``, so that no configure overwrites an
    earlier one's file.
    """
    rrd = node.get_parameter("record.rrd").value or None
    if rrd and session > 1:
        path = Path(rrd)
        rrd = str(path.with_name(f"{path.stem}.{session}{path.suffix}"))
    connect = node.get_parameter("record.connect").value or None
    try:
        recorder = Recorder(rrd=rrd, connect=connect)
    except (RecordingUnavailable, ValueError, RuntimeError, OSError) as exc:
        raise StartupError(
            f"parameters record.rrd='{safe_text(rrd or '')}' / "
            f"record.connect='{safe_text(connect or '')}': {safe_text(exc, 500)}"
        ) from None
    if recorder.enabled:
        try:
            recorder.log_scene(scene, frame_id=frame_id)
        except Exception:
            recorder.close()
            raise
        where = " and ".join(
            x for x in (str(recorder.rrd) if recorder.rrd else "", recorder.url or "") if x
        )
        node.get_logger().info(f"recording to {safe_text(where)}")
    return recorder
