"""Observations of a string's shape, and the observation file (``msg_docs/fitting.md``).

An observation is one static shape: the grip poses it was held at and observed centreline points
(unordered, noisy with a stated σ, possibly partial), optionally the force and the torque measured
at a grip (each at one grip, not necessarily the same).  An observation set adds what is fitted,
the scene it refers to and, optionally, the known total mass. Every reader raises
``ObservationError`` (a ValueError) whose message starts with the offending key path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from ..model.problem import GripPose, Problem, finite_vector
from ..scene import LIMITS, FileLimitError, parse_bounded_yaml, read_regular_file
from .pointfiles import MAX_POINTS, read_points

#: parameters that can be fitted: bend, twist and stretch stiffness and weight per length
PARAMETERS = ("Rf", "Rt", "D", "Re")
#: standard gravity [m/s²]: a known mass [kg] is turned into a weight [N] with it
STANDARD_GRAVITY = 9.80665
#: the most observations in one set: each builds its own equilibrium solver (about 1.5 MB each, and
#: one solve per observation and iteration)
MAX_OBSERVATIONS = 100
#: the most points over all observations of a set (the residuals and their Jacobian are held at
#: once)
MAX_TOTAL_POINTS = 1_000_000
#: the largest coordinate [m] of a point or a grip position: farther is no cable in a lab (1e30 m
#: made every later number meaningless and ``--write-scene`` wrote a weight of 5e-7 N/m)
MAX_COORDINATE = 1e4
#: the largest σ of the points [m], and of a force [N], torque [N·m] or mass [kg]
MAX_SIGMA = {"points": 1.0, "force": 1e6, "torque": 1e6, "mass": 1e6}
#: the largest observation file [bytes] (the scene files' limit; large clouds go in points_file)
FILE_BYTES = LIMITS["file_bytes"]
#: the most knots of a piecewise-linear profile fit
MAX_KNOTS = 50


class ObservationError(ValueError):
    """A malformed observation or observation file; the message starts with the key path."""


@dataclass(frozen=True)
class ForceObservation:
    """A measured grip force on the string, with its noise.

    The force [N] one grip exerts ON the string (world frame; a sensor on the gripper reads
    −force), with its standard deviation σ [N] per component.
    """

    grip: str
    force: np.ndarray
    sigma: float


@dataclass(frozen=True)
class TorqueObservation:
    """A measured grip torque on the string about the grip point, with its noise.

    The torque [N·m] one grip exerts ON the string about the grip point (world frame), with its
    standard deviation σ [N·m] per component.  A sensor on the gripper with origin o reading (F_s,
    T_s) gives torque = −(T_s − r × F_s), r = x_grip − o.  The grip must hold an orientation (a pin
    exerts no torque).
    """

    grip: str
    torque: np.ndarray
    sigma: float


@dataclass(frozen=True)
class Observation:
    """One observed static shape: grip poses, points, their noise, grip force and torque.

    One static shape: grip poses (grips not named keep the scene's poses), observed points (N,
    3) [m] in any order, their noise σ [m] (standard deviation per coordinate), an optional grip
    force and an optional grip torque.
    """

    name: str
    poses: dict[str, GripPose]
    points: np.ndarray
    sigma: float
    force: ForceObservation | None = None
    torque: TorqueObservation | None = None


@dataclass(frozen=True)
class MassObservation:
    """The string's known total mass [kg] and its standard deviation [kg]."""

    value: float
    sigma: float

    @property
    def weight(self) -> tuple[float, float]:
        """(weight, σ) [N]."""
        return self.value * STANDARD_GRAVITY, self.sigma * STANDARD_GRAVITY


@dataclass(frozen=True)
class ProfileFit:
    """How to fit one material as a smooth piecewise-linear table.

    Fit a material as a piecewise-linear table of ``knots`` values evenly spaced over [0, L],
    with the smoothness regulariser of weight ``smoothing`` (``parameters.py``).
    """

    knots: int
    smoothing: float = 1.0


@dataclass(frozen=True)
class ObservationSet:
    """Everything a fit is given: observations, parameters, scene and known mass.

    What a fit is given: the observations, the parameters to identify, the scene (name or path,
    '' when the caller supplies it) and the known total mass.
    """

    observations: tuple[Observation, ...]
    parameters: tuple[str, ...] = ("Rf", "D")
    scene: str = ""
    total_mass: MassObservation | None = None
    source: str = field(default="<dict>", compare=False)
    profiles: dict[str, ProfileFit] = field(default_factory=dict)

    def check(self, problem: Problem) -> None:
        """Check that the observations fit ``problem``.

        Raise ObservationError when the observations do not fit ``problem`` (unknown grips, a
        torque at a pin).
        """
        names = {g.name for g in problem.grips}
        modes = {g.name: g.mode for g in problem.grips}
        for i, obs in enumerate(self.observations):
            for grip in obs.poses:
                if grip not in names:
                    raise ObservationError(
                        f"observations[{i}].grips.{grip}: no such grip in the scene "
                        f"(grips: {sorted(names)})"
                    )
            if obs.force is not None and obs.force.grip not in names:
                raise ObservationError(
                    f"observations[{i}].force.grip: no grip {obs.force.grip!r} in the scene"
                )
            if obs.torque is not None and obs.torque.grip not in names:
                raise ObservationError(
                    f"observations[{i}].torque.grip: no grip {obs.torque.grip!r} in the scene"
                )
            if obs.torque is not None and modes[obs.torque.grip] == "pin":
                raise ObservationError(
                    f"observations[{i}].torque.grip: grip {obs.torque.grip!r} is a pin: it exerts "
                    "no torque (measure it at a clamp or tangent grip)"
                )


# ---- readers ------------------------------------------------------------------------------------
def _positive(value: object, key: str, upper: float = float("inf")) -> float:
    if isinstance(value, bool):
        raise ObservationError(f"{key}: expected a number > 0, got {value!r}")
    try:
        x = float(cast(Any, value))  # any object: float() says whether it is a number
    except (TypeError, ValueError):
        raise ObservationError(
            f"{key}: expected a number > 0, got {type(value).__name__}"
        ) from None
    if not (np.isfinite(x) and x > 0):
        raise ObservationError(f"{key}: expected a finite number > 0, got {x}")
    if x > upper:
        raise ObservationError(
            f"{key}: {x:g} is over the limit of {upper:g} (msg_docs/fitting.md, Limits)"
        )
    return x


def _mapping(value: object, key: str) -> dict:
    if not isinstance(value, dict):
        raise ObservationError(f"{key}: expected a mapping, got {type(value).__name__}")
    return value


def _only(d: dict, allowed: tuple[str, ...], key: str) -> None:
    unknown = sorted(str(k) for k in d if k not in allowed)
    if unknown:
        where = f"{key}.{unknown[0]}" if key else unknown[0]
        raise ObservationError(f"{where}: unknown key (known: {', '.join(allowed)})")


def _points(value: object, key: str) -> np.ndarray:
    if isinstance(value, list) and len(value) > MAX_POINTS:
        raise ObservationError(f"{key}: {len(value)} points, over the limit of {MAX_POINTS}")
    if isinstance(value, np.ndarray) and value.dtype.kind not in "fiu":
        raise ObservationError(
            f"{key}: the points must be real numbers, got dtype {value.dtype.kind!r}"
        )
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ObservationError(f"{key}: expected a list of [x, y, z] points") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ObservationError(
            f"{key}: expected N rows of [x, y, z], got an array of shape {arr.shape}"
        )
    if arr.shape[0] < 3:
        raise ObservationError(f"{key}: at least 3 points are needed, got {arr.shape[0]}")
    if arr.shape[0] > MAX_POINTS:
        raise ObservationError(f"{key}: {arr.shape[0]} points, over the limit of {MAX_POINTS}")
    bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
    if bad.size:
        raise ObservationError(f"{key}[{bad[0]}]: contains NaN or infinity")
    far = np.flatnonzero(np.any(np.abs(arr) > MAX_COORDINATE, axis=1))
    if far.size:
        raise ObservationError(
            f"{key}[{far[0]}]: a coordinate of {np.abs(arr[far[0]]).max():.3g} "
            f"m, over the limit of {MAX_COORDINATE:g} m (msg_docs/fitting.md, "
            "Limits)"
        )
    return arr


def _points_file(value: object, key: str, base: Path) -> np.ndarray:
    if not isinstance(value, str) or not value:
        raise ObservationError(f"{key}: expected a file name (.npy or .ply)")
    path = Path(value) if Path(value).is_absolute() else base / value
    try:
        arr = read_points(path)
    except FileNotFoundError:
        raise ObservationError(f"{key}: no such file: {path}") from None
    except (OSError, ValueError) as exc:
        raise ObservationError(f"{key}: cannot read {path}: {str(exc)[:300]}") from None
    return _points(arr, key)


def _grip_vector(value: object, key: str, field: str) -> tuple[str, np.ndarray, float]:
    """(grip, 3-vector, σ) of a measured force or torque mapping {grip, <field>, sigma}."""
    d = _mapping(value, key)
    _only(d, ("grip", field, "sigma"), key)
    for name in ("grip", field, "sigma"):
        if name not in d:
            raise ObservationError(f"{key}.{name}: missing")
    if not isinstance(d["grip"], str):
        raise ObservationError(f"{key}.grip: expected a grip name")
    try:
        vector = finite_vector(d[field], 3, f"{key}.{field}")
    except (TypeError, ValueError) as exc:
        raise ObservationError(str(exc)) from None
    return d["grip"], vector, _positive(d["sigma"], f"{key}.sigma", MAX_SIGMA[field])


def _force(value: object, key: str) -> ForceObservation:
    return ForceObservation(*_grip_vector(value, key, "force"))


def _torque(value: object, key: str) -> TorqueObservation:
    return TorqueObservation(*_grip_vector(value, key, "torque"))


def _observation(value: object, key: str, sigma: float | None, base: Path) -> Observation:
    d = _mapping(value, key)
    _only(d, ("name", "grips", "points", "points_file", "sigma", "force", "torque"), key)
    if ("points" in d) == ("points_file" in d):
        raise ObservationError(f"{key}.points: give exactly one of points or points_file")
    points = (
        _points(d["points"], f"{key}.points")
        if "points" in d
        else _points_file(d["points_file"], f"{key}.points_file", base)
    )
    s = _positive(d["sigma"], f"{key}.sigma", MAX_SIGMA["points"]) if "sigma" in d else sigma
    if s is None:
        raise ObservationError(f"{key}.sigma: missing (give it here or at the top level)")
    poses = {}
    for grip, pose in _mapping(d.get("grips", {}), f"{key}.grips").items():
        where = f"{key}.grips.{grip}"
        pd = _mapping(pose, where)
        _only(pd, ("position", "orientation"), where)
        for name in ("position", "orientation"):
            if name not in pd:
                raise ObservationError(f"{where}.{name}: missing")
        try:
            poses[str(grip)] = GripPose.checked(pd["position"], pd["orientation"], where)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ObservationError(str(exc)) from None
        if np.abs(poses[str(grip)].position).max() > MAX_COORDINATE:
            raise ObservationError(
                f"{where}.position: a coordinate over the limit of "
                f"{MAX_COORDINATE:g} m (msg_docs/fitting.md, Limits)"
            )
    force = _force(d["force"], f"{key}.force") if d.get("force") is not None else None
    torque = _torque(d["torque"], f"{key}.torque") if d.get("torque") is not None else None
    return Observation(str(d.get("name", key)), poses, points, s, force, torque)


def observation_set_from_dict(
    d: object, source: str = "<dict>", base: Path | None = None
) -> ObservationSet:
    """Parse the observation file's content (module docstring of ``msg_docs/fitting.md``)."""
    if not isinstance(d, dict):
        raise ObservationError(
            f"expected a mapping of keys (scene, parameters, sigma, total_mass, observations), "
            f"got {type(d).__name__}"
        )
    _only(d, ("scene", "parameters", "sigma", "total_mass", "profiles", "observations"), "")
    base = base or Path(".")
    sigma = _positive(d["sigma"], "sigma", MAX_SIGMA["points"]) if "sigma" in d else None
    params = d.get("parameters", ["Rf", "D"])
    if not isinstance(params, list) or not params:
        raise ObservationError(f"parameters: expected a non-empty list among {list(PARAMETERS)}")
    for i, name in enumerate(params):
        if name not in PARAMETERS:
            raise ObservationError(
                f"parameters[{i}]: unknown parameter {name!r} (known: {', '.join(PARAMETERS)})"
            )
    if len(set(params)) != len(params):
        raise ObservationError("parameters: a parameter is listed twice")
    mass = None
    if d.get("total_mass") is not None:
        md = _mapping(d["total_mass"], "total_mass")
        _only(md, ("value", "sigma"), "total_mass")
        if "value" not in md:
            raise ObservationError("total_mass.value: missing")
        value = _positive(md["value"], "total_mass.value", MAX_SIGMA["mass"])
        mass = MassObservation(
            value, _positive(md.get("sigma", 1e-3 * value), "total_mass.sigma", MAX_SIGMA["mass"])
        )
    profiles = {}
    for name, spec in _mapping(d.get("profiles") or {}, "profiles").items():
        where = f"profiles.{name}"
        if name not in params:
            raise ObservationError(f"{where}: {name!r} is not in parameters")
        spec = _mapping(spec, where)
        _only(spec, ("knots", "smoothing"), where)
        knots = spec.get("knots")
        if isinstance(knots, bool) or not isinstance(knots, int) or not 2 <= knots <= MAX_KNOTS:
            raise ObservationError(
                f"{where}.knots: expected an integer in [2, {MAX_KNOTS}], got {knots!r}"
            )
        smoothing = spec.get("smoothing", 1.0)
        if (
            isinstance(smoothing, bool)
            or not isinstance(smoothing, (int, float))
            or not 0 <= smoothing < 1e12
        ):
            raise ObservationError(f"{where}.smoothing: expected a number >= 0, got {smoothing!r}")
        profiles[str(name)] = ProfileFit(knots, float(smoothing))
    if "observations" not in d:
        raise ObservationError("observations: missing")
    items = d["observations"]
    if not isinstance(items, list) or not items:
        raise ObservationError("observations: expected a non-empty list")
    if len(items) > MAX_OBSERVATIONS:
        raise ObservationError(
            f"observations: {len(items)} items, at most {MAX_OBSERVATIONS} are "
            "allowed (msg_docs/fitting.md, Limits)"
        )
    obs, total = [], 0
    for i, v in enumerate(items):
        obs.append(_observation(v, f"observations[{i}]", sigma, base))
        total += len(obs[-1].points)
        if total > MAX_TOTAL_POINTS:
            raise ObservationError(
                f"observations[{i}]: more than {MAX_TOTAL_POINTS} points in "
                "all (msg_docs/fitting.md, Limits)"
            )
    scene = d.get("scene", "")
    if not isinstance(scene, str):
        raise ObservationError("scene: expected a scene name or file")
    return ObservationSet(tuple(obs), tuple(params), scene, mass, source, profiles)


def load_observations(path: str | Path) -> ObservationSet:
    """Read an observation file (YAML or JSON).

    Read an observation file (YAML or JSON).  Raises ObservationError (``<file>: <key path>:
    ...`` or ``<file>:<line>:<column>: YAML/JSON syntax error ...``) or FileNotFoundError.
    """
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise FileNotFoundError(f"{path}: no such observation file")
    try:
        text = read_regular_file(
            path, str(path), FILE_BYTES, "observation file", "msg_docs/fitting.md, Limits"
        ).decode("utf-8")
        data = parse_bounded_yaml(text, str(path))
    except FileLimitError as exc:
        message = str(exc).replace("YAML syntax error", "YAML/JSON syntax error")
        raise ObservationError(message) from None
    except UnicodeDecodeError:
        raise ObservationError(f"{path}: not a UTF-8 text file") from None
    try:
        return observation_set_from_dict(data, str(path), path.parent)
    except ObservationError as exc:
        raise ObservationError(f"{path}: {exc}") from None
