"""Warm updates back to back against updates spaced in time, as a stream at a fixed rate spaces them.

The node solves a target when it arrives: at 100 Hz a 1 ms update is followed by about 9 ms of other
work or idleness.  solver_speed.py times updates back to back.  This benchmark times the same compiled
warm update (``ShapeSolver.solve``, ``compile='blocking'``) on `default_cable` with a pause before every
update: a sleep of each of ``--gaps`` milliseconds, and a busy wait (a Python loop reading the clock) of
4 ms.  One solver per model; every column solves the same right-grip targets (steps of 1 % of L around
solver_speed.py's ellipse in the x–z plane), in ROUNDS pieces interleaved with the other columns', so
that the machine's drift over the run falls on every column alike.

    bash scripts/dlo-env run python bench/perf/paced_updates.py [--updates 300] [--gaps 0 0.5 1 2 4 9]
                                                                [--out bench/results/paced_updates.md]
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script: make `bench` importable
from bench.common import machine, write_report  # noqa: E402
from solver_speed import path_targets  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import ShapeSolver  # noqa: E402

BUSY_WAIT_MS = 4.0
ROUNDS = 5  # each column's updates in this many interleaved pieces
MODELS = {"planar, order 16": dict(model="planar", order=16),
          "3D director, order 16": dict(model="full", order=16)}


def pause(kind: str, ms: float) -> None:
    """Sleep ``ms`` milliseconds, or (``kind`` 'busy') loop on the clock for that long."""
    if kind == "sleep":
        if ms > 0:
            time.sleep(ms / 1e3)
        return
    end = time.perf_counter() + ms / 1e3
    while time.perf_counter() < end:
        pass


def timed_updates(solver: ShapeSolver, targets: list[np.ndarray], orientation, kind: str, ms: float) -> np.ndarray:
    """Wall time [ms] of each warm update to ``targets``, each after a pause."""
    times = []
    for target in targets:
        pause(kind, ms)
        t0 = time.perf_counter()
        result = solver.solve({"right": (target, orientation)})
        times.append((time.perf_counter() - t0) * 1e3)
        if not result.ok:
            raise RuntimeError(f"update failed: {result.message}")
    return np.asarray(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=300)
    ap.add_argument("--gaps", type=float, nargs="+", default=[0, 0.5, 1, 2, 4, 9], help="sleeps before each update [ms]")
    ap.add_argument("--out", default="bench/results/paced_updates.md")
    args = ap.parse_args()
    scene = load_scene("default_cable")
    orientation = scene.problem.grip("right").pose.orientation
    targets = path_targets(scene, args.updates + 1)
    pauses = [("sleep", g) for g in args.gaps] + [("busy", BUSY_WAIT_MS)]
    columns = " | ".join(f"{'sleep' if k == 'sleep' else 'busy wait'} {ms:g} ms" for k, ms in pauses)
    info = machine()
    lines = [
        "# Warm updates back to back and spaced in time", "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other work), Python "
        f"{info.get('python')}, load average {info['load_average'][0]:.2f} at the start; git {info.get('git', '?')}.",
        "", f"`default_cable`, compiled derivatives, {args.updates} warm updates of 1 % of L per row; median "
        "(p90) of each update's wall time [ms], by the pause before every update.", "",
        f"| model | {columns} |", "|---|" + "---|" * len(pauses),
    ]
    for name, settings in MODELS.items():
        solver = ShapeSolver(scene.problem, replace(scene.options, **settings), compile="blocking")
        if not solver.solve().ok:
            raise RuntimeError(f"{name}: the cold solve failed")
        timed_updates(solver, targets[:50], orientation, "sleep", 0.0)  # warm-up
        times: dict[tuple, list] = {p: [] for p in pauses}
        chunk = max(1, len(targets) // ROUNDS)
        for r in range(ROUNDS):  # interleaved: the machine's drift over the run falls on every column alike
            for p in pauses:
                # from the path's start, so that every column solves the same targets from the same shape
                timed_updates(solver, targets[:1], orientation, "sleep", 0.0)
                times[p] += list(timed_updates(solver, targets[1 + r * chunk: 1 + (r + 1) * chunk], orientation, *p))
        cells = [f"{np.median(t):.2f} ({np.percentile(t, 90):.2f})" for t in times.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    write_report(lines, args.out, "bench/perf/paced_updates.py", sys.argv[1:])


if __name__ == "__main__":
    main()
