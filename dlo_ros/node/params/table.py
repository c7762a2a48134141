"""The node's parameter table: every parameter's name, type, default, range and description.

Pure data (no ROS): the node declares these (startup.py), the checks (values.py) and the command
line (command_line.py) read them.  ``from_scene`` parameters take their default from the scene
file; ``read_only`` ones are fixed at start-up; the others may change at run time.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

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


#: Per-grip parameters ``grips.<grip>.tf_frame`` (string, read-only, default ''): the tf2 frame
#: whose pose is that grip's target (msg_docs/node.md, "Targets from tf2").  One per scene grip.
GRIP_TF_FRAME = re.compile(r"^grips\.([A-Za-z_][A-Za-z0-9_]*)\.tf_frame$")


def grip_tf_frame(grip: str) -> str:
    """Return the name of grip ``grip``'s tf_frame parameter."""
    return f"grips.{grip}.tf_frame"


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
        "How the solver gets compiled (C) derivatives, cached per machine in ~/.cache/dlo_ros: "
        "'background' "
        "(solve at once, interpreted, switch to C when gcc is done: seconds for a new scene "
        "structure or "
        "after a solver change), 'blocking' (compile before the first solve), 'cached' (only a "
        "library "
        "compiled earlier), 'off' (interpreted only; also false, as `-p compile:=off` reads as "
        "one).",
        read_only=True,
        constraints="one of: background, blocking, cached, off (or false)",
        dynamic=True,
    ),
    ParamSpec(
        "solver.model",
        "string",
        "",
        "Override the scene's solver.model: 'auto' (the solver picks the smallest model the scene "
        "needs), "
        "'full' (3D) or 'planar'; empty: the scene's value.",
        read_only=True,
        constraints="empty, auto, full or planar",
    ),
    ParamSpec(
        "use_tf",
        "bool",
        True,
        "Transform targets from other frames with tf2 when tf2_ros is importable (else they are "
        "rejected).",
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
        "Period [s] of ~/markers (the newest shape); building and publishing a MarkerArray in "
        "Python "
        "holds the GIL the solver needs for about 2 ms.",
        read_only=True,
        low=0.02,
        high=60.0,
    ),
    ParamSpec(
        "record.rrd",
        "string",
        "",
        "Save a rerun recording of every solve, target and rejected input to this .rrd file (dlo "
        "replay "
        "FILE opens it); empty: no file.",
        read_only=True,
    ),
    ParamSpec(
        "record.connect",
        "string",
        "",
        "Stream the rerun recording to a running viewer at HOST[:PORT] or a "
        "rerun+http://HOST:PORT/proxy "
        "URL; empty: no streaming.",
        read_only=True,
    ),
    ParamSpec(
        "query_workers",
        "integer",
        1,
        "Worker processes that answer ~/query_shape beside the stream, each with its own solver "
        "of the "
        "scene (they take the other cores); 0: queries are solved in the solver thread between "
        "stream "
        "updates.",
        read_only=True,
        low=0,
        high=16,
    ),
    ParamSpec(
        "query_timeout",
        "double",
        30.0,
        "Longest a query worker may take for one ~/query_shape [s]; past it the call answers an "
        "empty plan "
        "(timeout) and the worker is killed and replaced. 0 = no limit.",
        read_only=True,
        low=0.0,
        high=3600.0,
    ),
    ParamSpec(
        "managed",
        "bool",
        False,
        "Run as a managed (lifecycle) node: it starts unconfigured, builds its solver on "
        "configure and publishes shapes only while active (msg_docs/node.md); the same as "
        "`dlo node --managed`.",
        read_only=True,
    ),
    ParamSpec(
        "configure_timeout",
        "double",
        120.0,
        "Longest a managed node's configure transition waits for its solver and first shape [s]; "
        "past it the transition fails and the node stays unconfigured.",
        read_only=True,
        low=1.0,
        high=3600.0,
    ),
    ParamSpec(
        "planning_scene.enabled",
        "bool",
        True,
        "Publish the cable as a chain of capsules (~/capsules markers; a moveit_msgs "
        "CollisionObject too when moveit_msgs is importable), msg_docs/planning_scene.md.",
        read_only=True,
    ),
    ParamSpec(
        "planning_scene.rate",
        "double",
        2.0,
        "Rate [Hz] of the capsules (only when the shape changed).",
        read_only=True,
        low=0.01,
        high=100.0,
    ),
    ParamSpec(
        "planning_scene.padding",
        "double",
        0.01,
        "Padding [m] around the cable's tube (string.radius): the capsules contain the tube and "
        "reach at most this far beyond it.",
        read_only=True,
        low=1e-4,
        high=1.0,
    ),
    ParamSpec(
        "planning_scene.topic",
        "string",
        "/collision_object",
        "Topic of the moveit_msgs/CollisionObject (MoveIt's planning scene monitor listens on "
        "/collision_object); used only when moveit_msgs is importable.",
        read_only=True,
    ),
    ParamSpec(
        "envelope.rate",
        "double",
        1.0,
        "Rate [Hz] of the shape and tension envelope (~/envelope, diagnostics, recording) when "
        "the scene has string.uncertainty or a fit gave a covariance; computed only while the "
        "solver is idle; 0: never.",
        read_only=True,
        low=0.0,
        high=100.0,
    ),
    ParamSpec(
        "envelope.k",
        "double",
        2.0,
        "The envelope tube's radius in standard deviations: k sigma(s) about the centreline.",
        read_only=True,
        low=0.1,
        high=10.0,
    ),
    ParamSpec(
        "tf_targets.rate",
        "double",
        20.0,
        "Rate [Hz] at which grips with a grips.<grip>.tf_frame read their target from tf2 (needs "
        "tf2_ros); a target is handed to the solver only when it moved.",
        read_only=True,
        low=0.1,
        high=1000.0,
    ),
    ParamSpec(
        "grip_names",
        "string_array",
        [],
        "Informational: the scene's grips in configuration order (the order of ~/grips/targets "
        "poses).",
        read_only=True,
        from_scene=True,
    ),
)

#: String properties: parameter name -> StringProperties field.  A table-valued (s-dependent)
#: property is represented by its maximum; setting the parameter scales the whole table.
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
        "Bending stiffness Rf [N m^2] (> 0). For an s-dependent table: its maximum; setting it "
        "scales the table.",
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
        "Extensional stiffness Re [N]; 0 = inextensible. Cannot switch between 0 and > 0 at run "
        "time.",
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
        "Centreline samples in ~/centerline and the markers (a change rebuilds the solver: next "
        "solve is cold).",
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
        "Subscribe to ~/observed (sensor_msgs/PointCloud2) and serve ~/fit: identify the string's "
        "properties "
        "from the observed shape in a worker process beside the stream.",
        read_only=True,
    ),
    ParamSpec(
        "fit.period_s",
        "double",
        0.0,
        "Fit continuously: every period_s [s], when a cloud arrived since the last fit; 0 = only "
        "on ~/fit.",
        read_only=True,
        low=0.0,
        high=3600.0,
    ),
    ParamSpec(
        "fit.max_points",
        "integer",
        20000,
        "Largest ~/observed cloud [points] accepted; a larger one is refused by its size before "
        "it is read.",
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
        "Apply an estimate to the string.* parameters only when the relative standard deviation "
        "of every "
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

#: Values of the ``compile`` parameter (= dlo_ros.solver.shape_solver.COMPILE_MODES).
COMPILE_MODES = ("background", "blocking", "cached", "off")
#: Values of the ``solver.model`` parameter ('' = the scene's).
MODELS = ("", "auto", "full", "planar")
#: Parameters rclpy declares on every node (accepted in params files and -p without a warning).
ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")
ROS_PARAMETER_PREFIXES = ("qos_overrides.",)
#: Longest ``scene`` / ``record.*`` value (a path).
PATH_CHARS = 4096
