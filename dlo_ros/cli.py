"""``dlo``: command-line access to scenes and the shape solver (no ROS needed).

    dlo solve SCENE [--json] [--points N] [--basis B] [--order N] [--compile] [--rrd FILE] [--spawn] [--connect [ADDR]]
    dlo scenes
    dlo demo [--scene NAME] [--steps N] [--json] [--compile] [--rrd FILE] [--spawn] [--connect [ADDR]]
    dlo replay FILE.rrd [--resolve [--tolerance M] [--json]] [--web] [--screenshot PNG]
    dlo fit OBSERVATIONS [--scene SCENE] [--json] [--write-scene FILE] [--rrd FILE]

SCENE is a scene file path or the name of a shipped scene (config/scenes/<name>.yaml).
Exit codes: 0 success (solve: status ok), 1 the solve (or a demo step) did not reach status ok,
2 malformed scene or bad usage (the message names the offending key, on stderr, no traceback).
Documented in msg_docs/cli.md; also runs as ``python -m dlo_ros.cli``.

Other subcommands (``node``, ``replay``, ...) plug into :data:`SUBCOMMANDS` at the bottom of this file.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .jsonio import json_safe, stdout_to_stderr

from .paths import available_scenes, scene_path

EXIT_OK = 0
EXIT_NOT_OK = 1
EXIT_USAGE = 2

#: Keys of ``dlo solve --json`` output (ShapeResult.to_dict() plus scene and frame_id).
JSON_KEYS = ("scene", "frame_id", "status", "message", "stable", "min_eigenvalue", "s", "points", "orientations",
             "energy", "grips", "contact_forces", "solver")


class UsageError(Exception):
    """Bad command-line input: printed as ``dlo: error: ...`` and exit code 2."""


# ---- helpers ----------------------------------------------------------------------------------------
def _err(message: str) -> None:
    print(f"dlo: error: {message}", file=sys.stderr)


def _compile_mode(enabled: bool) -> str:
    """ShapeSolver's compile mode for a one-shot command: 'blocking' with --compile (compile the KKT
    function to C now, about a minute per new scene structure, cached), else 'cached' (use a library
    an earlier run compiled, never wait for gcc)."""
    return "blocking" if enabled else "cached"


def _load(scene_arg: str):
    from .scene import load_scene

    return load_scene(scene_arg)


# ---- rerun recording (--rrd / --spawn / --connect; dlo_ros/recording.py, msg_docs/recording.md) --------
def _add_record_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("rerun recording (any combination; default off)")
    g.add_argument("--rrd", metavar="FILE", help="save a rerun recording to FILE (.rrd); `dlo replay FILE` opens it")
    g.add_argument("--spawn", action="store_true", help="start a rerun viewer and stream the recording to it")
    g.add_argument("--connect", nargs="?", const="", default=None, metavar="ADDR",
                   help="stream to a running rerun viewer: HOST[:PORT] or rerun+http://HOST:PORT/proxy "
                        "(no ADDR: 127.0.0.1:9876)")


def _recorder(args: argparse.Namespace):
    """The Recorder the recording flags ask for (a disabled one when none is given)."""
    from .recording import Recorder, RecordingUnavailable

    try:
        return Recorder(rrd=args.rrd, spawn=args.spawn, connect=args.connect)
    except (RecordingUnavailable, ValueError) as exc:
        raise UsageError(str(exc)) from None
    except RuntimeError as exc:  # e.g. no display for --spawn, or the recorder process did not start
        raise UsageError(f"{'--spawn' if args.spawn else 'recording'}: {exc}") from None


def _close_recorder(recorder) -> None:
    recorder.close()
    if recorder.enabled and recorder.errors:
        print(f"dlo: warning: recording: {recorder.errors} error(s), last: {recorder.last_error}", file=sys.stderr)
    if recorder.enabled and recorder.rrd is not None:
        print(f"dlo: recording saved to {recorder.rrd}", file=sys.stderr)


def _with_overrides(options, points: int | None, basis: str | None, order: int | None, model: str | None = None):
    """SolverOptions with the command-line overrides; raises UsageError naming the option.

    An explicit --order pins the order, so it implies --model full unless --model is given
    (model 'auto' chooses the order itself)."""
    changes: dict[str, Any] = {}
    if model is not None:
        changes["model"] = model
    elif order is not None and options.model == "auto":
        changes["model"] = "full"
    if points is not None:
        changes["output_points"] = points
    if basis is not None:
        changes["basis"] = basis
    if order is not None:
        changes["order"] = order
        # keep the default ratio of quadrature nodes to basis functions (40 for 12)
        needed = max(8, order + 2, math.ceil(10 * order / 3))
        if options.quadrature_nodes < needed:
            changes["quadrature_nodes"] = min(400, needed)
    new = replace(options, **changes)
    try:
        new.validate()
    except ValueError as exc:
        flag = {"solver.output_points": "--points", "solver.basis": "--basis", "solver.order": "--order",
                "solver.model": "--model"}
        key = str(exc).split(":", 1)[0]
        raise UsageError(f"{flag.get(key, key)}: {str(exc).split(':', 1)[-1].strip()}") from None
    return new


def max_sag(points: np.ndarray, grip_positions: list[np.ndarray], gravity: np.ndarray) -> float:
    """How far the lowest point of the string hangs below the lowest grip, along gravity [m].

    Negative when the whole string is above its lowest grip (e.g. buckled upward).
    """
    g = np.asarray(gravity, dtype=float)
    g = g / np.linalg.norm(g)
    if len(points) == 0 or not grip_positions:
        return float("nan")
    depth = np.asarray(points) @ g
    return float(depth.max() - max(float(np.dot(p, g)) for p in grip_positions))


def _vec(a: Any, digits: int = 4) -> str:
    return "[" + ", ".join(f"{float(v) + 0.0:+.{digits}g}" for v in np.asarray(a, dtype=float).ravel()) + "]"


def format_summary(scene, result) -> str:
    """Short human-readable summary of one solve."""
    lines = [f"scene   {scene.name}  ({scene.source})", f"status  {result.status}: {result.message}"]
    if result.ok:
        eig = "" if result.min_eigenvalue is None else f"  (min reduced eigenvalue {result.min_eigenvalue:.4g})"
        lines.append(f"stable  {result.stable}{eig}")
        lines.append("energy  " + "  ".join(f"{k} {v + 0.0:.6g}" for k, v in result.energy.items()) + "  [J]")
        width = max(len(n) for n in result.grips) if result.grips else 0
        for name, w in result.grips.items():
            lines.append(f"grip    {name:<{width}}  force {_vec(w.force)} N  torque {_vec(w.torque)} N m")
        for i, f in result.contact_forces.items():
            if np.linalg.norm(f) > 0:
                ob = scene.problem.obstacles[i]
                lines.append(f"contact obstacles[{i}] {ob.name or ob.type}: total force {_vec(f)} N")
        for c in result.self_contacts:
            lines.append(f"self    s = {c.s_a:.4g} m and {c.s_b:.4g} m pressed together: force {_vec(c.force)} N "
                         f"(on s = {c.s_a:.4g} m; gap {c.gap:.4g} m)")
        sag = max_sag(result.points, [g.pose.position for g in scene.problem.grips], scene.problem.gravity)
        lines.append(f"sag     {sag:.4g} m  (lowest point below the lowest grip, along gravity)")
    if result.status in ("ok", "unverified"):
        lines.append(f"check   equilibrium residual {result.equilibrium_residual_m:.3g} m (equivalent centreline error)")
    lines.append(
        f"solver  {result.iterations} iterations, {result.solve_time_ms:.1f} ms, "
        f"{result.basis} order {result.order}" + (f", IPOPT {result.ipopt_status}" if result.ipopt_status else "")
    )
    m = result.model
    if m is not None:
        kinds = ["planar" if m.planar else "3D"] + [k for k in ("twist", "stretch", "gravity") if getattr(m, k)]
        err = m.estimated_error_m
        lines.append(
            f"model   {'auto' if m.auto else 'fixed'}: {', '.join(kinds)}; order {m.order}, "
            f"{m.obstacles} obstacle(s) in the NLP, {m.variables} unknowns"
            + (f", estimated error {err:.2g} m (tolerance {m.tolerance_m:.2g} m"
               + ("" if m.tolerance_met else ": NOT met, even at the highest order") + ")" if err is not None else "")
        )
        for change in m.changes:
            lines.append(f"        model change: {change}")
    return "\n".join(lines)


# ---- solve ------------------------------------------------------------------------------------------
def _add_solve_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", metavar="SCENE", help="scene file path, or the name of a shipped scene (see `dlo scenes`)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object (schema in msg_docs/cli.md)")
    p.add_argument("--points", type=int, metavar="N", help="number of output samples along s (solver.output_points)")
    p.add_argument("--basis", choices=("chebyshev", "fourier"), help="Ritz basis (solver.basis)")
    p.add_argument("--order", type=int, metavar="N",
                   help="basis functions per field (solver.order); raises solver.quadrature_nodes to "
                        "ceil(10 N / 3) if the scene's is smaller; implies --model full unless --model is given")
    p.add_argument("--model", choices=["auto", "full", "planar"],
                   help="solver.model: auto (default: the smallest model the scene needs), full or planar")
    p.add_argument("--compile", action="store_true",
                   help="compile the solver's KKT function to C (slow first build; only useful for benchmarks)")
    _add_record_arguments(p)


def cmd_solve(args: argparse.Namespace) -> int:
    from .solver import make_solver

    scene = _load(args.scene)
    options = _with_overrides(scene.options, args.points, args.basis, args.order, args.model)
    guard = stdout_to_stderr() if args.json else contextlib.nullcontext()
    with guard:
        try:
            solver = make_solver(scene.problem, options, compile=_compile_mode(args.compile), checks="sync")
        except ValueError as exc:  # the solver's own checks (e.g. loads[i].moment); they name the field
            raise UsageError(str(exc)) from None
        recorder = _recorder(args)
        try:
            if recorder.enabled:
                recorder.log_scene(replace(scene, options=options), solver=solver)
                targets = {g.name: g.pose for g in scene.problem.grips}
                stamp = time.time_ns()
                recorder.log_targets(targets, update=0, ros_time_ns=stamp)
            result = solver.solve()
            if recorder.enabled:
                recorder.log_result(result, update=0, ros_time_ns=stamp, targets=targets, warm=False)
        finally:
            _close_recorder(recorder)
    if args.json:
        out = {"scene": scene.name, "frame_id": scene.frame_id, **result.to_dict()}
        print(json.dumps(json_safe(out), allow_nan=False))
    else:
        print(format_summary(scene, result))
    return EXIT_OK if result.ok else EXIT_NOT_OK


# ---- scenes -----------------------------------------------------------------------------------------
def _add_scenes_arguments(p: argparse.ArgumentParser) -> None:
    del p  # no options


def scene_summaries() -> list[tuple[str, str]]:
    """(name, first line of the description) of every shipped scene; unreadable files say why."""
    import yaml

    from .scene import _SceneLoader

    out = []
    for name in available_scenes():
        try:
            data = yaml.load(scene_path(name).read_text(encoding="utf-8"), Loader=_SceneLoader)  # noqa: S506
            desc = data.get("description") if isinstance(data, dict) else None
            first = next((ln.strip() for ln in str(desc or "").splitlines() if ln.strip()), "(no description)")
        except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
            first = f"(unreadable: {type(exc).__name__})"
        out.append((name, first))
    return out


def cmd_scenes(args: argparse.Namespace) -> int:
    del args
    rows = scene_summaries()
    if not rows:
        print("no shipped scenes found")
        return EXIT_OK
    width = max(len(n) for n, _ in rows)
    for name, first in rows:
        print(f"{name:<{width}}  {first}")
    return EXIT_OK


# ---- demo -------------------------------------------------------------------------------------------
def demo_path(scene, steps: int) -> tuple[str, list[np.ndarray]]:
    """The moving grip (named 'right', else the one with the largest s) and its ``steps`` target positions.

    It moves in a straight line, in equal steps, by 15 % of the chord toward the first grip and by 5 % of
    the string length against gravity: small steps, always reachable.
    """
    grips = scene.problem.grips
    moving = next((g for g in grips if g.name == "right"), max(grips, key=lambda g: g.s))
    start = np.asarray(moving.pose.position, dtype=float)
    first = min(grips, key=lambda g: g.s)
    chord = start - np.asarray(first.pose.position, dtype=float) if first is not moving else np.zeros(3)
    up = -scene.problem.gravity_unit
    total = -0.15 * chord + 0.05 * scene.problem.string.length * up
    return moving.name, [start + total * (k / steps) for k in range(1, steps + 1)]


def run_demo(scene_name: str | None = None, steps: int = 50, log: Callable[[str], None] | None = None,
             compile: str = "cached", recorder=None) -> dict:
    """Solve a scene cold, then move one grip through ``steps`` small warm-started updates.

    Returns a summary dict: scene, moving_grip, steps, build_time_s, cold {status, message, time_ms,
    iterations, stable}, warm {time_ms (list), median_ms, p90_ms, max_ms, iterations (list),
    mean_iterations, statuses (status -> count), stable_count, ok_count}, final_sag_m, ok.
    (A placeholder for the ROS node demo; the CLI prints it with :func:`format_demo`.)
    ``recorder``: a dlo_ros.recording.Recorder; update 0 is the cold solve, update k the k-th step.
    """
    from .model.problem import GripPose
    from .scene import DEFAULT_SCENE, SceneError
    from .solver import make_solver

    scene = _load(scene_name or DEFAULT_SCENE)
    log = log or (lambda _msg: None)
    if compile == "blocking":
        log(f"building the solver for {scene.name} (compiling C code: up to a minute the first time)")
    t0 = time.perf_counter()
    try:
        solver = make_solver(scene.problem, scene.options, compile=compile, checks="sync")
    except ValueError as exc:  # the solver's own checks name the field
        raise SceneError(str(exc), source=scene.source) from None
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

    times, iters, statuses, stable, last = [], [], {}, 0, cold
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
    warm = {
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
    return {
        "scene": scene.name,
        "moving_grip": name,
        "steps": steps,
        "build_time_s": build_s,
        "cold": {"status": cold.status, "message": cold.message, "time_ms": cold.solve_time_ms,
                 "iterations": cold.iterations, "stable": cold.stable},
        "warm": warm,
        "final_sag_m": max_sag(last.points, grip_positions, scene.problem.gravity) if last.ok else None,
        "ok": cold.ok and warm["ok_count"] == steps,
    }


def format_demo(summary: dict) -> str:
    c, w = summary["cold"], summary["warm"]
    lines = [
        f"demo    scene {summary['scene']}: grip {summary['moving_grip']!r} moved in {summary['steps']} warm-started steps",
        f"build   {summary['build_time_s']:.2f} s",
        f"cold    {c['status']} ({c['message']}), {c['time_ms']:.1f} ms, {c['iterations']} iterations, stable {c['stable']}",
    ]
    if w["time_ms"]:
        statuses = ", ".join(f"{k} {v}" for k, v in sorted(w["statuses"].items()))
        lines += [
            f"warm    median {w['median_ms']:.2f} ms, p90 {w['p90_ms']:.2f} ms, max {w['max_ms']:.2f} ms",
            f"        mean {w['mean_iterations']:.1f} iterations; statuses: {statuses}; "
            f"stable {w['stable_count']}/{summary['steps']}",
        ]
        if summary["final_sag_m"] is not None:
            lines.append(f"final   sag {summary['final_sag_m']:.4g} m")
    else:
        lines.append("warm    skipped: the cold solve failed")
    return "\n".join(lines)


def _add_demo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--solver-only", action="store_true",
                   help="no ROS: solve the scene in this process and move a grip (the default demo runs the ROS "
                        "node and a dual-arm driver over DDS; its options: python -m dlo_ros.node.demo --help)")
    p.add_argument("--scene", default=None, metavar="NAME", help="scene name or file (default: default_cable)")
    p.add_argument("--steps", type=int, default=50, metavar="N", help="number of warm-started grip moves (default 50)")
    p.add_argument("--json", action="store_true", help="print the summary dict as JSON")
    p.add_argument("--compile", action="store_true",
                   help="compile the solver's KKT function to C (about a minute per new scene structure)")
    _add_record_arguments(p)


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job: the ROS node on the default scene with a dual-arm driver in this process (real DDS),
    printing updates, latency p50/p99, failures and stable shapes; ``--solver-only`` for the ROS-free demo."""
    if not args.solver_only:
        from .node.demo import run_demo_job

        job = ["--compile", "blocking" if args.compile else "cached"]
        if getattr(args, "rrd", None):  # without --rrd the demo records to its default, ./dlo_demo.rrd
            job += ["--rrd", args.rrd]
        return run_demo_job(job)
    if args.steps < 1:
        raise UsageError(f"--steps: must be >= 1, got {args.steps}")
    log = (lambda msg: print(msg, file=sys.stderr)) if not args.json else None
    guard = stdout_to_stderr() if args.json else contextlib.nullcontext()
    with guard:
        recorder = _recorder(args)
        try:
            summary = run_demo(args.scene, args.steps, log=log, compile=_compile_mode(args.compile),
                               recorder=recorder)
        finally:
            _close_recorder(recorder)
    print(json.dumps(json_safe(summary)) if args.json else format_demo(summary))
    return EXIT_OK if summary["ok"] else EXIT_NOT_OK


# =====================================================================================================
# SUBCOMMAND REGISTRY — add new subcommands here (or call register_subcommand() from your module).
#   name -> (help, add_arguments(parser) -> None, handler(args) -> exit code)
# The handler may raise SceneError / FileNotFoundError / UsageError: main() prints them as
# "dlo: error: ..." and returns exit code 2.  "node": main() hands its arguments to the node unparsed (dlo_ros/node/params.py
# checks them).
# =====================================================================================================
def _node_handler(args: argparse.Namespace) -> int:
    """The built-in ``node`` subcommand (``main`` passes its arguments to :func:`_run_node` unparsed)."""
    return _run_node(args.node_args)


Subcommand = tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]

SUBCOMMANDS: dict[str, Subcommand] = {
    "solve": ("solve a scene once and print the shape (exit 0 if status ok)", _add_solve_arguments, cmd_solve),
    "scenes": ("list the shipped scenes", _add_scenes_arguments, cmd_scenes),
    "demo": ("the main job: the ROS node + a dual-arm driver over DDS, with a summary (--solver-only: no ROS)",
             _add_demo_arguments, cmd_demo),
    "node": ("run the ROS 2 node: dlo node [--params-file FILE] [--scene NAME_OR_PATH] [--check] [--ros-args ...] "
             "(`dlo node --help`)",
             lambda p: p.add_argument("node_args", nargs=argparse.REMAINDER), _node_handler),
}


def _run_node(argv: list[str]) -> int:
    """``dlo node ARGS``: the node's own command line (``--params-file``, ``--scene``, ``--check``,
    ``--ros-args ...``), parsed and checked by dlo_ros.node.params.prepare_node_args; ``main`` hands
    everything after ``node`` here untouched (argparse cannot pass ``--scene`` through a subparser)."""
    from .node.signals import stop_on_first_signal

    stop_on_first_signal()  # before the node's imports (CasADi, rclpy): SIGTERM then stops it with 0, not −15
    from .node.params import node_argument_parser

    if any(a in ("-h", "--help") for a in argv[: argv.index("--ros-args") if "--ros-args" in argv else None]):
        node_argument_parser("dlo node").print_help()  # without importing rclpy
        return EXIT_OK
    from .node import main as node_main

    try:
        result = node_main(argv, prog="dlo node")
    except SystemExit as exc:  # argparse: an unknown option of the node's own (usage printed)
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    return int(result or 0)


def register_subcommand(name: str, help: str, add_arguments: Callable[[argparse.ArgumentParser], None],
                        handler: Callable[[argparse.Namespace], int]) -> None:
    """Add (or replace) a subcommand of ``dlo``."""
    SUBCOMMANDS[name] = (help, add_arguments, handler)


# ---- replay (reading and re-solving: dlo_ros/recording/replay.py; viewing: dlo_ros/recording/viewer.py) --
REPLAY_HELP = "open a rerun recording (.rrd) in the viewer, or re-solve it and compare the shapes (--resolve)"


def _add_replay_arguments(p: argparse.ArgumentParser) -> None:
    from .recording.replay import DEFAULT_TOLERANCE

    p.add_argument("file", metavar="FILE.rrd", help="a recording made with --rrd (dlo solve / dlo demo / the node)")
    p.add_argument("--resolve", action="store_true",
                   help="re-run the solver on the recorded targets and report how far today's shapes are from the "
                        "recorded ones (exit 1 if any update exceeds --tolerance)")
    p.add_argument("--tolerance", type=float, default=DEFAULT_TOLERANCE, metavar="M",
                   help=f"with --resolve: largest allowed centreline deviation [m] (default {DEFAULT_TOLERANCE:g})")
    p.add_argument("--json", action="store_true", help="with --resolve: print the report as one JSON object")
    p.add_argument("--compile", action="store_true",
                   help="with --resolve: compile the solver's derivatives to C first (slow first build)")
    p.add_argument("--web", action="store_true", help="serve the recording to a browser (rerun --web-viewer)")
    p.add_argument("--screenshot", metavar="PNG", help="render the recording headlessly into PNG and exit")
    p.add_argument("--update", type=int, metavar="N", help="with --screenshot: show update N (default: the last)")


def cmd_replay(args: argparse.Namespace) -> int:
    from .recording import replay, viewer

    path = Path(args.file)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if args.resolve:
        if not (args.tolerance >= 0 and math.isfinite(args.tolerance)):
            raise UsageError(f"--tolerance: must be a finite number >= 0, got {args.tolerance}")
        try:
            rec = replay.read_recording(path)
            with stdout_to_stderr():  # IPOPT's banner must not mix with the report
                report = replay.resolve(rec, args.tolerance, compile="blocking" if args.compile else "cached")
        except UsageError:
            raise
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        print(json.dumps(json_safe(report)) if args.json else replay.format_resolve(report))
        return EXIT_OK if report["ok"] else EXIT_NOT_OK
    try:
        replay.read_recording(path)  # a clear error for a file that is not a recording, before starting a viewer
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.screenshot:
        try:
            out = viewer.screenshot(path, args.screenshot, update=args.update)
        except Exception as exc:  # noqa: BLE001 - the viewer's reasons are varied (no GPU, port, ...)
            print(f"dlo replay: could not render {path} headlessly: {type(exc).__name__}: {exc}\n"
                  "  the headless viewer needs a Vulkan adapter; a software one is Debian's mesa-vulkan-drivers "
                  "(lavapipe)", file=sys.stderr)
            return EXIT_NOT_OK
        print(f"dlo replay: screenshot saved to {out}")
        return EXIT_OK
    if args.web:
        return _run_viewer([*viewer.rerun_command(), "--web-viewer", str(path)])
    if not viewer.has_display():
        print(viewer.no_display_message(path))
        return EXIT_OK
    return _run_viewer([*viewer.rerun_command(), str(path)])


def _run_viewer(cmd: list[str]) -> int:
    try:
        code = subprocess.call(cmd)
    except OSError as exc:
        print(f"dlo replay: could not start the rerun viewer ({' '.join(cmd)}): {exc}", file=sys.stderr)
        return EXIT_NOT_OK
    if code not in (0, -2, 130):  # Ctrl-C in the viewer is a normal way out
        print(f"dlo replay: the rerun viewer exited with code {code} ({' '.join(cmd)})", file=sys.stderr)
        return EXIT_NOT_OK
    return EXIT_OK


register_subcommand("replay", REPLAY_HELP, _add_replay_arguments, cmd_replay)


def _register_fit() -> None:
    """``dlo fit`` lives in dlo_ros/identify/command.py (imported when it runs)."""
    from .identify import command

    def handler(args: argparse.Namespace) -> int:
        try:
            return command.cmd_fit(args)
        except ValueError as exc:  # ObservationError (a ValueError; SceneError is caught by main first)
            from .scene import SceneError

            if isinstance(exc, SceneError):
                raise
            raise UsageError(str(exc)) from None

    register_subcommand("fit", command.HELP, command.add_arguments, handler)


_register_fit()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dlo", description="Static shape of a cable/rope/paper strip held by grippers (Hirai & Wakamatsu).",
        epilog="Exit codes: 0 ok, 1 solve status not ok, 2 malformed scene or usage.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (help_text, add_arguments, handler) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add_arguments(p)
        p.set_defaults(_handler=handler)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    node = SUBCOMMANDS.get("node")
    if argv[:1] == ["node"] and node is not None and node[2] is _node_handler:
        # everything after `node` is the node's (and rclpy's): argparse would refuse `--scene` here
        return _run_node(argv[1:])
    from .scene import SceneError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0) if isinstance(exc.code, int) else EXIT_USAGE
    try:
        return int(args._handler(args))
    except (SceneError, FileNotFoundError, UsageError) as exc:
        # FileNotFoundError/KeyError-style messages may come quoted; SceneError's never start with a quote
        text = exc.args[0] if isinstance(exc, FileNotFoundError) and len(exc.args) == 1 else str(exc)
        _err(str(text))
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # e.g. `dlo scenes | head -1`
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silence the flush at exit
        return EXIT_OK
    except OSError as exc:  # a file the command was given cannot be read or written: its name and why
        from .text import safe_text

        name = f"{safe_text(exc.filename)}: " if exc.filename is not None else ""
        _err(f"{name}{exc.strerror or type(exc).__name__}")
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
