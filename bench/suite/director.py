"""The 3D model without a pole against the Euler-angle model: error against unknowns, and streams.

    bash scripts/dlo-env run python bench/suite/director.py            # writes bench/results/director.md

1. Convergence: centreline error (and energy error) against the number of unknowns, director and the
   rotated Euler frame, on exact or independent references: the clamped elastica (closed form), a
   cantilever with a point moment at mid-length (two circular arcs), the paper's Fig. 2 set-up at chord
   0.5 L (test/reference shooting solution, its stable non-planar branch) and a general 3D cable
   (default_cable with the right end moved and turned; test/reference shooting polished from the
   director's order-32 shape, so the reference is the shooting solution, not the director's).
2. Streams: ``default_cable`` along the closed 3D path of test/unit/test_director_stream.py (2,000 warm
   updates, translation, yaw, pitch and ±1.2 rad of twist), ``auto`` (library defaults: background
   checks) against fixed models: median, p99 and max per update, and the end against a cold solve.
All times from one run on this machine, interpreted derivatives (compile off).
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
from reference.kirchhoff import blas_threads, relaxed_guess, solve_clamped  # noqa: E402
from test_kirchhoff_reference import planar_buckling_guess  # noqa: E402
from test_director_stream import UPDATES, path  # noqa: E402

from dlo_ros.model import Grip, GripPose, Load, Problem, Profile, StringProperties  # noqa: E402
from dlo_ros.model.elastica import clamped_clamped_elastica  # noqa: E402
from dlo_ros.model.rotations import quat_to_matrix  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver.auto import make_solver  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402

ORDERS = (8, 12, 16, 20, 24, 32)
S = np.linspace(0.0, 1.0, 201)


def modulo_chord(points, ref):
    """max |R p − q| over the best rotation about x, with or without the mirror y → −y."""
    best = np.inf
    for mirror in (1.0, -1.0):
        p = points * np.array([1.0, mirror, 1.0])
        a = np.sum(p[:, 1] * ref[:, 1] + p[:, 2] * ref[:, 2])
        b = np.sum(p[:, 1] * ref[:, 2] - p[:, 2] * ref[:, 1])
        c, s = np.cos(np.arctan2(b, a)), np.sin(np.arctan2(b, a))
        turned = np.stack([p[:, 0], c * p[:, 1] - s * p[:, 2], s * p[:, 1] + c * p[:, 2]], axis=1)
        best = min(best, float(np.max(np.linalg.norm(turned - ref, axis=1))))
    return best


def cases():
    """(name, problem, reference points at S (m), reference energy or None, compare)."""
    out = []
    ex = clamped_clamped_elastica(1.0, 1.0, 0.6)
    planar = ex.positions(S)
    out.append(("clamped elastica 0.6 L", clamped_pair(right=(0.6, 0, 0)),
                np.column_stack([planar[:, 0], planar[:, 1], 0 * S]), ex.energy, "chord"))
    m = 2.0
    string = StringProperties(1.0, Profile.constant(1.0), Profile.constant(0.5), Profile.constant(0.0))
    cant = Problem(string, (Grip("c", 0.0, "clamp", GripPose.checked((0, 0, 0), (0, 0, 0, 1), "c")),),
                   loads=(Load(0.5, moment=np.array([0.0, -m, 0.0])),))
    arc = np.stack([np.sin(m * np.minimum(S, 0.5)) / m, 0 * S, (1 - np.cos(m * np.minimum(S, 0.5))) / m], axis=1)
    arc += np.maximum(S - 0.5, 0)[:, None] * np.array([np.cos(m / 2), 0.0, np.sin(m / 2)])[None, :]
    # (energies not compared: the director's moment work is a re-centred pseudo-potential, the Euler's −m φ)
    out.append(("cantilever, moment at L/2", cant, arc, None, "plain"))
    with blas_threads(1):
        planar = solve_clamped(1.0, 1.0, 0.01, np.zeros(3), np.eye(3), (0.5, 0, 0), (1, 0, 0), mode_end="tangent",
                               guess=planar_buckling_guess(0.5, 1.0, 1.0), s_eval=S)
        fn, _ = relaxed_guess(planar, n_edges=40)
        fig2 = solve_clamped(1.0, 1.0, 0.01, np.zeros(3), np.eye(3), (0.5, 0, 0), (1, 0, 0), mode_end="tangent",
                             guess=fn, s_eval=S)
    out.append(("Fig. 2 set-up, chord 0.5 L", clamped_pair(right=(0.5, 0, 0), twist=0.01, modes=("clamp", "tangent")),
                fig2.x, fig2.energy, "chord"))
    sc = load_scene("default_cable")
    q = np.array([np.sin(0.25), 0.0, 0.0, np.cos(0.25)])  # 0.5 rad about x
    cable = sc.problem.with_grip_poses({"right": GripPose.checked((0.5, 0.1, 0.45), q, "right")})
    cable = replace(cable, obstacles=())
    seed = ShapeSolver(cable, SolverOptions(model="full", order=32, quadrature_nodes=40), compile="off").solve()
    left = seed.grips["left"]
    st = cable.string
    with blas_threads(1):
        ref = solve_clamped(1.0, st.bend_stiffness.maximum, st.twist_stiffness.maximum, cable.grips[0].pose.position,
                            quat_to_matrix(cable.grips[0].pose.orientation), cable.grips[1].pose.position,
                            quat_to_matrix(q), D=st.weight_per_length.maximum, g=(0, 0, -1),
                            guess=(-left.force, -left.torque), s_eval=S)
    out.append(("3D cable (default_cable, end moved and turned 0.5 rad)", cable, ref.x, ref.energy, "plain"))
    return out


def convergence(lines):
    lines += ["## 1. Error against unknowns", "",
              "Centreline error max |x − x_ref| [m] (modulo the neutral rotation about the chord where there is one)"
              " and the equilibrium residual the result reports, per order, for the director model (default) and "
              "the rotated Euler frame (`rotation: euler`).  Cold solves; time per cold solve in ms.", ""]
    for name, problem, ref, energy, compare in cases():
        lines += [f"**{name}**", "", "| model | order | unknowns | centreline error m | energy rel. error | residual m | cold ms |",
                  "|---|---|---|---|---|---|---|"]
        for rotation in ("director", "euler"):
            for order in ORDERS:
                opts = SolverOptions(model="full", rotation=rotation, order=order, quadrature_nodes=max(40, order + 8),
                                     output_points=201, error_tolerance=1.0)
                try:
                    solver = ShapeSolver(problem, opts, compile="off")
                except ValueError as exc:
                    lines.append(f"| {rotation} | {order} | — | rejected: {str(exc)[:60]} | | | |")
                    break
                t0 = time.perf_counter()
                r = solver.solve()
                ms = (time.perf_counter() - t0) * 1e3
                if r.status not in ("ok", "unverified"):
                    lines.append(f"| {rotation} | {order} | {solver.model.layout.size} | {r.status} | | | {ms:.0f} |")
                    continue
                err = modulo_chord(r.points, ref) if compare == "chord" else float(np.max(np.linalg.norm(r.points - ref, axis=1)))
                e_rel = abs(r.energy["total"] - energy) / abs(energy) if energy else float("nan")
                lines.append(f"| {rotation} | {order} | {solver.model.layout.size} | {err:.2e} | {e_rel:.1e} | "
                             f"{r.equilibrium_residual_m:.1e} | {ms:.0f} |")
        lines.append("")


def streams(lines):
    sc = load_scene("default_cable")
    start = sc.problem.grip("right").pose.position
    lines += ["## 2. Streams: `default_cable` along a closed 3D path", "",
              f"{UPDATES} warm updates (translation, yaw, pitch, ±1.2 rad of twist) and back; end compared with a "
              "cold solve at the start pose.  `auto` with the library defaults (background checks).", "",
              "| solver | model at the end | median ms | p99 ms | max ms | not ok | end vs cold m |",
              "|---|---|---|---|---|---|---|"]
    runs = [("auto", None), ("full 12 (director)", replace(sc.options, model="full", order=12)),
            ("full 16 (director)", replace(sc.options, model="full", order=16)),
            ("full 16 (euler)", replace(sc.options, model="full", order=16, rotation="euler"))]
    for name, opts in runs:
        solver = make_solver(sc.problem, opts or sc.options, compile="off") if opts is None else \
            ShapeSolver(sc.problem, opts, compile="off")
        solver.solve()
        times, bad = [], 0
        for k in range(1, UPDATES + 1):
            t0 = time.perf_counter()
            r = solver.solve({"right": path(k, start)})
            times.append((time.perf_counter() - t0) * 1e3)
            bad += not r.ok
        cold = ShapeSolver(sc.problem, replace(opts or sc.options, model="full", order=r.model.order),
                           compile="off").solve()
        end = float(np.max(np.linalg.norm(r.points - cold.points, axis=1))) if cold.ok else float("nan")
        t = np.array(times)
        model = f"{'3D' if not r.model.planar else 'planar'} order {r.model.order} ({r.model.rotation})"
        lines.append(f"| {name} | {model} | {np.median(t):.2f} | {np.percentile(t, 99):.2f} | {t.max():.1f} | {bad} | {end:.1e} |")
        if hasattr(solver, "close"):
            solver.close()
    lines.append("")


def main() -> None:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    info = machine()
    lines = ["# The 3D model without a pole (director) against the Euler frame", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; git {info.get('git', '?')}.",
             "Command: `bash scripts/dlo-env run python bench/suite/director.py`", ""]
    convergence(lines)
    streams(lines)
    out = ROOT / "bench" / "results" / "director.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
