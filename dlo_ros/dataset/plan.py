"""A data set's plan: how many samples, which grip poses, how each is solved (``PLAN.yaml``).

A plan is a YAML (or JSON) mapping::

    samples: 1000            # how many shapes (1 … 10⁸; 1e6 is read as 1000000)
    seed: 7                  # the same plan and seed give the same samples
    grips:                   # per grip, where its position goes (others keep the scene's pose):
      right:                 # position_box, position_grid or around_path (positions.py)
        position_box: {min: [0.4, -0.1, -0.1], max: [0.7, 0.1, 0.1]}   # [m], uniform
    chunk: 50                # samples per shard file (default 50)
    start: held              # 'held': each sample solved from the scene's equilibrium at its
                             # own poses (a query); 'cold': from the initial guess; 'previous':
                             # from the sample before it (a chunk is a stream, work.py)
    string:                  # optional: the string's values drawn per sample (materials.py)
      bend_stiffness: {min: 0.01, max: 0.04, log: true}
    resolution: 51           # centreline points stored per sample (2 … 10000; default: the
                             # scene's); chunk × resolution ≤ 2·10⁶, at most 10⁶ shards

Orientations are kept.  Samples are drawn from ``numpy.random.PCG64(seed)``, grip by grip in
the plan's order, so sample ``i`` is the same whatever the workers, the chunks or a resume
(:meth:`DatasetPlan.targets`).  A malformed plan raises :class:`PlanError` naming the field
(``plan.grips.right.position_box.min: …``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..model.problem import GripPose, Problem
from ..scene.bounded_yaml import parse_bounded_yaml
from ..scene.files import FileLimitError, read_regular_file
from .materials import MaterialRange, check_scene
from .materials import parse as parse_materials
from .positions import PlanError, Sampler, parse

#: the largest plan file read [bytes]
PLAN_FILE_BYTES = 1 << 20
MAX_SAMPLES = 10**8
MAX_CHUNK = 100_000
MAX_RESOLUTION = 10_000  # as solver.output_points
#: at most this many shard files (each a chunk)
MAX_SHARDS = 10**6
#: at most this many centreline points in one shard (chunk × resolution): a chunk travels whole
MAX_SHARD_POINTS = 2 * 10**6
STARTS = ("held", "cold", "previous")
KEYS = ("samples", "seed", "grips", "string", "chunk", "start", "resolution")


@dataclass(frozen=True)
class DatasetPlan:
    """A validated plan (module docstring); ``resolution`` 0: the scene's output points."""

    samples: int
    seed: int
    grips: dict[str, Sampler] = field(default_factory=dict)
    chunk: int = 50
    start: str = "held"
    resolution: int = 0
    string: dict[str, MaterialRange] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Return the plan as the YAML mapping it was read from (the manifest stores it)."""
        string = {key: r.as_dict() for key, r in self.string.items()}
        return {
            "samples": self.samples,
            "seed": self.seed,
            "grips": {name: sampler.as_dict() for name, sampler in self.grips.items()},
            "chunk": self.chunk,
            "start": self.start,
            "resolution": self.resolution,
            **({"string": string} if string else {}),
        }

    @property
    def chunks(self) -> int:
        """How many shards the samples fill."""
        return -(-self.samples // self.chunk)

    def span(self, k: int) -> tuple[int, int]:
        """Return the sample indices [a, b) of chunk ``k``."""
        return k * self.chunk, min(self.samples, (k + 1) * self.chunk)

    def check(self, problem: Problem, points: int) -> None:
        """Raise PlanError unless ``problem`` takes this plan with ``points``-point centrelines.

        Each plan grip must be one of its grips, each material range one its string can take,
        and a chunk's centrelines within MAX_SHARD_POINTS.
        """
        names = [g.name for g in problem.grips]
        for name in self.grips:
            if name not in names:
                raise PlanError(f"plan.grips.{name}: no such grip in the scene (it has {names})")
        check_scene(self.string, problem)
        self.check_size(points)

    def check_size(self, points: int) -> None:
        """Raise PlanError when one chunk of ``points``-point centrelines is too large to send."""
        if self.chunk * points > MAX_SHARD_POINTS:
            raise PlanError(
                f"plan.chunk: {self.chunk} samples × {points} centreline points is over "
                f"{MAX_SHARD_POINTS} per shard: a smaller chunk or resolution"
            )

    def _draws(self, a: int, b: int) -> np.ndarray:
        """Return samples [a, b)'s uniform draws, (b − a, 3·G + M): G grips, M materials.

        Sample i's are the draws 3·G·i … of ``PCG64(seed)`` when the plan draws no material,
        (3·G + M)·i … else, so a chunk draws only its own and equals the same slice of the whole.
        """
        width = 3 * len(self.grips) + len(self.string)
        bits = np.random.PCG64(self.seed)
        bits.advance(width * a)
        return np.random.Generator(bits).random((b - a, width))

    def targets(self, problem: Problem, a: int = 0, b: int | None = None) -> list[dict]:
        """Return the grip targets of samples [a, b) (the plan's grips; orientations kept)."""
        b = self.samples if b is None else b
        u = self._draws(a, b)
        index = np.arange(a, b)
        positions = [
            sampler.positions(index, u[:, 3 * j : 3 * j + 3], self.samples)
            for j, sampler in enumerate(self.grips.values())
        ]
        held = {g.name: g.pose.orientation for g in problem.grips}
        return [
            {
                name: GripPose(positions[j][i].copy(), held[name])
                for j, name in enumerate(self.grips)
            }
            for i in range(b - a)
        ]

    def values(self, a: int = 0, b: int | None = None) -> list[dict[str, float]]:
        """Return the drawn string values of samples [a, b) (``materials.py``; {} without)."""
        b = self.samples if b is None else b
        if not self.string:
            return [{} for _ in range(b - a)]
        u = self._draws(a, b)[:, 3 * len(self.grips) :]
        drawn = [r.draw(u[:, j]) for j, r in enumerate(self.string.values())]
        keys = list(self.string)
        return [{k: float(drawn[j][i]) for j, k in enumerate(keys)} for i in range(b - a)]


def read_plan(path: Path | str) -> DatasetPlan:
    """Read and check the plan file ``path`` (module docstring); PlanError names what is wrong."""
    source = str(path)
    try:
        text = read_regular_file(path, source, PLAN_FILE_BYTES, what="plan file").decode()
    except FileLimitError as exc:  # its message starts with the file's name
        raise PlanError(str(exc)) from None
    except UnicodeDecodeError:
        raise PlanError(f"{source}: not UTF-8 text") from None
    try:
        data = parse_bounded_yaml(text, source)
    except (FileLimitError, ValueError) as exc:
        raise PlanError(str(exc)) from None
    return plan_from_dict(data)


def plan_from_dict(data: object) -> DatasetPlan:
    """Check the plan mapping ``data`` and return it as a DatasetPlan (PlanError if malformed)."""
    if not isinstance(data, dict):
        raise PlanError("plan: must be a mapping with at least 'samples', 'seed' and 'grips'")
    unknown = [str(k) for k in data if k not in KEYS]
    if unknown:
        raise PlanError(f"plan.{unknown[0]}: unknown key (a plan has {', '.join(KEYS)})")
    for key in ("samples", "seed", "grips"):
        if key not in data:
            raise PlanError(f"plan.{key}: missing")
    grips = data["grips"]
    if not isinstance(grips, dict) or not grips:
        raise PlanError("plan.grips: must map at least one grip name to where it goes")
    plan = DatasetPlan(
        samples=_integer(data["samples"], "plan.samples", 1, MAX_SAMPLES),
        seed=_integer(data["seed"], "plan.seed", 0, 2**63 - 1),
        grips={str(name): parse(spec, f"plan.grips.{name}") for name, spec in grips.items()},
        chunk=_integer(data.get("chunk", 50), "plan.chunk", 1, MAX_CHUNK),
        start=_choice(data.get("start", "held"), "plan.start", STARTS),
        resolution=_resolution(data.get("resolution", 0)),
        string=parse_materials(data["string"]) if "string" in data else {},
    )
    if plan.chunks > MAX_SHARDS:
        raise PlanError(f"plan.chunk: {plan.chunks} shards, at most {MAX_SHARDS}: a larger chunk")
    plan.check_size(plan.resolution)
    return plan


def _integer(value: object, key: str, low: int, high: int) -> int:
    """Return ``value`` as an int in [low, high] (an integral float such as 1e6 too)."""
    whole = isinstance(value, float) and value.is_integer()
    if isinstance(value, bool) or not (isinstance(value, int) or whole):
        raise PlanError(f"{key}: must be an integer in [{low}, {high}], got {value!r:.40}")
    number = int(value) if isinstance(value, (int, float)) else low - 1
    if not low <= number <= high or number != value:
        raise PlanError(f"{key}: must be an integer in [{low}, {high}], got {value!r:.40}")
    return number


def _resolution(value: object) -> int:
    points = _integer(value, "plan.resolution", 0, MAX_RESOLUTION)
    if points == 1:
        raise PlanError("plan.resolution: 0 (the scene's output points) or 2 … 10000")
    return points


def _choice(value: object, key: str, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise PlanError(f"{key}: must be one of {', '.join(choices)}, got {value!r:.40}")
    return str(value)
