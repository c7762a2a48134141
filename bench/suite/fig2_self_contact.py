"""The paper's Fig. 2 regenerated with self-contact (issue #15): planar → twisted → one knot.

    bash scripts/dlo-env run python bench/suite/fig2_self_contact.py   # writes bench/results/paper_fig2_self_contact.{png,md}

Set-up (the paper's Fig. 2, as in test/test_self_contact.py): a string of length L = 1, clamp at s = 0,
the end s = L held by its tangent (grip mode "tangent": position and tangent along +x held, twist free) at
(c, 0, 0), Rf = 1, Rt = 0.01 (Rf/Rt = 100), no weight, radius r = 0.01 L.

Method: ``model: full`` with self-contact (``SolverOptions(model="full", order=16, self_contact_pairs=16)``,
the order and slot count of the tests), one ``ShapeSolver`` solved cold at 0.8 L, then streamed down to
0.2 L in warm steps of ``--step`` (one warm update per step, as test_fig2_streamed_into_contact does).
At each of the figure's chords (0.8 … 0.2 L) the answer is measured on its own:

* status, the stability verdict and the smallest eigenvalue of the reduced Hessian (as the result reports);
* total energy;
* out-of-plane / L: the largest distance of the centreline from the plane through the chord (the x-axis)
  that fits it best in least squares (both ends and end tangents lie on the x-axis, so a planar shape lies
  in such a plane);
* writhe: the Gauss writhe of the centreline extended at both ends by straight rays along its end tangents
  (``dlo_ros.solver.contact.topology.ray_writhe``), ≈ 0 for a planar shape and near ±1 once a loop has closed;
* min self-distance / 2r: the closest approach of the centreline to itself between points more than the
  solver's exclusion arc apart along s (its non-adjacent pairs; ``self_contact.contact_geometry``), and
  between points more than 0.25 L apart (the strands of a loop; an open shape's value for the exclusion
  arc is only its own arc's chord), on 1001 points of the solved centreline refined on a spline
  (test_fig2_reference.closest_self_approach), divided by 2r; also the solver's own value at its contact
  samples (``min_self_distance``);
* the self-contacts the result reports, and the sum of their force magnitudes.

The figure: one column per chord, the top (x–y), front (x–z) and side (y–z) views as in the paper.  Each
shape is turned about the chord (a neutral symmetry of the set-up) so that its best-fit plane through the
chord is x–z, as the paper draws the planar shapes.  The string is drawn to scale as a tube of radius r
(discs of radius r at 201 points, 0.005 L apart), the centreline on top, contact points as red dots
joined by a line.  Each column is titled with the paper's description for that chord and the measures
above.  The paper shows 0.8 … 0.3 L; 0.2 L is ours only.
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

L, RF, RT = 1.0, 1.0, 0.01
RADIUS = 0.01 * L
ORDER, PAIRS = 16, 16
POINTS = 201
CHORDS = (0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2)
STRAIGHT = (0.0, 0.0, 0.0, 1.0)
FAR = 0.25 * L  # also the self-approach between points more than this apart along s (the loop's strands)
#: the paper's words for each chord (seed paper, Section on Fig. 2); 0.2 L is not in the paper
PAPER = {0.8: "planar (in the x–z plane)", 0.7: "planar (in the x–z plane)",
         0.6: "twisted, not in any plane", 0.5: "twisted, not in any plane",
         0.4: "one knot", 0.3: "one knot", 0.2: "(not in the paper)"}


def fig2(c: float):
    from support.problems import clamped_pair
    p = clamped_pair(right=(c, 0.0, 0.0), bend=RF, twist=RT, modes=("clamp", "tangent"))
    return replace(p, string=replace(p.string, radius=RADIUS))


def plane_normal(points: np.ndarray) -> np.ndarray:
    """Unit normal (0, ny, nz) of the least-squares plane through the x-axis."""
    yz = points[:, 1:]
    w, v = np.linalg.eigh(yz.T @ yz)
    return np.array([0.0, *v[:, 0]])


def turned_to_xz(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points, R): the shape turned by R about the x-axis so that its best-fit plane through the x-axis is
    x–z, its farthest point from the chord up."""
    n = plane_normal(points)
    angle = np.arctan2(n[2], n[1])  # turn n onto +y
    c, s = np.cos(-angle), np.sin(-angle)
    rot = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    out = points @ rot.T
    if out[np.argmax(np.abs(out[:, 2])), 2] < 0:
        rot = np.diag([1.0, -1.0, -1.0]) @ rot  # and half a turn about x
    return points @ rot.T, rot


def measure(sol, result) -> dict:
    from test_fig2_reference import closest_self_approach

    from dlo_ros.solver.contact import self_contact as SC
    from dlo_ros.solver.contact.topology import ray_writhe
    m = {"status": result.status, "stable": result.stable, "min_eig": result.min_eigenvalue,
         "warm": result.warm_started, "message": result.message, "iterations": result.iterations,
         "ms": result.solve_time_ms}
    if result.points.size == 0:
        return m
    pts = result.points
    n = plane_normal(pts)
    t = np.gradient(pts, result.s, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    s_fine = np.linspace(0.0, L, 1001)
    snap = sol.snapshot()
    fine = sol.model.positions(snap.z, s_fine) if snap is not None else pts
    s_at = s_fine if snap is not None else result.s
    gap = SC.contact_geometry(L, RADIUS).exclusion  # the solver's non-adjacent pairs
    d, sa, sb = closest_self_approach(s_at, fine, gap)
    d_far, _, _ = closest_self_approach(s_at, fine, FAR)
    m.update(energy=result.energy["total"], out_of_plane=float(np.max(np.abs(pts @ n))) / L,
             writhe=ray_writhe(pts, t), min_dist=d / (2 * RADIUS), min_at=(sa, sb), min_far=d_far / (2 * RADIUS), gap=gap,
             solver_min=result.min_self_distance / (2 * RADIUS), contacts=len(result.self_contacts),
             force=float(sum(np.linalg.norm(c.force) for c in result.self_contacts)),
             residual=result.equilibrium_residual_m, points=pts,
             contact_points=[(c.point_a, c.point_b, c.s_a, c.s_b) for c in result.self_contacts])
    return m


def fmt(v, spec: str) -> str:
    return "—" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


def draw(rows: dict, out: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    views = (("top (x–y)", 0, 1), ("front (x–z)", 0, 2), ("side (y–z)", 1, 2))
    chords = list(rows)
    fig, axes = plt.subplots(3, len(chords), figsize=(2.9 * len(chords), 10.2))
    for j, c in enumerate(chords):
        m = rows[c]
        head = f"c = {c} L\npaper: {PAPER[c]}"
        if "points" not in m:
            axes[0, j].set_title(head + f"\nours: {m['status']} (no shape)", fontsize=7.5)
            for i in range(3):
                axes[i, j].axis("off")
            continue
        pts, rot = turned_to_xz(m["points"])
        axes[0, j].set_title(head, fontsize=8)
        for i, (vname, a, b) in enumerate(views):
            ax = axes[i, j]
            discs = [Circle((p[a], p[b]), RADIUS) for p in pts]
            ax.add_collection(PatchCollection(discs, facecolor="#9ecae1", edgecolor="none", alpha=0.6))
            ax.plot(pts[:, a], pts[:, b], "-", color="#08519c", lw=0.6)
            ax.plot(pts[[0, -1], a], pts[[0, -1], b], "ks", ms=3)
            for pa, pb, _, _ in m["contact_points"]:
                q = np.array([pa, pb]) @ rot.T
                ax.plot(q[:, a], q[:, b], "r-", lw=0.8)
                ax.plot(q[:, a], q[:, b], "ro", ms=2.5)
            ax.set_aspect("equal", "datalim")
            ax.autoscale_view()
            ax.tick_params(labelsize=6)
            if j == 0:
                ax.set_ylabel(vname, fontsize=8)
        stable = {True: "stable", False: "UNSTABLE", None: "stability ?"}[m["stable"]]
        axes[2, j].set_xlabel(
            f"ours: {m['status']}, {stable} (λmin {fmt(m['min_eig'], '.1e')})\n"
            f"E = {m['energy']:.4f}, out-of-plane {m['out_of_plane']:.3f} L\n"
            f"writhe {m['writhe']:+.3f}, min dist / 2r: {m['min_dist']:.3f} / {m['min_far']:.3f}\n"
            f"contacts {m['contacts']}, Σ|f| = {m['force']:.3g}", fontsize=7.5)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--step", type=float, default=0.01, help="chord step of the warm stream [L] (default 0.01)")
    args = ap.parse_args()

    from bench.common import machine
    from dlo_ros.solver.options import SolverOptions
    from dlo_ros.solver.shape_solver import ShapeSolver

    info = machine()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    t_all = time.perf_counter()
    opts = SolverOptions(model="full", order=ORDER, self_contact_pairs=PAIRS, output_points=POINTS)
    t0 = time.perf_counter()
    sol = ShapeSolver(fig2(CHORDS[0]), opts, compile="off")
    first = sol.solve()
    t_first = time.perf_counter() - t0
    rows = {CHORDS[0]: measure(sol, first)}
    stream = np.round(np.arange(CHORDS[0] - args.step, CHORDS[-1] - 1e-9, -args.step), 10)
    bad, t_stream, touched_at = [], time.perf_counter(), None
    for c in stream:
        r = sol.solve({"right": ((float(c), 0.0, 0.0), STRAIGHT)})
        if not (r.ok and r.stable and r.warm_started):
            bad.append(f"{c:g}: {r.status}, stable {r.stable}, warm {r.warm_started} ({r.message[:100]})")
        if touched_at is None and r.self_contacts:
            touched_at = float(c)
        key = next((k for k in CHORDS if abs(k - c) < 1e-9), None)
        if key is not None:
            rows[key] = measure(sol, r)
        print(f"{c:.3f}: {r.status} stable={r.stable} contacts={len(r.self_contacts)} "
              f"E={r.energy.get('total', float('nan')):.6f} {r.solve_time_ms:.0f} ms", flush=True)
    t_stream = time.perf_counter() - t_stream
    total = time.perf_counter() - t_all

    out = ROOT / "bench" / "results"
    title = (f"Paper Fig. 2 with self-contact: s=0 clamped, s=L tangent held (twist free) at (c,0,0), Rf/Rt = 100, "
             f"radius {RADIUS / L:g} L (drawn to scale); model full, order {ORDER}, {PAIRS} contact slots, "
             f"streamed 0.8 L → 0.2 L in steps of {args.step:g} L")
    draw(rows, out / "paper_fig2_self_contact.png", title)

    cmd = "bash scripts/dlo-env run python bench/suite/fig2_self_contact.py"
    if args.step != 0.01:
        cmd += f" --step {args.step:g}"
    lines = ["# The paper's Fig. 2 with self-contact: planar → twisted → one knot", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared; load average "
             f"{', '.join(f'{v:.2f}' for v in info.get('load_average', ()))}), Python {info.get('python')}; "
             f"git {info.get('git', '?')}; started {started}.",
             f"Command: `{cmd}`.  Set-up, method and the measures: the module docstring.", "",
             f"Fig. 2 set-up with radius r = {RADIUS / L:g} L; `model: full`, order {ORDER}, "
             f"`self_contact_pairs: {PAIRS}`; cold at 0.8 L ({t_first:.1f} s with the build), then "
             f"{len(stream)} warm updates down to 0.2 L in steps of {args.step:g} L ({t_stream:.1f} s); "
             f"whole run {total:.0f} s.", "",
             "![fig2 with self-contact](paper_fig2_self_contact.png)", "",
             "## Per chord", "",
             "Out-of-plane: largest distance from the best-fit plane through the chord.  Writhe: Gauss writhe with "
             "the end tangents extended as rays.  Min distance: closest approach of the centreline to itself "
             f"(points more than the exclusion arc {rows[CHORDS[0]].get('gap', float('nan')) / L:.4f} L apart along s "
             f"/ more than {FAR / L:g} L apart; 1001 points + spline) / 2r; in brackets the solver's own "
             "`min_self_distance` / 2r at its contact samples (∞: no two strands within reach).  Σ|f|: sum of the "
             "contact force magnitudes [N].", "",
             "| chord | paper says | we get | status | stable | min eigenvalue | energy | out-of-plane / L | writhe | "
             "min distance / 2r: > arc / > 0.25 L (solver's) | contacts | Σ\\|f\\| [N] | residual [m] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c, m in rows.items():
        if "points" not in m:
            lines.append(f"| {c} | {PAPER[c]} | no shape: {m['message'][:120]} | {m['status']} | {m['stable']} | "
                         f"{fmt(m['min_eig'], '.1e')} | | | | | | | |")
            continue
        planar = m["out_of_plane"] < 1e-3
        if m["contacts"]:
            ours = f"loop closed on itself, touching at {m['contacts']} point(s)"
        elif planar:
            ours = "planar"
        else:
            ours = "non-planar (twisted), not touching"
        ours += f"; writhe {m['writhe']:+.2f}"
        lines.append(f"| {c} | {PAPER[c]} | {ours} | {m['status']} | {m['stable']} | {fmt(m['min_eig'], '.1e')} | "
                     f"{m['energy']:.6f} | {m['out_of_plane']:.4f} | {m['writhe']:+.4f} | "
                     f"{m['min_dist']:.4f} / {m['min_far']:.4f} ({fmt(m['solver_min'], '.4f')}) | {m['contacts']} | "
                     f"{m['force']:.4g} | {m['residual']:.1e} |")
    lines += ["", "Smallest eigenvalues of order 1e-11 and below (either sign) are the rotation of the shape about the "
              "chord, a neutral direction of the set-up (the reference rod of `fig2_knots.md` has it too); the "
              "stability verdict is the solver's.",
              "", f"First self-contact on the stream: {'none' if touched_at is None else f'{touched_at:g} L'}.",
              "Stream updates not ok, not stable or not warm: " + ("none." if not bad else "; ".join(bad) + "."), ""]
    for c, m in rows.items():
        if m.get("contact_points"):
            pairs = ", ".join(f"s = {a:.3f} / {b:.3f}" for _, _, a, b in m["contact_points"])
            lines.append(f"Contacts at {c} L: {pairs}.")
    (out / "paper_fig2_self_contact.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
