"""The scene format's vocabulary: its keys, its limits, the ``Scene`` it gives and its errors.

Every other module of ``dlo_ros.scene`` reads these names; the format itself is documented in
``msg_docs/scene_format.md`` (the limits under "Limits").
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..model.obstacle_types import OBSTACLE_TYPES
from ..model.problem import Problem
from ..solver.options import SolverOptions
from ..solver.results.uncertainty import Uncertainty
from ..text import safe_text

DEFAULT_SCENE = "default_cable"

#: Relative tolerance on a quaternion's norm (passed to model.rotations.check_quaternion).
QUATERNION_TOLERANCE = 1e-3

TOP_LEVEL_KEYS = (
    "name",
    "description",
    "frame_id",
    "string",
    "gravity",
    "grips",
    "loads",
    "obstacles",
    "relative_positions",
    "solver",
)
STRING_KEYS = (
    "length",
    "bend_stiffness",
    "lateral_bend_stiffness",
    "twist_stiffness",
    "stretch_stiffness",
    "weight_per_length",
    "radius",
    "uncertainty",
)
GRAVITY_KEYS = ("direction",)
GRIP_KEYS = ("name", "s", "mode", "position", "orientation")
LOAD_KEYS = ("s", "force", "moment")
RELATIVE_KEYS = ("s_a", "s_b", "offset")
#: Keys of each obstacle type (besides ``type`` and ``name``) and which of them are required (each
#: type's ``keys`` in ``model.obstacle_types``).
OBSTACLE_KEYS: dict[str, dict[str, bool]] = {
    name: {k: key.required for k, key in kind.keys.items()}
    for name, kind in OBSTACLE_TYPES.items()
}

#: What a scene may cost (documented in msg_docs/scene_format.md, "Limits").  File and YAML limits
#: are checked while reading and composing, before any alias is expanded or any object is
#: constructed; list and string limits before the items are parsed (for dicts too).
LIMITS: dict[str, int] = {
    "file_bytes": 1 << 20,  # size of a scene file (1 MiB; the shipped ones are < 3 KB)
    "depth": 16,  # nesting of mappings and lists (a valid scene needs 4)
    "aliases": 64,  # YAML aliases (*name) in one file
    "nodes": 100_000,  # YAML nodes, counting an aliased subtree at every alias
    "scalar_chars": 10_000,  # characters of one YAML scalar (key or value)
    "integer_digits": 30,  # digits of an integer in the file (larger ones are no physical value)
    "grips": 16,
    "loads": 100,  # each load adds a breakpoint (an element) and parameters: bounds the build
    "obstacles": 32,  # each adds obstacle_samples constraints: bounds the build's time and memory
    "relative_positions": 32,
    "profile_rows": 1000,  # rows of a string.* profile table
    "name_chars": 128,  # name, grips[].name, obstacles[].name
    "frame_id_chars": 256,  # = dlo_ros.node.validation.FRAME_ID_LIMIT
    "description_chars": 10_000,
}


class SceneError(ValueError):
    """A malformed scene.  ``str(err)`` starts with the offending key path (``key``).

    ``source`` is the file (or ``"<dict>"``) the scene came from; ``line`` the 1-based line of the
    key in that file when known.
    """

    def __init__(self, message: str, key: str = "", source: str = "", line: int | None = None):
        super().__init__(message)
        self.key = key
        self.source = source
        self.line = line


def fail(key: str, message: str) -> SceneError:
    """Return a SceneError for ``key`` whose message reads ``<key>: <message>``."""
    return SceneError(f"{key}: {message}", key=key)


@dataclass(frozen=True)
class Scene:
    """A validated scene: the problem, how to solve it and where it is expressed.

    uncertainty: ``string.uncertainty``, the standard deviations of the string's materials (the
    envelope's input, ``solver/results/envelope.py``), None when the scene gives none.
    """

    name: str
    problem: Problem
    options: SolverOptions
    frame_id: str = "world"
    source: str = ""
    description: str = ""
    uncertainty: Uncertainty | None = None


def describe_value(value: object) -> str:
    """Describe a value for an error message in a few safe words.

    Numbers and short one-line strings appear as they are; longer strings and containers by their
    size only (never their content).
    """
    if isinstance(value, str):
        if len(value) <= 40 and value.isprintable():
            return repr(value)
        return f"of {len(value)} characters"
    if isinstance(value, (list, tuple)):
        return f"of {len(value)} items"
    if isinstance(value, dict):
        return f"of {len(value)} keys"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**15:
        return f"with {len(str(abs(value)))} digits"
    return safe_text(repr(value), 60)


_KEY_TEXT_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,39}")


def key_text(k: object) -> str:
    """Show a key in a key path: itself when it looks like a scene key, else a placeholder.

    An unknown key of a file that is not a scene must not be echoed.
    """
    if isinstance(k, str) and _KEY_TEXT_RE.fullmatch(k):
        return k
    return "<unknown key>"
