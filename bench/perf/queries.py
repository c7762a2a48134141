"""Shape-query throughput in-process: one solver answering ``solve(poses, commit=False)`` one after the
other, against ``query_many`` on a process pool of 1 and 2 workers, on the same random targets.

    bash scripts/dlo-env run python bench/perf/queries.py [--queries 400] [--compile off|cached]
        [--out bench/results/queries.md]

``default_cable`` (``solver.model: auto``), random right-grip targets within 15 cm of the held pose.
Each pool is started and warmed (its workers build their solvers) before it is timed; the warm-up time
is reported apart.  Reported: queries per second for each way, the ratios to the single solver, and
whether every batch answer equals the single one (points within 1e-9 m).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "test" / "unit"))  # test modules the bench reuses (references, set-ups)

from bench.common import machine  # noqa: E402
from random_scenes import targets_near  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import make_solver  # noqa: E402
from dlo_ros.solver.parallel.batch import process_pool, query_many  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--queries", type=int, default=400)
    ap.add_argument("--compile", default="off", choices=["off", "cached"])
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "queries.md"))
    args = ap.parse_args()
    if args.compile == "off":
        os.environ["DLO_NO_COMPILE"] = "1"  # inherited by the workers
    scene = load_scene("default_cable")
    # 'cached': the libraries of every model the queries use are built first (the stream's now, the query
    # model's in auto's compile-ahead), so that this measures queries at full speed, not a cache that a
    # new version of the code has not filled yet (compile_cost.py measures the first start)
    solver = make_solver(scene.problem, scene.options, compile="blocking" if args.compile == "cached" else "off",
                         checks="sync")
    solver.solve()
    qs = targets_near(scene.problem, args.queries)
    if args.compile == "cached":
        solver.solve(qs[0], commit=False)  # starts the query model's compile
        deadline = time.monotonic() + 600
        def building() -> bool:
            pool = solver.pool.solvers()
            return any(s.compile_pending or (s.compile_mode != "cached" and not s.all_compiled) for s in pool)

        while building() and time.monotonic() < deadline:
            time.sleep(0.5)
    t0 = time.perf_counter()
    single = [solver.solve(q, commit=False) for q in qs]
    t_single = time.perf_counter() - t0
    rows = [("one solver, in the caller's thread", 1, t_single, None, True)]
    for workers in (1, 2):
        with process_pool(workers) as pool:
            t0 = time.perf_counter()
            query_many(make_solver, solver.problem, solver.options, qs[:workers], pool, chunks=workers)  # warm-up: builds
            warm_up = time.perf_counter() - t0
            t0 = time.perf_counter()
            batch = query_many(make_solver, solver.problem, solver.options, qs, pool, chunks=4 * workers)
            elapsed = time.perf_counter() - t0
        same = all(a.status == b.status and (not a.ok or np.allclose(a.points, b.points, atol=1e-9))
                   for a, b in zip(batch, single))
        rows.append((f"query_many, {workers} worker process{'es' if workers > 1 else ''}", workers, elapsed,
                     warm_up, same))
    info = machine()
    ok = sum(r.ok for r in single)
    lines = ["# Shape queries in-process", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; git {info.get('git', '?')}.",
             f"Command: `bash scripts/dlo-env run python bench/perf/queries.py --queries {args.queries} --compile {args.compile}`",
             "", f"`default_cable`, solver.model auto, {args.queries} random right-grip targets within 15 cm "
             f"({ok} answered ok); derivatives {'interpreted' if args.compile == 'off' else 'compiled when cached'}.", "",
             "| way | cores used | queries/s | vs one solver | warm-up s | answers equal the single ones |",
             "|---|---|---|---|---|---|"]
    for name, cores, elapsed, warm_up, same in rows:
        lines.append(f"| {name} | {cores} | {args.queries / elapsed:.0f} | {t_single / elapsed:.2f}× | "
                     f"{'' if warm_up is None else f'{warm_up:.1f}'} | {'yes' if same else 'NO'} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
