"""A scene from a mapping (:func:`scene_from_dict`) or from a file (:func:`load_scene`).

Errors are SceneErrors whose message starts with the key path; those of a file also say where the
key is, `` (in path/to/scene.yaml:12)``, and YAML syntax errors start with ``file:line:column``.
Messages never quote the file beyond the scene format's own keys and short values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..model.problem import Problem
from ..paths import scene_path
from ..solver.build.nlp import choose_reference_frame
from ..solver.options import SolverOptions
from ..text import safe_text
from .bounded_yaml import YamlLimitError, compose_yaml, key_lines, line_of
from .files import read_scene_text
from .format import LIMITS, TOP_LEVEL_KEYS, Scene, SceneError, fail
from .sections import (
    parse_grips,
    parse_gravity,
    parse_loads,
    parse_obstacles,
    parse_relative,
    parse_solver,
    parse_string,
    parse_uncertainty,
    wrap_error,
)
from .values import check_known_keys, read_mapping, read_string


def check_moments(problem: Problem, options: SolverOptions) -> None:
    """Refuse point moments off the working-plane normal where the model cannot apply them.

    The Euler-angle models ('planar', or rotation 'euler') apply a moment's work exactly only
    about the working-plane normal.  The director models ('auto' and 'full' with the default
    rotation 'director') take moments about any axis (msg_docs/model_and_solver.md "Point
    moments about any axis"), so nothing is refused for them.
    """
    if options.model != "planar" and options.rotation == "director":
        return
    if not any(np.any(ld.moment != 0) for ld in problem.loads):
        return
    n = choose_reference_frame(problem, options.frame)[:, 2]
    for i, ld in enumerate(problem.loads):
        m = np.asarray(ld.moment, dtype=float)
        if np.linalg.norm(m - np.dot(m, n) * n) > 1e-9 * max(1.0, float(np.linalg.norm(m))):
            raise fail(
                f"loads[{i}].moment",
                "only moments about the working-plane normal n = "
                f"{np.round(n, 6).tolist()} (normal to the grips' chord and gravity) are "
                "supported",
            )


def _default_name(source: str) -> str:
    """Return the scene name used when the scene has none: its file's stem, else 'scene'."""
    name = Path(source).stem if source and not source.startswith("<") else "scene"
    if not (name.isprintable() and 0 < len(name) <= LIMITS["name_chars"]):
        return "scene"
    return name


def scene_from_dict(d: dict, source: str = "<dict>") -> Scene:
    """Build and validate a Scene from a mapping in the scene-file format.

    Raises SceneError (a ValueError) whose message starts with the offending key path.
    """
    if not isinstance(d, dict):
        raise SceneError(
            f"{source}: a scene must be a mapping of keys, got {type(d).__name__}", key=""
        )
    d = read_mapping(d, "<scene>")
    check_known_keys(d, TOP_LEVEL_KEYS, "")
    name = read_string(d.get("name", _default_name(source)), "name", allow_empty=False)
    description = (
        ""
        if d.get("description") is None
        else read_string(d["description"], "description", limit="description_chars")
    )
    frame_id = read_string(
        d.get("frame_id", "world"), "frame_id", allow_empty=False, limit="frame_id_chars"
    )
    if "string" not in d:
        raise fail("string", "required (length, bend_stiffness, ...)")
    string = parse_string(d["string"])
    uncertainty = parse_uncertainty(d["string"].get("uncertainty"), string)
    gravity = parse_gravity(d.get("gravity"))
    grips = parse_grips(d.get("grips"), string.length)
    loads = parse_loads(d.get("loads"), string.length)
    obstacles = parse_obstacles(d.get("obstacles"))
    relative = parse_relative(d.get("relative_positions"), string.length)
    options = parse_solver(d.get("solver"))
    problem = Problem(
        string=string,
        grips=grips,
        gravity=gravity,
        loads=loads,
        obstacles=obstacles,
        relative_positions=relative,
    )
    try:
        problem.validate()
    except ValueError as exc:
        raise wrap_error(exc, "<scene>") from None
    check_moments(problem, options)
    return Scene(
        name=name,
        problem=problem,
        options=options,
        frame_id=frame_id,
        source=source,
        description=description.strip(),
        uncertainty=uncertainty,
    )


def _compose_scene_file(text: str, source: str) -> tuple[object, dict[str, int]]:
    """Return (the document, the line of each key path) of a scene file's text.

    Raises SceneError naming the file (and line) on a limit, a YAML syntax error or another YAML
    error.
    """
    try:
        data, root = compose_yaml(text)
        return data, key_lines(root)
    except YamlLimitError as exc:
        mark = exc.problem_mark
        line = mark.line + 1 if mark else None
        where = f"{source}:{line}" if line else source
        raise SceneError(
            f"{exc.key}: over a limit: {exc.problem} (in {where}; msg_docs/scene_format.md, "
            "Limits)",
            key=exc.key,
            source=source,
            line=line,
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        where = f"{source}:{line}:{mark.column + 1}" if mark else source
        context = exc.context or ""
        cm = exc.context_mark
        if context and cm is not None and mark is not None and cm.line != mark.line:
            context += f" (started at line {cm.line + 1}, column {cm.column + 1})"
        # context and problem only: str(exc) would quote the offending line of the file
        detail = safe_text(": ".join(p for p in (context, exc.problem) if p))
        raise SceneError(
            f"{where}: YAML syntax error: {detail}", source=source, line=line
        ) from None
    except yaml.YAMLError as exc:  # e.g. ReaderError: a control character in the file
        reason = getattr(exc, "reason", "") or type(exc).__name__
        position = getattr(exc, "position", None)
        at = f" at character {position}" if isinstance(position, int) else ""
        raise SceneError(f"{source}: YAML error: {safe_text(reason)}{at}", source=source) from None


def _check_scene_document(data: object, source: str) -> dict:
    """Return the document if it is a non-empty mapping with a scene key, else SceneError."""
    if data is None:
        raise SceneError(f"{source}: the scene file is empty", source=source)
    if not isinstance(data, dict):
        raise SceneError(
            f"{source}: a scene file must be a mapping of keys, got a {type(data).__name__}",
            source=source,
            line=1,
        )
    if not any(isinstance(k, str) and k in TOP_LEVEL_KEYS for k in data):
        raise SceneError(
            f"{source}: not a scene file: none of its top-level keys is a scene key "
            f"({', '.join(TOP_LEVEL_KEYS)})",
            source=source,
            line=1,
        )
    return data


def load_scene(path_or_name: str | Path) -> Scene:
    """Load a scene from a file path or the name of a shipped scene (config/scenes/<name>.yaml).

    Raises:
        FileNotFoundError: neither a file nor a shipped scene (the message lists the shipped
            scenes).
        SceneError: a path that is not a readable regular file, or one over the size limit;
            malformed YAML (message ``<file>:<line>:<column>: ...``); a file over one of
            :data:`LIMITS` (``<key path>: ... (in <file>:<line>)``); or a malformed scene (message
            ``<key path>: ... (in <file>:<line>)``).
    """
    given = Path(path_or_name)
    try:
        exists_as_other = given.exists() and not given.is_file()  # a directory, FIFO, device, ...
    except OSError:
        exists_as_other = False
    path = given if exists_as_other else scene_path(path_or_name)
    # control characters escaped; a path is never cut (PATH_MAX)
    source = safe_text(str(path), 4096)
    text = read_scene_text(path, source)
    data, lines = _compose_scene_file(text, source)
    document = _check_scene_document(data, source)
    try:
        return scene_from_dict(document, source=source)
    except SceneError as exc:
        line = line_of(exc.key, lines)
        where = f"{source}:{line}" if line else source
        raise SceneError(f"{exc} (in {where})", key=exc.key, source=source, line=line) from None
