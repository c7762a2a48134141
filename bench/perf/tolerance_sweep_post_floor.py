"""The default against the tolerance on the main job's post and the paper's Fig. 3 floor (#37).

Two contact cases with independent references, beside a fixed model at order 16:

* the main job's last pose on the post (test/unit/test_post_last_pose.py: shooting of the
  Kirchhoff rod with one point force, exact tangential contact), cold at δ = 1e-3 … 1e-5 m and
  streamed as that test streams (its last 40 targets, held until a check there says met) at 1e-3
  and 1e-4 m; each answer against the reference started from its own contact;
* the paper's Fig. 3 strip on its floor (config/scenes/bench_fig3_floor.yaml, ``plane: keep``)
  at ρ = 1000, 2000, 3000 N/m, cold at δ = 1e-3 … 1e-6 L, against the nearest of the floor
  reference's curled equilibria (test/reference/floor_rod.py, shooting on the heavy elastica).

Times are wall-clock, compile off, checks inline (as the CLI), building included.

Run: bash scripts/dlo-env run python bench/perf/tolerance_sweep_post_floor.py [--out FILE]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # as a script: `bench` importable
sys.path.insert(0, str(ROOT / "test"))  # the references
sys.path.insert(0, str(ROOT / "test" / "unit"))  # the cases

import test_plane_keep as floor  # noqa: E402
from bench.common import machine, write_report  # noqa: E402
import test_post_last_pose as post  # noqa: E402
from reference.floor_rod import fig3_floor, shoot, solve_discrete, start_angles  # noqa: E402

from dlo_ros.solver.auto import make_solver  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402

HEADER = [
    "| case | δ | model | status | tolerance met | unknowns | elements | time [ms] | "
    "true error [m] | estimate [m] |",
    "|---|---|---|---|---|---|---|---|---|---|",
]


def row(name: str, delta: str, model: str, r, seconds: float, error: float) -> str:
    """One table row of result ``r``."""
    m = r.model
    est = "-" if m.estimated_error_m is None else f"{m.estimated_error_m:.1e}"
    met = m.tolerance_met if model.startswith("auto") else "-"
    return (
        f"| {name} | {delta} | {model} | {r.status} | {met} | {m.variables} | "
        f"{m.elements or '-'} | {seconds * 1e3:.0f} | {error:.1e} | "
        f"{est if model.startswith('auto') else '-'} |"
    )


def post_error(r) -> float:
    """The answer's distance to the shooting reference on its own branch (nan: none found)."""
    try:
        return post.Reference(post.problem_at(post.LAST), r).error(r)
    except (AssertionError, ValueError):
        return float("nan")


def post_rows() -> list[str]:
    out = []
    for how, tolerances in (("cold", (1e-3, 1e-4, 1e-5)), ("streamed", (1e-3, 1e-4))):
        for tol in tolerances:
            t0 = time.perf_counter()
            r = post.solve(tol, how)
            seconds = time.perf_counter() - t0
            out.append(row("post", f"{tol:g} m", f"auto {how}", r, seconds, post_error(r)))
            print(out[-1], flush=True)
    options = replace(post.scene().options, model="full", order=16, output_points=post.POINTS)
    t0 = time.perf_counter()
    r = ShapeSolver(post.problem_at(post.LAST), options, compile="off").solve()
    seconds = time.perf_counter() - t0
    out.append(row("post", "-", "full chebyshev 16", r, seconds, post_error(r)))
    print(out[-1], flush=True)
    return out


def floor_error(r, refs) -> float:
    return min(
        float(np.max(np.linalg.norm(r.points[:, [0, 2]] - ref.at(r.s), axis=1))) for ref in refs
    )


def floor_rows() -> list[str]:
    out = []
    length = floor.L
    for rho in (1000.0, 2000.0, 3000.0):
        pr = fig3_floor(rho)
        refs = [shoot(solve_discrete(pr, 200, start_angles(200, at))) for at in (0.2, 0.8)]
        problem = floor.floor_problem(rho)
        for tol in (1e-3, 1e-4, 1e-5, 1e-6):
            options = replace(floor.SCENE.options, output_points=401, error_tolerance=tol * length)
            t0 = time.perf_counter()
            r = make_solver(problem, options, checks="sync", compile="off").solve()
            seconds = time.perf_counter() - t0
            name = f"Fig. 3 ρ = {rho:.0f}"
            out.append(row(name, f"{tol:g} L", "auto cold", r, seconds, floor_error(r, refs)))
            print(out[-1], flush=True)
        options = replace(floor.SCENE.options, order=16, output_points=401, model="planar")
        t0 = time.perf_counter()
        r = ShapeSolver(problem, options, compile="off").solve()
        seconds = time.perf_counter() - t0
        out.append(row(name, "-", "planar chebyshev 16", r, seconds, floor_error(r, refs)))
        print(out[-1], flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", default=str(ROOT / "bench" / "results" / "tolerance_sweep_post_floor.md")
    )
    args = parser.parse_args()
    info = machine()
    lines = [
        "# The default against the tolerance on the post and on the Fig. 3 floor (#37)",
        "",
        f"Machine: {platform.machine()}, {info['cpus']} CPUs, Python {info['python']}, git "
        f"{info.get('git', '?')}, {time.strftime('%Y-%m-%d %H:%M')}. Compile off, auto with "
        "inline checks, building included. Error: max centreline distance from the independent "
        "reference (bench/perf/tolerance_sweep_post_floor.py's docstring); nan: no reference "
        "could be started from that answer (its contact is not one push on the post). A "
        "stream's time is the whole stream's.",
        "",
        *HEADER,
        *post_rows(),
        *floor_rows(),
    ]
    write_report(lines, args.out, "bench/perf/tolerance_sweep_post_floor.py", [])


if __name__ == "__main__":
    main()
