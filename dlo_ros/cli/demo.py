"""``dlo demo``: the ROS node with a dual-arm driver, or a grip moved in warm steps.

``dlo demo``: the ROS node with a dual-arm driver over DDS, or (``--solver-only``) a grip moved
in warm steps.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..jsonio import json_safe, stdout_to_stderr
from .common import EXIT_NOT_OK, EXIT_OK, UsageError, compile_mode, load_scene_arg
from .record import add_record_arguments, close_recorder, make_recorder
from .solve import max_sag

if TYPE_CHECKING:  # types only: start-up (cli/__init__)
    from ..scene import Scene
    from ..solver import Solver

HELP = (
    "the main job: the ROS node + a dual-arm driver over DDS, with a summary (--solver-only: "
    "no ROS)"
)


def demo_path(scene, steps: int) -> tuple[str, list[np.ndarray]]:
    """Return the moving grip and its ``steps`` target positions.

    The moving grip (named 'right', else the one with the largest s) and its ``steps`` target
    positions.

    It moves in a straight line, in equal steps, by 15 % of the chord toward the first grip and by
    5 % of the string length against gravity: small steps, always reachable.
    """
    grips = scene.problem.grips
    moving = next((g for g in grips if g.name == "right"), max(grips, key=lambda g: g.s))
    start = np.asarray(moving.pose.position, dtype=float)
    first = min(grips, key=lambda g: g.s)
    chord = (
        start - np.asarray(first.pose.position, dtype=float)
        if first is not moving
        else np.zeros(3)
    )
    up = -scene.problem.gravity_unit
    total = -0.15 * chord + 0.05 * scene.problem.string.length * up
    return moving.name, [start + total * (k / steps) for k in range(1, steps + 1)]


def _warm_summary(
    times: list[float], iters: list[int], statuses: dict[str, int], stable: int
) -> dict:
    """Return the ``warm`` part of :func:`run_demo`'s summary: time and iteration statistics."""
    return {
        "time_ms": times,
        "median_ms": float(np.median(times)) if times else None,
        "p90_ms": float(np.percentile(times, 90)) if times else None,
        "max_ms": float(np.max(times)) if times else None,
        "iterations": iters,
        "mean_iterations": float(np.mean(iters)) if iters else None,
        "statuses": statuses,
        "ok_count": statuses.get("ok", 0),
        "stable_count": stable,
    }


def _build_solver(scene: Scene, compile: str, log: Callable[[str], None]) -> Solver:
    """Return the scene's solver; a ValueError of the solver's checks becomes a SceneError."""
    # start-up (cli/__init__): the solver only when a demo runs
    from ..scene import SceneError
    from ..solver import make_solver

    if compile == "blocking":
        log(
            f"building the solver for {scene.name} (compiling C code: up to a minute the first "
            f"time)"
        )
    try:
        return make_solver(scene.problem, scene.options, compile=compile, checks="sync")
    except ValueError as exc:  # the solver's own checks name the field
        raise SceneError(str(exc), source=scene.source) from None


def run_demo(
    scene_name: str | None = None,
    steps: int = 50,
    log: Callable[[str], None] | None = None,
    compile: str = "cached",
    recorder=None,
) -> dict:
    """Solve a scene cold, then move one grip through ``steps`` small warm-started updates.

    Returns a summary dict: scene, moving_grip, steps, build_time_s, cold {status, message,
    time_ms, iterations, stable}, warm {time_ms (list), median_ms, p90_ms, max_ms, iterations
    (list), mean_iterations, statuses (status -> count), stable_count, ok_count}, final_sag_m, ok.
    The CLI prints it with :func:`format_demo`. ``recorder``: a dlo_ros.recording.Recorder; update
    0 is the cold solve, update k the k-th step.
    """
    # start-up (cli/__init__): the model and scene only when a demo runs
    from ..model.problem import GripPose
    from ..scene import DEFAULT_SCENE

    scene = load_scene_arg(scene_name or DEFAULT_SCENE)
    t0 = time.perf_counter()
    solver = _build_solver(scene, compile, log or (lambda _msg: None))
    build_s = time.perf_counter() - t0
    record = recorder is not None and recorder.enabled
    current = {g.name: g.pose for g in scene.problem.grips}
    if record:
        recorder.log_scene(scene, solver=solver)
        stamp = time.time_ns()
        recorder.log_targets(current, update=0, ros_time_ns=stamp)
    cold = solver.solve(warm=False)
    if record:
        recorder.log_result(cold, update=0, ros_time_ns=stamp, targets=current, warm=False)
    name, targets = demo_path(scene, steps)
    orientation = scene.problem.grip(name).pose.orientation

    times: list[float] = []
    iters: list[int] = []
    statuses: dict[str, int] = {}
    stable, last = 0, cold
    if cold.ok:
        for k, target in enumerate(targets, start=1):
            if record:
                stamp = time.time_ns()
                current = {**current, name: GripPose(target, orientation)}
                recorder.log_targets({name: current[name]}, update=k, ros_time_ns=stamp)
            r = solver.solve({name: GripPose(target, orientation)})
            if record:
                recorder.log_result(r, update=k, ros_time_ns=stamp, targets=current, warm=True)
            times.append(r.solve_time_ms)
            iters.append(r.iterations)
            statuses[r.status] = statuses.get(r.status, 0) + 1
            stable += int(bool(r.stable))
            if r.ok:
                last = r
    grip_positions = [g.pose.position for g in solver.problem.grips]
    warm = _warm_summary(times, iters, statuses, stable)
    return {
        "scene": scene.name,
        "moving_grip": name,
        "steps": steps,
        "build_time_s": build_s,
        "cold": {
            "status": cold.status,
            "message": cold.message,
            "time_ms": cold.solve_time_ms,
            "iterations": cold.iterations,
            "stable": cold.stable,
        },
        "warm": warm,
        "final_sag_m": max_sag(last.points, grip_positions, scene.problem.gravity)
        if last.ok
        else None,
        "ok": cold.ok and warm["ok_count"] == steps,
    }


def format_demo(summary: dict) -> str:
    c, w = summary["cold"], summary["warm"]
    lines = [
        f"demo    scene {summary['scene']}: grip {summary['moving_grip']!r} moved in "
        f"{summary['steps']} warm-started steps",
        f"build   {summary['build_time_s']:.2f} s",
        f"cold    {c['status']} ({c['message']}), {c['time_ms']:.1f} ms, {c['iterations']} "
        f"iterations, stable {c['stable']}",
    ]
    if w["time_ms"]:
        statuses = ", ".join(f"{k} {v}" for k, v in sorted(w["statuses"].items()))
        lines += [
            f"warm    median {w['median_ms']:.2f} ms, p90 {w['p90_ms']:.2f} ms, max "
            f"{w['max_ms']:.2f} ms",
            f"        mean {w['mean_iterations']:.1f} iterations; statuses: {statuses}; "
            f"stable {w['stable_count']}/{summary['steps']}",
        ]
        if summary["final_sag_m"] is not None:
            lines.append(f"final   sag {summary['final_sag_m']:.4g} m")
    else:
        lines.append("warm    skipped: the cold solve failed")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--solver-only",
        action="store_true",
        help="no ROS: solve the scene in this process and move a grip (the default demo runs the "
        "ROS node and a dual-arm driver over DDS; its options: "
        "python -m dlo_ros.node.demo --help)",
    )
    p.add_argument(
        "--scene", default=None, metavar="NAME", help="scene name or file (default: default_cable)"
    )
    p.add_argument(
        "--steps",
        type=int,
        default=50,
        metavar="N",
        help="number of warm-started grip moves (default 50)",
    )
    p.add_argument("--json", action="store_true", help="print the summary dict as JSON")
    p.add_argument(
        "--compile",
        action="store_true",
        help="compile the solver's KKT function to C (about a minute per new scene structure)",
    )
    add_record_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run the main job: the ROS node with a dual-arm driver, or the ROS-free demo.

    The main job: the ROS node on the default scene with a dual-arm driver in this process (real
    DDS), printing updates, latency p50/p99, failures and stable shapes; ``--solver-only`` for the
    ROS-free demo.
    """
    if not args.solver_only:
        from ..node.demo import run_demo_job  # start-up (cli/__init__): rclpy

        job = ["--compile", "blocking" if args.compile else "cached"]
        if getattr(
            args, "rrd", None
        ):  # without --rrd the demo records to its default, ./dlo_demo.rrd
            job += ["--rrd", args.rrd]
        return run_demo_job(job)
    if args.steps < 1:
        raise UsageError(f"--steps: must be >= 1, got {args.steps}")
    log = (lambda msg: print(msg, file=sys.stderr)) if not args.json else None
    guard = stdout_to_stderr() if args.json else contextlib.nullcontext()
    with guard:
        recorder = make_recorder(args)
        try:
            summary = run_demo(
                args.scene,
                args.steps,
                log=log,
                compile=compile_mode(args.compile),
                recorder=recorder,
            )
        finally:
            close_recorder(recorder)
    print(json.dumps(json_safe(summary)) if args.json else format_demo(summary))
    return EXIT_OK if summary["ok"] else EXIT_NOT_OK
