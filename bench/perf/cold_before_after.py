"""Cold solves of the default, this tree against an earlier revision, in one run (#37, #38).

The contact cases whose cold solves refine their mesh (auto's checked escalations, each pass a
Newton or IPOPT solve with the obstacle slot rounds): the paper's Fig. 3 strip on its floor
(config/scenes/bench_fig3_floor.yaml) at ρ = 1000, 2000, 3000 N/m at the default tolerance, and
at ρ = 2000 at 1e-4 L; the main job's last pose on its post at δ = 1e-3 and 1e-4 m
(test/unit/test_post_last_pose.py's cold solve).  ``make_solver`` with inline checks, compile off
(what gcc would do beside the solve is left out: the cases compare the solves themselves),
building included; ``--background 1``: the floor cases with ``make_solver``'s own checks mode, a
worker thread (as a planner or the node creates it: the first solve is checked before it
returns all the same, after the worker's start-up builds).

Each tree runs in a worker process of its own (``bench/before_after.py``: the earlier revision's
``dlo_ros`` extracted with ``git archive``), the cases in ``--rounds`` interleaved rounds, the
order alternating.  Per case: the median wall time of each tree and their ratio, the status and
unknowns of each, and the largest distance between the two trees' centrelines (the same answer,
or not).

    bash scripts/dlo-env run python bench/perf/cold_before_after.py [--before REV] [--rounds 3]
        [--background 1] [--out bench/results/cold_before_after.md]
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

#: (name, kind, ρ [N/m] or None, tolerance: a fraction of L for the floor, metres for the post)
CASES = [
    ("Fig. 3 floor ρ = 1000", "floor", 1000.0, 1e-3),
    ("Fig. 3 floor ρ = 2000", "floor", 2000.0, 1e-3),
    ("Fig. 3 floor ρ = 3000", "floor", 3000.0, 1e-3),
    ("Fig. 3 floor ρ = 2000, 1e-4 L", "floor", 2000.0, 1e-4),
    ("main job's post, 1e-3 m", "post", None, 1e-3),
    ("main job's post, 1e-4 m", "post", None, 1e-4),
]


def worker(checks: str) -> None:
    """Serve cases over stdin/stdout: a line [index] → {seconds, status, variables, points}.

    ``checks``: the floor cases' checks mode ('sync' or 'background').
    """
    from dataclasses import replace

    from dlo_ros.scene import load_scene
    from dlo_ros.scene.reading import scene_from_dict
    from dlo_ros.scene.writing import scene_to_dict
    from dlo_ros.solver.auto.factory import make_solver

    sys.path.insert(0, str(ROOT / "test"))
    sys.path.insert(0, str(ROOT / "test" / "unit"))
    import test_post_last_pose as post  # the case (its dlo_ros: the worker's own, imported above)

    def floor(rho: float, tolerance: float):
        d = scene_to_dict(load_scene("bench_fig3_floor"))
        d["string"]["weight_per_length"] = rho
        d["solver"] = {**d.get("solver", {}), "output_points": 401}
        scene = scene_from_dict(d)
        options = replace(
            scene.options, error_tolerance=tolerance * scene.problem.string.length
        )
        solver = make_solver(scene.problem, options, compile="off", checks=checks)
        try:
            return solver.solve()
        finally:
            solver.close()

    print(json.dumps({"file": __import__("dlo_ros").__file__}), flush=True)
    for line in sys.stdin:
        (index,) = json.loads(line)
        _, kind, rho, tolerance = CASES[index]
        t0 = time.perf_counter()
        result = floor(rho, tolerance) if kind == "floor" else post.solve(tolerance, "cold")
        seconds = time.perf_counter() - t0
        answer = {
            "seconds": seconds,
            "status": result.status,
            "variables": result.model.variables if result.model is not None else None,
            "met": result.model.tolerance_met if result.model is not None else None,
            "points": np.asarray(result.points).tolist() if result.points is not None else [],
        }
        print(json.dumps(answer), flush=True)


def main() -> None:
    # last on the path: a worker's dlo_ros is its tree's (PYTHONPATH), not this one's (until
    # 2026-12-08 both workers imported this tree's and every "same answer" was 0 m)
    sys.path.append(str(ROOT))
    from bench.before_after import arguments, ask, extract, revision, start
    from bench.common import machine, write_report

    args = arguments(__doc__, "bench/results/cold_before_after.md", rounds=3, background=0)
    checks = "background" if args.background else "sync"
    if args.worker:
        worker(checks)
        return
    info = machine()
    args.before, before_rev = revision(args.before)
    trees = ("before", "after")
    got: dict[tuple[str, int], list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        extract(args.before, tmp)
        flags = ["--background", str(args.background)]
        procs = {"before": start(__file__, tmp, flags), "after": start(__file__, str(ROOT), flags)}
        for r in range(args.rounds):
            for index in range(len(CASES)):
                for tree in trees if (r + index) % 2 == 0 else trees[::-1]:
                    got.setdefault((tree, index), []).append(ask(procs[tree], [index]))
                    print(tree, CASES[index][0], f"{got[(tree, index)][-1]['seconds']:.2f} s")
        for proc in procs.values():
            assert proc.stdin is not None
            proc.stdin.close()
            proc.wait()
    lines = [
        "# Cold solves of the default: this tree against an earlier one, same run",
        "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other work), "
        f"Python {info.get('python')}, load average {info['load_average'][0]:.2f} at the start; "
        f"git {info.get('git', '?')} (after) against {before_rev} (before); {args.rounds} rounds.",
        "",
        f"`make_solver(..., compile='off', checks='{checks}')` for the floor cases, the post's as "
        "test_post_last_pose.py solves it, building included; median wall time of the rounds.  "
        "Same answer: the largest distance between the two trees' centrelines (the last round's).",
        "",
        "| case | before [s] | after [s] | after / before | status before / after | "
        "unknowns before / after | tolerance met before / after | same answer [m] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for index, (name, *_) in enumerate(CASES):
        b, a = got[("before", index)], got[("after", index)]
        tb = float(np.median([x["seconds"] for x in b]))
        ta = float(np.median([x["seconds"] for x in a]))
        pb, pa = np.asarray(b[-1]["points"]), np.asarray(a[-1]["points"])
        apart = float(np.max(np.abs(pb - pa))) if pb.shape == pa.shape and pb.size else np.nan
        lines.append(
            f"| {name} | {tb:.2f} | {ta:.2f} | {ta / tb:.2f} | {b[-1]['status']} / "
            f"{a[-1]['status']} | {b[-1]['variables']} / {a[-1]['variables']} | "
            f"{b[-1]['met']} / {a[-1]['met']} | {apart:.1e} |"
        )
    argv = [f"--before {before_rev}", f"--rounds {args.rounds}", f"--background {args.background}",
            f"--out {args.out}"]
    write_report(lines, args.out, "bench/perf/cold_before_after.py", argv)


if __name__ == "__main__":
    main()
