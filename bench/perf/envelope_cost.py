"""The envelope's cost per update against the warm streamed update it describes (issue #40).

Scene: config/scenes/default_cable.yaml with ``string.uncertainty`` σ = 10 % of Rf, 20 % of Rt and 5 %
of D (``--uncertainty``).  One stream per row: the right grip moves by 1 % of L per update along
solver_speed.py's ellipse in the x–z plane; after every warm update (``solver.solve``, timed) the
envelope of that answer (``dlo_ros.solver.results.envelope.envelope``, timed: the KKT sensitivities at
the committed equilibrium, one dense linear solve with one right-hand side per parameter, and the
covariance propagation) is computed.  Both are wall-clock times of the same updates in the same run,
so their ratio is what the envelope adds to a stream that computes it at every update.  The first
envelope of a solver (which builds the CasADi functions of its sensitivity, once per NLP) is reported
apart.

Rows: two fixed models of this scene (planar, and the 3D director model, Chebyshev order 16: the
models of solver_speed.py and paced_updates.py; planar order 12 leaves some updates of this path over
the 1 mm tolerance), each with interpreted (``compile='off'``) and compiled
(``compile='blocking'``: compiled now, or loaded from the machine's cache) derivatives; and
``make_solver`` (auto, checks 'sync', interpreted) as ``dlo solve`` builds it.

    bash scripts/dlo-env run python bench/perf/envelope_cost.py [--updates 200] [--out bench/results/envelope_cost.md]
"""
from __future__ import annotations

import argparse
import os
import subprocess
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
from dlo_ros.solver import ShapeSolver, make_solver  # noqa: E402
from dlo_ros.solver.results.envelope import Envelope, Uncertainty, envelope  # noqa: E402

MODELS = {
    "planar, Chebyshev order 16": dict(model="planar", order=16),
    "3D director, Chebyshev order 16": dict(model="full"),
}


def uncommitted() -> str:
    """' (with uncommitted changes to dlo_ros/)' when the package differs from the commit, else ''."""
    changed = subprocess.run(["git", "status", "--porcelain", "--", "dlo_ros"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parents[2]).stdout.strip()
    return " (with uncommitted changes to dlo_ros/)" if changed else ""


def stream(solver, scene, uncertainty: Uncertainty, updates: int) -> dict:
    """Time each warm update and the envelope of its answer [ms]; the first envelope apart."""
    result = solver.solve()
    assert result.ok, result.message
    t0 = time.perf_counter()
    first = envelope(solver, result, uncertainty)
    first_ms = (time.perf_counter() - t0) * 1e3
    assert isinstance(first, Envelope), first
    orientation = scene.problem.grip("right").pose.orientation
    solve_ms, envelope_ms, sigma, unavailable = [], [], [], 0
    for target in path_targets(scene, updates):
        t0 = time.perf_counter()
        result = solver.solve({"right": (target, orientation)})
        t1 = time.perf_counter()
        spread = envelope(solver, result, uncertainty)
        t2 = time.perf_counter()
        if not isinstance(spread, Envelope):  # e.g. an unverified update auto's check raises later
            assert not result.ok, spread
            unavailable += 1
            continue
        solve_ms.append((t1 - t0) * 1e3)
        envelope_ms.append((t2 - t1) * 1e3)
        sigma.append(spread.max_sigma)
    solve, env = np.asarray(solve_ms), np.asarray(envelope_ms)
    return {"first_ms": first_ms, "solve": solve, "envelope": env, "ratio": env / solve,
            "max_sigma_mm": 1e3 * float(np.median(sigma)), "unavailable": unavailable}


def row(name: str, derivatives: str, r: dict) -> str:
    s, e, q = r["solve"], r["envelope"], r["ratio"]
    return (f"| {name} | {derivatives} | {np.median(s):.2f} | {np.percentile(s, 90):.2f} | {np.median(e):.2f} | "
            f"{np.percentile(e, 90):.2f} | {np.median(e) / np.median(s):.2f} | "
            f"{np.percentile(e, 90) / np.percentile(s, 90):.2f} | {np.median(q):.2f} | {np.percentile(q, 90):.2f} | "
            f"{r['first_ms']:.0f} | {r['max_sigma_mm']:.3f} | {len(s)} ({r['unavailable']}) |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--updates", type=int, default=200)
    ap.add_argument("--uncertainty", nargs=3, type=float, default=[0.002, 0.003, 0.025], metavar=("RF", "RT", "D"),
                    help="σ of bend_stiffness [N·m²], twist_stiffness [N·m²], weight_per_length [N/m]")
    ap.add_argument("--out", default="bench/results/envelope_cost.md")
    args = ap.parse_args()
    scene = load_scene("default_cable")
    keys = ("bend_stiffness", "twist_stiffness", "weight_per_length")
    uncertainty = Uncertainty.from_sigmas(dict(zip(keys, args.uncertainty)))
    os.environ.pop("DLO_NO_COMPILE", None)
    info = machine()
    lines = [
        "# The envelope's cost per update", "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other work), Python "
        f"{info.get('python')}, load average {info['load_average'][0]:.2f} at the start; git {info.get('git', '?')}"
        f"{uncommitted()}.", "",
        f"`default_cable`, σ: {', '.join(f'{k} {v:g}' for k, v in zip(keys, args.uncertainty))} (SI); "
        f"{args.updates} warm updates of 1 % of L per row, each followed by the envelope of its answer. "
        "Wall time [ms] of the update (solve) and of the envelope: median and p90; the ratio envelope / solve "
        "of the medians, of the p90s, and the median and p90 of the per-update ratio. `first`: the solver's "
        "first envelope (builds the sensitivity's CasADi functions, once per NLP); max σ: the median over the "
        "updates of the envelope's largest σ(s). An update that is not `ok` has no envelope (it is unavailable "
        "at once): such updates are counted, not timed.", "",
        "| model | derivatives | solve median | solve p90 | envelope median | envelope p90 | ratio of medians "
        "| ratio of p90s | per-update ratio median | per-update ratio p90 | first envelope ms | max σ mm | updates timed (not ok) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, settings in MODELS.items():
        options = replace(scene.options, **settings)
        for mode, label in (("off", "interpreted"), ("blocking", "compiled")):
            solver = ShapeSolver(scene.problem, options, compile=mode)
            lines.append(row(name, label, stream(solver, scene, uncertainty, args.updates)))
            print(lines[-1], flush=True)
    auto = make_solver(scene.problem, scene.options, compile="off", checks="sync")
    lines.append(row("auto (`make_solver`, checks sync)", "interpreted", stream(auto, scene, uncertainty,
                                                                                args.updates)))
    print(lines[-1], flush=True)
    write_report(lines, args.out, "bench/perf/envelope_cost.py", sys.argv[1:])


if __name__ == "__main__":
    main()
