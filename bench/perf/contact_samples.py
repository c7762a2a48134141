"""What obstacle samples cost: the main job's cable draped over the post, at 41 to 641 samples.

    bash scripts/dlo-env run python bench/perf/contact_samples.py [--samples 41 161 641]
        [--out bench/results/contact_samples.md]

Scene: the main job's (``default_cable`` plus the sphere 'post', ``dlo_ros.node.demo``), model ``full``
(order 16), compiled derivatives.  Every obstacle is enforced at the same ``obstacle_samples`` arc
lengths, so the samples multiply the inequality rows (two obstacles: 2 × samples rows).  For each
sample count, in one process, one after another:

* the demo's manoeuvre (its keyframes, 300 targets: bring the ends together, twist, lift, carry over
  the post, lower onto it), warm-started: median and largest update, and the updates that land the
  cable on the post;
* 60 more updates that raise and lower both grips by ±1 cm while the cable lies on the post: median,
  p90, largest, and how many were answered by Newton (the rest went to IPOPT);
* one evaluation of each compiled function at the draped shape: the KKT system over every row (what
  Newton evaluates while a contact is active), the contact-free one, the inequality rows' values.

``solver.model: auto`` raises the samples when doubling them moves the shape by more than half the
tolerance (``solver/auto/auto_solver.py``); the main job's summary lists those changes.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402

from dlo_ros.model.problem import GripPose  # noqa: E402
from dlo_ros.node import demo  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import ShapeSolver  # noqa: E402

STEPS = 300
WIGGLE = 60


def keyframe_targets(steps: int) -> list[dict[str, GripPose]]:
    """The demo's keyframes, linearly interpolated at ``steps`` instants."""
    frames, total = demo.KEYFRAMES, demo.duration()
    out = []
    for k in range(1, steps + 1):
        t = total * k / steps
        i = max(j for j in range(len(frames) - 1) if frames[j][0] <= t)
        a, b = frames[i], frames[i + 1]
        f = min(1.0, (t - a[0]) / (b[0] - a[0]))
        left = np.add(a[1], f * np.subtract(b[1], a[1]))
        right = np.add(a[2], f * np.subtract(b[2], a[2]))
        twist = a[3] + f * (b[3] - a[3])
        out.append({"left": GripPose(left, np.array([0.0, 0.0, 0.0, 1.0])), "right": GripPose(right, demo._twist(twist))})
    return out


def timed(solver: ShapeSolver, targets) -> tuple[float, object]:
    t0 = time.perf_counter()
    r = solver.solve(targets)
    return (time.perf_counter() - t0) * 1e3, r


def per_call_ms(fn, *args, repeats: int = 20) -> float:
    fn(*args)
    t0 = time.perf_counter()
    for _ in range(repeats):
        fn(*args)
    return (time.perf_counter() - t0) / repeats * 1e3


def run(samples: int, scene) -> dict:
    solver = ShapeSolver(scene.problem, replace(scene.options, model="full", obstacle_samples=samples),
                         compile="blocking")
    first = solver.solve()
    path = [timed(solver, t) for t in keyframe_targets(STEPS)]
    touching = [k for k, (_, r) in enumerate(path) if np.linalg.norm(r.contact_forces.get(1, np.zeros(3))) > 0]
    final = path[-1][1]
    left, right = final.points[0], final.points[-1]
    wiggle = []
    for k in range(WIGGLE):
        dz = np.array([0.0, 0.0, 0.01 * math.sin(2 * math.pi * k / 30)])
        q_right = solver.problem.grip("right").pose.orientation
        wiggle.append(timed(solver, {"left": GripPose(left + dz, np.array([0.0, 0.0, 0.0, 1.0])),
                                     "right": GripPose(right + dz, q_right)}))
    state, nlp, fns = solver.committed_state, solver.nlp, solver.functions
    lam = state.lam_g
    path_ms = np.array([t for t, _ in path])
    wiggle_ms = np.array([t for t, _ in wiggle])
    return {
        "samples": samples, "rows": int(nlp.lbg.size), "first": first.status,
        "path_median": float(np.median(path_ms)), "path_max": float(path_ms.max()),
        "landing": [float(path_ms[k]) for k in touching[:3]],
        "wiggle_median": float(np.median(wiggle_ms)), "wiggle_p90": float(np.percentile(wiggle_ms, 90)),
        "wiggle_max": float(wiggle_ms.max()),
        "wiggle_newton": sum(r.ipopt_status == "Newton" for _, r in wiggle),
        "wiggle_ok": sum(r.ok for _, r in wiggle), "on_post": bool(touching),
        "residual": float(wiggle[-1][1].equilibrium_residual_m),
        "kkt_ms": per_call_ms(fns.kkt, state.z, state.p, lam),
        "kkt_free_ms": per_call_ms(fns.kkt_free, state.z, state.p, lam[:nlp.n_free_rows]),
        "obstacle_g_ms": per_call_ms(fns.obstacle_g, state.z, state.p),
        "compiled": solver.kkt_compiled,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, nargs="+", default=[41, 161, 641])
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "contact_samples.md"))
    args = ap.parse_args()
    scene = load_scene(str(demo.write_demo_scene(Path(tempfile.mkdtemp()))))
    rows = []
    for n in args.samples:
        rows.append(run(n, scene))
        print(rows[-1], flush=True)
    info = machine()
    lines = [
        "# Obstacle samples: what they cost with the cable draped over the post",
        "",
        f"Machine: {info.get('cpu', '?')}, {info['cpus']} CPUs, Python {info['python']}, load average "
        f"{', '.join(f'{v:.2f}' for v in info.get('load_average', ()))} at the end; git {info.get('git', '?')}.",
        "",
        f"Command: `bash scripts/dlo-env run python bench/perf/contact_samples.py --samples "
        f"{' '.join(str(n) for n in args.samples)}`",
        "",
        "Scene: the main job's (`default_cable` plus the sphere 'post'), `solver.model: full`, order 16, compiled. "
        f"The demo's keyframes as {STEPS} warm updates, then {WIGGLE} updates raising and lowering both grips by "
        "±1 cm with the cable on the post. Times are wall clock on a shared machine: compare rows as ratios.",
        "",
        "| samples | constraint rows (2 × samples are obstacle rows) | manoeuvre: median / largest update [ms] | landing on the post: first updates [ms] "
        "| on the post: median / p90 / largest [ms] | Newton answers (of the rest: IPOPT) | KKT over every row "
        "[ms per call] | contact-free KKT [ms] | rows' values [ms] |",
        "|---:|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        landing = ", ".join(f"{t:.0f}" for t in r["landing"]) or "(never touched)"
        lines.append(f"| {r['samples']} | {r['rows']} | {r['path_median']:.1f} / {r['path_max']:.0f} | {landing} | "
                     f"{r['wiggle_median']:.1f} / {r['wiggle_p90']:.1f} / {r['wiggle_max']:.0f} | "
                     f"{r['wiggle_newton']} of {WIGGLE} | {r['kkt_ms']:.2f} | {r['kkt_free_ms']:.2f} | "
                     f"{r['obstacle_g_ms']:.3f} |")
    lines += [
        "",
        "Every answer on the post was `ok` in this run: "
        + ", ".join(f"{r['samples']} samples {r['wiggle_ok']}/{WIGGLE}" for r in rows) + ".",
        "",
        "While a contact is active, each Newton step evaluates the KKT system over every row: its cost grows "
        "with the samples of every obstacle, touching or not (the Jacobian of each row is dense in the "
        "unknowns, and a curved obstacle adds its curvature at every sample to the Hessian).",
    ]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
