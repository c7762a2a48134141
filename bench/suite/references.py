"""Reference answers for the benchmark cases.

* Clamped elastica: the closed form (dlo_ros.model.elastica).
* Other planar cases: two converged high-resolution solves of *different* methods —
  ``rod``: Richardson extrapolation (4 x_2N − x_N)/3 of the planar rod at N = 320, 640 (second order);
  ``ritz``: the planar Chebyshev Ritz model at order 48.  Ritz-family methods are checked against the
  rod reference, the rod and the dynamic peers against the Ritz one; their distance is reported as the
  reference's own uncertainty.
* 3D twist: ``rod`` = Richardson of the quaternion rod at N = 160, 320 (continuation in τ, 32 steps);
  ``ritz`` = dlo_ros ShapeSolver, Chebyshev order 40 (--quick: 32) (continuation, 32 steps).
"""
from __future__ import annotations

import numpy as np

from dlo_ros.model.elastica import clamped_clamped_elastica
from dlo_ros.solver import ShapeSolver, SolverOptions

from bench.common import S_OUT, Case, interp_points
from bench.methods.planar import PlanarRitz, PlanarRod
from bench.methods.rod3d import Rod3D
from bench.methods.runners import twisted_problem

RITZ_FAMILY = ("paper", "fourier", "default", "default-planar")


def elastica_points(chord: float, L: float = 1.0) -> np.ndarray:
    el = clamped_clamped_elastica(L, 1.0, chord)
    xy = el.positions(S_OUT * L)
    return np.stack([xy[:, 0], np.zeros(len(S_OUT)), xy[:, 1]], axis=1)


def planar_rod_solution(problem, N, weight_scale=1.0, sag_sign=None):
    m = PlanarRod(problem, N)
    out, sol = m.cold(problem, weight_scale, sag_sign)
    return out


def reference(case: Case, quick: bool = False) -> dict:
    """{'rod': points, 'ritz': points, 'energy': float, 'spread': |rod − ritz|/L, 'stable': bool}."""
    if case.reference_kind == "elastica":
        pts = elastica_points(case.chord, case.L)
        el = clamped_clamped_elastica(case.L, 1.0, case.chord)
        return {"rod": pts, "ritz": pts, "energy": el.energy, "spread": 0.0, "stable": True, "kind": "closed form"}
    if case.planar:
        n1, n2 = (160, 320) if quick else (320, 640)
        # the lowest-energy stable equilibrium of two starts (buckled down, buckled up)
        trials = [(planar_rod_solution(case.problem, n1, sag_sign=sg), sg) for sg in (-1.0, 1.0)]
        good = [t for t in trials if t[0].ok and t[0].stable]
        a, sag = min(good, key=lambda t: t[0].energy)
        b = planar_rod_solution(case.problem, n2, sag_sign=sag)
        rod = (4 * b.points - a.points) / 3
        r = PlanarRitz(case.problem, "chebyshev", 32 if quick else 48, nodes=96)
        out, _ = r.cold(case.problem, sag_sign=sag)
        spread = float(np.max(np.linalg.norm(rod - out.points, axis=1)))
        return {"rod": rod, "ritz": out.points, "energy": out.energy, "spread": spread, "stable": bool(out.stable),
                "ok": a.ok and b.ok and out.ok, "kind": f"rod N={n1},{n2} Richardson / Chebyshev {r.order}",
                "other_energies": [t[0].energy for t in trials], "sag": sag}
    # 3D twist: continuation in τ
    steps = 16 if quick else 32
    pts = {}
    n_pair = (80, 160) if quick else (160, 320)
    for N in n_pair:
        m = Rod3D(case.problem, N)
        out, sol = m.cold(twisted_problem(case, 0.0), check=False)
        for k in range(1, steps + 1):
            out, sol = m.warm(twisted_problem(case, case.tau * k / steps), sol, check=(k == steps))
        pts[N] = out
    # the two resolutions may sit at different angles of the neutral rotation about the chord: align first
    a, b = pts[n_pair[0]].points, pts[n_pair[1]].points
    if case.align_about_chord:
        from bench.common import rotation_about_x

        za, zb = a[:, 1] + 1j * a[:, 2], b[:, 1] + 1j * b[:, 2]
        a = a @ rotation_about_x(float(np.angle(np.vdot(za, zb)))).T
    rod = (4 * b - a) / 3
    order = 32 if quick else 40  # measured on the 2π case: 2.8e-3, 8.3e-4, 2.0e-4 L at orders 24, 32, 40
    s = ShapeSolver(case.problem, SolverOptions(order=order, quadrature_nodes=2 * order + 8, output_points=101),
                    compile="off")
    r = s.solve({"right": twisted_problem(case, 0.0).grip("right").pose}, warm=False)
    for k in range(1, steps + 1):
        r = s.solve({"right": twisted_problem(case, case.tau * k / steps).grip("right").pose})
    ritz = interp_points(r.s, r.points)
    from bench.common import max_error

    spread = max_error(ritz, rod, case.align_about_chord)
    return {"rod": rod, "ritz": ritz, "energy": pts[n_pair[1]].energy, "spread": spread,
            "stable": bool(pts[n_pair[1]].stable), "ok": r.ok and pts[n_pair[1]].ok,
            "kind": f"quaternion rod N={n_pair[0]},{n_pair[1]} Richardson / Chebyshev {order}"}


def reference_for(method: str, ref: dict) -> np.ndarray:
    return ref["rod"] if method in RITZ_FAMILY else ref["ritz"]
