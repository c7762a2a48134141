"""Check the README's Layout block against the tree: every package folder is named, and every
file or folder it names exists.

The block is the fenced block under ``## Layout``. A folder counts as named when its path from the
repository root, ending in ``/``, appears in the block (``dlo_ros/solver/update/``); a name ending in
``.py`` must be the tail of a file in the repository (``shape_solver.py``, ``update/context.py``).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _layout_block() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Layout", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```[^\n]*\n(.*?)```", section, re.S)
    assert blocks, "README.md: no fenced block under '## Layout'"
    return blocks[0]


def test_every_package_folder_is_named() -> None:
    block = _layout_block()
    folders = sorted(
        p.parent.relative_to(ROOT).as_posix() + "/" for p in (ROOT / "dlo_ros").rglob("__init__.py")
    )
    missing = [f for f in folders if f not in block]
    assert not missing, f"README.md's Layout does not name: {missing}"


def test_every_named_path_exists() -> None:
    block = _layout_block()
    files = [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.py") if ".venv" not in p.parts]
    missing = []
    for name in sorted(set(re.findall(r"(?<![\w./-])([\w/]+\.py)\b", block))):
        if not any(f == name or f.endswith("/" + name) for f in files):
            missing.append(name)
    for folder in sorted(set(re.findall(r"(?<![\w./-])((?:dlo_ros|test|bench)/[\w/]*/)", block))):
        if not (ROOT / folder).is_dir():
            missing.append(folder)
    assert not missing, f"README.md's Layout names what is not in the tree: {missing}"
