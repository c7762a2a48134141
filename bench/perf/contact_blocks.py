"""The rows' curvature as blocks: the full KKT evaluation on the main job's post, before and after.

The compiled split full KKT function (``StringNLP.kkt_split_fn``) used to hold Σ_j D_jᵀ λ_j∇²ψ_j D_j
over every row nonlinear in the positions (every sample of a curved obstacle, every contact
slot) in ∇²L; it now outputs the blocks (``assembled_contact.contact_blocks``) and its callers add
those whose multiplier is not zero (``native.blocks.add_contact_part``; in C
``dlo_add_contact_part``).  This measures, in one process at the states the main job's stream
passes through on its post (updates 409–430: the landing and the slide), with the same compiled
cache:

* the compiled function alone: the layout before (the term summed inside; built here by
  switching the blocks off) against the split one;
* the call a Python path makes (``WithNodePart``: the node part, and the blocks, added in numpy);
* the rows: how many, and how many carry force.

    python bench/perf/contact_blocks.py [--repeats 300] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import datetime
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # as a script: `bench` importable
from bench.common import machine, write_report  # noqa: E402
from bench.perf.auto_vs_full import PERIOD, demo_stream  # noqa: E402

from dlo_ros.solver import make_solver  # noqa: E402
from dlo_ros.solver.build import assembled, assembled_contact  # noqa: E402
from dlo_ros.solver.build.compiled import compiled  # noqa: E402
from dlo_ros.solver.native.blocks import WithNodePart  # noqa: E402

FIRST, LAST = 409, 430  # the landing and the slide along the post
ACTIVE = 1e-8  # a multiplier above this carries force (as ``update/kkt.active_rows``)


def capture() -> tuple[object, list[list[np.ndarray]]]:
    """Stream the main job's manoeuvre under auto (compiled, checks inline) to LAST; return the
    streaming NLP and the full KKT function's arguments at each of its calls FIRST … LAST."""
    _, scene, targets = demo_stream()
    solver = make_solver(scene.problem, scene.options, compile="blocking", checks="sync")
    calls: list[list[np.ndarray]] = []
    solver.solve()
    for i, poses in enumerate(targets[: LAST + 1]):
        if i >= FIRST:
            kkt = solver.inner.functions.kkt
            split = kkt._split

            def record(*args, split=split):
                calls.append([np.array(a, copy=True) for a in args])
                return split(*args)

            kkt._split = record
            solver.solve(poses)
            kkt._split = split
        else:
            solver.solve(poses)
        time.sleep(PERIOD if i < FIRST else 0.0)
    nlp = solver.inner.nlp
    solver.close()
    return nlp, calls


def summed_layout(nlp) -> ca.Function:
    """The split function as it was: the curvature summed into ∇²L, no blocks out."""
    blocks, terms = assembled.contact_blocks, assembled_contact.group_terms
    assembled.contact_blocks = lambda kkt, groups, jt, E, n: (ca.MX(0, n), ca.MX(0, 1), ())
    assembled.group_terms = lambda kkt, groups, jt, E, n, hessian=True: terms(
        kkt, groups, jt, E, n, hessian=True
    )
    try:
        return nlp._assembled.kkt_split()[0]
    finally:
        assembled.contact_blocks, assembled.group_terms = blocks, terms


def per_call(fn, calls, repeats: int) -> float:
    """Median over the calls of the mean time [ms] of ``repeats`` evaluations of ``fn``."""
    times = []
    for args in calls:
        fn(*args)
        t0 = time.perf_counter()
        for _ in range(repeats):
            fn(*args)
        times.append((time.perf_counter() - t0) / repeats * 1e3)
    return float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=300)
    ap.add_argument("--out", default="bench/results/contact_blocks.md")
    args = ap.parse_args()
    nlp, calls = capture()
    before, _ = compiled(summed_layout(nlp))
    after, _ = compiled(nlp.kkt_split_fn)
    blocks = nlp.node_blocks
    blocks.attach_contact(nlp.contact_sizes)
    whole_before = WithNodePart(before, blocks, 3)
    whole_after = WithNodePart(after, blocks, 3, nlp.contact_sizes)
    rows = len(nlp.contact_sizes)
    carrying = [int(np.count_nonzero(c[2][nlp.n_free_rows:] > ACTIVE)) for c in calls]
    # the two give the same ∇²L
    gap = max(float(np.abs(whole_before(*c)[3] - whole_after(*c)[3]).max()) for c in calls)
    results = []
    for _ in range(3):  # alternating, so that a change of load hits both
        results.append((per_call(before, calls, args.repeats), per_call(after, calls, args.repeats),
                        per_call(whole_before, calls, args.repeats),
                        per_call(whole_after, calls, args.repeats)))
    med = np.median(np.array(results), axis=0)
    m = machine()
    lines = [
        "# The rows' curvature as blocks: the full KKT evaluation on the main job's post",
        "",
        f"Machine: {m.get('cpu')}, {m.get('cpus')} CPUs, Python {m.get('python')}; git {m.get('git')}; "
        f"{datetime.now():%Y-%m-%d %H:%M}; load average {m.get('load_average')}.",
        "",
        f"The full KKT function's {len(calls)} calls of the main job's stream at updates {FIRST}–{LAST} "
        f"(auto, compiled, checks inline: {nlp.params.size} parameters, {nlp.z_sym.shape[0]} unknowns, "
        f"{nlp.g_sym.shape[0]} rows, {rows} rows with curvature); each evaluated {args.repeats}× per "
        "round, 3 rounds, medians in ms.  Rows carrying force at those calls (after the free rows): "
        f"median {int(np.median(carrying))}, max {max(carrying)}.  Largest |∇²L| difference between "
        f"the two layouts: {gap:.1e}.",
        "",
        "| evaluation | curvature summed inside (before) | blocks, added where carrying (after) | after / before |",
        "|---|---:|---:|---:|",
        f"| compiled function alone | {med[0]:.3f} | {med[1]:.3f} | {med[1] / med[0]:.2f} |",
        f"| Python call (`WithNodePart`: node part, blocks in numpy) | {med[2]:.3f} | {med[3]:.3f} | "
        f"{med[3] / med[2]:.2f} |",
        "",
        "The compiled drivers (active-set Newton, saddle escape) add the blocks in C "
        "(`dlo_add_contact_part`), a few µs for a carrying block.",
    ]
    write_report(lines, args.out, "bench/perf/contact_blocks.py", sys.argv[1:])


if __name__ == "__main__":
    main()
