"""The default against the tolerance asked for (#37): unknowns, elements, time and true error.

For each case of test/unit/test_tolerance_sweep.py (exact or independent references) and each
tolerance δ in 1e-3 … 1e-6 L, a cold solve under ``solver.model: auto`` (checks inline, as the
CLI), beside fixed models at order 16 (the 3D director model, and where the scene is planar the
single-polynomial planar model).  Times are wall-clock on this machine (compile off), one solve
each after a warm-up of the same case: compare them within a table, not across machines.

Run: bash scripts/dlo-env run python bench/perf/tolerance_sweep.py [--out FILE]
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "test"))  # the references
sys.path.insert(0, str(ROOT / "test" / "unit"))  # the cases

from test_tolerance_sweep import CASES, S  # noqa: E402

from dlo_ros.solver.auto import make_solver  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402

TOLERANCES = (1e-3, 1e-4, 1e-5, 1e-6)


def timed(make):
    """Return (result, seconds) of one cold solve built and run by ``make()``."""
    t0 = time.perf_counter()
    solver = make()
    result = solver.solve()
    seconds = time.perf_counter() - t0
    close = getattr(solver, "close", None)
    if close is not None:
        close()
    return result, seconds


def auto_row(name: str, problem, error, tolerance: float) -> str:
    options = SolverOptions(error_tolerance=tolerance, output_points=len(S))
    r, seconds = timed(lambda: make_solver(problem, options, compile="off", checks="sync"))
    m = r.model
    elements = m.elements if m.elements is not None else "-"
    return (
        f"| {name} | {tolerance:g} | auto ({'planar' if m.planar else '3D'}) | {r.status} | "
        f"{m.tolerance_met} | {m.variables} | {elements} | {seconds * 1e3:.0f} | "
        f"{error(r):.1e} | {m.estimated_error_m:.1e} |"
    )


def fixed_row(name: str, problem, error, model: str, basis: str) -> str:
    options = SolverOptions(model=model, basis=basis, order=16, output_points=len(S))
    try:
        r, seconds = timed(lambda: ShapeSolver(problem, options, compile="off"))
    except ValueError as exc:  # a planar model of a scene that is not planar
        return f"| {name} | - | {model} {basis} 16 | refused: {exc} | | | | | | |"
    m = r.model
    elements = m.elements if m.elements is not None else "-"
    return (
        f"| {name} | - | {model} {basis} 16 | {r.status} | - | {m.variables} | {elements} | "
        f"{seconds * 1e3:.0f} | {error(r):.1e} | - |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "tolerance_sweep.md"))
    args = parser.parse_args()
    git = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    lines = [
        "# The default against the tolerance asked for (#37)",
        "",
        f"Machine: {platform.machine()}, {platform.python_version()}, git {git}, "
        f"{time.strftime('%Y-%m-%d %H:%M')}. Cold solves, compile off, auto with inline checks. "
        "Error: max centreline distance from the exact or independent answer "
        "(test/unit/test_tolerance_sweep.py). Time includes building the models.",
        "",
        "| case | δ / L | model | status | tolerance met | unknowns | elements | time [ms] | "
        "true error [m] | estimate [m] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, make_case in CASES.items():
        problem, error = make_case()
        timed(lambda: make_solver(problem, SolverOptions(), compile="off", checks="sync"))
        for tolerance in TOLERANCES:
            lines.append(auto_row(name, problem, error, tolerance))
        lines.append(fixed_row(name, problem, error, "full", "chebyshev"))
        lines.append(fixed_row(name, problem, error, "planar", "chebyshev"))
        print("\n".join(lines[-6:]), flush=True)
    lines += ["", "Command: `bash scripts/dlo-env run python bench/perf/tolerance_sweep.py`", ""]
    Path(args.out).write_text("\n".join(lines))


if __name__ == "__main__":
    main()
