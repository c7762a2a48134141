"""Contact slots against samples alone: accuracy against an independent reference, and cost per update.

    bash scripts/dlo-env run python bench/perf/contact_slots.py [--out bench/results/contact_slots.md]

Scene: a 1 m cable (Rf 0.02 N·m², 0.5 N/m) clamped level 0.6 m apart, lowered in 20 warm updates onto a
round post (r = 3 cm) off its middle, then 40 updates sliding the right grip ±2 cm along x while it
rests there; model planar (the Euler-angle model: the reference is planar), order 24, interpreted
derivatives (``compile='off'``), one process.  The reference is the shooting solution of the planar
heavy elastica touching the post at one point (``test/reference/post_contact.py``, nothing of dlo_ros),
from the final answer's reactions as its guess.  For each count of uniform samples, without slots
(``obstacle_slots: 0``) and with the default slots: the centreline's largest distance from the
reference, the post's push against the reference's, and the median and largest warm update on the
post with how many Newton answered.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable
sys.path.insert(0, str(ROOT / "test"))  # the reference

from bench.common import machine  # noqa: E402

from dlo_ros.model.problem import GripPose  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402
from unit.test_obstacle_slots import HEIGHT, LEVEL, lowered, post_scene, reference_for, deviation  # noqa: E402

CONFIGS = [(41, 0), (81, 0), (161, 0), (321, 0), (21, 2), (41, 2), (81, 2)]


def run(samples: int, slots: int) -> dict:
    sc = post_scene(slots)
    options = SolverOptions(**{**sc.options.__dict__, "obstacle_samples": samples})
    solver = ShapeSolver(sc.problem, options, compile="off")
    lowered(solver)
    times, newton = [], 0
    for k in range(40):
        x = 0.6 + 0.02 * np.sin(2 * np.pi * k / 40)
        t0 = time.perf_counter()
        r = solver.solve({"right": GripPose(np.array([x, 0.0, HEIGHT]), LEVEL)})
        times.append((time.perf_counter() - t0) * 1e3)
        newton += r.ipopt_status == "Newton"
    final = solver.solve({"right": GripPose(np.array([0.6, 0.0, HEIGHT]), LEVEL)})
    ref = reference_for(final)
    push = float(np.linalg.norm(final.contact_forces[0]))
    return {"samples": samples, "slots": slots, "error_mm": deviation(final, ref) * 1e3, "push": push,
            "push_ref": ref.push, "median": float(np.median(times)), "max": float(np.max(times)), "newton": newton,
            "rows": int(solver.nlp.lbg.size)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "contact_slots.md"))
    args = ap.parse_args()
    rows = []
    for samples, slots in CONFIGS:
        rows.append(run(samples, slots))
        print(rows[-1], flush=True)
    info = machine()
    lines = [
        "# Contact slots against samples alone: a cable resting on a post",
        "",
        f"Machine: {info.get('cpu', '?')}, {info['cpus']} CPUs, Python {info['python']}; git {info.get('git', '?')}.",
        "",
        "Command: `bash scripts/dlo-env run python bench/perf/contact_slots.py`",
        "",
        "Scene and method: the module docstring of `bench/perf/contact_slots.py` (planar model, order 24, "
        "interpreted). Error: the largest distance of the centreline from the shooting reference. Times are "
        "wall clock on a shared machine: compare rows as ratios.",
        "",
        "| samples | slots | rows | centreline error [mm] | push [N] (reference) | on the post: median / largest update [ms] | Newton answers |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['samples']} | {r['slots']} | {r['rows']} | {r['error_mm']:.3f} | {r['push']:.4f} ({r['push_ref']:.4f}) "
                     f"| {r['median']:.1f} / {r['max']:.0f} | {r['newton']} of 40 |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
