"""The dual-arm demo: the node in a subprocess, a driver in this process, real DDS between them.

``run_demo_job(argv)`` starts ``python -m dlo_ros.node`` on the default scene with a sphere "post"
added (a demo scene written to a temporary directory), waits for its first centreline, then moves
the two grippers through a short manoeuvre by publishing ``~/grips/targets`` (PoseArray) at a fixed
rate:

1. bring the ends together (and raise them a little),
2. twist the right end by half a turn about the cable's tangent,
3. lift the cable, carry it over the post and lower it until it drapes over the post.

It records every centreline it receives and prints a summary: targets sent, centrelines received,
end-to-end latency target -> centreline (p50/p99/max; the centreline's header stamp is the stamp of
the newest target it answers), failures and rejected inputs, how many shapes were stable, and where
the cable ended.  The node is always stopped (SIGINT, then SIGTERM/SIGKILL of its process group)
and the temporary directory removed.  Run it with ``python -m dlo_ros.node.demo`` (or through the
CLI).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from ..scene import load_scene, scene_from_dict, scene_to_dict
from ..solver.auto import ORDERS
from .client import DloClient, NodeProcess, PathEvent, allocate_domain_id

DEMO_SCENE = "default_cable"
#: Added to the default scene: the obstacle the cable is carried over.
POST: dict[str, Any] = {
    "type": "sphere",
    "name": "post",
    "center": [0.175, 0.35, 0.25],
    "radius": 0.08,
}

#: (time [s], left position, right position, right twist about the tangent [rad], phase starting
#: here)
KEYFRAMES = (
    (0.0, (0.0, 0.0, 0.40), (0.60, 0.0, 0.40), 0.0, "bring the ends together"),
    (2.0, (0.0, 0.0, 0.55), (0.35, 0.0, 0.55), 0.0, "twist the right end by half a turn"),
    (4.0, (0.0, 0.0, 0.55), (0.35, 0.0, 0.55), math.pi, "lift the cable"),
    (5.0, (0.0, 0.0, 0.85), (0.35, 0.0, 0.85), math.pi, "carry it over the post"),
    (7.0, (0.0, 0.35, 0.85), (0.35, 0.35, 0.85), math.pi, "lower it onto the post"),
    (9.0, (0.0, 0.35, 0.55), (0.35, 0.35, 0.55), math.pi, "done"),
)


#: The node's rerun recording of the run (in the current directory; overwritten by every run).
DEFAULT_RRD = "dlo_demo.rrd"


def _twist(angle: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of a rotation by ``angle`` about x (the held tangent)."""
    return np.array([math.sin(angle / 2), 0.0, 0.0, math.cos(angle / 2)])


def duration() -> float:
    return KEYFRAMES[-1][0]


def phase_at(t: float) -> str:
    label = KEYFRAMES[0][4]
    for k in KEYFRAMES[:-1]:
        if t >= k[0]:
            label = k[4]
    return label


def targets_at(t: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return [(left position, quaternion), (right position, quaternion)] at time t [s].

    Smoothstep between keyframes.
    """
    t = min(max(t, 0.0), duration())
    for (t0, l0, r0, a0, _), (t1, l1, r1, a1, _) in zip(KEYFRAMES, KEYFRAMES[1:]):
        if t <= t1:
            u = (t - t0) / (t1 - t0)
            u = u * u * (3 - 2 * u)
            break

    def lerp(a, b):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        return a + u * (b - a)

    return [(lerp(l0, l1), _twist(0.0)), (lerp(r0, r1), _twist(a0 + u * (a1 - a0)))]


def write_demo_scene(directory: Path) -> Path:
    """Write the default scene plus the post, validated, as ``<directory>/dual_arm_demo.yaml``."""
    d = scene_to_dict(load_scene(DEMO_SCENE))
    d["name"] = "dual_arm_demo"
    d["description"] = (
        f"{DEMO_SCENE} plus a sphere 'post' the cable is carried over (dlo_ros.node.demo)."
    )
    d["obstacles"] = list(d.get("obstacles", [])) + [dict(POST)]
    scene_from_dict(d)  # validate before the node sees it
    path = Path(directory) / "dual_arm_demo.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def _percentiles(values: Sequence[float]) -> tuple[float, float, float]:
    if not values:
        return float("nan"), float("nan"), float("nan")
    a = np.asarray(values, dtype=float)
    return float(np.percentile(a, 50)), float(np.percentile(a, 99)), float(a.max())


def _model_summary(values: dict[str, str]) -> str:
    """Summarise the node's final model from its diagnostics (model.* keys).

    What it solved, its estimated error against the tolerance, and how many times it changed.
    """
    if not values.get("model.order"):
        return "not reported"

    def yes(key: str) -> bool:
        return str(values.get(key)).lower() == "true"

    kind = "planar" if yes("model.planar") else "3D"
    fields = [f for f in ("twist", "stretch", "gravity") if yes(f"model.{f}")]
    text = (
        ("auto: " if yes("model.auto") else "")
        + ", ".join([kind, *fields])
        + f", order {values['model.order']}, {values.get('model.variables', '?')} unknowns, "
        f"{values.get('model.obstacles', '?')} obstacle(s) in the NLP"
    )
    est, tol = values.get("model.estimated_error_m", ""), values.get("model.tolerance_m", "")
    if est not in ("", "None"):
        met = "met" if float(est) <= float(tol) else "NOT met"
        text += f"; estimated error {float(est):.2g} m (tolerance {float(tol):.2g} m: {met})"
    changes = values.get("model.changes")
    if changes not in (None, "", "0"):
        text += f"; {changes} change(s) during the run"
    return text


def model_settled(values: dict[str, str], held: int = 0) -> bool:
    """Return whether auto's checks describe the final shape and its model is good enough.

    The checks must be of a solve of the last target: at most ``held`` updates ago (``held`` the
    solves of the last target since the manoeuvre's end); the model must meet the tolerance or be
    the richest order (a fixed model: always true).
    """
    if str(values.get("model.auto")).lower() != "true":
        return True
    checked = str(values.get("model.checked")).lower() == "true"
    try:
        age = int(values.get("model.checked_updates_ago", ""))
    except (TypeError, ValueError):
        return False
    met = str(values.get("model.tolerance_met")).lower() == "true"
    return checked and age <= held and (met or str(values.get("model.order")) == str(ORDERS[-1]))


def _settle(client, values: dict, timeout: float, rate: float):
    """Hold the last target until ``model_settled`` or ``timeout`` s.

    The target is republished at ``rate`` [Hz], the manoeuvre's (a robot holding still keeps
    sending its pose): auto applies a check's verdict a fixed number of updates after the shape
    it checked (``solver/auto/check_schedule.py``), so a slower hold only slows the settling.
    Each publish waits for its centreline; the newest diagnostics (``diagnostics_period``) say
    whether the checks describe the final shape.  Returns (diagnostic values, last centreline or
    None, seconds, solves), with 0 s and 0 solves when the final shape's checks were already
    done, or None when settling is off (timeout 0).
    """
    if timeout <= 0:
        return None
    if model_settled(values):
        return values, None, 0.0, 0
    t0, held, final = time.monotonic(), 0, None
    target = targets_at(duration())
    base = int(values.get("targets received") or 0)
    while time.monotonic() - t0 < timeout:
        tick = time.monotonic()
        stamp = client.publish_targets(target)
        held += 1
        final = client.wait_for_path(5.0, where=lambda ev, s=stamp: ev.stamp_ns == s) or final
        diag = client.wait_for_diagnostics(lambda v, st: True, 0.0)
        if diag:
            # the solves of the last target that these diagnostics have seen
            seen = int(diag[0].get("targets received") or 0) - base
            if seen > 0:
                values = diag[0]
                if model_settled(values, seen):
                    break
        time.sleep(max(0.0, 1.0 / rate - (time.monotonic() - tick)))
    return values, final, time.monotonic() - t0, held


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="dlo demo", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--rate", type=float, default=50.0, help="target publication rate [Hz] (default 50)"
    )
    ap.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="manoeuvre speed factor (default 1: the manoeuvre takes %.0f s)" % duration(),
    )
    ap.add_argument(
        "--compile",
        default="off",
        choices=("background", "blocking", "cached", "off"),
        help="the node's compile mode (default off: interpreted derivatives, no gcc; 'blocking' "
        "compiles before the first solve, seconds the first time for this scene)",
    )
    ap.add_argument(
        "--model",
        default="auto",
        choices=("auto", "full", "planar", "scene"),
        help="solver.model of the node (default auto: it starts planar and switches to 3D when "
        "the "
        "twist starts, raising the basis order to meet its 1 mm tolerance; 'scene': the scene's "
        "own setting)",
    )
    ap.add_argument(
        "--settle",
        type=float,
        default=120.0,
        metavar="S",
        help="after the manoeuvre, hold the last target (at --rate) until auto's checks of the "
        "final shape are done and meet the tolerance, at most S seconds (default 120; 0: do not "
        "wait)",
    )
    ap.add_argument(
        "--startup-timeout",
        type=float,
        default=60.0,
        help="seconds to wait for the node's first centreline (default 60)",
    )
    ap.add_argument("--log", metavar="FILE", help="keep the node's output in FILE")
    ap.add_argument(
        "--rrd",
        metavar="FILE",
        default=DEFAULT_RRD,
        help=f"the node records the run to this rerun file (default ./{DEFAULT_RRD}, overwritten "
        "each "
        "run; `dlo replay FILE` opens it); '' for no recording",
    )
    return ap


def run_demo_job(argv: Sequence[str] | None = None) -> int:
    """Run the demo (see the module docstring); return the exit code.

    0: the demo ran and the node shut down cleanly.
    """
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.rate <= 0 or args.speed <= 0:
        print("dlo demo: --rate and --speed must be > 0", file=sys.stderr)
        return 2
    t_job = time.monotonic()
    tmp = Path(tempfile.mkdtemp(prefix="dlo_demo_"))
    lease = node = client = rrd = None
    code = 1
    try:
        scene = write_demo_scene(tmp)
        lease = allocate_domain_id()
        rrd = Path(args.rrd).expanduser().resolve() if args.rrd else None
        if rrd is not None:
            rrd.parent.mkdir(parents=True, exist_ok=True)
            rrd.unlink(missing_ok=True)  # a stale file must not pass for this run's recording
        node_args = _node_args(args, scene, rrd)
        node = NodeProcess(node_args, lease.domain_id, log_path=args.log or tmp / "node.log")
        client = DloClient(lease.domain_id, client_name="dlo_demo_driver")
        print(
            f"dlo demo: node pid {node.pid}, ROS_DOMAIN_ID={lease.domain_id}, scene "
            f"{DEMO_SCENE} + sphere 'post' at {POST['center']} (r = {POST['radius']} m)"
        )
        if not _first_shape(node, client, args):
            return 1
        code = _manoeuvre(client, args, rrd)
    except KeyboardInterrupt:
        print("dlo demo: interrupted", file=sys.stderr)
        code = 130
    finally:
        if client is not None:
            client.close()
        if node is not None and not _stop_node(node, rrd, t_job):
            code = code or 1
        if lease is not None:
            lease.release()
        shutil.rmtree(tmp, ignore_errors=True)
    return code


def _node_args(args: argparse.Namespace, scene: Path, rrd: Path | None) -> list[str]:
    """Build the node's command line for the demo scene and the demo's options."""
    return [
        "--scene",
        str(scene),
        "--ros-args",
        "-p",
        f"compile:={args.compile}",
        *([] if args.model == "scene" else ["-p", f"solver.model:={args.model}"]),
        "-p",
        "diagnostics_period:=0.25",
        *([] if rrd is None else ["-p", f"record.rrd:={rrd}"]),
    ]


def _first_shape(node: NodeProcess, client: DloClient, args: argparse.Namespace) -> bool:
    """Wait for the node's first centreline; say why not (with the node's output) if none came."""
    t0 = time.monotonic()
    first = None
    while first is None and node.alive() and time.monotonic() - t0 < args.startup_timeout:
        first = client.wait_for_path(0.5)
    if first is None:
        print(
            f"dlo demo: the node published no centreline within {args.startup_timeout:.0f} s "
            f"(alive: {node.alive()}); its output:\n{node.output()}",
            file=sys.stderr,
        )
        return False
    client.wait_for_subscribers(10.0)
    print(
        f"dlo demo: first centreline after {time.monotonic() - t0:.1f} s; manoeuvre of "
        f"{duration() / args.speed:.1f} s at {args.rate:g} Hz"
    )
    return True


def _publish_manoeuvre(
    client: DloClient, args: argparse.Namespace
) -> tuple[dict[int, float], int]:
    """Publish the keyframed targets at ``args.rate`` Hz.

    Returns {header stamp [ns]: manoeuvre time [s]} and the stamp of the final target, published
    once more after the manoeuvre.
    """
    published: dict[int, float] = {}
    period = 1.0 / args.rate
    start = time.monotonic()
    phase = None
    k = 0
    while True:
        t = (time.monotonic() - start) * args.speed
        if t > duration():
            break
        label = phase_at(t)
        if label != phase:
            phase = label
            print(f"  t = {t:4.1f} s  {label}")
        published[client.publish_targets(targets_at(t))] = t
        k += 1
        time.sleep(max(0.0, start + k * period - time.monotonic()))
    last_stamp = client.publish_targets(targets_at(duration()))
    published[last_stamp] = duration()
    return published, last_stamp


def _manoeuvre(client: DloClient, args: argparse.Namespace, rrd: Path | None) -> int:
    """Drive the manoeuvre, let auto settle, print the summary; return the exit code."""
    published, last_stamp = _publish_manoeuvre(client, args)
    final = client.wait_for_path(10.0, where=lambda ev: ev.stamp_ns == last_stamp)
    # diagnostics newer than the final centreline count every target the node got (it had
    # counted 450 of 451 published: waiting for all of them took the 5 s timeout)
    seen = client.diagnostics_count
    client.wait_for(lambda: client.diagnostics_count > seen or None, 5.0)
    values = client.diagnostic_values()
    events = [ev for ev in client.paths if ev.stamp_ns in published]
    settled = _settle(client, values, args.settle, args.rate) if final is not None else None
    if settled is not None:
        values, held_final, settle_s, held = settled
        final = held_final or final
    _print_summary(args, values, published, events, rrd)
    if settled is not None:
        done = model_settled(values, held)
        print(
            f"  settling                "
            f"{'checked' if done else f'NOT checked within {args.settle:g} s'}: held the last "
            f"target {settle_s:.1f} s ({held} more solves) for auto's checks of the final shape "
            "(model above)"
        )
    _print_recording(rrd)
    _print_final(final)
    return 0 if events and final is not None else 1


def _print_summary(
    args: argparse.Namespace,
    values: dict[str, str],
    published: dict[int, float],
    events: list,
    rrd: Path | None,
) -> None:
    """Print the manoeuvre's counts, latencies, failures and model from the node's diagnostics."""
    latencies = [(ev.received_ns - ev.stamp_ns) / 1e6 for ev in events]
    p50, p99, pmax = _percentiles(latencies)
    updates = int(values.get("updates", "0") or 0)
    stable = int(values.get("stable updates", "0") or 0)
    failures = int(values.get("failures", "0") or 0)
    rejected = int(values.get("rejected inputs", "0") or 0)
    print("dlo demo: summary")
    print(
        f"  targets published       {len(published)} ({args.rate:g} Hz, PoseArray for both grips)"
    )
    print(
        f"  centrelines received    {len(events)} during the manoeuvre ({updates} shapes "
        f"published by the node in total, {values.get('targets coalesced', '?')} targets "
        "coalesced)"
    )
    print(f"  latency target->path    p50 {p50:.1f} ms, p99 {p99:.1f} ms, max {pmax:.1f} ms")
    print(
        f"  solve time (last)       {values.get('solve time ms', '?')} ms, "
        f"{values.get('iterations', '?')} iterations"
    )
    print(
        f"  failures                {failures} failed solves, {rejected} rejected inputs"
        + (f" (last: {values.get('last error')})" if failures + rejected else "")
    )
    unverified = int(values.get("unverified updates", "0") or 0)
    print(
        f"  stable shapes           {stable} of {updates}"
        + (
            f" ({unverified} published unverified: equilibrium residual over the tolerance)"
            if unverified
            else ""
        )
    )
    print(f"  model                   {_model_summary(values)}")


def _print_recording(rrd: Path | None) -> None:
    """Print where the recording goes."""
    print(
        f"  recording               {rrd if rrd is not None else 'off'}"
        + (
            " (complete when the node has stopped; `dlo replay FILE` opens it)"
            if rrd is not None
            else ""
        )
    )


def _print_final(final: PathEvent | None) -> None:
    """Print where the final shape ends and how far it is from the post."""
    if final is None:
        print(
            "  final shape             the centreline of the last target did not arrive within 10 "
            "s"
        )
        return
    centre, r = np.asarray(POST["center"]), float(POST["radius"])
    gap = float(np.min(np.linalg.norm(final.points - centre, axis=1)) - r)
    resting = "resting on the post" if gap < 0.02 else f"{gap * 100:.1f} cm from the post"
    print(
        f"  final shape             ends at the last target; lowest point "
        f"z = {final.points[:, 2].min():.3f} m, {resting}"
    )


def _stop_node(node: NodeProcess, rrd: Path | None, t_job: float) -> bool:
    """Stop the node and report its exit, its recording and its model changes; True if clean."""
    rc = node.stop(timeout=15.0)
    text = node.output()
    clean = rc == 0 and "Traceback" not in text
    print(
        f"dlo demo: node stopped (exit code {rc}{'' if clean else ', NOT clean'}); "
        f"total {time.monotonic() - t_job:.1f} s"
    )
    if rrd is not None:
        size = rrd.stat().st_size if rrd.is_file() else 0
        print(
            f"dlo demo: recording: {rrd} ({size / 1e6:.1f} MB)"
            if size
            else f"dlo demo: recording: {rrd} was not written (see the node's output)"
        )
    for line in text.splitlines():  # the node's INFO lines for every change of model, with reasons
        if "model change (update" in line:
            print("  " + line[line.index("model change") :])
    if not clean:
        print(text[-4000:], file=sys.stderr)
    return clean


def main() -> None:
    sys.exit(run_demo_job())


if __name__ == "__main__":
    main()
