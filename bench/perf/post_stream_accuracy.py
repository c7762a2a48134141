"""The main job's manoeuvre on the post, every update against the exact reference (#37).

The demo's targets (``dlo_ros.node.demo``, 50 Hz) streamed in-process under ``model: auto`` at
δ = 1 mm from target ``--first`` to the last, then held 30 updates; checks inline (``checks:
sync``, the same answers as the node's background checks), compile off, no update time limit.  At
every update that presses on the post: the centreline's true error against the exact reference
(test/unit/test_post_last_pose.py: shooting of the Kirchhoff rod with one point force at an exact
tangential contact, started from the answer's own contact), the estimate the answer reports (of
the shape its latest check measured) and the unknowns.  Two ways of holding the post's contact,
side by side in one run:

* ``points`` (auto's now): a contact slot on the sphere (``solver.slotted_obstacles: points``),
  a slot inside an element bounded by a mesh with a breakpoint moved onto it;
* ``rows`` (auto's before): the obstacle rows on the mesh nodes (the scene's ``obstacle_slots:
  2`` with ``slotted_obstacles: flat``: slots on the table only).

Run: bash scripts/dlo-env run python bench/perf/post_stream_accuracy.py [--first 380] [--out FILE]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # as a script: `bench` importable
sys.path.insert(0, str(ROOT / "test"))  # the references
sys.path.insert(0, str(ROOT / "test" / "unit"))  # the case

from bench.common import machine, write_report  # noqa: E402
import test_post_last_pose as post  # noqa: E402

from dlo_ros.solver.auto import make_solver  # noqa: E402

TOLERANCE = 1e-3
HOLD = 30
WAYS = {"points": {}, "rows": {"obstacle_slots": 2, "slotted_obstacles": "flat"}}


def stream(way: str, first: int) -> list[tuple[int, float, float | None, int, float]]:
    """(target, true error [m], reported estimate [m], unknowns, update [ms]) on the post."""
    options = replace(
        post.scene().options, model="auto", error_tolerance=TOLERANCE,
        output_points=post.POINTS, update_time_limit=0.0, **WAYS[way],
    )  # fmt: skip
    solver = make_solver(post.problem_at(first), options, compile="off", checks="sync")
    solver.solve()
    sphere = [o.type for o in post.problem_at(first).obstacles].index("sphere")
    out = []
    try:
        for k in list(range(first + 1, post.LAST + 1)) + [post.LAST] * HOLD:
            t0 = time.perf_counter()
            r = solver.solve(post.targets(k))
            ms = 1e3 * (time.perf_counter() - t0)
            loads = [c for c in r.contact_loads if c.obstacle == sphere]
            if not any(np.linalg.norm(c.force) > 1e-3 for c in loads):
                continue
            try:
                error = post.Reference(post.problem_at(k), r).error(r)
            except (AssertionError, ValueError):  # the reference's checks refuse a match
                error = float("nan")
            out.append((k, error, r.model.estimated_error_m, r.model.variables, ms))
    finally:
        solver.close()
    return out


def summary(way: str, rows) -> str:
    """One table row: how many updates on the post are within δ, and the errors' spread."""
    e = np.array([r[1] for r in rows])
    known = e[np.isfinite(e)]
    within = int(np.sum(known <= TOLERANCE))
    est = [r[2] for r in rows]
    unknown = sum(1 for x in est if x is None)
    return (
        f"| {way} | {len(rows)} | {within} | {int(np.sum(known > TOLERANCE))} | "
        f"{len(e) - known.size} | {np.median(known):.2e} | {np.max(known):.2e} | {unknown} | "
        f"{min(r[3] for r in rows)}–{max(r[3] for r in rows)} | "
        f"{max(r[4] for r in rows):.0f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first", type=int, default=380, help="the first target (solved cold)")
    parser.add_argument("--out", default="bench/results/post_stream_accuracy.md")
    args = parser.parse_args()
    results = {way: stream(way, args.first) for way in WAYS}
    info = machine()
    lines = [
        "# The main job's manoeuvre on the post: every update against the exact reference",
        "",
        f"Machine: {platform.machine()}, {info['cpus']} CPUs ({info.get('cpu', '?')}), Python "
        f"{info['python']}, git {info.get('git', '?')}, {time.strftime('%Y-%m-%d %H:%M')}.  "
        f"auto at δ = {TOLERANCE:g} m, targets {args.first}…{post.LAST} then held {HOLD} "
        "updates, checks inline, compile off (bench/perf/post_stream_accuracy.py docstring).",
        "",
        "| post's contact | updates on the post | within δ | over δ | not matched by the "
        "reference | median true error [m] | max true error [m] | estimates unknown | "
        "unknowns | slowest update [ms] |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *(summary(way, rows) for way, rows in results.items()),
        "",
        "Per update (target, true error, reported estimate):",
        "",
    ]
    for way, rows in results.items():
        cells = [
            f"{k} {e:.1e}/{'–' if est is None else f'{est:.1e}'}" for k, e, est, _, _ in rows
        ]
        lines += [f"* {way}: " + ", ".join(cells), ""]
    write_report(lines, args.out, "bench/perf/post_stream_accuracy.py", [])


if __name__ == "__main__":
    main()
