"""Shared helpers for the tests: small scenes built from the model classes (no YAML, no ROS)."""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties


def quat_about(axis: str, angle: float) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation by ``angle`` about a coordinate axis."""
    q = [0.0, 0.0, 0.0, np.cos(angle / 2)]
    q["xyz".index(axis)] = np.sin(angle / 2)
    return q


def clamped_pair(
    left: tuple = (0.0, 0.0, 0.0),
    right: tuple = (0.5, 0.0, 0.0),
    q_left: list | None = None,
    q_right: list | None = None,
    length: float = 1.0,
    bend: float = 1.0,
    twist: float = 1.0,
    weight: float = 0.0,
    modes: tuple[str, str] = ("clamp", "clamp"),
    loads: tuple[Load, ...] = (),
    obstacles: tuple = (),
    gravity: tuple = (0.0, 0.0, -1.0),
) -> Problem:
    """A string of ``length`` held at s = 0 and s = L (tangents along +x unless given)."""
    ident = [0.0, 0.0, 0.0, 1.0]
    string = StringProperties(length, Profile.constant(bend), Profile.constant(twist), Profile.constant(weight))
    grips = (
        Grip("left", 0.0, modes[0], GripPose.checked(left, q_left or ident, "left")),
        Grip("right", length, modes[1], GripPose.checked(right, q_right or ident, "right")),
    )
    return Problem(string, grips, gravity=np.array(gravity, dtype=float), loads=loads, obstacles=obstacles)


@pytest.fixture
def make_pair():
    return clamped_pair


@pytest.fixture(autouse=True)
def _no_background_compile(monkeypatch):
    """Tests use interpreted CasADi derivatives (compiling a scene takes gcc ~1 min); the compiled path
    has its own test that opts back in."""
    monkeypatch.setenv("DLO_NO_COMPILE", "1")


@contextmanager
def clean_node(*node_args: str, log_path: Path):
    """``running_node`` (the node in its own process and domain, a client); afterwards the node must
    have exited with code 0 and logged no traceback (its log is the assertion message)."""
    from dlo_ros.node.client import running_node

    with running_node(*node_args, log_path=log_path) as (proc, client):
        yield proc, client
    text = Path(log_path).read_text()
    assert proc.returncode == 0, text
    assert "Traceback" not in text, text


@pytest.fixture(scope="module")
def node_scene():
    """(the node tests' scene with their solver.model, the node's solver factory): what the node under
    test solves, to compare with in this process (interpreted: the autouse fixture above)."""
    from dlo_ros.node.client import TEST_MODEL, TEST_SCENE
    from dlo_ros.node.engine import build_solver
    from dlo_ros.scene import load_scene

    scene = load_scene(TEST_SCENE)
    return replace(scene, options=replace(scene.options, model=TEST_MODEL)), build_solver
