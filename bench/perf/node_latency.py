"""End-to-end latency of the dlo node across processes: target publication -> centreline reception.

The node runs in a subprocess on the default scene (its own ROS_DOMAIN_ID, discovery on localhost);
this process publishes ~/grips/targets and receives ~/centerline over real DDS.  The centreline's header
stamp is the stamp of the newest target it answers, so latency = reception time - that stamp.

Three measurements:
  closed loop  publish a target, wait for its centreline, repeat: latency without queueing, and the
               sustained rate of a client that waits for every answer;
  open loop    publish at a fixed rate (default 100 Hz) whatever happens: latency of the answered
               targets (includes waiting for the solve in progress) and the centreline rate;
  flood        publish as fast as possible: the sustained centreline rate the node reaches.
For reference the same closed-loop target sequence is also solved in this process by a ShapeSolver,
which separates the solver's time from the node's overhead (DDS, messages, threads).

The floor: an echo process (bench/perf/echo_node.py, started and driven exactly like the node) answers
every target at once with a Path of the node's size and the target's stamp, without solving.  Its
closed-loop and open-loop latencies, with rclpy's SingleThreadedExecutor (the node's) and with
rclpy.experimental.EventsExecutor at both ends, are the DDS round trip and serialisation no node can go
below on this machine; in-process (no DDS) medians time building the Path bytes, the client's
deserialisation, the target's serialisation and deserialisation, and one LU of the node's Newton matrix.
Node overhead above the floor = closed-loop p50 - in-process solve p50 - echo closed-loop p50.

    scripts/dlo-env run python bench/perf/node_latency.py [--mode interpreted|native|both] [--model full|auto|...]
                                                     [--n 300] [--rate 100] [--seconds 5] [--path 3d|planar]
                                                     [--floor-only]
                                                     [--out FILE]

--floor-only measures just the floor (about half a minute) and prints it (written only with --out); the
default run measures it first, then the node.  Writes a Markdown report (default
bench/results/node_latency.md).
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

REPO = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(REPO))  # run as a script: make `bench` importable (the echo's module)
ECHO_MODULE = "bench.perf.echo_node"
FLOOR_EXECUTORS = ("single", "events")  # the echo's and the client's executor (the same at both ends)
OUTPUT_POINTS = 51  # the node's centreline on default_cable (its output_points)
REPEATS = 1000  # in-process timings: the median of this many
Q0 = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q0)


PATH = {"kind": "3d"}  # the motion of this run (--path: a key of MOTION)


def target(i: int, n: int):
    """A smooth dual-arm-like motion.  '3d': the right grip circles (radius 5 cm, height ±3 cm) and turns
    about the cable's axis by up to ±0.3 rad, so the shape leaves the plane; 'planar': it circles with
    radius 5 cm in the x–z plane that holds both grips, without turning, so the shape stays in that plane."""
    a = 2 * math.pi * i / n
    if PATH["kind"] == "planar":
        return [LEFT, ((0.55 + 0.05 * math.cos(a), 0.0, 0.42 + 0.05 * math.sin(a)), Q0)]
    pos = (0.55 + 0.05 * math.cos(a), 0.05 * math.sin(a), 0.42 + 0.03 * math.sin(2 * a))
    tw = 0.3 * math.sin(a)
    return [LEFT, (pos, (math.sin(tw / 2), 0.0, 0.0, math.cos(tw / 2)))]


MOTION = {
    "3d": "The right grip circles (radius 5 cm, height ±3 cm) and twists by up to ±0.3 rad",
    "planar": "The right grip circles (radius 5 cm) in the x–z plane of both grips without turning (the shape "
              "stays in that plane: `auto` streams its planar model)",
}


NOTE = (
    "One run on a shared 2-CPU VM: repeated runs differ by tens of percent with the other load, between "
    "the two modes as much as within one. Where the node's own time goes (probes in the node's target "
    "callback, its solver thread and its Path publish; `auto`, compiled, the 3D closed loop, 300 targets, "
    "2026-12-03, median): the executor's target callback (deserialise, check, hand over) 0.16 ms; from the "
    "callback to the solver thread starting the solve 0.43 ms (the callback, the executor's next wait-set "
    "rebuild, 0.16 ms idle, and the thread switch); the solve 1.9 ms; from the solve's end to the Path "
    "published 0.13 ms (its publish call 0.07 ms); the rest of the round trip is the DDS transport the echo "
    "measures (the node before #38: its target subscriptions now have their own small node and thread, "
    "bench/results/node_latency_hot.md). rclpy.experimental.EventsExecutor cannot run the main node (its "
    "coroutine services: ros2/rclpy#1473; its spin() livelocks on these wheels), but spins the small "
    "target node with spin_once. rclpy's MultiThreadedExecutor, tried first, added 3-8 ms per update and "
    "p99 outliers of several hundred ms (GIL contention with the solver thread)."
)


def pct(values):
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return float("nan"), float("nan"), float("nan")
    return float(np.percentile(a, 50)), float(np.percentile(a, 99)), float(a.max())


def closed_loop(cl, n: int):
    lat, t0 = [], time.monotonic()
    for i in range(n):
        stamp = cl.publish_targets(target(i, n))
        ev = cl.wait_for_path(10.0, where=lambda e, s=stamp: e.stamp_ns == s)
        if ev is None:
            raise RuntimeError(f"closed loop: no centreline for target {i}")
        lat.append((ev.received_ns - stamp) / 1e6)
    return lat, n / (time.monotonic() - t0)


def open_loop(cl, rate: float, seconds: float, n_cycle: int):
    stamps = set()
    period = 1.0 / rate
    c0 = cl.path_count
    start = time.monotonic()
    k = 0
    while time.monotonic() - start < seconds:
        stamps.add(cl.publish_targets(target(k, n_cycle)))
        k += 1
        time.sleep(max(0.0, start + k * period - time.monotonic()))
    last = cl.publish_targets(target(k, n_cycle))
    stamps.add(last)
    cl.wait_for_path(10.0, where=lambda e: e.stamp_ns == last)
    elapsed = time.monotonic() - start
    events = [e for e in list(cl.paths)[-(cl.path_count - c0):] if e.stamp_ns in stamps]
    lat = [(e.received_ns - e.stamp_ns) / 1e6 for e in events]
    return lat, len(events) / elapsed, k + 1


def flood(cl, seconds: float, n_cycle: int):
    c0 = cl.path_count
    start = time.monotonic()
    k = 0
    while time.monotonic() - start < seconds:
        cl.publish_targets(target(k, n_cycle))
        k += 1
        if k % 50 == 0:
            time.sleep(0.001)  # let the client's own thread breathe
    elapsed = time.monotonic() - start
    return (cl.path_count - c0) / elapsed, k / elapsed


def in_process_solve_times(n: int, native: bool, model: str):
    if native:
        os.environ.pop("DLO_NO_COMPILE", None)
    else:
        os.environ["DLO_NO_COMPILE"] = "1"
    mode = "blocking" if native else "off"
    from dlo_ros.scene import load_scene
    from dlo_ros.node.engine import build_solver as ShapeSolver  # the node's solver factory

    scene = load_scene("default_cable")
    options = scene.options if model == "scene" else replace(scene.options, model=model)
    solver = ShapeSolver(scene.problem, options, compile=mode)
    solver.solve()
    times, newton = [], 0
    for i in range(n):
        r = solver.solve({"left": target(i, n)[0], "right": target(i, n)[1]})
        times.append(r.solve_time_ms)
        newton += r.ipopt_status == "Newton"
    return times, newton


def measure(native: bool, args) -> tuple[list[str], float, float]:
    """Run the node in one mode; the Markdown section of its results, its closed-loop p50 and the in-process
    solve p50 [ms]."""
    from dlo_ros.node.client import running_node

    node_args = ["--ros-args", "-p", f"compile:={'blocking' if native else 'off'}",
                 *([] if args.model == "scene" else ["-p", f"solver.model:={args.model}"])]
    t0 = time.monotonic()
    with running_node(*node_args, startup_timeout=900.0, client_name="bench_client") as (proc, cl):
        startup = time.monotonic() - t0
        closed_loop(cl, 20)  # warm-up: DDS, allocator, first IPOPT calls
        cl_lat, cl_rate = closed_loop(cl, args.n)
        ol_lat, ol_rate, ol_sent = open_loop(cl, args.rate, args.seconds, args.n)
        fl_rate, fl_sent = flood(cl, args.seconds, args.n)
        time.sleep(0.5)
        rss = proc.rss_bytes() / 2**20
        diag = cl.diagnostic_values()
    solve_ms, newton = in_process_solve_times(args.n, native, args.model)
    c50, c99, cmax = pct(cl_lat)
    o50, o99, omax = pct(ol_lat)
    s50, s99, smax = pct(solve_ms)
    mode = ("`compile:=blocking` (compiled C derivatives from the first solve; start-up includes gcc when the "
            "cache is cold; the default `background` ends up here once gcc is done)"
            if native else "`compile:=off` (interpreted CasADi derivatives only)")
    return [
        f"## {mode}",
        "",
        f"Node start-up to first centreline: {startup:.1f} s.",
        "",
        "| measurement | p50 [ms] | p99 [ms] | max [ms] | rate |",
        "| --- | ---: | ---: | ---: | --- |",
        f"| closed loop ({args.n} targets, each waits for its centreline) | {c50:.1f} | {c99:.1f} | {cmax:.1f} | "
        f"{cl_rate:.1f} round trips/s |",
        f"| open loop at {args.rate:g} Hz ({ol_sent} targets in {args.seconds:g} s) | {o50:.1f} | {o99:.1f} | "
        f"{omax:.1f} | {ol_rate:.1f} centrelines/s |",
        f"| flood (as fast as possible: {fl_sent:.0f} targets/s) | | | | {fl_rate:.1f} centrelines/s sustained |",
        f"| in-process `ShapeSolver.solve`, same closed-loop sequence | {s50:.1f} | {s99:.1f} | {smax:.1f} | "
        f"Newton warm update taken {newton}/{args.n} |",
        "",
        f"Node overhead (closed-loop p50 minus in-process solve p50): {c50 - s50:.1f} ms. "
        f"Node RSS after the run: {rss:.0f} MiB; targets received {diag.get('targets received')}, "
        f"coalesced {diag.get('targets coalesced')}, failures {diag.get('failures')}, "
        f"stable {diag.get('stable updates')}/{diag.get('updates')}; the model at the end: "
        f"{'planar' if diag.get('model.planar') == 'true' else '3D'}, order {diag.get('model.order')}, "
        f"{diag.get('model.variables')} unknowns.",
        "",
    ], c50, s50


# ---- the floor: the same client and procedures against an echo that does not solve -----------------------


@dataclass
class EchoRun:
    """The echo's latencies [ms] with one executor at both ends."""

    executor: str
    closed: list[float]
    closed_rate: float  # round trips/s
    open: list[float]
    open_rate: float  # centrelines/s
    open_sent: int
    answered: str  # the echo's own count, from its output


def echo_env() -> dict:
    """This process's environment with the repository on PYTHONPATH, so ``python -m bench.perf.echo_node``
    imports from any working directory."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    return env


def measure_echo(executor: str, args) -> EchoRun:
    """The closed-loop and open-loop procedures of the node's measurement, against the echo process."""
    import tempfile

    from dlo_ros.node.client import running_node

    with tempfile.NamedTemporaryFile(prefix="echo_node_", suffix=".log") as log:
        with running_node("--executor", executor, "--points", str(OUTPUT_POINTS), module=ECHO_MODULE,
                          env=echo_env(), startup_timeout=60.0, log_path=log.name, client_name="bench_client",
                          executor=executor) as (proc, cl):
            closed_loop(cl, 20)  # warm-up, as for the node
            cl_lat, cl_rate = closed_loop(cl, args.n)
            ol_lat, ol_rate, ol_sent = open_loop(cl, args.rate, args.seconds, args.n)
        answered = next((line.split("answered", 1)[1].split()[0] for line in proc.output().splitlines()
                         if "answered" in line), "?")
    return EchoRun(executor, cl_lat, cl_rate, ol_lat, ol_rate, ol_sent, answered)


def median_ms(fn: Callable[[], object], repeats: int = REPEATS) -> float:
    """The median wall time of ``fn()`` [ms] over ``repeats`` calls (after one untimed call)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        times.append(time.perf_counter_ns() - t0)
    return float(np.median(times)) / 1e6


def message_costs() -> dict[str, float]:
    """In-process (no DDS) medians [ms] of the message work on the round trip, in its order."""
    from geometry_msgs.msg import PoseArray
    from nav_msgs.msg import Path as PathMsg
    from rclpy.serialization import deserialize_message, serialize_message

    from bench.perf.echo_node import straight_path
    from dlo_ros.node.conversions import arrays_to_pose, header, path_cdr, path_from_cdr, path_to_arrays

    stamp = time.time_ns()
    poses = target(1, 300)

    def target_msg():  # as DloClient.publish_targets builds it
        return PoseArray(header=header("world", stamp), poses=[arrays_to_pose(p, q) for p, q in poses])

    target_bytes = serialize_message(target_msg())
    points, orientations = straight_path(OUTPUT_POINTS)
    path_bytes = path_cdr(points, orientations, "world", stamp)
    path_msg = deserialize_message(path_bytes, PathMsg)
    return {
        "client: build the target PoseArray and serialise it (rclpy does in publish)":
            median_ms(lambda: serialize_message(target_msg())),
        "node: deserialise the target (raw subscription, `deserialize_message`)":
            median_ms(lambda: deserialize_message(target_bytes, PoseArray)),
        f"node: build the Path bytes (`conversions.path_cdr`, {OUTPUT_POINTS} poses, {len(path_bytes)} B)":
            median_ms(lambda: path_cdr(points, orientations, "world", stamp)),
        "client: read the Path's bytes into arrays (`conversions.path_from_cdr`, what `DloClient._on_path` does)":
            median_ms(lambda: path_from_cdr(path_bytes)),
        "a client that lets rclpy deserialise the Path instead (`deserialize_message`, as a non-raw subscription does)":
            median_ms(lambda: deserialize_message(path_bytes, PathMsg)),
        "that client, then `path_to_arrays` of the message": median_ms(lambda: path_to_arrays(path_msg)),
    }


def lu_cost(model: str) -> tuple[float, int]:
    """(median [ms] of one LAPACK LU solve (gesv) of the node's contact-free Newton matrix, its size) after a
    warm update on default_cable: what each Newton step of a warm update costs at least."""
    from scipy.linalg.lapack import dgesv

    from dlo_ros.node.engine import build_solver
    from dlo_ros.scene import load_scene
    from dlo_ros.solver.update.kkt import regularised

    scene = load_scene("default_cable")
    options = scene.options if model == "scene" else replace(scene.options, model=model)
    solver = build_solver(scene.problem, options, compile="off")
    try:
        solver.solve()
        solver.solve({"left": target(1, 300)[0], "right": target(1, 300)[1]})
        state = getattr(solver, "_state", None)  # the committed equilibrium keeps K (ShapeSolver only)
        if state is None or state.kkt is None:
            return float("nan"), 0
        kkt, rhs, n = state.kkt, state.residual, state.z.size
        return median_ms(lambda: dgesv(regularised(kkt, n), rhs)), kkt.shape[0]
    finally:
        close = getattr(solver, "close", None)
        if close is not None:
            close()


def floor_section(args, runs: list[EchoRun], costs: dict[str, float], lu: tuple[float, int],
                  overheads: list[tuple[str, float, float]], events_problem: str | None) -> list[str]:
    """The Markdown section of the floor; ``overheads``: (mode, closed-loop p50, in-process solve p50 [ms])
    of each node run, for the overhead above the floor."""
    names = {"single": "SingleThreadedExecutor (the node's)", "events": "rclpy.experimental.EventsExecutor"}
    lines = [
        "## The floor: DDS round trip without a solve",
        "",
        f"`bench/perf/echo_node.py` runs in a subprocess started like the node (own ROS_DOMAIN_ID, discovery on "
        f"localhost), named `dlo`, with the node's QoS: it subscribes the targets raw, deserialises each one and "
        f"publishes from the subscription callback a `nav_msgs/Path` of {OUTPUT_POINTS} poses with the target's "
        "stamp, built by the node's own CDR builder. No checks, no solve, no hand-off to a solver thread, no "
        "wrenches. The same client (`DloClient`) and the same closed-loop and open-loop procedures as above; "
        "the executor is the same at both ends.",
        "",
        "| echo (executor at both ends) | p50 [ms] | p99 [ms] | max [ms] | rate |",
        "| --- | ---: | ---: | ---: | --- |",
    ]
    for run in runs:
        c50, c99, cmax = pct(run.closed)
        o50, o99, omax = pct(run.open)
        lines += [
            f"| closed loop ({args.n} targets), {names[run.executor]} | {c50:.2f} | {c99:.2f} | {cmax:.2f} | "
            f"{run.closed_rate:.0f} round trips/s |",
            f"| open loop at {args.rate:g} Hz ({run.open_sent} targets), {names[run.executor]} | {o50:.2f} | "
            f"{o99:.2f} | {omax:.2f} | {run.open_rate:.1f} Paths/s (the echo answered {run.answered} targets in all) |",
        ]
    lines += ["", f"In this process, no DDS (median of {REPEATS}):", ""]
    lines += [f"- {what}: {ms * 1e3:.0f} µs" for what, ms in costs.items()]
    lu_ms, size = lu
    if size:
        lines.append(f"- one LU solve (LAPACK gesv) of the node's contact-free Newton matrix ({size}×{size}, "
                     f"`solver.model: {args.model}`): {lu_ms * 1e3:.0f} µs")
    lines.append("")
    if events_problem:
        lines += [events_problem, ""]
    if overheads:
        e50 = pct(runs[0].closed)[0]
        parts = [f"{mode}: {c50:.1f} − {s50:.1f} − {e50:.1f} = {c50 - s50 - e50:.1f} ms"
                 for mode, c50, s50 in overheads]
        lines += [f"Node overhead above the floor (closed-loop p50 − in-process solve p50 − echo closed-loop p50, "
                  f"{names[runs[0].executor]}): " + "; ".join(parts) + ".", ""]
    return lines


def measure_floor(args) -> tuple[list[EchoRun], dict[str, float], tuple[float, int], str | None]:
    """The echo with each of FLOOR_EXECUTORS (one that fails is left out with its reason), the in-process
    message costs and one LU."""
    from dlo_ros.node.client import NodeStartError

    runs, problem = [], None
    for executor in FLOOR_EXECUTORS:
        try:
            runs.append(measure_echo(executor, args))
        except (NodeStartError, RuntimeError) as exc:
            if executor == "single":
                raise
            problem = f"The echo with `{executor}` failed: {str(exc).splitlines()[0]}"
    return runs, message_costs(), lu_cost(args.model), problem


def _git_head() -> str:
    import subprocess

    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() or "unknown"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=300, help="closed-loop targets (default 300)")
    ap.add_argument("--rate", type=float, default=100.0, help="open-loop publication rate [Hz] (default 100)")
    ap.add_argument("--seconds", type=float, default=5.0, help="open-loop and flood duration [s] (default 5)")
    ap.add_argument("--mode", choices=("interpreted", "native", "both"), default="both",
                    help="node compile mode off (interpreted), blocking (native), or both (default)")
    ap.add_argument("--model", default="full", choices=("auto", "full", "planar", "scene"),
                    help="solver.model of the node (default full; 'scene': the scene's own, i.e. auto)")
    ap.add_argument("--path", choices=tuple(MOTION), default="3d",
                    help="the grips' motion: '3d' (circle and twist, default) or 'planar' (circle in the grips' plane)")
    ap.add_argument("--floor-only", action="store_true",
                    help="measure only the floor (the echo without a solve, in-process message costs, one LU); "
                         "printed, written only with --out")
    ap.add_argument("--out", help="the report (default bench/results/node_latency.md; none with --floor-only)")
    args = ap.parse_args()
    PATH["kind"] = args.path

    modes = [] if args.floor_only else {"interpreted": [False], "native": [True], "both": [False, True]}[args.mode]
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?")
    lines = [
        "# dlo node: end-to-end latency (target -> centreline, across processes)",
        "",
        f"Measured {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}: {cpu}, {os.cpu_count()} CPUs shared with "
        f"other work (load average {os.getloadavg()[0]:.1f} at the start), Python {platform.python_version()}, "
        f"ROS 2 Jazzy PyPI wheels, Fast DDS, discovery on localhost; git {_git_head()}.",
        "",
        f"Command: `scripts/dlo-env run python bench/perf/node_latency.py --mode {args.mode} --model {args.model} "
        f"--n {args.n} --rate {args.rate:g} --seconds {args.seconds:g}"
        f"{' --path ' + args.path if args.path != '3d' else ''}{' --floor-only' if args.floor_only else ''}`",
        "",
        "The node runs in a subprocess on scene `default_cable` (1 m cable, two clamps, table half-space, "
        f"51 output points) with `solver.model: {args.model}`; this process publishes `~/grips/targets` and "
        "receives `~/centerline`. Latency = "
        "reception time minus the centreline's header stamp, which is the stamp of the newest target it "
        f"answers (same clock, same machine). {MOTION[args.path]}, "
        f"{args.n} targets per revolution. Open-loop latency includes waiting for the "
        "solve in progress (the newest target is taken as soon as the worker is free; older ones are "
        "coalesced, never queued). In the flood, this process publishing flat out takes one of the two "
        "CPUs and the node's receiving thread competes with its solver thread for the other and for the GIL.",
        "",
    ]
    runs, costs, lu, events_problem = measure_floor(args)  # first: the node's runs need its closed-loop p50
    overheads = []
    for native in modes:
        section, c50, s50 = measure(native, args)
        lines += section
        overheads.append(("`compile:=blocking`" if native else "`compile:=off`", c50, s50))
    lines += floor_section(args, runs, costs, lu, overheads, events_problem)
    if modes:
        lines += [NOTE, ""]
    text = "\n".join(lines)
    if args.out or not args.floor_only:  # a floor alone never replaces the committed full report by default
        out = Path(args.out or REPO / "bench" / "results" / "node_latency.md")
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
