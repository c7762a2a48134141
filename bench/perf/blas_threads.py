"""A planner's own process streaming the main job's manoeuvre: OpenBLAS at two threads against one.

A program that calls ``make_solver`` itself has loaded numpy (and with it OpenBLAS) before dlo_ros,
so the ``OPENBLAS_NUM_THREADS`` the executables set comes too late for it; importing
``dlo_ros.solver`` now sets the loaded OpenBLAS libraries to one thread unless the user set the
variable (``dlo_ros/blas_threads.py``).  Each round runs two fresh processes, alternating:

* ``two threads``: OPENBLAS_NUM_THREADS=2 set by the user (kept), i.e. what such a program ran
  with before the change on this 2-core machine;
* ``one thread``: the variable not set, the library's default now.

Each imports numpy and SciPy first, builds ``make_solver`` (defaults: auto, background checks,
compile off, as the main job's node) for the default cable and the post, and solves the main job's
manoeuvre (``dlo_ros.node.demo``), one update per 20 ms period as the node gets them.  Reported:
per-update wall time p50 / p99 / max, updates over 20 ms (#37), and the same over the last 50
updates (the cable held on the post while auto's checks run on the worker).  The shapes are the
same in both (background checks switch at fixed updates): the bench asserts the last centrelines
agree to 1e-9 m.

    bash scripts/dlo-env run python bench/perf/blas_threads.py [--rounds 2]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

PERIOD = 0.02  # s: the demo driver's 50 Hz
SLOW_MS = 20.0
HOLD = 50  # the last updates: the cable on the post, checks running beside them


def worker() -> None:
    """One stream in this process; print its times and last centreline as JSON."""
    import numpy as np
    import scipy.linalg  # noqa: F401  (loaded first, as in a planner's program)

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from dlo_ros.blas_threads import loaded_blas
    from dlo_ros.model.problem import GripPose
    from dlo_ros.node import demo
    from dlo_ros.scene import load_scene, scene_from_dict, scene_to_dict
    from dlo_ros.solver import make_solver

    d = scene_to_dict(load_scene("default_cable"))
    d["obstacles"] = list(d.get("obstacles", [])) + [dict(demo.POST)]
    scene = scene_from_dict(d)
    solver = make_solver(scene.problem, scene.options, compile="off")
    first = solver.solve()
    assert first.ok, first.message
    times, statuses = [], []
    for i in range(1, int(demo.duration() / PERIOD) + 1):
        (pl, ql), (pr, qr) = demo.targets_at(i * PERIOD)
        t0 = time.perf_counter()
        r = solver.solve({"left": GripPose(pl, ql), "right": GripPose(pr, qr)})
        dt = time.perf_counter() - t0
        times.append(dt * 1e3)
        statuses.append(r.status)
        time.sleep(max(0.0, PERIOD - dt))
    print(
        json.dumps(
            {
                "times": times,
                "statuses": statuses,
                "points": np.asarray(r.points).tolist(),
                "threads": [b.threads for b in loaded_blas()],
            }
        )
    )


def run(mode: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if mode == "two threads":
        env["OPENBLAS_NUM_THREADS"] = "2"
    out = subprocess.run(
        [sys.executable, __file__, "--worker"], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker()
        return
    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from bench.common import RESULTS, machine

    modes = ("two threads", "one thread")
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    for _ in range(args.rounds):
        for m in modes:
            runs[m].append(run(m))
            print(m, "done", flush=True)
    ref = np.asarray(runs["one thread"][0]["points"])
    rows = []
    for m in modes:
        for k, r in enumerate(runs[m]):
            t, hold = np.asarray(r["times"]), np.asarray(r["times"][-HOLD:])
            gap = float(np.abs(np.asarray(r["points"]) - ref).max())
            assert gap < 1e-9, f"{m} round {k}: last centreline {gap:.2e} m from the other runs"
            rows.append(
                f"| {m} | {k + 1} | {r['threads']} | {np.median(t):.1f} | "
                f"{np.percentile(t, 99):.1f} | "
                f"{t.max():.0f} | {int((t > SLOW_MS).sum())} | {np.median(hold):.1f} | "
                f"{hold.max():.0f} | {int((hold > SLOW_MS).sum())} | "
                f"{sum(s != 'ok' for s in r['statuses'])} |"
            )
    info = machine()
    text = "\n".join(
        [
            "# OpenBLAS threads in a planner's own process: the main job's manoeuvre in-process",
            "",
            f"Machine: {info.get('cpu')}, {info.get('cpus')} cores, load average "
            f"{info.get('load_average')}; Python {info.get('python')}; git {info.get('git')}; "
            f"written {time.strftime('%Y-%m-%d %H:%M')}.",
            "",
            "`make_solver` defaults (auto, background checks, compile off), 50 Hz, "
            f"{len(runs['one thread'][0]['times'])} updates; rounds alternate.  Times in ms; "
            f"'hold': the last {HOLD} updates (on the post, auto's checks running).  The last "
            "centreline agrees to 1e-9 m in every run.",
            "",
            "| OpenBLAS | round | threads (numpy, SciPy) | p50 | p99 | max | > 20 ms | "
            "hold p50 | hold max | hold > 20 ms | not ok |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
            *rows,
            "",
            "Command: `bash scripts/dlo-env run python bench/perf/blas_threads.py`",
            "",
        ]
    )
    (RESULTS / "blas_threads.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
