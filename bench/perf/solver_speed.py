"""Solver-only speed on a 3D scene: cold solve and warm-started updates (issue 2's benchmark).

Scene: config/scenes/default_cable.yaml (1 m cable; bend, twist, gravity; two clamping grips; a table).
Cold: a fresh ShapeSolver's first solve (median of --cold runs).  Warm: the right grip moves by 1 % of L
per update along a smooth closed path (x, z) — ≥ 100 updates, median and p90.  Reports the build time
(NLP + IPOPT set-up), the one-off compile time of the KKT function and the time to load it from the
cache on a later start, for the interpreted and the compiled derivatives side by side (same run).

    bash scripts/dlo-env run python bench/perf/solver_speed.py [--updates 200] [--out bench/results/solver_speed.md]

``--model planar --order 16``: the model ``solver.model: auto`` streams for this planar scene (the path
stays in the x–z plane; order 12 leaves some of its updates over the 1 mm tolerance), e.g.
``--out bench/results/solver_speed_planar.md``.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script: make `bench` importable
from bench.common import write_report  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import ShapeSolver  # noqa: E402


def path_targets(scene, updates: int) -> list[np.ndarray]:
    """Right-grip positions: steps of 1 % of L around an ellipse in the x–z plane."""
    L = scene.problem.string.length
    start = scene.problem.grip("right").pose.position
    radius = 0.08 * L
    circumference = 2 * np.pi * radius
    dtheta = 0.01 * L / radius
    out = []
    for i in range(1, updates + 1):
        a = i * dtheta
        out.append(start + np.array([radius * (np.cos(a) - 1), 0.0, radius * np.sin(a)]))
    assert circumference > 0
    return out


def run(mode: str, scene, updates: int, cold_runs: int) -> dict:
    t0 = time.perf_counter()
    solver = ShapeSolver(scene.problem, scene.options, compile=mode)
    build = time.perf_counter() - t0
    cold = []
    for _ in range(cold_runs):
        solver.reset()
        r = solver.solve()
        assert r.ok, r.message
        cold.append(r.solve_time_ms)
    q = scene.problem.grip("right").pose.orientation
    warm, iters, newton = [], [], 0
    for target in path_targets(scene, updates):
        r = solver.solve({"right": (target, q)})
        assert r.ok, r.message
        warm.append(r.solve_time_ms)
        iters.append(r.iterations)
        newton += r.ipopt_status == "Newton"
    return {
        "mode": mode, "compiled": solver.kkt_compiled, "build_s": build, "compile_s": solver.compile_time_s,
        "cold_ms": statistics.median(cold), "warm_median_ms": statistics.median(warm),
        "warm_p90_ms": float(np.percentile(warm, 90)), "warm_p99_ms": float(np.percentile(warm, 99)),
        "iterations_median": statistics.median(iters),
        "newton_fraction": newton / len(warm), "variables": solver.model.layout.size,
        "constraints": int(solver.nlp.lbg.size),
    }


def _git() -> str:
    import subprocess

    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() or "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="default_cable")
    ap.add_argument("--updates", type=int, default=200)
    ap.add_argument("--cold", type=int, default=5)
    ap.add_argument("--model", choices=["full", "planar"], help="solver.model (default: the scene's)")
    ap.add_argument("--order", type=int, help="solver.order (default: the scene's)")
    ap.add_argument("--out", default="bench/results/solver_speed.md")
    args = ap.parse_args()
    scene = load_scene(args.scene)
    if args.model or args.order:
        scene = replace(scene, options=replace(scene.options, model=args.model or scene.options.model,
                                               order=args.order or scene.options.order))
    os.environ.pop("DLO_NO_COMPILE", None)
    rows = [run("off", scene, args.updates, args.cold)]
    import tempfile

    shared_cache = os.environ.get("DLO_CACHE_DIR")
    with tempfile.TemporaryDirectory() as empty:  # first start on a machine: nothing cached yet
        os.environ["DLO_CACHE_DIR"] = empty
        rows.append(run("blocking", scene, args.updates, args.cold))
    if shared_cache is None:
        os.environ.pop("DLO_CACHE_DIR")
    else:
        os.environ["DLO_CACHE_DIR"] = shared_cache
    run("blocking", scene, 1, 1)  # make sure the machine's cache holds this scene
    rows.append(run("blocking", scene, args.updates, args.cold))   # a later start: loads from the cache
    rows[1]["mode"], rows[2]["mode"] = "compiled (first start)", "compiled (later start, cached)"
    base = rows[0]["warm_median_ms"]
    lines = [
        f"# Solver speed: `{args.scene}`, solver.model {scene.options.model}", "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, load average "
        f"{', '.join(f'{v:.2f}' for v in os.getloadavg())} at the end; git {_git()}; "
        f"{rows[0]['variables']} unknowns, {rows[0]['constraints']} constraints (order {scene.options.order}, "
        f"{scene.options.obstacle_samples} table samples). {args.updates} warm updates of 1 % of L.", "",
        "| derivatives | build s | compile s | cold ms | warm median ms | warm p90 ms | warm p99 ms | warm/interpreted | median iterations | Newton share |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['mode']} | {r['build_s']:.2f} | {r['compile_s']:.1f} | {r['cold_ms']:.1f} | {r['warm_median_ms']:.2f} | "
            f"{r['warm_p90_ms']:.2f} | {r['warm_p99_ms']:.2f} | {r['warm_median_ms'] / base:.2f} | {r['iterations_median']:.0f} | {r['newton_fraction']:.0%} |"
        )
    write_report(lines, args.out, "bench/perf/solver_speed.py", sys.argv[1:])


if __name__ == "__main__":
    main()
