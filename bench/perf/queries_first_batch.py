"""Shape queries on an empty compiled-code cache: workers that compile what they lack ('on_query', the
default of ``query_many``) against workers that never compile ('cached'), same run (#38).

    bash scripts/dlo-env run python bench/perf/queries_first_batch.py [--queries 4000] [--batches 3]
        [--out bench/results/queries_first_batch.md]

``default_cable`` (``solver.model: auto``), random right-grip targets within 15 cm of the held pose
(``test/random_scenes.targets_near``), answered by ``query_many`` on a fresh pool of two
worker processes with a fresh empty cache (``DLO_CACHE_DIR``) per mode; the same batch is sent
``--batches`` times.  Per batch: wall time, queries per second, how many answers ran compiled, and
where the workers' time went: the answers of the streaming model's mesh against those refined on
other meshes (a query touching an obstacle whose rows sit on the nodes is refined as a cold solve
is: ``solver/auto/query_refine.py``), as the sum of their ``solve_time_ms``.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # as a script: `bench` importable
sys.path.insert(0, str(ROOT / "test"))  # the targets

from bench.common import machine  # noqa: E402
from random_scenes import targets_near  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import make_solver  # noqa: E402
from dlo_ros.solver.parallel.batch import process_pool, query_many, stop_pool  # noqa: E402


def run_mode(mode: str, queries: int, batches: int) -> list[dict]:
    """The batches of one compile mode, on a fresh empty cache and a fresh pool of two workers."""
    scene = load_scene("default_cable")
    targets = targets_near(scene.problem, queries)
    rows = []
    with tempfile.TemporaryDirectory(prefix="dlo-cache-") as cache:
        os.environ["DLO_CACHE_DIR"] = cache  # the spawned workers inherit it
        pool = process_pool(2)
        try:
            for k in range(batches):
                t0 = time.perf_counter()
                answers = query_many(make_solver, scene.problem, scene.options, targets, pool,
                                     compile=mode)
                seconds = time.perf_counter() - t0
                spent: dict[str, float] = defaultdict(float)
                count: dict[str, int] = defaultdict(int)
                base = min(r.model.variables for r in answers if r.model is not None)
                for r in answers:
                    kind = "held mesh" if r.model is not None and r.model.variables == base else "refined"
                    spent[kind] += r.solve_time_ms / 1e3
                    count[kind] += 1
                rows.append(dict(mode=mode, batch=k + 1, seconds=seconds, rate=queries / seconds,
                                 compiled=sum(r.derivatives == "compiled" for r in answers),
                                 ok=sum(r.ok for r in answers), spent=dict(spent), count=dict(count)))
                print(rows[-1], flush=True)
        finally:
            stop_pool(pool)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--queries", type=int, default=4000)
    ap.add_argument("--batches", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "queries_first_batch.md"))
    args = ap.parse_args()
    os.environ.pop("DLO_NO_COMPILE", None)
    rows = run_mode("cached", args.queries, args.batches) + run_mode("on_query", args.queries, args.batches)
    info = machine()
    lines = [
        "# Shape queries on an empty compiled-code cache (#38)", "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; "
        f"git {info.get('git', '?')}; {time.strftime('%Y-%m-%d %H:%M')}.",
        f"Command: `bash scripts/dlo-env run python bench/perf/queries_first_batch.py --queries {args.queries} "
        f"--batches {args.batches}`", "",
        f"`default_cable`, solver.model auto, {args.queries} random right-grip targets within 15 cm, "
        "`query_many` on two worker processes, each mode on its own empty cache and pool; the same batch "
        "sent again. *compiled*: answers computed with compiled derivatives. *Worker seconds*: the sum of "
        "the answers' solve times, on the held stream's mesh and on refined meshes (queries touching the "
        "table, refined as cold solves are, each on meshes built for it).", "",
        "| workers compile | batch | wall [s] | queries/s | compiled | ok | answers held mesh / refined | "
        "worker seconds held mesh / refined |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        c, s = r["count"], r["spent"]
        lines.append(
            f"| {r['mode']} | {r['batch']} | {r['seconds']:.1f} | {r['rate']:.0f} | {r['compiled']} | {r['ok']} | "
            f"{c.get('held mesh', 0)} / {c.get('refined', 0)} | "
            f"{s.get('held mesh', 0.0):.1f} / {s.get('refined', 0.0):.1f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
