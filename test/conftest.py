"""Fixtures shared by test/unit and test/ros. Helpers to import are in test/support/ (``support``),
test/random_scenes.py and test/reference/; this directory is on sys.path (pytest's rootdir-relative
conftest import), so both halves import them the same way."""
from __future__ import annotations

import os
from dataclasses import replace

# gcc at -O0 for every library the tests compile (``native.compiler.optimize_flags``: a third of
# -O3's time; the tests compare compiled with interpreted values, the same at every level), set
# before dlo_ros is imported; test_compiled_cache.py builds at the release level -O3 too
os.environ.setdefault("DLO_OPTIMIZE", "0")
from pathlib import Path

import pytest

ROS_TESTS = Path(__file__).resolve().parent / "ros"


@pytest.hookimpl(tryfirst=True)  # before -m deselects
def pytest_collection_modifyitems(items):
    """Every test under test/ros/ carries the ``ros`` marker (registered in pytest.ini)."""
    for item in items:
        if ROS_TESTS in Path(item.path).parents:
            item.add_marker(pytest.mark.ros)


@pytest.fixture(scope="session", autouse=True)
def _no_background_compile(tmp_path_factory):
    """Tests use interpreted CasADi derivatives (compiling a scene takes gcc ~1 min); the compiled path
    has its own tests that opt back in (and restore it).  Session-wide, so that module-scoped
    fixtures, which pytest sets up before any function-scoped one, and the worker processes they
    spawn solve interpreted too: a background gcc there took a CI core, and its library arriving
    mid-chunk made a data set's answers depend on timing.

    What a test compiles goes to a cache of this run (``DLO_CACHE_DIR``; tests of the cache itself
    set their own), never to the user's ~/.cache/dlo_ros: a run here then compiles what a fresh CI
    machine does, whatever earlier runs left (the compiled inertia corpus took 2 s on a warm
    cache and 48 s on an empty one)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DLO_NO_COMPILE", "1")
        mp.setenv("DLO_CACHE_DIR", str(tmp_path_factory.mktemp("compiled")))
        yield


@pytest.fixture(autouse=True)
def _no_compile_in_each_test(monkeypatch):
    """Each test starts with compiling off, whatever a test before it left."""
    monkeypatch.setenv("DLO_NO_COMPILE", "1")


@pytest.fixture
def empty_cache(tmp_path, monkeypatch):
    """An empty compiled-code cache of this test, compiling allowed (spawned workers inherit the
    environment); skips without a C compiler."""
    from dlo_ros.solver.build import compiled

    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    return tmp_path


@pytest.fixture(scope="module")
def node_scene():
    """(the node tests' scene with their solver.model, the node's solver factory): what the node under
    test solves, to compare with in this process (interpreted: the autouse fixture above)."""
    from dlo_ros.node.engine import build_solver
    from dlo_ros.scene import load_scene
    from support.node import TEST_MODEL, TEST_SCENE

    scene = load_scene(TEST_SCENE)
    return replace(scene, options=replace(scene.options, model=TEST_MODEL)), build_solver
