"""Twist-free frames of the tangent models: the step loop before, the prefix product now.

``model/transport.transported_frames`` carries d1 along the tangents by the smallest rotation
between neighbours.  It used to take one step at a time (a Python loop of small numpy calls); it
now forms every rotation from the start point at once, as a prefix product of the steps'
quaternions.  This times both on the grid ``pose_frames`` uses (4·max(n, 16) + 1 tangents for n
output points) along a helix, and the result frames of the paper's Fig. 2 under the default
(``paper_fig2_transition``: clamp and tangent grip, twist free: the tangent model).

    python bench/perf/transport_frames.py [--repeats 30] [--out FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from datetime import datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # as a script: `bench` importable
from bench.common import machine, write_report  # noqa: E402

from dlo_ros.model import director  # noqa: E402
from dlo_ros.model.rotations import cross3  # noqa: E402
from dlo_ros.model.transport import transported_frames  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import make_solver  # noqa: E402

OUTPUT_POINTS = (51, 101, 401)


def loop_frames(t: np.ndarray, k0: int, hint: np.ndarray) -> np.ndarray:
    """The implementation before (git 799fa13): one step at a time, both ways from k0."""
    d1s = np.empty_like(t)
    d1 = hint - np.dot(hint, t[k0]) * t[k0]
    d1s[k0] = d1 / np.linalg.norm(d1)
    for rng in (range(k0 + 1, len(t)), range(k0 - 1, -1, -1)):
        prev = k0
        for k in rng:
            v, t0, t1 = d1s[prev], t[prev], t[k]
            c = float(np.dot(t0, t1))
            axis = cross3(t0, t1)
            turned = v * c + cross3(axis, v) + axis * np.dot(axis, v) / (1 + c)
            step = v if c < -0.999999 else turned
            d1s[k] = step / np.linalg.norm(step)
            prev = k
    return np.stack([t, d1s, cross3(t, d1s)], axis=-1)


def best_of(fn, repeats: int) -> float:
    """The fastest of ``repeats`` calls [ms] (the least disturbed on a shared machine)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--out", default="bench/results/transport_frames.md")
    args = ap.parse_args(argv)
    rows = []
    for n in OUTPUT_POINTS:
        k = 4 * max(n, 16) + 1
        phi = np.linspace(0.0, 6.0, k)
        t = np.stack([-np.sin(phi), np.cos(phi), np.full(k, 0.3)], axis=1)
        t /= np.linalg.norm(t, axis=1)[:, None]
        hint = np.array([0.0, 0.0, 1.0])
        diff = float(np.abs(loop_frames(t, 0, hint) - transported_frames(t, 0, hint)).max())
        before = best_of(lambda: loop_frames(t, 0, hint), args.repeats)
        now = best_of(lambda: transported_frames(t, 0, hint), args.repeats)
        rows.append((n, k, before, now, diff))
    scene = load_scene("paper_fig2_transition")
    fig2 = []
    for n in OUTPUT_POINTS:
        auto = make_solver(scene.problem, replace(scene.options, output_points=n), compile="off")
        result = auto.solve()
        solver = auto.inner  # the model the default ended on
        z = solver.snapshot().z
        now = best_of(lambda: solver.pose_frames(z, result.s), args.repeats)
        director.transported_frames = loop_frames
        try:
            before = best_of(lambda: solver.pose_frames(z, result.s), args.repeats)
        finally:
            director.transported_frames = transported_frames
        fig2.append((n, result.status, before, now))
        auto.close()
    info = machine()
    lines = [
        "# Twist-free frames of the tangent models: the step loop before, the prefix product now",
        "",
        f"Machine: {info.get('cpu')}, {info.get('cpus')} cores, Python {info.get('python')}; "
        f"git {info.get('git')}; written {datetime.now():%Y-%m-%d %H:%M}.",
        "",
        "`transported_frames` along a helix on the grid `pose_frames` uses for n output points; "
        f"fastest of {args.repeats} calls.",
        "",
        "| output points | tangents | loop before [ms] | prefix product [ms] | before / now "
        "| largest difference |",
        "|---:|---:|---:|---:|---:|---:|",
        *(
            f"| {n} | {k} | {b:.2f} | {a:.3f} | {b / a:.0f}× | {d:.1e} |"
            for n, k, b, a, d in rows
        ),
        "",
        "The frames of the default's answer on the paper's Fig. 2 (`paper_fig2_transition`: "
        "a clamp and a tangent grip, the tangent model, on the mesh it ends on): `pose_frames` "
        "at the result's output points, as its orientations are worked out; before: the loop "
        "put back.",
        "",
        "| output points | status | loop before [ms] | prefix product [ms] | before / now |",
        "|---:|---|---:|---:|---:|",
        *(f"| {n} | {st} | {b:.2f} | {a:.2f} | {b / a:.0f}× |" for n, st, b, a in fig2),
    ]
    write_report(lines, args.out, "bench/perf/transport_frames.py", argv or sys.argv[1:])


if __name__ == "__main__":
    main()
