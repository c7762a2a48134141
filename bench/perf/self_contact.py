"""The cost of self-contact (issue #15).

    bash scripts/dlo-env run python bench/perf/self_contact.py      # writes bench/results/self_contact.md
    bash scripts/dlo-env run python bench/perf/self_contact.py --far-only   # part 1 only, printed

1. A stream that never comes near itself: the paper's Fig. 2 set-up (test/unit/test_fig2_reference.py, radius
   0.01 L) from chord 0.9 L down to 0.6 L in steps of 0.005 L (planar, stable, the loop open), ``model:
   full`` order 16, with ``self_contact_pairs`` 16 and 0.  Per-update wall time (median and total over
   the warm updates of each update's fastest of 5 interleaved runs); the ratio is the cost of self-contact.
2. The Fig. 2 loop stream: 0.5 L down to 0.2 L in steps of 0.01 L with self-contact, ``model: full``
   order 16, and ``model: auto`` (checks 'sync', default tolerance 1e-3 L) with the order it chose:
   per-update time, contacts, closest approach of two strands.
Derivatives interpreted (compile 'off') in both, so the ratio compares like with like.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "test" / "unit"))  # test modules the bench reuses (references, set-ups)
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402
from support.problems import clamped_pair  # noqa: E402

from dlo_ros.solver.auto import AutoShapeSolver  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402

L, R = 1.0, 0.01
STRAIGHT = (0.0, 0.0, 0.0, 1.0)


def fig2(c: float):
    p = clamped_pair(right=(c, 0.0, 0.0), bend=1.0, twist=0.01, modes=("clamp", "tangent"))
    return replace(p, string=replace(p.string, radius=R))


def stream(solver, chords) -> tuple[list[float], list]:
    times, results = [], []
    for c in chords:
        t0 = time.perf_counter()
        r = solver.solve({"right": ((c, 0.0, 0.0), STRAIGHT)})
        times.append(time.perf_counter() - t0)
        results.append(r)
    return times, results


def far_stream(runs: int = 5) -> list[str]:
    """Each update's time is the smallest over ``runs`` interleaved repetitions of the stream (the machine is
    shared: the minimum drops other processes' interruptions), then the median and total over updates."""
    chords = np.round(np.arange(0.895, 0.6 - 1e-9, -0.005), 10)
    solvers = {pairs: ShapeSolver(fig2(0.9), SolverOptions(model="full", order=16, self_contact_pairs=pairs),
                                  compile="off") for pairs in (0, 16)}
    best = {pairs: np.full(len(chords), np.inf) for pairs in solvers}
    for _ in range(runs):
        for pairs, sol in solvers.items():
            sol.reset()
            assert sol.solve({"right": ((0.9, 0.0, 0.0), STRAIGHT)}).ok
            times, results = stream(sol, chords)
            assert all(r.ok for r in results) and not any(r.self_contacts for r in results)
            best[pairs] = np.minimum(best[pairs], times)
    (m0, t0), (m1, t1) = ((float(np.median(best[k])), float(np.sum(best[k]))) for k in (0, 16))
    return ["## 1. A stream that never comes near itself (Fig. 2, 0.9 L → 0.6 L, 60 warm updates, order 16)", "",
            f"Each update's time: the smallest of {runs} interleaved repetitions.", "",
            "| self_contact_pairs | median per update [ms] | total [ms] |", "|---|---|---|",
            f"| 0 | {m0 * 1e3:.2f} | {t0 * 1e3:.1f} |", f"| 16 | {m1 * 1e3:.2f} | {t1 * 1e3:.1f} |", "",
            f"Ratio with / without self-contact: median {m1 / m0:.3f}×, total {t1 / t0:.3f}× (target ≤ 1.1×).", ""]


def loop_rows(name: str, chords, times, results) -> list[str]:
    rows = [f"### {name}", "", "| chord [L] | status | stable | order | contacts | closest approach [m] | time [ms] |",
            "|---|---|---|---|---|---|---|"]
    for c, t, r in zip(chords, times, results):
        d = r.min_self_distance
        rows.append(f"| {c:.2f} | {r.status} | {r.stable} | {r.model.order} | {len(r.self_contacts)} | "
                    f"{'—' if not np.isfinite(d) else f'{d:.5f}'} | {t * 1e3:.0f} |")
    return rows + [""]


def loop_stream() -> list[str]:
    chords = np.round(np.arange(0.49, 0.2 - 1e-9, -0.01), 10)
    out = ["## 2. The Fig. 2 loop stream (0.5 L → 0.2 L, steps of 0.01 L, radius 0.01 L: 2r = 0.02 m)", ""]
    sol = ShapeSolver(fig2(0.5), SolverOptions(model="full", order=16, self_contact_pairs=16), compile="off")
    assert sol.solve().ok
    times, results = stream(sol, chords)
    out += loop_rows("model: full, order 16, self_contact_pairs 16", chords, times, results)
    auto = AutoShapeSolver(fig2(0.5), SolverOptions(), compile="off", checks="sync")
    assert auto.solve().ok
    times, results = stream(auto, chords)
    out += loop_rows("model: auto (checks sync)", chords, times, results)
    out += ["auto's reasons at the end: " + "; ".join(results[-1].model.reasons), ""]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--far-only", action="store_true", help="part 1 only, printed (nothing written)")
    args = ap.parse_args()
    lines = ["# Self-contact: cost (bench/perf/self_contact.py)", "", f"Machine: {machine()}", ""]
    lines += far_stream()
    if args.far_only:
        print("\n".join(lines))
        return
    lines += loop_stream()
    out = ROOT / "bench" / "results" / "self_contact.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
