"""`dlo dataset` throughput (#39): samples per second on two local workers and on a local Dask cluster,
an empty compiled-code cache against a filled one, same plan, same run.

    bash scripts/dlo-env run python bench/perf/dataset_rate.py [--samples 400] [--out bench/results/dataset_rate.md]

``default_cable`` with ``config/plans/default_cable_right_grip.yaml``'s box (the right grip anywhere in
20 x 20 x 25 cm around its pose; the lowest samples press the cable onto the table), ``--samples`` samples in
chunks of 25.  Rows: (1) local pool, empty cache (the workers compile what their samples use,
``compile='on_query'``); (2) local pool again on the cache (1) filled; (3) a Dask ``LocalCluster`` of two
worker processes on that cache.  Each row: wall time of ``build_dataset`` (worker start-up included),
samples per second, counts per status, how many answers ran compiled, and the workers' solve seconds
split into the samples answered on the held mesh and those refined on meshes built for them.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # as a script: `bench` importable

from bench.common import machine  # noqa: E402

from dlo_ros.dataset import build_dataset, load_arrays, plan_from_dict, read_plan  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402


def row(label: str, out: Path, seconds: float) -> dict:
    a = load_arrays(out)
    counts: dict[str, int] = {}
    for s in a["status"]:
        counts[s] = counts.get(s, 0) + 1
    variables = [json.loads(m).get("variables") for m in a["model"]]
    base = min(v for v in variables if v is not None)
    held = sum(t for t, v in zip(a["solve_time_ms"], variables) if v == base) / 1e3
    refined = sum(t for t, v in zip(a["solve_time_ms"], variables) if v != base) / 1e3
    return dict(label=label, seconds=seconds, n=len(a["sample"]), counts=counts,
                compiled=int(sum(d == "compiled" for d in a["derivatives"])),
                refined_n=sum(v != base for v in variables), held_s=held, refined_s=refined)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=400)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "dataset_rate.md"))
    args = ap.parse_args()
    os.environ.pop("DLO_NO_COMPILE", None)
    base = read_plan(ROOT / "config" / "plans" / "default_cable_right_grip.yaml").as_dict()
    plan = plan_from_dict({**base, "samples": args.samples, "chunk": 25})
    scene = load_scene("default_cable")
    rows = []
    with tempfile.TemporaryDirectory(prefix="dlo-bench-") as tmp:
        os.environ["DLO_CACHE_DIR"] = str(Path(tmp, "cache"))  # the workers inherit it
        for label, dask in (("local, 2 workers, empty cache", False), ("local, 2 workers, cache filled", False),
                            ("Dask LocalCluster, 2 worker processes, cache filled", True)):
            out = Path(tmp, "out")
            shutil.rmtree(out, ignore_errors=True)
            t0 = time.perf_counter()
            if dask:
                from distributed import Client, LocalCluster

                with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, Client(cluster) as client:
                    build_dataset(scene, plan, out, executor=client.get_executor(), executor_name="dask",
                                  progress=False)
            else:
                build_dataset(scene, plan, out, workers=2, progress=False)
            rows.append(row(label, out, time.perf_counter() - t0))
            print(rows[-1], flush=True)
    info = machine()
    lines = [
        "# `dlo dataset` throughput (#39)", "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; "
        f"git {info.get('git', '?')}; {time.strftime('%Y-%m-%d %H:%M')}.",
        f"Command: `bash scripts/dlo-env run python bench/perf/dataset_rate.py --samples {args.samples}`", "",
        f"`default_cable`, the box of `config/plans/default_cable_right_grip.yaml`, {args.samples} samples in "
        "chunks of 25, `start: held`. Wall time includes starting the workers (and, on an empty cache, "
        "their compiles). *Held / refined*: samples answered on the held mesh, and those refined on meshes "
        "built for them (a query touching the table), with the workers' solve seconds of each.", "",
        "| run | wall [s] | samples/s | statuses | compiled answers | held / refined samples | "
        "solve seconds held / refined |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        statuses = ", ".join(f"{n} {s}" for s, n in sorted(r["counts"].items()))
        lines.append(f"| {r['label']} | {r['seconds']:.1f} | {r['n'] / r['seconds']:.1f} | {statuses} | "
                     f"{r['compiled']} | {r['n'] - r['refined_n']} / {r['refined_n']} | "
                     f"{r['held_s']:.1f} / {r['refined_s']:.1f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
