"""Shared pieces of the speed-vs-accuracy benchmark (issue 5): cases, outcomes, error metric, machine.

Every case is a dlo_ros ``Problem`` (so the Ritz methods take it as is) plus the extras the other
methods need (which plane is the working plane, how many turns the twisted end has made).  Lengths are
in units of L = 1 m, stiffness in units of Rf = 1 N m², so every error below is already "per L".
"""
from __future__ import annotations

import os
import platform
import subprocess
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from dlo_ros.model.obstacles import Obstacle
from dlo_ros.model.problem import Grip, GripPose, Load, Problem, StringProperties
from dlo_ros.model.profile import Profile

ROOT = Path(__file__).resolve().parent.parent  # the repository
RESULTS = ROOT / "bench" / "results"  # every result file of every bench script

S_OUT = np.linspace(0.0, 1.0, 101)  # where every method's centreline is compared [m] (L = 1)


# ---------------------------------------------------------------------------------------------------
# orientation helpers (quaternions x, y, z, w; pose x-axis = tangent)
def quat_planar(beta: float) -> np.ndarray:
    """Tangent (cos β, 0, sin β) in the x–z plane: a rotation about y by −β."""
    return np.array([0.0, np.sin(-beta / 2), 0.0, np.cos(-beta / 2)])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def quat_twisted(beta: float, tau: float) -> np.ndarray:
    """Planar tangent angle β, then turned by τ about the tangent."""
    return quat_mul(quat_planar(beta), np.array([np.sin(tau / 2), 0.0, 0.0, np.cos(tau / 2)]))


# ---------------------------------------------------------------------------------------------------
@dataclass
class Case:
    """One benchmark problem.  ``problem`` holds the grips at the target; ``tau`` is the end's total
    turn about its tangent (twist cases: methods that cannot know the turn count from a quaternion are
    brought there by continuation); ``planar`` says the case lives in the x–z plane."""

    name: str
    title: str
    problem: Problem
    planar: bool = True
    tau: float = 0.0
    align_about_chord: bool = False  # no gravity, no loads: the buckling plane is neutral about the chord
    reference_kind: str = "elastica"  # or "converged"
    chord: float = 0.0
    notes: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def L(self) -> float:
        return self.problem.string.length


def make_problem(*, chord: float, beta0: float = 0.0, beta1: float = 0.0, dz: float = 0.0, rf=1.0, rt=1.0,
                 d=0.0, modes=("clamp", "clamp"), tau: float = 0.0, loads=(), obstacles=(), L=1.0) -> Problem:
    prof = lambda v: v if isinstance(v, Profile) else Profile.constant(v)  # noqa: E731
    string = StringProperties(L, prof(rf), prof(rt), prof(d))
    grips = (
        Grip("left", 0.0, modes[0], GripPose(np.zeros(3), quat_planar(beta0))),
        Grip("right", L, modes[1], GripPose(np.array([chord, 0.0, dz]), quat_twisted(beta1, tau))),
    )
    return Problem(string, grips, np.array([0.0, 0.0, -1.0]), tuple(loads), tuple(obstacles))


def table(height: float) -> Obstacle:
    return Obstacle("halfspace", np.array([0.0, 0.0, height, 0.0, 0.0, 1.0]), "table")


def elastica_case(chord: float) -> Case:
    return Case(f"elastica_{chord:.1f}", f"clamped–clamped elastica, chord {chord:.1f}L", make_problem(chord=chord),
                align_about_chord=True, reference_kind="elastica", chord=chord)


def asym_case() -> Case:
    return Case("asymmetric", "asymmetric clamps (+0.6, −0.25 rad), ends (0,0)–(0.55L, 0.1L)",
                make_problem(chord=0.55, dz=0.1, beta0=0.6, beta1=-0.25), reference_kind="converged", chord=0.56)


def heavy_case(rho: float = 1500.0, table_z: float = -0.25) -> Case:
    return Case("heavy_table", f"heavy strip ρ = {rho:g} over a table at z = {table_z}L, chord 0.7L",
                make_problem(chord=0.7, rt=0.0, d=rho, obstacles=(table(table_z),)), reference_kind="converged",
                chord=0.7, meta={"rho": rho, "table": table_z})


def loads_case() -> Case:
    F = 8.0 * np.array([np.cos(3 * np.pi / 4), 0.0, np.sin(3 * np.pi / 4)])
    loads = (Load(0.3, force=F), Load(0.6, moment=np.array([0.0, 2.0, 0.0])))
    return Case("point_loads", "force 8 Rf/L² at 0.3L (direction 3π/4) + moment 2 Rf/L about y at 0.6L, chord 0.7L",
                make_problem(chord=0.7, loads=loads), reference_kind="converged", chord=0.7)


def twist_case(tau: float = 2 * np.pi, chord: float = 0.6) -> Case:
    return Case("twist3d", f"3D: clamps {chord}L apart, right end turned {tau / np.pi:g}π about its tangent",
                make_problem(chord=chord, tau=tau, rt=1.0 / 1.3), planar=False, tau=tau, reference_kind="converged",
                chord=chord, align_about_chord=True)


def with_chord(case: Case, chord: float) -> Problem:
    p = case.problem
    right = p.grip("right")
    pos = right.pose.position.copy()
    pos[0] = chord
    return p.with_grip_poses({"right": GripPose(pos, right.pose.orientation)})


# ---------------------------------------------------------------------------------------------------
@dataclass
class Outcome:
    """What one solve of one method gave."""

    ok: bool
    points: np.ndarray | None = None  # (len(S_OUT), 3)
    time_s: float = float("nan")
    iterations: int = 0
    stable: bool | None = None
    energy: float = float("nan")
    message: str = ""
    extra: dict = field(default_factory=dict)


def rotation_about_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def max_error(points: np.ndarray, reference: np.ndarray, align_about_chord: bool = False, L: float = 1.0,
              mirror: bool = False) -> float:
    """max_s |x(s) − x_ref(s)| / L; with ``align_about_chord`` the best rotation about the reference's chord
    (the line through its end points) is applied first: without gravity two clamps leave that rotation
    neutral, so every rotated copy is the same equilibrium.  ``mirror``: the scene is symmetric about the
    x–z plane, so the mirror image (y → −y) of a non-planar equilibrium is one too; the smaller error counts."""
    if points is None or not np.all(np.isfinite(points)):
        return float("nan")
    if mirror:
        flipped = points * np.array([1.0, -1.0, 1.0])
        return min(max_error(points, reference, align_about_chord, L), max_error(flipped, reference, align_about_chord, L))
    if align_about_chord:
        o = reference[0]
        e1 = reference[-1] - o
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(e1, [0.0, 0.0, 1.0]) if abs(e1[2]) < 0.9 else np.cross(e1, [0.0, 1.0, 0.0])
        e2 /= np.linalg.norm(e2)
        e3 = np.cross(e1, e2)
        frame = np.stack([e1, e2, e3], axis=1)  # columns
        p_loc, r_loc = (points - o) @ frame, (reference - o) @ frame
        a, b = p_loc[:, 1] + 1j * p_loc[:, 2], r_loc[:, 1] + 1j * r_loc[:, 2]
        angle = float(np.angle(np.vdot(a, b))) if np.abs(np.vdot(a, b)) > 0 else 0.0
        points = o + (p_loc @ rotation_about_x(angle).T) @ frame.T
    return float(np.max(np.linalg.norm(points - reference, axis=1)) / L)


def machine() -> dict:
    info = {"python": platform.python_version(), "platform": platform.platform(), "cpus": os.cpu_count()}
    try:
        with open("/proc/cpuinfo") as f:
            names = [ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")]
        info["cpu"] = names[0] if names else platform.processor()
    except OSError:
        info["cpu"] = platform.processor()
    try:
        info["load_average"] = os.getloadavg()
    except OSError:
        pass
    try:
        info["git"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                     cwd=os.path.dirname(__file__)).stdout.strip()
    except OSError:
        pass
    return info


def write_report(lines: list[str], out: str | Path, script: str, argv: list[str]) -> None:
    """Append the command that regenerates a Markdown report (``script`` run with ``argv`` through
    scripts/dlo-env), write it to ``out`` and print it."""
    command = " ".join([f"bash scripts/dlo-env run python {script}", *argv])
    text = "\n".join([*lines, "", f"Command: `{command}`", ""])
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(text)
    print(text)


class Timer:
    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.dt = time.perf_counter() - self.t0


def interp_points(s_nodes: np.ndarray, x_nodes: np.ndarray, s: np.ndarray = S_OUT) -> np.ndarray:
    return np.stack([np.interp(s, s_nodes, x_nodes[:, k]) for k in range(3)], axis=1)


def progress(iterable, total=None, desc=""):
    """tqdm when installed (requirements-bench.txt), else a plain iterator with a line per item."""
    try:
        from tqdm import tqdm

        return tqdm(iterable, total=total, desc=desc, dynamic_ncols=True, mininterval=1.0)
    except ImportError:  # pragma: no cover
        return iterable


__all__ = [n for n in dir() if not n.startswith("_")] + ["replace"]
