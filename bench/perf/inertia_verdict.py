"""Warm updates with the stability verdict from the inertia (#38) against the eigenvalue, same run.

`default_cable`, the fixed 3D model (``make_solver(problem, replace(options, model='full'))``,
compiled), the right grip moved in small steps (1 % of L around solver_speed.py's ellipse in the
x–z plane: every update one compiled Newton call).  Three columns, each its own solver on the same
targets, in ``--rounds`` interleaved pieces so that the machine's drift falls on all alike:

* before: the code of git revision ``--before`` (default: where this branch left ``main``, ``git
  merge-base main HEAD``; its ``dlo_ros`` extracted with ``git archive`` into a temporary folder),
  in a worker process of its own;
* after, eigenvalue: this tree's code with the loops' inertia switched off (``lapack.inertia = 0``:
  the eigenpair at every answer, as before);
* after, inertia: this tree's code as it runs (the verdict from LDLᵀ, λ_min computed when read).

The two "after" columns share one worker process.  Each update's wall time around
``solver.solve`` [ms]: median and p99, and their ratios to "before".  Then the verdict's LAPACK
work alone on the matrices of the last committed state (SciPy's wrappers, the routines the C calls:
dsytrf of [H Jᵀ; J 0] against geqp3 + orgqr + syevr of Nᵀ H N), median of ``--repeat`` calls.

    bash scripts/dlo-env run python bench/perf/inertia_verdict.py [--updates 400] [--rounds 8]
                                          [--before REV] [--out bench/results/inertia_verdict.md]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def worker(columns: list[str]) -> None:
    """Serve rounds over stdin/stdout: a line [column, first, count] → the update times [ms]."""
    from dataclasses import replace

    from dlo_ros.scene import load_scene
    from dlo_ros.solver.auto.factory import make_solver

    # after dlo_ros (solver_speed puts this tree first on the path: the 'before' worker's code must
    # already be the imported one)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from solver_speed import path_targets

    scene = load_scene("default_cable")
    options = replace(scene.options, model="full")
    rot = scene.problem.grip("right").pose.orientation
    targets = path_targets(scene, 100_000)
    solvers = {}
    for column in columns:
        solver = make_solver(scene.problem, options, compile="blocking")
        assert solver.solve().ok and solver.functions.newton_native is not None
        solvers[column] = solver
    print(json.dumps({"ready": columns, "file": __import__("dlo_ros").__file__}), flush=True)
    for line in sys.stdin:
        column, first, count = json.loads(line)
        solver = solvers[column]
        loops = (solver.functions.newton_native, solver.functions.newton_active)
        for loop in loops:  # the inertia's switch (this tree's code only)
            if loop is not None and hasattr(loop, "lapack"):
                loop.lapack.inertia = int(column != "after, eigenvalue")
        times, newton = [], 0
        for target in targets[first : first + count]:
            t0 = time.perf_counter()
            result = solver.solve({"right": (target, rot)})
            times.append((time.perf_counter() - t0) * 1e3)
            assert result.ok, result.message
            newton += result.ipopt_status == "Newton"
        print(json.dumps({"times": times, "newton": newton}), flush=True)
    if "after, inertia" in solvers:  # the verdict's LAPACK work alone, at the last state
        print(json.dumps(lapack_alone(solvers["after, inertia"])), flush=True)


def lapack_alone(solver, repeat: int = 2000) -> dict:
    """Median [µs] of the interpreted verdicts' LAPACK calls on the committed state's matrices."""
    from dlo_ros.solver.results.inertia import inertia, kkt_matrix
    from dlo_ros.solver.results.stability import held_derivatives, reduced_eigenpair

    state = solver.snapshot()
    h, held = held_derivatives(solver.nlp, solver.functions, state)
    k = kkt_matrix(h, held)

    def timed(call) -> float:
        out = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            call()
            out.append(time.perf_counter() - t0)
        return float(np.median(out)) * 1e6

    return {
        "n": int(h.shape[0]),
        "m": int(held.shape[0]),
        "inertia_us": timed(lambda: inertia(k)),
        "eigen_us": timed(lambda: reduced_eigenpair(h, held)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=400)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--before", default="", help="git revision (default: merge-base main HEAD)")
    ap.add_argument("--out", default="bench/results/inertia_verdict.md")
    ap.add_argument("--worker", nargs="+")
    args = ap.parse_args()
    if args.worker:
        worker(args.worker)
        return
    sys.path.insert(0, str(ROOT))
    from bench.before_after import ask, extract, revision, start
    from bench.common import machine, write_report

    info = machine()
    args.before, before_rev = revision(args.before)
    with tempfile.TemporaryDirectory() as tmp:
        extract(args.before, tmp)
        before = start(__file__, tmp, ["before"])
        after = start(__file__, str(ROOT), ["after, eigenvalue", "after, inertia"])
        procs = {"before": before, "after, eigenvalue": after, "after, inertia": after}
        times: dict[str, list[float]] = {c: [] for c in procs}
        newton = dict.fromkeys(procs, 0)
        piece = args.updates // args.rounds
        for r in range(args.rounds):
            order = list(procs) if r % 2 == 0 else list(procs)[::-1]
            for column in order:
                got = ask(procs[column], [column, r * piece, piece])
                times[column] += got["times"]
                newton[column] += got["newton"]
        for proc in (before, after):
            assert proc.stdin is not None and proc.stdout is not None
            proc.stdin.close()
        alone = json.loads(after.stdout.readline()) if after.stdout else {}
        for proc in (before, after):
            proc.wait()
    count = piece * args.rounds
    stats = {c: (float(np.median(t)), float(np.percentile(t, 99))) for c, t in times.items()}
    base = stats["before"]
    lines = [
        "# Stability verdict from the inertia (#38) against the eigenvalue: warm updates",
        "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other work), "
        f"Python {info.get('python')}, load average {info['load_average'][0]:.2f} at the start; "
        f"git {info.get('git', '?')} (after) against {before_rev} (before).",
        "",
        f"`default_cable`, model 'full' (3D, compiled), {count} warm updates of the right grip by "
        f"1 % of L, in {args.rounds} interleaved rounds; wall time of each `solve` [ms].",
        "",
        "| column | Newton updates | median | p99 | median / before | p99 / before |",
        "|---|---|---|---|---|---|",
    ]
    for column, (med, p99) in stats.items():
        lines.append(
            f"| {column} | {newton[column]}/{count} | {med:.3f} | {p99:.3f} | "
            f"{med / base[0]:.3f} | {p99 / base[1]:.3f} |"
        )
    lines += [
        "",
        f"The verdict's LAPACK work alone at the last state (n = {alone.get('n')} unknowns, "
        f"m = {alone.get('m')} held rows), SciPy's wrappers (Python overhead included), median of "
        f"2000 calls: inertia (dsytrf of the (n + m)² KKT matrix, pivot counting) "
        f"{alone.get('inertia_us', float('nan')):.1f} µs; eigenvalue (geqp3, orgqr, Nᵀ H N, syevr "
        f"for one pair) {alone.get('eigen_us', float('nan')):.1f} µs.  In C the difference per "
        "update is the 'after, eigenvalue' − 'after, inertia' medians above.",
        "",
        f"p99 is among the {max(1, count // 100)} slowest of {count} updates: with the "
        "updates IPOPT answers (see the Newton column) and the shared machine's outliers it is "
        "about the same in all three columns; the verdict shows in the median.  'after, "
        "eigenvalue' against 'before' checks that nothing else changed.",
    ]
    argv = [f"--updates {args.updates}", f"--rounds {args.rounds}", f"--before {before_rev}"]
    write_report(lines, args.out, "bench/perf/inertia_verdict.py", [*argv, f"--out {args.out}"])


if __name__ == "__main__":
    main()
