"""YAML read with the scene's bounds: the cost of a document is checked while it is composed.

:class:`SceneLoader` is a SafeLoader that reads YAML 1.2 floats, refuses duplicate keys, and counts
nesting depth, aliases, scalar sizes, integer digits and the nodes the document would have with
every alias expanded (:data:`~dlo_ros.scene.format.LIMITS`) without expanding any alias.  The node
parameters file of ``dlo_ros.node.params`` and the observation files of ``dlo_ros.identify`` are
read with it too (:func:`compose_bounded_yaml`, :func:`parse_bounded_yaml`).
"""

from __future__ import annotations

import re
from typing import Any

import yaml

from ..text import safe_text
from .files import FileLimitError
from .format import LIMITS, key_text


class YamlLimitError(yaml.composer.ComposerError):
    """A YAML document exceeds one of :data:`LIMITS` (raised while composing it).

    ``key`` is the key path of the node being composed; nothing has been expanded yet.
    """

    def __init__(self, key: str, problem: str, mark: Any):
        super().__init__(problem=problem, problem_mark=mark)
        self.key = key


class SceneLoader(yaml.SafeLoader):
    """A SafeLoader that bounds what a document may cost while composing it.

    It reads YAML 1.2 floats (``1e-3`` is a number, not a string), rejects duplicate keys, and
    bounds (:data:`LIMITS`) nesting depth, aliases, scalar sizes, and the number of nodes with
    every alias expanded — computed from the node counts of the anchored subtrees, so a "billion
    laughs" file is rejected without expanding anything.
    """

    def __init__(self, stream: str):
        super().__init__(stream)
        self._paths: list[str] = []  # key path of every node being composed (innermost last)
        self._weights: dict[int, int] = {}  # id(node) -> nodes in its subtree, aliases expanded
        self.node_paths: dict[int, str] = {}  # id(node) -> its key path (first occurrence)
        self._aliases = 0

    def _limit(self, problem: str, mark: Any) -> YamlLimitError:
        key = self._paths[-1] if self._paths else ""
        return YamlLimitError(key or "<scene>", problem, mark)

    def _node_path(self, index: object) -> str:
        """Return the key path of the node composed at ``index`` of the current one."""
        where = self._paths[-1] if self._paths else ""
        if isinstance(index, yaml.ScalarNode):  # the value of a key
            part = key_text(index.value)
            return f"{where}.{part}" if where else part
        if isinstance(index, int):
            return f"{where}[{index}]"
        return where

    def _weigh(self, node: yaml.Node, where: str) -> int:
        """Return the nodes in a freshly composed ``node``'s subtree (aliases expanded)."""
        if isinstance(node, yaml.ScalarNode):
            if len(node.value) > LIMITS["scalar_chars"]:
                raise self._limit(
                    f"a value of {len(node.value)} characters (at most {LIMITS['scalar_chars']})",
                    node.start_mark,
                )
            weight = 1
        elif isinstance(node, yaml.SequenceNode):
            weight = 1 + sum(self._weights[id(item)] for item in node.value)
        else:
            weight = 1 + sum(self._weights[id(k)] + self._weights[id(v)] for k, v in node.value)
        self._weights[id(node)] = weight
        self.node_paths[id(node)] = where
        return weight

    def compose_node(self, parent, index):  # noqa: D401 - yaml.composer.Composer API
        """Compose one node as SafeLoader does, checking depth, aliases, scalars and nodes."""
        where = self._node_path(index)
        self._paths.append(where)
        try:
            event = self.peek_event()
            if len(self._paths) > LIMITS["depth"]:
                raise self._limit(
                    f"nested more than {LIMITS['depth']} levels deep", event.start_mark
                )
            if isinstance(event, yaml.AliasEvent):
                self._aliases += 1
                if self._aliases > LIMITS["aliases"]:
                    raise self._limit(
                        f"more than {LIMITS['aliases']} YAML aliases", event.start_mark
                    )
            node = super().compose_node(parent, index)
            if isinstance(event, yaml.AliasEvent):
                weight = self._weights.get(id(node))
                if weight is None:
                    raise self._limit(
                        "an alias refers to a node that contains it (a recursive structure)",
                        event.start_mark,
                    )
            else:
                weight = self._weigh(node, where)
            # the whole document so far, aliases expanded: the root's weight bounds every subtree's
            if weight > LIMITS["nodes"]:
                raise self._limit(
                    f"more than {LIMITS['nodes']} YAML nodes with aliases expanded",
                    event.start_mark,
                )
            return node
        finally:
            self._paths.pop()


SceneLoader.yaml_implicit_resolvers = {
    k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def _construct_mapping(loader: SceneLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: dict[object, yaml.Node] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            continue  # SafeLoader reports unhashable keys itself
        if key in seen:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping",
                node.start_mark,
                f"found duplicate key {key!r} (first at line {seen[key].start_mark.line + 1})",
                key_node.start_mark,
            )
        seen[key] = key_node
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


SceneLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _construct_int(loader: SceneLoader, node: yaml.ScalarNode) -> int:
    """Construct SafeLoader's int, refusing more than LIMITS['integer_digits'] digits.

    int() of a 5000-digit string raises a ValueError outside YAML's errors, and no physical value
    of a scene needs 30 digits.
    """
    digits = sum(c.isalnum() for c in node.value)
    if digits > LIMITS["integer_digits"]:
        raise YamlLimitError(
            loader.node_paths.get(id(node)) or "<scene>",
            f"an integer with {digits} digits (at most {LIMITS['integer_digits']})",
            node.start_mark,
        )
    return yaml.SafeLoader.construct_yaml_int(loader, node)


SceneLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def key_lines(
    node: yaml.Node | None, path: str = "", out: dict[str, int] | None = None
) -> dict[str, int]:
    """Map every key path of a composed YAML document ("grips[1].orientation") to its line.

    Lines are 1-based; a key that occurs twice keeps its first line.
    """
    out = {} if out is None else out
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                continue
            sub = f"{path}.{key_node.value}" if path else str(key_node.value)
            out.setdefault(sub, key_node.start_mark.line + 1)
            key_lines(value_node, sub, out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            sub = f"{path}[{i}]"
            out.setdefault(sub, item.start_mark.line + 1)
            key_lines(item, sub, out)
    return out


def line_of(key: str, lines: dict[str, int]) -> int | None:
    """Return the line of ``key``, or of its nearest enclosing key present in the file."""
    while key:
        if key in lines:
            return lines[key]
        cut = max(key.rfind("."), key.rfind("["))
        if cut <= 0:
            break
        key = key[:cut]
    return lines.get(key) if key else None


def compose_yaml(text: str) -> tuple[object, yaml.Node | None]:
    """Return (the constructed document, its node tree) from one pass of the bounded composer.

    Raises YamlLimitError or yaml's own errors; :func:`compose_bounded_yaml` turns them into one
    line each.
    """
    loader = SceneLoader(text)
    try:
        node = loader.get_single_node()
        data = None if node is None else loader.construct_document(node)
        return data, node
    finally:
        loader.dispose()


def parse_bounded_yaml(text: str, source: str) -> object:
    """Return the document of YAML (or JSON) ``text`` read with the scene reader's bounds.

    See :func:`compose_bounded_yaml` for the bounds and the errors.
    """
    return compose_bounded_yaml(text, source)[0]


def compose_bounded_yaml(text: str, source: str) -> tuple[object, yaml.Node | None]:
    """Return (the document, its YAML node tree) of YAML (or JSON) ``text``, read with bounds.

    The bounds are the scene reader's (:data:`LIMITS`: nesting depth, aliases, nodes with aliases
    expanded, scalar characters, integer digits; YAML 1.2 floats, duplicate keys refused).  The
    node tree gives each key its line (:func:`key_lines`).  Raises FileLimitError with one line:
    ``<source>:<line>: <key path>: over a limit: ...`` or ``<source>:<line>:<column>: YAML syntax
    error: ...`` (never the offending text).
    """
    try:
        return compose_yaml(text)
    except YamlLimitError as exc:
        line = f":{exc.problem_mark.line + 1}" if exc.problem_mark else ""
        raise FileLimitError(f"{source}{line}: {exc.key}: over a limit: {exc.problem}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        detail = safe_text(": ".join(p for p in (exc.context, exc.problem) if p))
        raise FileLimitError(f"{where}: YAML syntax error: {detail}") from None
    except yaml.YAMLError as exc:
        reason = safe_text(getattr(exc, "reason", "") or type(exc).__name__)
        raise FileLimitError(f"{source}: YAML error: {reason}") from None
