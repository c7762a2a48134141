"""Tests for dlo_ros.paths: ament index look-up and source-tree fallback."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from dlo_ros import paths

REPO_ROOT = Path(paths.__file__).resolve().parent.parent


def make_prefix(root: Path, scenes: tuple[str, ...] = ('x',)) -> Path:
    """Create a minimal install prefix that registers dlo_ros in the ament index."""
    marker = root / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'dlo_ros'
    marker.parent.mkdir(parents=True)
    marker.touch()
    scene_dir = root / 'share' / 'dlo_ros' / 'config' / 'scenes'
    scene_dir.mkdir(parents=True)
    for name in scenes:
        (scene_dir / f'{name}.yaml').write_text('name: %s\n' % name)
    return root


@pytest.fixture
def prefix(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = make_prefix(tmp_path / 'prefix')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(root))
    return root


@pytest.fixture
def no_ament(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)


# --- ament index -------------------------------------------------------------------------------


def test_share_dir_from_ament_index(prefix: Path) -> None:
    assert paths.share_dir() == prefix / 'share' / 'dlo_ros'


def test_config_and_scene_path_from_ament_index(prefix: Path) -> None:
    expected = prefix / 'share' / 'dlo_ros' / 'config' / 'scenes' / 'x.yaml'
    assert paths.config_path('scenes', 'x.yaml') == expected
    assert paths.scene_path('x') == expected
    assert paths.scene_path('x.yaml') == expected
    assert paths.available_scenes() == ['x']


def test_first_prefix_in_ament_prefix_path_wins(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = make_prefix(tmp_path / 'first', scenes=('a',))
    second = make_prefix(tmp_path / 'second', scenes=('b',))
    monkeypatch.setenv('AMENT_PREFIX_PATH', os.pathsep.join([str(first), str(second)]))
    assert paths.share_dir() == first / 'share' / 'dlo_ros'
    assert paths.available_scenes() == ['a']


# --- source-tree fallback ----------------------------------------------------------------------


def test_fallback_without_ament_prefix_path(no_ament: None) -> None:
    assert paths.share_dir() == REPO_ROOT
    assert paths.config_path('scenes', 'y.yaml') == REPO_ROOT / 'config' / 'scenes' / 'y.yaml'


def test_fallback_when_package_not_in_index(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    other = tmp_path / 'other_prefix'
    (other / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(other))
    assert paths.share_dir() == REPO_ROOT


def test_fallback_without_ament_index_python(
    prefix: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A None entry in sys.modules makes the import raise ImportError.
    monkeypatch.setitem(sys.modules, 'ament_index_python.packages', None)
    assert paths.share_dir() == REPO_ROOT


def test_fallback_scene_lookup(
    no_ament: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A fake checkout, so the test does not depend on which scenes the repository ships.
    root = tmp_path / 'checkout'
    (root / 'config' / 'scenes').mkdir(parents=True)
    (root / 'package.xml').write_text('<package/>')
    (root / 'config' / 'scenes' / 'demo.yaml').write_text('{}\n')
    monkeypatch.setattr(paths, '_SOURCE_ROOT', root)
    assert paths.share_dir() == root
    assert paths.scene_path('demo') == root / 'config' / 'scenes' / 'demo.yaml'
    assert paths.available_scenes() == ['demo']


def test_nothing_found_raises(
    no_ament: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(paths, '_SOURCE_ROOT', tmp_path / 'site-packages')
    with pytest.raises(FileNotFoundError, match='share directory'):
        paths.share_dir()


# --- scene_path --------------------------------------------------------------------------------


def test_scene_path_accepts_existing_file_as_is(prefix: Path, tmp_path: Path) -> None:
    own = tmp_path / 'my_scene.yaml'
    own.write_text('{}\n')
    assert paths.scene_path(own) == own
    assert paths.scene_path(str(own)) == own


def test_scene_path_relative_existing_file(
    prefix: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    Path('local.yaml').write_text('{}\n')
    assert paths.scene_path('local.yaml') == Path('local.yaml')


def test_unknown_scene_lists_available(prefix: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"unknown scene 'nope'.*available: x"):
        paths.scene_path('nope.yaml')


def test_missing_scene_file_path_raises(prefix: Path, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match='scene file not found'):
        paths.scene_path(tmp_path / 'missing.yaml')
    with pytest.raises(FileNotFoundError, match='scene file not found'):
        paths.scene_path('some/dir/x.yaml')
