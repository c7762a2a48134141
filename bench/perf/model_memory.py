"""Memory of fine element models: what one build holds, and a long refinement's peak (#37).

Two measures, each in a fresh child process (its own peak RSS), on a checkout given by
``--tree`` (default: this one) and, with ``--before DIR``, on another checkout side by side
(e.g. ``git worktree add /tmp/before <rev>``; both run with this venv, each tree first on the
path):

* the paper's Fig. 3 strip (ρ = 3000 N/m) on a hand-made planar element mesh of E elements with
  30 nodes each: the parameter vector's length and the resident memory the build adds;
* the default streaming the strip onto its floor at δ = 1e-6 L, ρ = 1000 (test_plane_keep.py's
  ``floor_answer``: the refinement climbs to its cap of 320 nodes per field and pools the models
  on its way): peak RSS, wall time, the answer's status.

Run: bash scripts/dlo-env run python bench/perf/model_memory.py [--before DIR] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # as a script: `bench` importable

from bench.common import machine, write_report  # noqa: E402

BUILD = """
import json, sys
import numpy as np
from test_fig3_floor_mesh import problem_at
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver

def rss():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 2**20

elements = int(sys.argv[1])
options = SolverOptions(model="planar", basis="elements", obstacle_points="nodes", order=30,
                        quadrature_nodes=38, output_points=401)
spec = MeshSpec(tuple(np.linspace(0, 0.5, elements + 1)[1:-1]), (30,) * elements)
problem = problem_at(3000.0)
before = rss()
nlp = ShapeSolver(problem, options, mesh=spec).nlp
print(json.dumps({"nodes": int(nlp.model.layout.order), "p": int(nlp.params.size),
                  "mb": rss() - before}))
"""

STREAM = """
import json, resource, time
from dataclasses import replace
from test_plane_keep import SCENE, L, floor_answer

options = replace(SCENE.options, output_points=401, update_time_limit=0.0,
                  error_tolerance=1e-6 * L)
t0 = time.perf_counter()
r = floor_answer(1000.0, options, "streamed")
print(json.dumps({"seconds": time.perf_counter() - t0, "status": r.status,
                  "met": r.model.tolerance_met, "unknowns": r.model.variables,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def child(tree: Path, code: str, *args: str) -> dict:
    """Run ``code`` in a fresh interpreter, ``tree`` (its package, its tests) first on the path."""
    paths = [str(tree), str(tree / "test"), str(tree / "test" / "unit")]
    prelude = f"import sys; sys.path[:0] = {paths!r}\n"
    done = subprocess.run(
        [sys.executable, "-c", prelude + code, *args],
        capture_output=True,
        text=True,
        timeout=1800,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", default=str(ROOT))
    parser.add_argument("--before", default=None)
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "model_memory.md"))
    args = parser.parse_args()
    trees = [("this tree", Path(args.tree))]
    if args.before:
        trees.insert(0, ("before", Path(args.before)))
    info = machine()
    revs = {
        name: subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True
        ).stdout.strip()
        for name, tree in trees
    }
    lines = [
        "# Memory of fine element models (#37)",
        "",
        f"Machine: {platform.machine()}, {info['cpus']} CPUs, Python {info['python']}, git "
        f"{info.get('git', '?')}, {time.strftime('%Y-%m-%d %H:%M')}. Trees: "
        + ", ".join(f"{name} = {revs[name]}" for name, _ in trees)
        + ". Each figure from a fresh process (bench/perf/model_memory.py's docstring).",
        "",
        "## One build: Fig. 3, ρ = 3000, planar elements of 30 nodes",
        "",
        "| tree | elements | nodes | parameters | build [MB] |",
        "|---|---|---|---|---|",
    ]
    for elements in (3, 6, 11, 21):
        for name, tree in trees:
            b = child(tree, BUILD, str(elements))
            lines.append(f"| {name} | {elements} | {b['nodes']} | {b['p']} | {b['mb']:.0f} |")
            print(lines[-1], flush=True)
    lines += [
        "",
        "## The default streamed onto the floor at 1e-6 L, ρ = 1000",
        "",
        "| tree | status | tolerance met | unknowns | time [s] | peak RSS [MB] |",
        "|---|---|---|---|---|---|",
    ]
    for name, tree in trees:
        s = child(tree, STREAM)
        lines.append(
            f"| {name} | {s['status']} | {s['met']} | {s['unknowns']} | {s['seconds']:.0f} | "
            f"{s['peak_mb']:.0f} |"
        )
        print(lines[-1], flush=True)
    argv = [f"--before {args.before}"] if args.before else []
    write_report(lines, args.out, "bench/perf/model_memory.py", argv)


if __name__ == "__main__":
    main()
