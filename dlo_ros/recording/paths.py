"""Entity paths and timelines of a dlo_ros recording.

Entity paths and timelines of a dlo_ros recording: the names the writer logs under and replay
reads back.

Entity tree (world frame, right-handed, z up, metres; timelines ``update`` (sequence) and
``ros_time`` (timestamp)):

=============================  ===================================================================
``world``                      ViewCoordinates RIGHT_HAND_Z_UP (static)
``world/obstacles/<i>_<name>`` the scene's obstacles as their own shapes (static)
``world/cable``                centreline: one segment per pair of samples, coloured by bend energy
                               density ½ Rf κ² (viridis; scale in ``scene/legend``)
``world/cable/frames``         material frames at a few samples (x tangent red, y green, z blue)
``world/grips/<name>``         grip pose (axes) at the grip's s on the solved shape
``world/grips/<name>/force``   force the gripper exerts on the string (arrow, label in N)
``world/targets/<name>``       the grip target as received (point + tangent arrow)
``timeseries/solve_time_ms``   wall time of each solve [ms]
``timeseries/iterations``      Newton steps or IPOPT iterations
``timeseries/energy``          bend, twist, stretch, gravity, external_work, total [J]
``timeseries/min_eigenvalue``  smallest reduced Hessian eigenvalue (< 0: unstable); where the
                               inertia alone showed the shape stable, at most once a second
                               (``recorder.EIGEN_PERIOD_S``)
``model/<key>``                the solver's model per update (``ShapeResult.model``): ``order``,
                               ``variables``, ``planar`` (1/0), ``estimated_error_m``,
                               ``tolerance_m``
``events/status``              status text, logged when it (or stability) changes
``events/rejected``            every rejected input with its reason (WARN) ``events/model``
model events (INFO): changes of the model with their reasons, scene changes ``events/recorder``
the recorder's own warnings (dropped items) ``world/fit/observed``         the node's fits
(``log_fit``): observed points, red beyond the robust ``world/fit/fitted``           loss's
threshold; the fitted centreline; one segment per point to its ``world/fit/residuals``
nearest point on it (dlo_ros.identify.drawing), at the fit's update ``events/fit``
each fit's summary line and what it applied (INFO; WARN if not ok) ``scene/yaml``
the scene file (scene_to_dict as YAML), static; ``scene/changes`` later ones ``scene/legend``
colour and arrow scales (static) ``data/result``                exact float64 copy of each result
(for ``dlo replay --resolve``) ``data/targets``               exact float64 copy of each received
target set
=============================  ===================================================================
"""

from __future__ import annotations

TIMELINE_UPDATE = "update"
TIMELINE_ROS = "ros_time"

E_WORLD = "world"
E_CABLE = "world/cable"
E_FRAMES = "world/cable/frames"
E_GRIPS = "world/grips"
E_TARGETS = "world/targets"
E_OBSTACLES = "world/obstacles"
E_SOLVE_TIME = "timeseries/solve_time_ms"
E_ITERATIONS = "timeseries/iterations"
E_ENERGY = "timeseries/energy"
E_EIGEN = "timeseries/min_eigenvalue"
E_MODEL_SERIES = (
    "model"  # model/<key>: scalars of ShapeResult.model, one row per result that has them
)
#: ShapeResult.model entries recorded as scalars (model/<key>; booleans as 1/0), with their series
#: names.
MODEL_SCALARS = {
    "order": "basis order",
    "variables": "unknowns",
    "planar": "planar (1) / 3D (0)",
    "estimated_error_m": "estimated error [m]",
    "tolerance_m": "tolerance [m]",
}
E_STATUS = "events/status"
E_REJECTED = "events/rejected"
E_MODEL = "events/model"
E_RECORDER = "events/recorder"
# world/fit/{observed,fitted,residuals}: the node's newest fit (dlo_ros.identify.drawing)
E_FIT = "world/fit"
E_FIT_EVENTS = "events/fit"  # each fit's summary and what it applied (INFO) or why not (WARN)
E_ENVELOPE = "world/envelope"  # the k-σ tube of the newest envelope: a ball per output point
E_ENVELOPE_EVENTS = "events/envelope"  # each envelope's one-line summary
E_SCENE = "scene/yaml"
E_SCENE_CHANGES = "scene/changes"
E_LEGEND = "scene/legend"
E_DATA_RESULT = "data/result"
E_DATA_TARGETS = "data/targets"
#: Series of ``timeseries/energy``, in the order they are logged.
ENERGY_TERMS = ("bend", "twist", "stretch", "gravity", "external_work", "total")


def path_part(name: str) -> str:
    """Return a name as one entity-path part."""
    cleaned = "".join(c if c.isalnum() or c in "_-" else "_" for c in str(name))
    return cleaned or "_"
