"""Every dotted ``dlo_ros.xxx.name`` the documentation names imports.

The docs (msg_docs/*.md, README.md, QUALITY_DECLARATION.md) name modules, classes, functions and
constants by their dotted path, e.g. ``dlo_ros.recording.replay.read_recording``.  A rename or a
move that forgets the docs leaves a reader with a name that no longer exists (msg_docs/recording.md
documented ``dlo_ros.replay.read_recording`` long after ``dlo_ros/replay.py`` had moved).  Each
reference is resolved as Python would: the longest prefix that imports as a module, then
attributes.  Nothing is skipped: a failing case names the file, the line and the reference.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = sorted((REPO / "msg_docs").glob("*.md")) + [REPO / "README.md",
                                                   REPO / "QUALITY_DECLARATION.md"]
REFERENCE = re.compile(r"(?<![\w./-])dlo_ros(?:\.[A-Za-z_]\w*)+")
#: ``from dlo_ros.x import a, b as c``: each imported name is a reference ``dlo_ros.x.a``
FROM_IMPORT = re.compile(r"from\s+(dlo_ros(?:\.\w+)*)\s+import\s+\(?([\w\s,]+)")


def references() -> list[tuple[str, int, str]]:
    """Return (doc file, line, dotted name) of every reference in the docs, in order."""
    found = []
    for doc in DOCS:
        for number, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), start=1):
            where = doc.relative_to(REPO).as_posix()
            for match in REFERENCE.finditer(line):
                found.append((where, number, match.group(0)))
            for match in FROM_IMPORT.finditer(line):
                for item in match.group(2).split(","):
                    name = item.split(" as ")[0].strip()
                    if name:
                        found.append((where, number, f"{match.group(1)}.{name}"))
    return found


def resolve(dotted: str) -> object:
    """Return the object ``dotted`` names: the longest importable module prefix, then getattr.

    Raises ImportError or AttributeError naming what is missing.
    """
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        module_name = ".".join(parts[:cut])
        try:
            obj = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and module_name.startswith(exc.name):
                continue  # this prefix is not a module: try a shorter one
            raise  # the module exists but imports something missing
        for attribute in parts[cut:]:
            obj = getattr(obj, attribute)  # AttributeError names the missing attribute
        return obj
    raise ImportError(f"no module in {dotted}")


def test_the_docs_name_something():
    names = {ref for _, _, ref in references()}
    # the pattern finds the references these docs are known to hold (not an empty scan)
    assert "dlo_ros.scene.LIMITS" in names
    assert "dlo_ros.scene.load_scene" in names  # README: from dlo_ros.scene import load_scene
    assert len(names) >= 15


def test_resolve_refuses_missing_names():
    scene = importlib.import_module("dlo_ros.scene")
    assert resolve("dlo_ros.scene.load_scene") is scene.load_scene
    with pytest.raises((ImportError, AttributeError)):
        resolve("dlo_ros.replay.read_recording")  # the old name the issue found
    with pytest.raises(AttributeError):
        resolve("dlo_ros.scene.no_such_name")


@pytest.mark.parametrize(
    "doc, line, dotted", references(), ids=[f"{d}:{n}:{r}" for d, n, r in references()]
)
def test_reference_imports(doc, line, dotted):
    try:
        resolve(dotted)
    except (ImportError, AttributeError) as exc:
        pytest.fail(f"{doc}:{line}: {dotted} does not import: {type(exc).__name__}: {exc}")
