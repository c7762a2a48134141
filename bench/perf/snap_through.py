"""The snap-through updates of `default_cable`'s streams (#38): how long, how much is the escape.

Two streams of ``--updates`` warm updates of the right grip (at most 2,000), compiled derivatives
(``compile='blocking'``; set ``DLO_CACHE_DIR`` for a cache of one's own):

* ``path3d on table``: the cable lying on its table (both grips lowered 0.32 m), the right grip
  along the closed 3D path of test/unit/test_director_stream.py (bench/perf/auto_vs_full.py's
  ``path3d_stream(on_table=True)``);
* ``ellipse``: the hanging cable, the right grip in steps of 1 % of L around an ellipse of radius
  0.08 L in its x–z plane (bench/perf/solver_speed.py's stream; test/unit/test_leave_saddle.py's
  ``circling``): the sag touches down on the table once a lap, and there the in-plane shape
  Newton lands on is a saddle.

and two solvers for each:

* ``slots 12``: the fixed model ``solver.model: auto`` streams on for this scene (3D order 12, the
  table's rows at the nodes, 2 contact slots, ``slotted_obstacles: flat``; as
  bench/perf/update_python.py's);
* ``auto``: ``make_solver(problem, options, compile='blocking')`` with the scene's options.

A snap-through update is one whose warm Newton answer is a saddle, which ``ladder.
leave_newton_saddle`` leaves by shifted Newton steps (``saddle.leave_saddle``, wrapped here with a
clock); 'left' among them: the update's answer is that escape's (its message carries
``ipopt.LEFT_SADDLE``).  Per snap-through update: the wall time around ``solve`` and the part in
``leave_saddle`` [ms].

With ``--before REV`` the stream runs twice in the same run, on ``dlo_ros`` of git revision REV
(``before``, extracted with ``git archive``, bench/before_after.py) and on this tree (``after``),
each in a worker process, in ``--rounds`` interleaved pieces; the report then gives the ratio of
the snap-through updates' median times and the largest difference between the two columns'
escapes (each ``leave_saddle`` call's final z, scaled unknowns).

    bash scripts/dlo-env run python bench/perf/snap_through.py [--updates 2000] [--rounds 8]
                                          [--before REV] [--out bench/results/snap_through.md]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SOLVERS = ("slots 12", "auto")
STREAMS = ("path3d on table", "ellipse")


class Clock:
    """A function with the seconds spent in it added up (``reset`` starts over)."""

    def __init__(self, run) -> None:
        self.run, self.seconds = run, 0.0

    def __call__(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self.run(*args, **kwargs)
        self.seconds += time.perf_counter() - t0
        return out


class Escapes:
    """``ladder.leave_saddle`` with a clock: each call's seconds and its final z, per update."""

    def __init__(self, run) -> None:
        self.run, self.seconds, self.calls, self.z = run, 0.0, 0, []

    def __call__(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self.run(*args, **kwargs)
        self.seconds += time.perf_counter() - t0
        self.calls += 1
        self.z.append([bool(out[0]), np.asarray(out[1].z, dtype=float).tolist()])
        return out

    def reset(self) -> None:
        """Start the count of a new update."""
        self.seconds, self.calls, self.z = 0.0, 0, []


def worker() -> None:
    """Serve pieces over stdin/stdout: [solver, stream, first, count] → the snap-throughs."""
    from dataclasses import replace

    from dlo_ros.model.problem import GripPose
    from dlo_ros.scene import load_scene
    from dlo_ros.solver.auto.factory import make_solver
    from dlo_ros.solver.shape_solver import ShapeSolver
    from dlo_ros.solver.update import ladder, saddle
    from dlo_ros.solver.update.ipopt import LEFT_SADDLE

    sys.path.insert(0, str(ROOT / "test" / "unit"))
    from test_director_stream import path  # why here: test/unit is on the path only now

    scene = load_scene("default_cable")
    hanging = scene.problem
    down = np.array([0.0, 0.0, 0.32])
    lowered = hanging.with_grip_poses(
        {g.name: GripPose(g.pose.position - down, g.pose.orientation) for g in hanging.grips}
    )
    slots = replace(
        scene.options,
        model="full",
        order=12,
        obstacle_slots=2,
        slotted_obstacles="flat",
        obstacle_points="nodes",
    )
    start = lowered.grip("right").pose.position
    targets = {"path3d on table": [{"right": GripPose(*path(k, start))} for k in range(1, 2001)]}
    start, length = hanging.grip("right").pose.position, hanging.string.length
    radius, turn = 0.08 * length, hanging.grip("right").pose.orientation
    step = 0.01 * length / radius  # [rad] an arc of 1 % of L
    targets["ellipse"] = [
        {
            "right": GripPose(
                start + radius * np.array([np.cos(i * step) - 1, 0, np.sin(i * step)]), turn
            )
        }
        for i in range(1, 2001)
    ]
    solvers = {}
    for stream, problem in zip(STREAMS, (lowered, hanging)):
        solvers["slots 12", stream] = ShapeSolver(problem, slots, compile="blocking")
        solvers["auto", stream] = make_solver(problem, scene.options, compile="blocking")
    for solver in solvers.values():
        assert solver.solve().ok
    escapes = Escapes(ladder.leave_saddle)
    ladder.leave_saddle = escapes  # type: ignore[assignment]  # ladder calls it by this name
    # the escape's polish: Newton from the point its shifted steps reached (either tree's)
    polish = Clock(saddle.newton)
    saddle.newton = polish  # type: ignore[assignment]
    print(json.dumps({"file": __import__("dlo_ros").__file__}), flush=True)
    for line in sys.stdin:
        name, stream, first, count = json.loads(line)
        solver, snaps = solvers[name, stream], []
        for k, target in enumerate(targets[stream][first : first + count]):
            escapes.reset()
            polish.seconds = 0.0
            t0 = time.perf_counter()
            result = solver.solve(target)
            dt = time.perf_counter() - t0
            if escapes.calls:
                snaps.append(
                    {
                        "update": first + k,
                        "ms": dt * 1e3,
                        "escape_ms": escapes.seconds * 1e3,
                        "steps_ms": (escapes.seconds - polish.seconds) * 1e3,
                        "calls": escapes.calls,
                        "left": LEFT_SADDLE in result.message,
                        "status": result.status,
                        "z": escapes.z,
                    }
                )
        print(json.dumps(snaps), flush=True)


def summary(snaps: list[dict]) -> str:
    """Return a table row's cells: count, left, median, max, escape share, escape median, its
    shifted steps' median."""
    if not snaps:
        return "0 | 0 | – | – | – | – | –"
    ms = np.array([s["ms"] for s in snaps])
    esc = np.array([s["escape_ms"] for s in snaps])
    steps = np.array([s["steps_ms"] for s in snaps])
    left = sum(s["left"] for s in snaps)
    return (
        f"{len(snaps)} | {left} | {np.median(ms):.2f} | {ms.max():.2f} | "
        f"{esc.sum() / ms.sum():.0%} | {np.median(esc):.2f} | {np.median(steps):.2f}"
    )


def escape_gap(a: list[dict], b: list[dict]) -> tuple[float, int]:
    """Return (largest |Δz| between the columns' escapes, updates whose escapes do not pair)."""
    worst, unpaired = 0.0, 0
    by_update = {s["update"]: s for s in b}
    for s in a:
        t = by_update.pop(s["update"], None)
        if t is None or len(t["z"]) != len(s["z"]):
            unpaired += 1
            continue
        for (ok_a, za), (ok_b, zb) in zip(s["z"], t["z"]):
            if ok_a != ok_b:
                unpaired += 1
            elif ok_a:
                worst = max(worst, float(np.max(np.abs(np.subtract(za, zb)))))
    return worst, unpaired + len(by_update)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--before", default="", help="git revision to compare with (none: this tree)")
    ap.add_argument("--out", default="bench/results/snap_through.md")
    ap.add_argument("--worker", action="store_true")
    args = ap.parse_args()
    if args.worker:
        worker()
        return
    sys.path.insert(0, str(ROOT))
    from bench.before_after import ask, extract, revision, start
    from bench.common import machine, write_report

    info = machine()
    columns = ("before", "after") if args.before else ("after",)
    before_rev = revision(args.before)[1] if args.before else ""
    keys = [(name, stream) for stream in STREAMS for name in SOLVERS]
    snaps: dict[tuple, list[dict]] = {(c, *k): [] for c in columns for k in keys}
    piece = args.updates // args.rounds
    with tempfile.TemporaryDirectory() as tmp:
        procs = {"after": start(__file__, str(ROOT), [])}
        if args.before:
            extract(revision(args.before)[0], tmp)
            procs["before"] = start(__file__, tmp, [])
        for r in range(args.rounds):
            for key in keys:
                for column in columns if r % 2 == 0 else columns[::-1]:
                    snaps[(column, *key)] += ask(procs[column], [*key, r * piece, piece])
        for proc in procs.values():
            assert proc.stdin is not None
            proc.stdin.close()
            proc.wait()
    count = piece * args.rounds
    lines = [
        "# Snap-through updates of the cable on its table (#38)",
        "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other work), "
        f"Python {info.get('python')}, load average {info['load_average'][0]:.2f} at the start; "
        f"git {info.get('git', '?')}"
        + (f" (after) against {before_rev} (before)" if args.before else "")
        + ".",
        "",
        f"`default_cable`, {count} warm updates of the right grip per stream"
        + (f", in {args.rounds} interleaved rounds" if args.before else "")
        + ", compiled derivatives: 'path3d on table', lying on its table (both grips lowered "
        "0.32 m), along the closed 3D path of test/unit/test_director_stream.py; 'ellipse', "
        "hanging, around solver_speed.py's ellipse in its plane (the sag touches the table once "
        "a lap).  A snap-through update: its warm Newton answer was a saddle, "
        "left by shifted Newton steps (`saddle.leave_saddle`); 'left': the update's answer is "
        "that escape's.  Times are wall times of `solve` [ms]; 'escape share': the part of those "
        "updates' time inside `leave_saddle`; 'steps': its shifted steps alone (less the polish "
        "by `newton`).",
        "",
        "| stream | solver | column | snap-through updates | left | median | max | escape share "
        "| escape median | steps median |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key in keys:
        for column in columns:
            lines.append(f"| {key[1]} | {key[0]} | {column} | {summary(snaps[(column, *key)])} |")
    if args.before:
        lines += ["", "After against before:", ""]
        for key in keys:
            a, b = snaps[("before", *key)], snaps[("after", *key)]
            worst, unpaired = escape_gap(a, b)
            ratio, esc, steps = (
                [
                    np.median([s[k] for s in b]) / np.median([s[k] for s in a])
                    for k in ("ms", "escape_ms", "steps_ms")
                ]
                if a and b
                else [float("nan")] * 3
            )
            lines.append(
                f"* {key[1]}, {key[0]}: median time of a snap-through update after / before = "
                f"{ratio:.3f}, of its escape {esc:.3f}, of the shifted steps {steps:.3f}; "
                f"largest difference of an escape's final z (scaled) {worst:.3g}; escapes that "
                f"do not pair (another update, count or verdict): {unpaired}"
            )
    argv = [f"--updates {args.updates}", f"--rounds {args.rounds}"]
    if args.before:
        argv.append(f"--before {before_rev}")
    write_report(lines, args.out, "bench/perf/snap_through.py", [*argv, f"--out {args.out}"])


if __name__ == "__main__":
    main()
