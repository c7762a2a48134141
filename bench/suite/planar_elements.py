"""The planar model in one Chebyshev polynomial against spectral elements (``solver.basis``).

    bash scripts/dlo-env run python bench/suite/planar_elements.py  # planar_elements.md

Centreline error max |x − x_ref| / L over the result's output points, and the cold solve time
(best of ``--repeat``, interpreted derivatives, compile off; quadrature nodes as auto takes
them), for ``solver.model: planar`` with basis 'chebyshev' and 'elements', orders 8–32:

* the mid-moment cantilever (test/unit/test_moment_energy.py: clamp at 0, a dead moment at L/2; an
  arc of curvature m/EI then a straight part): the closed form;
* config/scenes/paper_fig3_gravity.yaml (both ends clamped 0.7 L apart, ρ = 3000): no independent
  reference here, so the reference is basis 'elements' at order 48 (the same discretisation
  family: it measures convergence, not correctness).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "test" / "unit"))  # the mid-moment cantilever's set-up
sys.path.insert(0, str(ROOT))

from bench.common import machine, write_report  # noqa: E402
from test_moment_energy import EI, LENGTH, MOMENT, cantilever  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402

ORDERS = (8, 12, 16, 20, 24, 32)
BASES = ("chebyshev", "elements")
NOTES = [
    "Reading: the mid-moment cantilever's curvature jumps at the load. One polynomial over [0, L]",
    "converges only algebraically there (5e-5 L at order 32, and 'unverified' at order 8); the",
    'elements, split at the load, hold the arc and the straight part exactly at every order',
    '(rounding, ~1e-14 L). paper_fig3_gravity.yaml has no interior breakpoint (grips at the ends,',
    "no load), so 'elements' is one element: it converges like the polynomial, slightly behind at",
    'order 32 (its quadrature is order + 8 nodes, build/mesh.quadrature_extra, against the',
    "polynomial's 2·order + 8 Clenshaw–Curtis nodes here).  Its reference is the same family at",
    'order 48: it shows convergence, not correctness (test_planar_elements.py checks smooth',
    'cantilevers against shooting instead).',
    '',
]


def moment_exact(s: np.ndarray) -> np.ndarray:
    """x(s) of the mid-moment cantilever: an arc of radius EI/m on [0, L/2], straight beyond."""
    kappa, half = MOMENT / EI, LENGTH / 2
    a = np.minimum(s, half)
    x = np.stack([np.sin(kappa * a) / kappa, 0 * a, -(1 - np.cos(kappa * a)) / kappa], axis=1)
    beyond = np.maximum(s - half, 0.0)[:, None]
    th = kappa * half
    return x + beyond * np.array([np.cos(th), 0.0, -np.sin(th)])


def solve(problem, basis: str, order: int, repeat: int):
    """Return (result, best cold time [ms], unknowns) of the planar model.

    quadrature_nodes as auto takes them (solver/auto/reduced.py): max(40, 2·order + 8).
    """
    options = SolverOptions(
        model="planar",
        basis=basis,
        order=order,
        quadrature_nodes=max(40, 2 * order + 8),
        output_points=101,
    )
    best, result, unknowns = float("inf"), None, 0
    for _ in range(repeat):
        solver = ShapeSolver(problem, options, compile="off")
        unknowns = solver.nlp.model.layout.size
        t0 = time.perf_counter()
        result = solver.solve()
        best = min(best, (time.perf_counter() - t0) * 1e3)
    return result, best, unknowns


def table(title: str, problem, reference, repeat: int) -> list[str]:
    lines = [
        f"**{title}**",
        "",
        "| basis | order | unknowns | status | centreline error / L | residual m | cold ms |",
        "|---|---|---|---|---|---|---|",
    ]
    for basis in BASES:
        for order in ORDERS:
            r, ms, n = solve(problem, basis, order, repeat)
            err = np.abs(r.points - reference(r.s)).max() / LENGTH if r.ok else float("nan")
            lines.append(
                f"| {basis} | {order} | {n} | {r.status} | {err:.2e} | "
                f"{r.equilibrium_residual_m:.1e} | {ms:.0f} |"
            )
            print(lines[-1], flush=True)
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "planar_elements.md"))
    args = ap.parse_args()
    info = machine()
    lines = [
        "# The planar model: one Chebyshev polynomial against spectral elements",
        "",
        f"Machine: {info.get('cpu')}, {info.get('cpus')} cores (shared), Python "
        f"{info.get('python')}; git {info.get('git')}.",
        "",
        "Cold solves, compile off, time best of "
        f"{args.repeat}; error over 101 output points.  unknowns: the NLP's z (x0 and φ's).",
        "",
    ]
    lines += table(
        "mid-moment cantilever (exact: closed form)",
        cantilever([0.0, MOMENT, 0.0]),
        moment_exact,
        args.repeat,
    )
    fig3 = load_scene(ROOT / "config" / "scenes" / "paper_fig3_gravity.yaml").problem
    ref = solve(fig3, "elements", 48, 1)[0]
    assert ref.ok, ref.message
    lines += table(
        "paper_fig3_gravity.yaml (reference: elements at order 48, not independent)",
        fig3,
        lambda s: ref.points,
        args.repeat,
    )
    write_report(lines + NOTES, args.out, "bench/suite/planar_elements.py", [])


if __name__ == "__main__":
    main()
