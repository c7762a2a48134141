"""A seeded generator of physically reasonable scenes (used by test_random_scenes.py and the bench).

Each scene is built around a smooth random space curve of length L (a random curvature and torsion
profile integrated as a Frenet-like frame): the grips sit on that curve at their arc lengths, with its
tangent (and frame) as their orientation, so every scene is reachable by construction.  Lengths
0.2–3 m, 1–3 grips of every mode (a single grip is a clamp), stiffness, twist and weight from a
cable's range, gravity on or off, at most one point load (force and moment) and at most one obstacle
(a table below the curve, or a sphere beside it).  Point moments only where a clamp holds the string
(a twisting moment that no grip can react has no equilibrium).
"""
from __future__ import annotations

import numpy as np

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties
from dlo_ros.model.director import frame_to_quat
from dlo_ros.model.obstacles import Obstacle


def random_curve(rng: np.random.Generator, length: float, count: int = 400):
    """Arc lengths, positions and frames (columns t, d1, d2) of a smooth random curve from the origin."""
    s = np.linspace(0.0, length, count)
    h = s[1] - s[0]
    k1 = rng.uniform(-4, 4) / length + rng.uniform(-3, 3) / length * np.sin(2 * np.pi * s / length + rng.uniform(0, 6))
    k2 = rng.uniform(-2, 2) / length * np.cos(np.pi * s / length + rng.uniform(0, 6))
    frame = np.eye(3)
    frames, x = [frame], [np.zeros(3)]
    for i in range(1, count):
        w = np.array([0.0, k2[i], k1[i]]) * h  # body rotation: bend about d1 and d2
        angle = np.linalg.norm(w)
        if angle > 0:
            a = w / angle
            K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
            frame = frame @ (np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K)
        x.append(x[-1] + 0.5 * h * (frames[-1][:, 0] + frame[:, 0]))
        frames.append(frame)
    return s, np.array(x), np.array(frames)


def random_scene(seed: int) -> Problem:
    return scene_and_curve(seed)[0]


def scene_and_curve(seed: int) -> tuple[Problem, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The scene of ``seed`` and the curve it is built around (arc lengths, positions, frames): a
    feasible shape of the scene up to its discretisation (bench/suite/random_scenes.py uses it as the witness
    that a scene is reachable and clear of its obstacles)."""
    rng = np.random.default_rng(seed)
    length = float(rng.uniform(0.2, 3.0))
    s, x, frames = random_curve(rng, length)
    x = x + np.array([0.0, 0.0, 1.0 + length])  # well above a table at z = 0
    rf = float(rng.uniform(0.005, 0.1)) * length
    weight = float(rng.choice([0.0, rng.uniform(0.1, 2.0)]))
    string = StringProperties(length, Profile.constant(rf), Profile.constant(rf * rng.uniform(0.3, 1.5)),
                              Profile.constant(weight), radius=0.0)
    count = int(rng.integers(1, 4))
    grip_s = {1: [0.0], 2: [0.0, length], 3: [0.0, float(rng.uniform(0.3, 0.7)) * length, length]}[count]
    grips = []
    for i, gs in enumerate(grip_s):
        j = int(np.argmin(np.abs(s - gs)))
        mode = "clamp" if count == 1 else str(rng.choice(["clamp", "pin", "tangent"]))
        grips.append(Grip(f"g{i}", float(s[j]) if 0 < i < count - 1 else gs, mode,
                          GripPose.checked(x[j], frame_to_quat(frames[j]), f"g{i}")))
    if count > 1 and all(g.mode == "pin" for g in grips):
        grips[0] = Grip(grips[0].name, grips[0].s, "clamp", grips[0].pose)
    loads = ()
    if rng.random() < 0.5:
        scale = max(weight * length, rf / length**2)
        # a point moment only where a clamp can react its twisting part (else no equilibrium exists)
        clamped = any(g.mode == "clamp" for g in grips)
        loads = (Load(float(rng.uniform(0.2, 0.8)) * length, force=rng.normal(size=3) * 0.3 * scale,
                      moment=rng.normal(size=3) * 0.1 * scale * length * clamped),)
    obstacles = ()
    roll = rng.random()
    if roll < 0.3:
        obstacles = (Obstacle("halfspace", np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0]), "table"),)
    elif roll < 0.5:
        centre = x[len(x) // 2] + frames[len(x) // 2][:, 1] * 0.3 * length
        obstacles = (Obstacle("sphere", np.array([*centre, 0.1 * length]), "ball"),)
    gravity = np.array([0.0, 0.0, -1.0])
    return Problem(string, tuple(grips), gravity=gravity, loads=loads, obstacles=obstacles), (s, x, frames)


def targets_near(problem: Problem, n: int, grip: str = "right", radius: float = 0.15, seed: int = 0) -> list[dict]:
    """``n`` seeded query targets: ``grip`` moved to a random point within ``radius`` [m] of its pose,
    its orientation kept (what a planner asks about around the held shape)."""
    rng = np.random.default_rng(seed)
    pose = problem.grip(grip).pose
    out = []
    for _ in range(n):
        d = rng.normal(size=3)
        out.append({grip: (pose.position + d * rng.random() * radius / np.linalg.norm(d), pose.orientation)})
    return out
