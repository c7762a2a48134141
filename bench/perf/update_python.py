"""The Python around one warm update (#38): before against after, same targets, same run.

`default_cable`, the right grip along the closed 3D path of test/unit/test_director_stream.py
(translation, yaw, pitch, ±1.2 rad of twist; ``--updates`` of its 2,000 steps), compiled
derivatives, two fixed models:

* ``full 12``: ``ShapeSolver(problem, replace(options, model='full', order=12),
  compile='blocking')``, no obstacle slots;
* ``slots 12``: the model ``solver.model: auto`` streams on for this scene (its options as auto
  leaves them: 3D order 12 on one element, the table in the NLP at the mesh's nodes with 2
  contact slots, ``slotted_obstacles: flat``), built as a fixed model (bench/perf/auto_vs_full.py's
  "fixed, same mesh").

Each model is streamed hanging (as the scene is) and lying on its table (both grips lowered
0.32 m, as the test does).  Columns: before (the ``dlo_ros`` of git revision ``--before``, default
``git merge-base main HEAD``, extracted with ``git archive`` into a temporary folder, in a worker
process of its own) and after (this tree, another process), in ``--rounds`` interleaved pieces so
that the machine's drift falls on both alike.  Per update: the wall time around ``solver.solve``
[ms] and its Python part, that time less the time inside the compiled loops' C calls (their
``_run`` wrapped with a clock).  Every result field of both columns is compared (numbers within
1e-12 absolute, strings equal; the solve time left out).

    bash scripts/dlo-env run python bench/perf/update_python.py [--updates 2000] [--rounds 8]
                                          [--before REV] [--out bench/results/update_python.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
MODELS = ("full 12", "slots 12")
STREAMS = ("hanging", "on the table")


class Clocked:
    """A compiled loop's C entry point with the seconds spent in it added up."""

    def __init__(self, run) -> None:
        self.run, self.seconds = run, 0.0

    def __call__(self, *args):
        t0 = time.perf_counter()
        out = self.run(*args)
        self.seconds += time.perf_counter() - t0
        return out


def flatten(value, name: str, numbers: list[float], strings: list[str]) -> None:
    """Append every number and string of a result (recursively) to ``numbers`` and ``strings``."""
    if "time" in name:
        return
    if dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            flatten(getattr(value, f.name), f.name, numbers, strings)
    elif isinstance(value, dict):
        for key in sorted(value, key=str):
            strings.append(str(key))
            flatten(value[key], str(key), numbers, strings)
    elif isinstance(value, (list, tuple)):
        strings.append(f"{name}:{len(value)}")
        for item in value:
            flatten(item, name, numbers, strings)
    elif isinstance(value, np.ndarray):
        strings.append(f"{name}:{value.shape}")
        numbers.extend(np.asarray(value, dtype=float).ravel().tolist())
    elif isinstance(value, (bool, int, float, np.floating, np.integer)):
        numbers.append(float(value))
    elif value is None:
        strings.append(f"{name}:None")
    else:
        strings.append(f"{name}:{value}")


def worker() -> None:
    """Serve rounds over stdin/stdout: [model, stream, first, count] → times and result fields."""
    from dataclasses import replace

    from dlo_ros.model.problem import GripPose
    from dlo_ros.scene import load_scene
    from dlo_ros.solver.shape_solver import ShapeSolver

    sys.path.insert(0, str(ROOT / "test" / "unit"))
    from test_director_stream import path

    scene = load_scene("default_cable")
    problem, options = scene.problem, scene.options
    down = np.array([0.0, 0.0, 0.32])
    lowered = problem.with_grip_poses(
        {g.name: GripPose(g.pose.position - down, g.pose.orientation) for g in problem.grips}
    )
    opts = {
        "full 12": replace(options, model="full", order=12),
        "slots 12": replace(
            options,
            model="full",
            order=12,
            obstacle_slots=2,
            slotted_obstacles="flat",
            obstacle_points="nodes",
        ),
    }
    solvers, targets, clocks = {}, {}, {}
    for stream, prob in zip(STREAMS, (problem, lowered)):
        start = prob.grip("right").pose.position
        targets[stream] = [{"right": GripPose(*path(k, start))} for k in range(1, 2001)]
        for model in MODELS:
            solver = ShapeSolver(prob, opts[model], compile="blocking")
            assert solver.solve().ok and solver.functions.newton_native is not None
            loops = [solver.functions.newton_native, solver.functions.newton_active]
            clocks[model, stream] = [Clocked(loop._run) for loop in loops if loop is not None]
            for loop, clock in zip((x for x in loops if x is not None), clocks[model, stream]):
                loop._run = clock
            solvers[model, stream] = solver
    print(json.dumps({"file": __import__("dlo_ros").__file__}), flush=True)
    for line in sys.stdin:
        model, stream, first, count = json.loads(line)
        solver, clock = solvers[model, stream], clocks[model, stream]
        times, python, newton, numbers, strings = [], [], 0, [], []
        for target in targets[stream][first : first + count]:
            c0 = sum(c.seconds for c in clock)
            t0 = time.perf_counter()
            result = solver.solve(target)
            dt = time.perf_counter() - t0
            times.append(dt * 1e3)
            python.append((dt - (sum(c.seconds for c in clock) - c0)) * 1e3)
            newton += result.ipopt_status == "Newton"
            flatten(result, "result", numbers, strings)
        print(
            json.dumps(
                {
                    "times": times,
                    "python": python,
                    "newton": newton,
                    "numbers": numbers,
                    "strings": strings,
                }
            ),
            flush=True,
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--before", default="", help="git revision (default: merge-base main HEAD)")
    ap.add_argument("--out", default="bench/results/update_python.md")
    ap.add_argument("--worker", action="store_true")
    args = ap.parse_args()
    if args.worker:
        worker()
        return
    sys.path.insert(0, str(ROOT))
    from bench.before_after import ask, extract, revision, start
    from bench.common import machine, write_report

    info = machine()
    args.before, before_rev = revision(args.before)
    columns = ("before", "after")
    keys = [(m, s) for s in STREAMS for m in MODELS]
    times = {(c, *k): [] for c in columns for k in keys}
    python = {(c, *k): [] for c in columns for k in keys}
    newton = dict.fromkeys(times, 0)
    worst, differing = dict.fromkeys(keys, 0.0), dict.fromkeys(keys, 0)
    with tempfile.TemporaryDirectory() as tmp:
        extract(args.before, tmp)
        procs = {"before": start(__file__, tmp, []), "after": start(__file__, str(ROOT), [])}
        piece = args.updates // args.rounds
        for r in range(args.rounds):
            for key in keys:
                got = {}
                for column in columns if r % 2 == 0 else columns[::-1]:
                    got[column] = ask(procs[column], [*key, r * piece, piece])
                    times[(column, *key)] += got[column]["times"]
                    python[(column, *key)] += got[column]["python"]
                    newton[(column, *key)] += got[column]["newton"]
                a, b = got["before"], got["after"]
                differing[key] += a["strings"] != b["strings"]
                na, nb = np.array(a["numbers"]), np.array(b["numbers"])
                if na.shape != nb.shape:
                    differing[key] += 1
                else:
                    same = (na == nb) | (np.isnan(na) & np.isnan(nb))
                    gap = np.abs(np.where(same, 0.0, na) - np.where(same, 0.0, nb))
                    worst[key] = max(worst[key], float(np.max(gap, initial=0.0)))
        for proc in procs.values():
            assert proc.stdin is not None
            proc.stdin.close()
            proc.wait()
    count = piece * args.rounds
    lines = [
        "# The Python around one warm update (#38): before against after",
        "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other work), "
        f"Python {info.get('python')}, load average {info['load_average'][0]:.2f} at the start; "
        f"git {info.get('git', '?')} (after) against {before_rev} (before).",
        "",
        f"`default_cable`, compiled derivatives, {count} warm updates of the right grip along the "
        f"closed 3D path of test/unit/test_director_stream.py, in {args.rounds} interleaved "
        "rounds.  Wall time of each `solve` [ms], and its Python part (less the time in the "
        "compiled loops' C calls).  'full 12': the fixed 3D model at order 12; 'slots 12': the "
        "model `solver.model: auto` streams on (order 12, the table's rows at the nodes, 2 "
        "contact slots).",
        "",
        "| model | stream | column | Newton updates | median | p99 | Python median | Python p99 "
        "| median / before | Python median / before |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key in keys:
        base = np.median(times[("before", *key)]), np.median(python[("before", *key)])
        for column in columns:
            t, py = np.array(times[(column, *key)]), np.array(python[(column, *key)])
            lines.append(
                f"| {key[0]} | {key[1]} | {column} | {newton[(column, *key)]}/{count} | "
                f"{np.median(t):.3f} | {np.percentile(t, 99):.3f} | {np.median(py):.3f} | "
                f"{np.percentile(py, 99):.3f} | {np.median(t) / base[0]:.3f} | "
                f"{np.median(py) / base[1]:.3f} |"
            )
    lines += ["", "Results before against after (every field but the solve time):", ""]
    for key in keys:
        lines.append(
            f"* {key[0]}, {key[1]}: largest difference of a number {worst[key]:.3g}; "
            f"rounds whose strings or shapes differ: {differing[key]}/{args.rounds}"
        )
    lines += [
        "",
        f"p99 is among the {max(1, count // 100)} slowest of {count} updates (IPOPT's updates "
        "and the shared machine's outliers); the Python part shows in the medians.",
    ]
    argv = [f"--updates {args.updates}", f"--rounds {args.rounds}", f"--before {before_rev}"]
    write_report(lines, args.out, "bench/perf/update_python.py", [*argv, f"--out {args.out}"])


if __name__ == "__main__":
    main()
