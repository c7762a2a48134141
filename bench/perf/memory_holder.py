"""What the node's solver holder keeps, over time, without ROS: RSS and live solver objects.

    bash scripts/dlo-env run python bench/perf/memory_holder.py [--seconds 150] [--param-every 10]
        [--rate 100] [--compile background] [--every 10] [--query-rate 0]

Runs the node's ShapeEngine with its solver (``build_solver``: ``solver.model: auto`` of the
default scene, background checks) in this process, streams the soak's target path
(bench/perf/soak.py) at ``--rate`` Hz and changes ``string.bend_stiffness`` (0.025 ↔ 0.02 N·m², the
node's own edit) every ``--param-every`` s; with ``--query-rate`` the engine also answers queries
(the node's ``query_workers: 0``) 2-4 cm from the target.  Every ``--every`` s, after a full
garbage collection, it prints RSS, auto's pooled models and the live ShapeSolver / casadi.Function
objects (``gc.get_objects`` by type: CasADi and IPOPT memory is invisible to tracemalloc, so growth
there shows as RSS and these counts), and which object types changed in number.  A flat run rules
the solver holder out as the cause of node growth; bench/perf/soak.py measures the whole node over
DDS.  (Not inside a running rclpy node: a ``gc.get_objects`` from another thread can catch a tuple
rclpy is still filling, and its service take then fails with "SystemError: bad argument to internal
function".)
"""
from __future__ import annotations

import argparse
import collections
import gc
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench.perf.soak import target  # noqa: E402

from dlo_ros.model.problem import GripPose  # noqa: E402
from dlo_ros.node import params as P  # noqa: E402
from dlo_ros.node.engine import ShapeEngine, build_solver  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024


def live_counts() -> collections.Counter:
    """Live objects of dlo_ros and casadi types by qualified type name, after a full collection."""
    gc.collect()
    counts: collections.Counter = collections.Counter()
    for obj in gc.get_objects():
        kind = type(obj)
        module = getattr(kind, "__module__", "")
        if isinstance(module, str) and module.startswith(("casadi", "dlo_ros")):
            counts[f"{module}.{kind.__qualname__}"] += 1
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=150.0)
    ap.add_argument("--param-every", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--every", type=float, default=10.0)
    ap.add_argument("--query-rate", type=float, default=0.0,
                    help="queries per second answered by the engine (the node's query_workers: 0)")
    ap.add_argument("--compile", default="background",
                    choices=("background", "blocking", "off"))
    args = ap.parse_args()
    scene = load_scene("default_cable")
    failures: list[str] = []
    engine = ShapeEngine(scene.problem, scene.options,
                         make_solver=lambda p, o: build_solver(p, o, args.compile),
                         on_update=lambda u: None,
                         on_failure=lambda kind, msg, u: failures.append(f"{kind}: {msg[:200]}"))
    engine.start()
    while not engine.ready:
        time.sleep(0.05)
    names = [g.name for g in scene.problem.grips]
    before = live_counts()
    start, k, changes, queries, n_queries = time.monotonic(), 0, 0, [], 0
    rng = np.random.default_rng(0)
    next_query = 0.0 if args.query_rate > 0 else float("inf")
    next_change, next_sample = args.param_every, 0.0
    print("| t s | RSS MB | pooled models | ShapeSolver | casadi.Function | changes "
          "| types changed |")
    print("|---|---|---|---|---|---|---|")
    while (now := time.monotonic() - start) < args.seconds:
        poses = {n: GripPose(np.array(p), np.array(q))
                 for n, (p, q) in zip(names, target(now))}
        engine.submit_targets(poses)
        k += 1
        if now >= next_query:  # the right grip 2-4 cm from its target, as soak.py's clients
            offset = rng.normal(size=3)
            step = 0.02 * (1 + rng.random()) * offset / np.linalg.norm(offset)
            goal = poses[names[1]].position + step
            n_queries += 1
            queries.append(engine.query({names[1]: GripPose(goal, poses[names[1]].orientation)}))
            queries = [q for q in queries if not q.done()]
            next_query += 1.0 / args.query_rate
        if args.param_every > 0 and now >= next_change:
            values = {"string.bend_stiffness": 0.025 if changes % 2 == 0 else 0.02}
            engine.change_problem(lambda pr, v=values: replace(
                pr, string=P.apply_string(pr.string, v))).result(120.0)
            changes += 1
            next_change += args.param_every
        if now >= next_sample:
            counts = live_counts()
            delta = {t: counts[t] - before[t] for t in counts.keys() | before.keys()
                     if counts[t] != before[t]}
            text = ", ".join(f"{t.rsplit('.', 1)[-1]} {d:+d}"
                             for t, d in sorted(delta.items(), key=lambda i: -abs(i[1]))[:6])
            pool = len(getattr(engine._solver, "_pool", ()))
            print(f"| {now:.0f} | {rss_mb():.0f} | {pool} | "
                  f"{counts['dlo_ros.solver.shape_solver.ShapeSolver']} | "
                  f"{counts['casadi.casadi.Function']} | {changes} | {text or '-'} |", flush=True)
            before, next_sample = counts, next_sample + args.every
        time.sleep(max(0.0, start + k / args.rate - time.monotonic()))
    engine.stop()
    print(f"{k} targets, {changes} parameter changes, {n_queries} queries, "
          f"{len(failures)} failures" + (f": {failures[:3]}" if failures else ""))


if __name__ == "__main__":
    main()
