"""Record the behaviour corpus of issue #36: what the solver answers, case by case, into one .npz.

A behaviour-preserving refactor of dlo_ros/solver/ must leave every number here unchanged (to
1e-12) or explain each difference: run this before and after, then ``bench/corpus/compare.py``.

Cases (public API only: the facades ``dlo_ros.solver``, ``dlo_ros.scene``, ``dlo_ros.model`` and
test/random_scenes.py, so that modules moving inside dlo_ros/solver/ do not break the script):

* ``scene/<name>``: every shipped scene (config/scenes/*.yaml) solved cold with its own options;
* ``random/<seed>``: random scenes (test/random_scenes.py), seeds 0..49, cold, ``model: auto``;
* ``stream/default_cable/<model>/<derivatives>``: the default cable cold, then 200 warm updates of
  the right grip (a 1 cm step per update on a circle in the vertical plane for the first half; the
  second half also leaves that plane by 0.1 m and turns the clamp by 1.5 rad about its tangent, so
  auto switches planar -> 3D), under ``auto`` and ``full``, with interpreted derivatives
  (``compile='off'``) and with compiled C (``compile='blocking'``: the native Newton loops);
* ``stream/self_contact/full`` and ``stream/self_contact/auto``: the paper's Fig. 2 loop (clamp at
  s = 0, tangent grip at s = L, Rf/Rt = 100, radius 0.01 L) brought from a 0.42 L chord to 0.2 L in
  0.01 L steps, so the loop closes onto itself (test_self_contact.py's stream; auto as in
  test_auto_models_self_contact_once_within_reach);
* ``moment/<k>``: the far-turning dead point moments of test_point_moments.py, cold and a stream
  that moves and turns the clamp and brings it back.

Deterministic by construction: no wall-clock limit affects an answer (update_time_limit 0; a cold
solve has none), auto's checks run synchronously (``checks='sync'``), BLAS/OpenMP run one thread,
and the compiled cases use a private, fresh library cache (``--cache-dir``) whose libraries are all
built before the recorded pass (auto's helper models load 'cached' libraries, whose presence would
otherwise depend on background compile threads).

    nice bash scripts/dlo-env run python bench/corpus/collect.py --out /work/corpus/a.npz [--quick]
"""

from __future__ import annotations

import os

# One BLAS/OpenMP thread: a threaded reduction may sum in another order from run to run.  Set
# before numpy (imported below) loads its BLAS.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402  (after the thread settings above)
import json  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, replace  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable, Iterator  # noqa: E402

import numpy as np  # noqa: E402

from dlo_ros.model import (  # noqa: E402
    Grip,
    GripPose,
    Load,
    Problem,
    Profile,
    StringProperties,
)
from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import ShapeResult, SolverOptions, make_solver  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "test"))
from random_scenes import random_scene  # noqa: E402

#: shipped scenes left out, with the reason (none so far: each solves cold in under 120 s)
SKIP_SCENES: dict[str, str] = {}
RANDOM_SEEDS = range(50)
STREAM_UPDATES = 200
STRAIGHT = (0.0, 0.0, 0.0, 1.0)


@dataclass
class Case:
    """One corpus case: a name and a function returning its results in order."""

    name: str
    run: Callable[[], list[ShapeResult]]


def no_time_limit(options: SolverOptions) -> SolverOptions:
    """Drop the wall-clock limit on warm updates (an answer must not depend on it)."""
    return replace(options, update_time_limit=0.0)


def solver_for(problem: Problem, options: SolverOptions, compile: str = "off"):
    """Build the solver the CLI would (sync checks), without a time limit."""
    return make_solver(problem, no_time_limit(options), compile=compile, checks="sync")


def stream(solver, targets: list[dict]) -> list[ShapeResult]:
    """Solve cold, then one warm update per target; return every result, whatever its status."""
    results = [solver.solve(warm=False)]
    for poses in targets:
        results.append(solver.solve(poses))
    solver.close()
    return results


# ---- the cases ---------------------------------------------------------------------------------
def shipped_scene(name: str) -> Case:
    """Solve a shipped scene cold with its own options."""

    def run() -> list[ShapeResult]:
        scene = load_scene(name)
        solver = solver_for(scene.problem, scene.options)
        result = solver.solve(warm=False)
        solver.close()
        return [result]

    return Case(f"scene/{name}", run)


def random_case(seed: int) -> Case:
    """Solve a random scene (test/random_scenes.py) cold with ``model: auto``."""

    def run() -> list[ShapeResult]:
        solver = solver_for(random_scene(seed), SolverOptions())
        result = solver.solve(warm=False)
        solver.close()
        return [result]

    return Case(f"random/{seed}", run)


def cable_targets(problem: Problem, updates: int) -> list[dict]:
    """Move the right grip on a circle (1 % of L per update, radius 0.05 L), ``updates`` targets.

    The circle lies in the vertical x-z plane; over the second half the grip also moves 0.1 m
    along y and turns by 1.5 rad about its tangent (x).
    """
    length = problem.string.length
    pose = problem.grip("right").pose
    radius, step = 0.05 * length, 0.01 * length / (0.05 * length)
    half = updates // 2
    targets = []
    for k in range(1, updates + 1):
        out = max(0, k - half) / max(1, updates - half)  # 0 over the first half, then up to 1
        angle = 1.5 * out
        position = pose.position + np.array(
            [-radius * np.sin(k * step), 0.1 * out, radius * (1.0 - np.cos(k * step))]
        )
        quat = np.array([np.sin(angle / 2), 0.0, 0.0, np.cos(angle / 2)])  # about x, the tangent
        targets.append({"right": GripPose(position, quat)})
    return targets


def cable_stream(model: str, compile: str, updates: int) -> Case:
    """default_cable cold, then ``updates`` warm updates (cable_targets) under ``model``."""

    def run() -> list[ShapeResult]:
        scene = load_scene("default_cable")
        options = replace(scene.options, model=model)
        targets = cable_targets(scene.problem, updates)
        if compile != "off":
            # build (or load) every library this stream needs, auto's helper models included,
            # so that the recorded pass below never depends on a compile thread's progress
            warmup = solver_for(scene.problem, options, compile)
            stream(warmup, targets)
            wait_for_compile_threads()
        return stream(solver_for(scene.problem, options, compile), targets)

    return Case(f"stream/default_cable/{model}/{'compiled' if compile != 'off' else 'off'}", run)


def wait_for_compile_threads() -> None:
    """Join the compile threads a solver started (auto compiles its helper models ahead)."""
    while True:  # a compile-ahead thread may start a compile thread before it ends
        running = [t for t in threading.enumerate() if t.name.startswith("dlo-compile")]
        if not running:
            return
        for thread in running:
            thread.join()


def fig2(chord: float) -> Problem:
    """Build the paper's Fig. 2 scene with the given chord [m] (test_self_contact.fig2).

    1 m, clamp at s = 0, tangent grip at (chord, 0, 0), Rf/Rt = 100, no weight, radius 0.01 m.
    """
    string = StringProperties(
        1.0, Profile.constant(1.0), Profile.constant(0.01), Profile.constant(0.0), radius=0.01
    )
    grips = (
        Grip("left", 0.0, "clamp", GripPose.checked((0.0, 0.0, 0.0), STRAIGHT, "left")),
        Grip("right", 1.0, "tangent", GripPose.checked((chord, 0.0, 0.0), STRAIGHT, "right")),
    )
    return Problem(string, grips, gravity=np.array([0.0, 0.0, -1.0]))


def self_contact_stream(model: str) -> Case:
    """Fig. 2 from a 0.42 L chord to 0.2 L in 0.01 L steps: the loop closes onto itself."""
    chords = [float(c) for c in np.round(np.arange(0.41, 0.195, -0.01), 10)]

    def run() -> list[ShapeResult]:
        if model == "full":
            options = SolverOptions(model="full", order=16, self_contact_pairs=16)
        else:  # auto switches self-contact on once the shape comes within reach of itself
            options = SolverOptions(error_tolerance=0.01)
        targets = [{"right": ((c, 0.0, 0.0), STRAIGHT)} for c in chords]
        return stream(solver_for(fig2(0.42), options), targets)

    return Case(f"stream/self_contact/{model}", run)


#: the dead point moments [N·m] of test_point_moments.py (they turn the string about a radian)
MOMENTS = ((0.02, -0.12, 0.1), (0.1, 0.1, 0.1))


def point_moment(index: int) -> Case:
    """Solve a cantilever with the dead moment MOMENTS[index] cold, then as a stream.

    1 m, clamp at s = 0, weight, a point force and the moment at s = 0.6 m; the stream moves and
    turns the clamp and brings it back (test_point_moments.py).
    """
    clamp = np.array([0.0, 0.0, 1.0])

    def turn(angle: float) -> tuple[float, ...]:
        return (0.0, 0.0, float(np.sin(angle / 2)), float(np.cos(angle / 2)))

    def run() -> list[ShapeResult]:
        string = StringProperties(
            1.0, Profile.constant(0.05), Profile.constant(0.04), Profile.constant(0.5)
        )
        grip = Grip("clamp", 0.0, "clamp", GripPose.checked(clamp, STRAIGHT, "clamp"))
        load = Load(0.6, force=np.array([0.1, 0.2, 0.0]), moment=np.array(MOMENTS[index]))
        problem = Problem(string, (grip,), gravity=np.array([0.0, 0.0, -1.0]), loads=(load,))
        targets = [
            {"clamp": (clamp + [0.0, 0.02 * k, -0.01 * k], turn(0.05 * k))}
            for k in (1, 2, 3, 4, 3, 2, 1, 0)
        ]
        return stream(solver_for(problem, SolverOptions(model="full", order=16)), targets)

    return Case(f"moment/{index}", run)


def cases(quick: bool) -> Iterator[Case]:
    """Every case in the order it is recorded (``quick``: a small subset for a smoke run)."""
    scenes = sorted(p.stem for p in (REPO / "config" / "scenes").glob("*.yaml"))
    for name in scenes[:2] if quick else scenes:
        yield shipped_scene(name)
    for seed in list(RANDOM_SEEDS)[: 3 if quick else None]:
        yield random_case(seed)
    updates = 20 if quick else STREAM_UPDATES
    for model in ("auto", "full"):
        yield cable_stream(model, "off", updates)
    for model in ("full", "auto"):
        yield cable_stream(model, "blocking", updates)
    yield self_contact_stream("full")
    yield self_contact_stream("auto")
    for index in range(len(MOMENTS)):
        yield point_moment(index)


# ---- recording ---------------------------------------------------------------------------------
def _stack(rows: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """``rows`` as one float array, each padded with NaN to ``shape`` (a failed solve has none)."""
    out = np.full((len(rows), *shape), np.nan)
    for i, row in enumerate(rows):
        row = np.asarray(row, dtype=float).reshape(-1, *shape[1:])
        out[i][tuple(slice(0, n) for n in row.shape)] = row
    return out


def record(results: list[ShapeResult]) -> dict[str, np.ndarray]:
    """Turn the results of one case into its arrays (one row per result)."""
    grips = sorted({name for r in results for name in r.grips})
    n_points = max((len(r.points) for r in results), default=0)
    n_contacts = max((len(r.self_contacts) for r in results), default=0)
    obstacles = sorted({i for r in results for i in r.contact_forces})

    def wrench(r: ShapeResult) -> np.ndarray:
        rows = [
            np.concatenate([r.grips[g].force, r.grips[g].torque]) if g in r.grips else [np.nan] * 6
            for g in grips
        ]
        return np.array(rows, dtype=float).reshape(len(grips), 6)

    def contacts(r: ShapeResult) -> np.ndarray:
        rows = [[c.s_a, c.s_b, *c.force, c.gap] for c in r.self_contacts]
        return np.array(rows, dtype=float).reshape(len(rows), 6)

    def optional(value: float | bool | None) -> float:
        return np.nan if value is None else float(value)

    return {
        "status": np.array([r.status for r in results]),
        "message": np.array([r.message for r in results]),
        "model": np.array([json.dumps(r.model_dict(), sort_keys=True) for r in results]),
        "ipopt_status": np.array([r.ipopt_status for r in results]),
        "stable": np.array([optional(r.stable) for r in results]),
        "warm_started": np.array([float(r.warm_started) for r in results]),
        "iterations": np.array([r.iterations for r in results], dtype=np.int64),
        "continuation_steps": np.array([r.continuation_steps for r in results], dtype=np.int64),
        "min_eigenvalue": np.array([optional(r.min_eigenvalue) for r in results]),
        "equilibrium_residual_m": np.array([r.equilibrium_residual_m for r in results]),
        "constraint_violation": np.array([r.constraint_violation for r in results]),
        "energy_total": np.array([r.energy.get("total", np.nan) for r in results]),
        "min_self_distance": np.array([r.min_self_distance for r in results]),
        "points": _stack([r.points for r in results], (n_points, 3)),
        "orientations": _stack([r.orientations for r in results], (n_points, 4)),
        "grip_names": np.array(grips, dtype=str),
        "wrench": np.array([wrench(r) for r in results]).reshape(len(results), len(grips), 6),
        "contact_forces": _stack(
            [
                np.array([r.contact_forces.get(i, [np.nan] * 3) for i in obstacles])
                for r in results
            ],
            (len(obstacles), 3),
        ),
        "self_contacts": _stack([contacts(r) for r in results], (n_contacts, 6)),
    }


def git_head() -> str:
    """Name the commit the corpus is recorded at ('+dirty' when tracked files changed)."""
    try:
        head = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        return head + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    """Record every case into ``--out``; print one line per case."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="the .npz file to write")
    ap.add_argument("--quick", action="store_true", help="a few cases, short streams (smoke run)")
    ap.add_argument(
        "--cache-dir",
        help="library cache of the compiled cases (default: a fresh temporary folder, removed)",
    )
    ap.add_argument("--only", help="record only the cases whose name contains this text")
    args = ap.parse_args(argv)
    cache = (
        Path(args.cache_dir) if args.cache_dir else Path(tempfile.mkdtemp(prefix="dlo-corpus-"))
    )
    os.environ["DLO_CACHE_DIR"] = str(cache)
    os.environ.pop("DLO_NO_COMPILE", None)
    arrays: dict[str, np.ndarray] = {}
    meta: dict = {"git": git_head(), "quick": args.quick, "cases": [], "skipped": {}}
    start = time.perf_counter()
    try:
        for name in SKIP_SCENES:
            meta["skipped"][f"scene/{name}"] = SKIP_SCENES[name]
        for case in cases(args.quick):
            if case.name.startswith("scene/") and case.name[6:] in SKIP_SCENES:
                continue
            if args.only and args.only not in case.name:
                continue
            t0 = time.perf_counter()
            results = case.run()
            seconds = time.perf_counter() - t0
            for key, value in record(results).items():
                arrays[f"{case.name}::{key}"] = value
            meta["cases"].append({"name": case.name, "results": len(results), "seconds": seconds})
            statuses = {
                s: [r.status for r in results].count(s) for s in {r.status for r in results}
            }
            print(
                f"{case.name:42s} {len(results):4d} results {seconds:7.1f} s  {statuses}",
                flush=True,
            )
    finally:
        if not args.cache_dir:
            shutil.rmtree(cache, ignore_errors=True)
    meta["seconds"] = time.perf_counter() - start
    arrays["__meta__"] = np.array(json.dumps(meta))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    # numpy's stub types **arrays as its keyword allow_pickle (a bool); the keys are case names
    np.savez_compressed(args.out, **arrays)  # type: ignore[arg-type]
    print(f"{len(meta['cases'])} cases in {meta['seconds']:.0f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
