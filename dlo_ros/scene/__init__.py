"""Scene files: YAML (or a dict) -> a validated :class:`Problem` plus :class:`SolverOptions`.

A *scene* is everything one solve needs: the string's properties, the grips and their poses, loads,
obstacles, relative-position constraints, the gravity direction and the solver options.  The format
is documented in ``msg_docs/scene_format.md``; every quantity is SI and quaternions are (x, y, z,
w) of a pose whose x-axis is the string's tangent, pointing toward increasing s.

Every malformed input raises :class:`SceneError` whose message starts with the offending key path
(``grips[1].orientation: quaternion norm is 1.3, not 1 ...``).  Errors found while loading a file
add where the key is, `` (in path/to/scene.yaml:12)``; YAML syntax errors start with
``file:line:column``. Messages never quote the file beyond the scene format's own keys and short
values: a file that is not a scene (``scene:=/etc/passwd``) is named, not echoed.

What a scene may cost is bounded before anything is built (:data:`LIMITS`, msg_docs/scene_format.md
"Limits"): the file's size and kind are checked before it is read, the YAML composer counts
aliases, nesting depth, scalar sizes and the nodes the document would have with every alias
expanded while it composes (no alias is ever expanded to count it), and the sections' list lengths
are checked before their items are parsed.

The package's modules, one job each:

* ``format``: the keys, :data:`LIMITS`, :class:`Scene` and :class:`SceneError`;
* ``files``: reading a regular file of bounded size (also used by the node's parameters file, the
  recordings and ``dlo fit``'s observation files);
* ``bounded_yaml``: the YAML composer that counts what a document costs;
* ``values`` and ``sections``: one value, and one section of the scene, each naming its key path;
* ``reading``: :func:`scene_from_dict` and :func:`load_scene`;
* ``writing``: :func:`scene_to_dict`.

No ROS here: only the model and solver layers are imported.
"""

from __future__ import annotations

from .bounded_yaml import (
    SceneLoader,
    YamlLimitError,
    compose_bounded_yaml,
    key_lines,
    parse_bounded_yaml,
)
from .files import FileLimitError, open_regular_file, read_regular_file, read_scene_text
from .format import (
    DEFAULT_SCENE,
    GRAVITY_KEYS,
    GRIP_KEYS,
    LIMITS,
    LOAD_KEYS,
    OBSTACLE_KEYS,
    QUATERNION_TOLERANCE,
    RELATIVE_KEYS,
    STRING_KEYS,
    TOP_LEVEL_KEYS,
    Scene,
    SceneError,
)
from .reading import load_scene, scene_from_dict
from .writing import scene_to_dict

__all__ = [
    "DEFAULT_SCENE",
    "Scene",
    "SceneError",
    "scene_from_dict",
    "load_scene",
    "scene_to_dict",
    "TOP_LEVEL_KEYS",
    "STRING_KEYS",
    "GRAVITY_KEYS",
    "GRIP_KEYS",
    "LOAD_KEYS",
    "RELATIVE_KEYS",
    "OBSTACLE_KEYS",
    "QUATERNION_TOLERANCE",
    "LIMITS",
    "FileLimitError",
    "open_regular_file",
    "read_regular_file",
    "read_scene_text",
    "SceneLoader",
    "YamlLimitError",
    "parse_bounded_yaml",
    "compose_bounded_yaml",
    "key_lines",
]
