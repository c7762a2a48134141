"""Where the Python around one warm update goes (#38): each part's time per update, this tree.

The stream of bench/perf/update_python.py (``default_cable``, the right grip along the closed 3D
path of test/unit/test_director_stream.py, compiled derivatives), one model and stream per run.
Each part is timed in place by wrapping the functions that bound it with a clock (a wrapper adds
~0.5 µs to the part it wraps); the compiled loops' C calls are timed apart (their ``_run``), and a
part is its function's time less the parts timed inside it.  Medians and 90th percentiles over
``--updates`` updates after 50 warm-up ones [ms].

    bash scripts/dlo-env run python bench/perf/update_python_parts.py [--model full|slots]
                                          [--stream hanging|table] [--updates 1500]

For the slots model, its own parts too (the slot rounds' stages, each timed in place), and the
medians of the updates solved once and of those the slot rounds solved twice, apart.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

#: (label, how the part is formed from the clocks ``a``, the solve's wall time ``total``)
PARTS = (
    ("admit: the pose checks, the grips' reach", lambda a, total: a("admit")),
    ("linking: the clamps' turns", lambda a, total: a("tracker")),
    (
        "solve(): context, compile check, time limit, commit",
        lambda a, total: total - a("run_update") - a("admit") - a("tracker"),
    ),
    ("pack: the parameter vector", lambda a, total: a("pack")),
    (
        "the compiled loop's Python side (arrays in and out, outputs collected)",
        lambda a, total: a("loop") - a("C"),
    ),
    (
        "Newton stage (first step's reuse, target shift, active rows)",
        lambda a, total: a("newton_to") - a("loop") - a("converged"),
    ),
    ("converged: the rows' values, the state, the violation", lambda a, total: a("converged")),
    ("stability verdict (the inertia's; λ_min deferred)", lambda a, total: a("stability")),
    (
        "result: outputs, residual check, ShapeResult",
        lambda a, total: a("result") - a("stability"),
    ),
    ("self-pass check (the apart memo)", lambda a, total: a("self_pass")),
    (
        "pipeline and ladder (stages, slot rounds, linking check)",
        lambda a, total: (
            a("run_update")
            - a("self_pass")
            - a("pack")
            - a("newton_to")
            - a("result")
            - sum(a(label) for label in SLOT_CLOCKS)
        ),
    ),
)

#: the slots model's parts (``--model slots``), each timed in place and taken out of the
#: pipeline's part above (the placement: its time in ``slot_offset``; a first solve's ``pack``
#: that places the slots itself, where no prediction stands, counts it in pack and here)
SLOT_PARTS = (
    ("slots: predicted_slots (the first solve's slots)", "predicted"),
    ("slots: carry_slots (the start's multipliers moved)", "carry"),
    ("slots: slot_offset less its placement (the answer's slots against their minima)", "offset"),
    ("slots: the placement on the answer (minima, assign, rows of p)", "place"),
    ("slots: placed_slots (the next round's slots)", "placed"),
    ("slots: slot_motion (the drift recorded)", "motion"),
)
#: the clocks of SLOT_PARTS outside ``pack`` (``offset`` includes ``place`` here)
SLOT_CLOCKS = ("predicted", "carry", "offset", "placed", "motion")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", choices=("full", "slots"), default="full")
    ap.add_argument("--stream", choices=("hanging", "table"), default="hanging")
    ap.add_argument("--updates", type=int, default=1500)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "test" / "unit"))
    import dlo_ros.solver.native.active as NA
    import dlo_ros.solver.native.newton as NN
    import dlo_ros.solver.results.outputs as OU
    import dlo_ros.solver.results.self_pass as SP
    import dlo_ros.solver.shape_solver as SS
    import dlo_ros.solver.update.attempts as AT
    import dlo_ros.solver.update.contact_free as CF
    import dlo_ros.solver.update.ladder as LD
    import dlo_ros.solver.update.moments as MO
    import dlo_ros.solver.update.pipeline as PL
    import dlo_ros.solver.update.slot_rounds as SR
    from dlo_ros.solver.build.parameters import ProblemParameters
    from dlo_ros.model.problem import GripPose
    from dlo_ros.scene import load_scene
    from test_director_stream import path

    clocks: dict[str, float] = defaultdict(float)

    def clocked(owner, name: str, label: str) -> None:
        fn = getattr(owner, name)

        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                clocks[label] += time.perf_counter() - t0

        setattr(owner, name, timed)

    scene = load_scene("default_cable")
    problem, options = scene.problem, scene.options
    if args.stream == "table":
        down = np.array([0.0, 0.0, 0.32])
        problem = problem.with_grip_poses(
            {g.name: GripPose(g.pose.position - down, g.pose.orientation) for g in problem.grips}
        )
    opts = replace(options, model="full", order=12)
    if args.model == "slots":
        opts = replace(opts, obstacle_slots=2, slotted_obstacles="flat", obstacle_points="nodes")
    solver = SS.ShapeSolver(problem, opts, compile="blocking")
    assert solver.solve().ok
    for loop in (solver.functions.newton_native, solver.functions.newton_active):
        if loop is not None:
            clocked(loop, "_run", "C")
    clocked(SS, "admit", "admit")
    clocked(solver._turn_tracker, "advance", "tracker")
    clocked(SS, "run_update", "run_update")
    clocked(AT, "pack", "pack")
    clocked(AT, "newton_to", "newton_to")
    clocked(NN.NativeNewton, "__call__", "loop")
    clocked(NA.ActiveNewton, "__call__", "loop")
    clocked(CF, "converged", "converged")
    clocked(AT, "result", "result")
    clocked(OU, "stability_verdict", "stability")
    clocked(SP, "check", "self_pass")
    solves = [0]
    if args.model == "slots":
        for owner in (LD, MO):
            clocked(owner, "carry_slots", "carry")
        clocked(PL, "predicted_slots", "predicted")
        offset = SR.slot_offset

        def offset_clocked(*a, **k):  # the placement's time inside it kept apart
            t0, placing = time.perf_counter(), clocks["place"]
            try:
                return offset(*a, **k)
            finally:
                clocks["offset"] += time.perf_counter() - t0
                clocks["place in offset"] += clocks["place"] - placing

        SR.slot_offset = offset_clocked
        clocked(SR, "placed_slots", "placed")
        clocked(SR, "slot_motion", "motion")
        clocked(ProblemParameters, "_place_slots", "place")
        counted = PL.solve_with_moments

        def counting(*a, **k):
            solves[0] += 1
            return counted(*a, **k)

        PL.solve_with_moments = counting
    start = problem.grip("right").pose.position
    targets = [{"right": GripPose(*path(k, start))} for k in range(1, 2001)]
    for target in targets[:50]:
        solver.solve(target)
    rows = defaultdict(list)
    rounds: list[int] = []  # the solves of each update (slots model)
    for target in targets[50 : 50 + args.updates]:
        clocks.clear()
        solves[0] = 0
        t0 = time.perf_counter()
        solver.solve(target)
        total = time.perf_counter() - t0

        def a(label: str) -> float:
            return clocks.get(label, 0.0)

        for label, part in PARTS:
            rows[label].append(part(a, total))
        if args.model == "slots":
            rounds.append(solves[0])
            rows[SLOT_PARTS[2][0]].append(a("offset") - a("place in offset"))
            for label, clock in SLOT_PARTS:
                if clock != "offset":
                    rows[label].append(a(clock))
        rows["Python in all"].append(total - a("C"))
        rows["C (the compiled loop)"].append(a("C"))
    print(f"{args.model} 12, {args.stream}, {args.updates} updates: [ms]\n")
    once = np.array(rounds) == 1
    head = "| part | median | p90 |"
    if rounds:
        head += " median of the updates solved once | median of those solved twice |"
    print(head + "\n|---|---|---|" + ("---|---|" if rounds else ""))
    for label, values in rows.items():
        v = np.array(values) * 1e3
        line = f"| {label} | {np.median(v):.3f} | {np.percentile(v, 90):.3f} |"
        if rounds:
            twice = v[np.array(rounds) == 2]
            second = f"{np.median(twice):.3f}" if twice.size else "–"
            line += f" {np.median(v[once]):.3f} | {second} |"
        print(line)
    if rounds:
        counts = ", ".join(f"{k}: {rounds.count(k)}" for k in sorted(set(rounds)))
        print(f"\nsolves per update (the first and the slot rounds' repeats): {counts}")


if __name__ == "__main__":
    main()
