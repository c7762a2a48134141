"""What rerun recording costs the solver's caller: warm-update time with recording on vs off (same run).

Scene default_cable, ShapeSolver(compile="cached"), the right grip moving 1 % of L per update along a
circle in the x–z plane, --updates warm updates per run.  The timed span is what a solver thread pays per
update: ``log_targets`` + ``solve`` + ``log_result`` (recording off: a disabled Recorder, whose calls return
at once; on: ``Recorder(rrd=...)`` writing an .rrd in a temporary directory).

Two ways of pairing on and off, because this 2-core machine is shared and its load moves on a scale of
seconds (single runs scatter by ±30 %):

* interleaved (the headline): within every run, blocks of --block updates alternate off / on (the
  recorder exists for the whole run and records the "on" blocks); the first --settle updates of each
  block are not counted (the recorder process works up to 20 ms behind, so its work on an "on" block
  spills into the next block).  On and off then see the same load.
* run-level: whole runs alternate off / on (a fresh recording per run).

Ratios are of the medians of the pooled samples; requirement: interleaved ratio <= 1.10.

    bash scripts/dlo-env run python bench/perf/recording_overhead.py [--updates 200] [--repeats 30] \
        [--out bench/results/recording_overhead.md]
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from dlo_ros.recording import Recorder
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver

OFF = Recorder()  # disabled


def path_targets(scene, updates: int) -> list[np.ndarray]:
    """Right-grip positions: steps of 1 % of L around a circle of radius 0.08 L in the x–z plane."""
    L = scene.problem.string.length
    start = scene.problem.grip("right").pose.position
    radius = 0.08 * L
    dtheta = 0.01 * L / radius
    return [start + np.array([radius * (np.cos(i * dtheta) - 1), 0.0, radius * np.sin(i * dtheta)])
            for i in range(1, updates + 1)]


def run(solver: ShapeSolver, scene, recorder: Recorder, targets: list[np.ndarray],
        choose=lambda k: (True, True)) -> dict:
    """One run: cold solve, then the warm updates; ``choose(k)`` = (update k is recorded, it is counted).
    Returns per-update samples keyed by mode ('on' / 'off')."""
    solver.reset()
    poses = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}
    q = scene.problem.grip("right").pose.orientation
    recorder.log_scene(scene, solver=solver)
    cold = solver.solve(poses, warm=False)
    assert cold.ok, cold.message
    recorder.log_result(cold, update=0, targets=poses, warm=False)
    out = {m: {"spans": [], "cpus": [], "solves": [], "log_us": [], "k": []} for m in ("on", "off")}
    for k, target in enumerate(targets, start=1):
        mode, counted = choose(k)
        rec = recorder if mode else OFF
        c0, t0 = time.thread_time(), time.perf_counter()
        poses = {**poses, "right": (target, q)}
        rec.log_targets({"right": poses["right"]}, update=k)
        r = solver.solve({"right": poses["right"]})
        t1 = time.perf_counter()
        rec.log_result(r, update=k, targets=poses, warm=True)
        t2, c2 = time.perf_counter(), time.thread_time()
        assert r.ok, r.message
        if not counted:
            continue
        bucket = out["on" if mode else "off"]
        bucket["spans"].append((t2 - t0) * 1e3)
        bucket["cpus"].append((c2 - c0) * 1e3)
        bucket["solves"].append(r.solve_time_ms)
        bucket["log_us"].append((t2 - t1) * 1e6)
        bucket["k"].append(k)
    t0 = time.perf_counter()
    recorder.close()
    out["drain_s"] = time.perf_counter() - t0
    out["dropped"], out["errors"] = recorder.dropped, recorder.errors
    return out


def summary(runs: list[dict], mode: str) -> dict:
    def pooled(key: str) -> list[float]:
        return [x for r in runs for x in r[mode][key]]

    spans = pooled("spans")
    return {"n": len(spans), "median": statistics.median(spans), "p90": float(np.percentile(spans, 90)),
            "mean": statistics.fmean(spans), "cpu": statistics.median(pooled("cpus")),
            "solve": statistics.median(pooled("solves")), "log_us": statistics.median(pooled("log_us"))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="default_cable")
    ap.add_argument("--updates", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--block", type=int, default=20)
    ap.add_argument("--settle", type=int, default=5)
    ap.add_argument("--out", default="bench/results/recording_overhead.md")
    args = ap.parse_args()
    scene = load_scene(args.scene)
    solver = ShapeSolver(scene.problem, scene.options, compile="cached")
    targets = path_targets(scene, args.updates)

    def interleaved(k: int):
        j = (k - 1) % (2 * args.block)
        return j >= args.block, j % args.block >= args.settle  # off block then on block; settling not counted

    load_before = os.getloadavg()
    inter, run_off, run_on, sizes = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        run(solver, scene, Recorder(rrd=Path(tmp) / "warmup.rrd"), targets[:20])  # imports, first calls
        for i in range(args.repeats):
            inter.append(run(solver, scene, Recorder(rrd=Path(tmp) / f"inter{i}.rrd"), targets, interleaved))
            run_off.append(run(solver, scene, OFF, targets, lambda k: (False, True)))
            path = Path(tmp) / f"on{i}.rrd"
            run_on.append(run(solver, scene, Recorder(rrd=path), targets, lambda k: (True, True)))
            sizes.append(path.stat().st_size)
    load_after = os.getloadavg()

    rows = [("interleaved", "off", summary(inter, "off")), ("interleaved", "on", summary(inter, "on")),
            ("run-level", "off", summary(run_off, "off")), ("run-level", "on", summary(run_on, "on"))]
    ratio = rows[1][2]["median"] / rows[0][2]["median"]
    # paired blocks: each off block and the on block right after it, ratio of their medians
    pairs = []
    for r in inter:
        for start in range(1, args.updates + 1, 2 * args.block):
            off = [x for x, k in zip(r["off"]["spans"], r["off"]["k"]) if start <= k < start + args.block]
            on = [x for x, k in zip(r["on"]["spans"], r["on"]["k"]) if start + args.block <= k < start + 2 * args.block]
            if off and on:
                pairs.append(statistics.median(on) / statistics.median(off))
    pair_median = statistics.median(pairs)
    groups = [inter[i:i + 10] for i in range(0, len(inter), 10)]
    group_ratios = [summary(g, "on")["median"] / summary(g, "off")["median"] for g in groups]
    q1, q3 = np.percentile(pairs, [25, 75])
    ratio_runs = rows[3][2]["median"] / rows[2][2]["median"]
    cpu_ratio = rows[1][2]["cpu"] / rows[0][2]["cpu"]
    lines = [
        f"# Recording overhead: `{args.scene}`", "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; derivatives "
        f"{'compiled (cached library)' if solver.kkt_compiled else 'interpreted (no cached library)'}; "
        f"{args.updates} warm updates of 1 % of L per run, {args.repeats} runs per pairing; recording = "
        f"`Recorder(rrd=...)` (rerun calls in the recorder process, the default backend; "
        f"{statistics.fmean(sizes) / 1e6:.2f} MB per fully recorded run). "
        f"Load average (1 min) before/after: {load_before[0]:.2f} / {load_after[0]:.2f} (other sessions were "
        "running: compare rows of this table, not tables of different runs).", "",
        "Timed per update: `log_targets` + `solve` + `log_result`, what the solver thread pays. Interleaved: "
        f"blocks of {args.block} updates alternate off/on inside each run, the first {args.settle} of each block "
        "not counted. Run-level: whole runs alternate.", "",
        "| pairing | recording | samples | update median ms | p90 ms | mean ms | solver-thread CPU median ms "
        "| solve_time_ms median | log_result µs median |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for pairing, mode, r in rows:
        lines.append(f"| {pairing} | {mode} | {r['n']} | {r['median']:.3f} | {r['p90']:.3f} | {r['mean']:.3f} "
                     f"| {r['cpu']:.3f} | {r['solve']:.3f} | {r['log_us']:.1f} |")
    all_on = inter + run_on
    lines += [
        "",
        f"**Ratio on/off of the median update time, interleaved: {ratio:.3f}** (requirement ≤ 1.10); "
        f"median of the {len(pairs)} paired-block ratios (an off block and the on block after it) "
        f"{pair_median:.3f} (quartiles {q1:.3f}–{q3:.3f}); solver-thread CPU ratio {cpu_ratio:.3f}; "
        f"run-level ratio {ratio_runs:.3f}. Interleaved ratio of each group of 10 runs (how much one such "
        "measurement scatters here): " + ", ".join(f"{x:.3f}" for x in group_ratios) + ".",
        f"Recorder: dropped {sum(r['dropped'] for r in all_on)}, errors {sum(r['errors'] for r in all_on)}; "
        f"close() (drain + flush) at most {max(r['drain_s'] for r in all_on):.2f} s.",
        "",
        "Command: `bash scripts/dlo-env run python bench/perf/recording_overhead.py`",
        "",
    ]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
