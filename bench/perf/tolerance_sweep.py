"""The default against the tolerance asked for (#37): unknowns, elements, time and true error.

For each case of test/unit/test_tolerance_sweep.py (exact or independent references) and each
tolerance δ in 1e-3 … 1e-6 L, a cold solve under ``solver.model: auto`` (checks inline, as the
CLI), beside fixed models at order 16 (the 3D director model, and where the scene is planar the
single-polynomial planar model).  Then the cases of test_tolerance_sweep_contact.py (Greenhill past
its threshold, Fig. 2 with a radius at 0.4 and 0.3 L, the paper's sheets), cold and streamed as
that file runs them (a stream: its updates to the pose and those held there until checked), beside
the fixed director model at order 16.  Times are wall-clock on this machine (compile off), one
solve each after a warm-up of the same case: compare them within a table, not across machines.

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

import test_tolerance_sweep_contact as contact_sweep  # noqa: E402
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


def contact_row(name: str, case, tolerance: float, how: str) -> str:
    """One auto row of a test_tolerance_sweep_contact case (δ = ``tolerance`` L)."""
    t0 = time.perf_counter()
    r = contact_sweep.solve(case, tolerance, how)
    seconds = time.perf_counter() - t0
    m = r.model
    est = "-" if m.estimated_error_m is None else f"{m.estimated_error_m:.1e}"
    return (
        f"| {name} | {tolerance:g} | auto {how} ({'planar' if m.planar else '3D'}) | {r.status} | "
        f"{m.tolerance_met} | {m.variables} | {m.elements or '-'} | {seconds * 1e3:.0f} | "
        f"{case.error(r):.1e} | {est} |"
    )


def contact_table() -> list[str]:
    """The rows of test_tolerance_sweep_contact.py's cases (module docstring)."""
    lines = [
        "",
        "## Greenhill, Fig. 2 with a radius, the paper's sheets (test_tolerance_sweep_contact.py)",
        "",
        "Streamed: the warm updates of the test (and those held at the pose until checked); its "
        "time is the whole stream's. δ in units of L (L = 0.2 m for the sheets).",
        "",
        "| case | δ / L | model | status | tolerance met | unknowns | elements | time [ms] | "
        "true error [m] | estimate [m] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, make_case in contact_sweep.CASES.items():
        case = make_case()
        for tolerance in TOLERANCES:
            for how in ("cold", "streamed"):
                lines.append(contact_row(name, case, tolerance, how))
        options = SolverOptions(model="full", order=16, output_points=contact_sweep.POINTS)
        r, seconds = timed(lambda: ShapeSolver(case.problem, options, compile="off"))
        lines.append(
            f"| {name} | - | full chebyshev 16 | {r.status} | - | {r.model.variables} | "
            f"{r.model.elements or '-'} | {seconds * 1e3:.0f} | {case.error(r):.1e} | - |"
        )
        print("\n".join(lines[-9:]), flush=True)
    return lines


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
    lines += contact_table()
    lines += ["", "Command: `bash scripts/dlo-env run python bench/perf/tolerance_sweep.py`", ""]
    Path(args.out).write_text("\n".join(lines))


if __name__ == "__main__":
    main()
