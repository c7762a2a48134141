"""Warm-update time of solver.model auto against full, same run, same targets (issue 6's benchmark).

Scenes: default_cable (planar cable over a table), elastica_clamped (planar strip, no gravity; its
reference is only defined up to a rotation about the chord, so its error column compares distances
from the chord axis) and a twisted 3D scene (default cable with the right clamp turned 1.5 rad about its tangent and moved out of
plane).  Each: 100 warm updates of 1 % of L on a circle; reports median and p90 times, the ratio
full/auto, and the centreline deviation of each from a full order-32 reference at the last target.

    bash scripts/dlo-env run python bench/auto_vs_full.py [--compile] [--updates 100]
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
from dataclasses import replace
from pathlib import Path

import numpy as np

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import ShapeSolver, SolverOptions, make_solver


def twisted(scene):
    p = scene.problem
    right = p.grip("right")
    q = np.array([np.sin(0.75), 0.0, 0.0, np.cos(0.75)])  # 1.5 rad about x (the tangent)
    pose = GripPose(right.pose.position + np.array([0.0, 0.1, 0.0]), q)
    return replace(scene, name="twisted_3d", problem=p.with_grip_poses({"right": pose}))


def targets(problem, updates):
    """Steps of 1 % of L around a circle of radius 0.05 L *above* the start (the cable stays off the
    table: a path that presses it onto the table makes 'auto' escalate, rightly, to a 3D model)."""
    L = problem.string.length
    start = problem.grip("right").pose.position
    r = 0.05 * L
    da = 0.01 * L / r
    return [start + np.array([-r * np.sin(i * da), 0.0, r * (1 - np.cos(i * da))]) for i in range(1, updates + 1)]


def run(solver, problem, updates):
    q = problem.grip("right").pose.orientation
    r = solver.solve()
    assert r.ok, r.message
    times = []
    for t in targets(problem, updates):
        r = solver.solve({"right": (t, q)})
        assert r.ok, r.message
        times.append(r.solve_time_ms)
    return r, times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--updates", type=int, default=100)
    ap.add_argument("--compile", action="store_true", help="compiled KKT functions (blocking compile, cached)")
    ap.add_argument("--out", default="bench/results/auto_vs_full.md")
    args = ap.parse_args()
    mode = "blocking" if args.compile else "off"
    if not args.compile:
        os.environ["DLO_NO_COMPILE"] = "1"
    rows = []
    for scene in (load_scene("default_cable"), load_scene("elastica_clamped"), twisted(load_scene("default_cable"))):
        prob = scene.problem
        auto = make_solver(prob, replace(scene.options, model="auto"), compile=mode)
        full = ShapeSolver(prob, replace(scene.options, model="full"), compile=mode)
        ra, ta = run(auto, prob, args.updates)
        rf, tf = run(full, prob, args.updates)
        last = {"right": (targets(prob, args.updates)[-1], prob.grip("right").pose.orientation)}
        ref = ShapeSolver(prob, replace(scene.options, model="full", order=32, quadrature_nodes=80), compile="off").solve(last)
        m = ra.model
        def error(res):
            if scene.problem.string.weight_per_length.is_zero:  # neutral rotation about the chord
                axis = last["right"][0] - prob.grip("left").pose.position
                axis = axis / np.linalg.norm(axis)
                def polar(pts):
                    rel = pts - prob.grip("left").pose.position
                    along = rel @ axis
                    return np.stack([along, np.linalg.norm(rel - np.outer(along, axis), axis=1)], 1)
                return np.max(np.linalg.norm(polar(res.points) - polar(ref.points), axis=1))
            return np.max(np.linalg.norm(res.points - ref.points, axis=1))

        rows.append((scene.name, m, statistics.median(ta), np.percentile(ta, 90), statistics.median(tf), np.percentile(tf, 90),
                     error(ra), error(rf), full.model.layout.size))
    lines = [
        "# solver.model auto vs full: warm updates", "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; derivatives "
        f"{'compiled (gcc -O1)' if args.compile else 'interpreted CasADi'}; {args.updates} warm updates of 1 % of L per scene.",
        "Error: max centreline deviation at the last target from a full order-32 solve.", "",
        "| scene | auto model | unknowns auto / full | auto median ms | auto p90 ms | full median ms | full p90 ms | full / auto | auto error m | full error m | auto estimate m |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, m, am, a90, fm, f90, ea, ef, nf in rows:
        kind = ", ".join(k for k in ("planar", "twist", "stretch", "gravity") if m[k]) + f", order {m['order']}"
        lines.append(f"| {name} | {kind} | {m['variables']} / {nf} | {am:.2f} | {a90:.2f} | {fm:.2f} | {f90:.2f} | "
                     f"{fm / am:.2f} | {ea:.1e} | {ef:.1e} | {m['estimated_error_m']:.1e} |")
    lines += ["", f"Command: `bash scripts/dlo-env run python bench/auto_vs_full.py{' --compile' if args.compile else ''}`", ""]
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
