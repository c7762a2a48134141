"""Locate dlo_ros data files (config/, config/scenes/, launch/).

The data lives in the package *share* directory: ``<prefix>/share/dlo_ros`` once the package is
installed (colcon, ``pip install .``, or ``scripts/dlo-env`` which links the source tree there) and
found through the ament index (``AMENT_PREFIX_PATH``). When the package is not in the ament index,
for example when running straight from a checkout, the source tree is used instead.
"""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_NAME = 'dlo_ros'
SCENE_SUFFIX = '.yaml'

# Repository root when running from a source checkout: <root>/dlo_ros/paths.py.
_SOURCE_ROOT = Path(__file__).resolve().parent.parent


def _ament_share_dir() -> Path | None:
    """Return the share directory registered in the ament index, or None if there is none."""
    try:  # optional: only in a ROS install (a plain pip install has no ament index)
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        return None
    try:
        share = Path(get_package_share_directory(PACKAGE_NAME, print_warning=False))
    except (PackageNotFoundError, OSError, ValueError):
        # PackageNotFoundError: not in the index; OSError: AMENT_PREFIX_PATH unset or empty.
        return None
    return share if share.is_dir() else None


def _source_share_dir() -> Path | None:
    """Return the source checkout root if this module runs from one, else None."""
    root = _SOURCE_ROOT
    # config/ may be absent from a fresh clone while it has no files (git keeps no empty dirs),
    # so package.xml identifies the checkout as well.
    if (root / 'package.xml').is_file() or (root / 'config').is_dir():
        return root
    return None


def share_dir() -> Path:
    """Return the dlo_ros share directory.

    Uses ``ament_index_python.get_package_share_directory('dlo_ros')`` when the package is in the
    ament index (i.e. some entry of ``AMENT_PREFIX_PATH`` contains
    ``share/ament_index/resource_index/packages/dlo_ros``); otherwise falls back to the source tree
    (the repository root, which contains ``config/`` and ``package.xml``).

    Raises:
        FileNotFoundError: if neither an installed share directory nor a source tree is found.
    """
    share = _ament_share_dir()
    if share is not None:
        return share
    source = _source_share_dir()
    if source is not None:
        return source
    raise FileNotFoundError(
        f'cannot locate the {PACKAGE_NAME} share directory: the package is not in the ament index '
        f'(AMENT_PREFIX_PATH={os.environ.get("AMENT_PREFIX_PATH", "")!r}) and {_SOURCE_ROOT} '
        'is not a source checkout (no package.xml or config/). Run through scripts/dlo-env or '
        'source the workspace setup file.'
    )


def config_path(*parts: str | os.PathLike[str]) -> Path:
    """Return ``<share>/config/<parts...>`` (the path is not required to exist).

    Example: ``config_path('scenes', 'two_grippers.yaml')``.
    """
    return share_dir().joinpath('config', *parts)


def available_scenes() -> list[str]:
    """Return the sorted names (without ``.yaml``) of the scenes shipped in ``config/scenes``."""
    scenes = config_path('scenes')
    if not scenes.is_dir():
        return []
    return sorted(
        p.name[: -len(SCENE_SUFFIX)] for p in scenes.glob('*' + SCENE_SUFFIX) if p.is_file()
    )


def scene_path(name: str | os.PathLike[str]) -> Path:
    """Return the path of a scene file.

    ``name`` may be a path to an existing file (returned as given), or the name of a shipped scene,
    with or without the ``.yaml`` suffix, resolved to ``<share>/config/scenes/<name>.yaml``.

    Raises:
        FileNotFoundError: if ``name`` is neither an existing file nor a shipped scene; the message
            lists the available scenes.
    """
    path = Path(name)
    if path.is_file():
        return path
    text = os.fspath(name)
    if path.is_absolute() or os.sep in text or (os.altsep and os.altsep in text):
        raise FileNotFoundError(f'scene file not found: {text}')
    stem = text[: -len(SCENE_SUFFIX)] if text.endswith(SCENE_SUFFIX) else text
    if not stem:
        raise FileNotFoundError(f'invalid scene name: {text!r}')
    candidate = config_path('scenes', stem + SCENE_SUFFIX)
    if candidate.is_file():
        return candidate
    available = ', '.join(available_scenes()) or '(none)'
    raise FileNotFoundError(
        f'unknown scene {stem!r}: {candidate} does not exist; available: {available}'
    )
