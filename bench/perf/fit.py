"""Identification benchmark (issue 16): σ coverage, the paper's copy-paper sheet, and the cost against
derivative-free fits on the same data.

    bash scripts/dlo-env run python bench/perf/fit.py [--trials 100] [--sheet-seeds 5] [--twist-trials 10] [--baseline-seeds 3]
        [--out bench/results/fit.md]

Synthetic observations come from the independent Kirchhoff shooting solver (test/reference/kirchhoff.py):
random arc lengths, 30 % of the length occluded at a random place, Gaussian noise per coordinate, shuffled.

1. Coverage: a cantilever (L = 0.5 m, Rf = 0.02 N·m², D = 0.5 N/m, clamp 0.3 rad below horizontal),
   1.5 mm noise, fitted from a start 40 % off; D/Rf from the shape alone, and Rf, D with the clamp's
   force (2 mN noise).  Counts how often |error| ≤ k σ for k = 1, 1.645, 2 (a calibrated σ gives 68 %,
   90 %, 95 %).
2. The paper's copy-paper sheet (sec. 5: L = 200 mm, Rf = 1e4 gw·mm², D = 2e-3 gw/mm, both ends clamped
   horizontally, the sagging branch) at chords 180, 140 and 70 mm, 0.5 and 0.1 mm noise: ρ = D L³/Rf
   (true 1.6) from the three shapes.
3. Twist: three poses of a string held by two clamps 0.3 m apart (5 cm sideways), the right clamp turned
   by 0, 1.5 and 3 rad about the tangent, 1.5 mm noise; Rf, Rt, D fitted from Rt 50 % low: Rt/Rf (true
   0.75) per seed, with its stated σ.
4. Cost: the same cantilever-with-force data fitted by (a) this package (IFT Jacobian, LM), (b) scipy
   ``least_squares`` with 2-point finite differences on the same robust residuals (loss 'huber'), (c) a
   particle swarm of 50 particles × 20 iterations (DLO_planning_2's size) on the same cost.  Each uses the
   package's warm-started equilibrium solver; an "equilibrium solve" is one ``ShapeSolver.solve`` call.
"""
from __future__ import annotations

import argparse
import datetime
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "test" / "unit"))  # test modules the bench reuses (references, set-ups)
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402
from reference.kirchhoff import continuation, rot_x, solve_clamped  # noqa: E402

from dlo_ros.identify import ForceObservation, Observation, ObservationSet, fit  # noqa: E402
from dlo_ros.identify.curve import point_to_curve  # noqa: E402
from dlo_ros.identify.parameters import Parameterisation  # noqa: E402
from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties  # noqa: E402
from dlo_ros.model.rotations import matrix_to_quat  # noqa: E402
from dlo_ros.solver import ShapeSolver, SolverOptions  # noqa: E402
from dlo_ros.solver.results.sensitivity import shape_sensitivity  # noqa: E402

L, RF, RT, D, TILT = 0.5, 0.02, 0.015, 0.5, -0.3
SIGMA, SIGMA_F = 1.5e-3, 2e-3
HUBER = 2.5
GW = 9.80665e-3  # N per gram-weight
SHEET_NOISE = (5e-4, 1e-4)  # m


def tilted(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def cloud(ref, length: float, sigma: float, rng: np.random.Generator, count: int = 300) -> np.ndarray:
    s = rng.uniform(0.0, length, count)
    start = rng.uniform(0.05, 0.65) * length
    s = s[(s < start) | (s > start + 0.3 * length)]
    pts = ref.position(s) + rng.normal(0.0, sigma, (len(s), 3))
    return pts[rng.permutation(len(pts))]


def cantilever_problem(bend: float, weight: float) -> Problem:
    string = StringProperties(L, Profile.constant(bend), Profile.constant(RT), Profile.constant(weight))
    return Problem(string, (Grip("hand", 0.0, "clamp", GripPose(np.zeros(3), matrix_to_quat(tilted(TILT)))),))


# ---- 1. coverage ------------------------------------------------------------------------------------------
def coverage(trials: int) -> dict:
    ref = solve_clamped(L, RF, RT, np.zeros(3), tilted(TILT), mode_end="free", D=D)
    start = cantilever_problem(RF, 0.6 * D)
    rows = {"D/Rf (shape)": [], "Rf (force)": [], "D (force)": []}
    solves, times = [], []
    for seed in range(trials):
        rng = np.random.default_rng(seed)
        pts = cloud(ref, L, SIGMA, rng)
        force = ForceObservation("hand", ref.force0 + rng.normal(0.0, SIGMA_F, 3), SIGMA_F)
        shape = fit(start, SolverOptions(), ObservationSet((Observation("hang", {}, pts, SIGMA),), ("Rf", "D")))
        with_force = fit(start, SolverOptions(), ObservationSet((Observation("hang", {}, pts, SIGMA, force),), ("Rf", "D")))
        for res in (shape, with_force):
            solves.append(res.equilibrium_solves)
            times.append(res.time_s)
        for key, est, truth in (("D/Rf (shape)", shape.ratios.get("D/Rf"), D / RF),
                                ("Rf (force)", with_force.parameters.get("Rf"), RF),
                                ("D (force)", with_force.parameters.get("D"), D)):
            rows[key].append((est.value - truth) / est.std if est is not None else np.nan)
            rows[key + " rel"] = rows.get(key + " rel", []) + [abs(est.value / truth - 1) if est else np.nan]
    return {"rows": rows, "solves": solves, "times": times}


# ---- 2. the paper's sheet ----------------------------------------------------------------------------------
def paper_sheet(seeds: int) -> dict:
    length, bend, weight = 0.2, 1e4 * GW * 1e-6, 2e-3 * GW / 1e-3
    p_buckle = 4 * np.pi ** 2 * bend / length ** 2

    def at(chord, guess):
        return solve_clamped(length, bend, bend, np.zeros(3), np.eye(3), (chord, 0.0, 0.0), np.eye(3), D=weight,
                             guess=guess, fallback=False)

    chords = [0.18, 0.14, 0.07]
    path = continuation(at, chords, guess=(np.array([-p_buckle, 0.0, -weight * length / 2]),
                                           np.array([0.0, np.pi * bend / length, 0.0])))
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    string = StringProperties(length, Profile.constant(1.5 * bend), Profile.constant(0.0), Profile.constant(weight))
    problem = Problem(string, (Grip("left", 0.0, "clamp", GripPose(np.zeros(3), ident)),
                               Grip("right", length, "clamp", GripPose(np.array([0.18, 0.0, 0.0]), ident))))
    out = []
    for noise in SHEET_NOISE:
        for seed in range(seeds):
            rng = np.random.default_rng(100 + seed)
            obs = tuple(Observation(f"l={c * 1e3:.0f} mm", {"right": GripPose(np.array([c, 0.0, 0.0]), ident)},
                                    cloud(ref, length, noise, rng), noise) for c, ref in path)
            res = fit(problem, SolverOptions(), ObservationSet(obs, ("Rf", "D")))
            ratio = res.ratios["D/Rf"]
            out.append({"noise": noise, "seed": seed, "status": res.status, "rho": ratio.value * length ** 3,
                        "std": ratio.std * length ** 3, "solves": res.equilibrium_solves, "time": res.time_s,
                        "chi2": res.chi2_reduced})
    return {"rho_true": weight * length ** 3 / bend, "runs": out, "sag_mm": [float(-ref.x[:, 2].min() * 1e3) for _, ref in path]}


# ---- 3. twist ----------------------------------------------------------------------------------------------
def twist(trials: int) -> dict:
    offset = np.array([0.3, 0.05, 0.0])

    def at(psi, guess):
        return solve_clamped(L, RF, RT, np.zeros(3), np.eye(3), offset, rot_x(psi), D=D, guess=guess, fallback=False)

    path = continuation(at, [0.0, 1.5, 3.0], guess=(np.array([0.2, 0.0, -D * L / 2]), np.array([0.0, 0.01, 0.0])))
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    string = StringProperties(L, Profile.constant(RF), Profile.constant(0.5 * RT), Profile.constant(0.3))
    problem = Problem(string, (Grip("left", 0.0, "clamp", GripPose(np.zeros(3), ident)),
                               Grip("right", L, "clamp", GripPose(offset, ident))))
    runs = []
    for seed in range(trials):
        rng = np.random.default_rng(500 + seed)
        obs = tuple(Observation(f"psi={psi}", {"right": GripPose(offset, matrix_to_quat(rot_x(psi)))},
                                cloud(ref, L, SIGMA, rng), SIGMA) for psi, ref in path)
        res = fit(problem, SolverOptions(), ObservationSet(obs, ("Rf", "Rt", "D")))
        est = res.ratios.get("Rt/Rf")
        runs.append({"seed": seed, "status": res.status, "value": est.value if est else np.nan,
                     "std": est.std if est else np.nan, "solves": res.equilibrium_solves, "time": res.time_s,
                     "d_rf": res.ratios["D/Rf"].value if "D/Rf" in res.ratios else np.nan})
    return {"truth": RT / RF, "runs": runs}


# ---- 4. cost against derivative-free fits -------------------------------------------------------------------
class Objective:
    """Robust residuals of the cantilever data at θ = (log Rf, log D), each evaluation one equilibrium solve."""

    def __init__(self, start: Problem, pts: np.ndarray, force: ForceObservation):
        self.start, self.pts, self.force = start, pts, force
        self.solver = ShapeSolver(start, SolverOptions(model="planar"), compile="off")
        self.s = np.linspace(0.0, L, 401)
        self.parameters = Parameterisation(start.string, ("Rf", "D"), {})
        self.solves = 0

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        self.solver.set_problem(replace(self.start, string=self.parameters.string(theta)))
        self.solves += 1
        if not self.solver.solve().ok:
            return np.full(3 * len(self.pts) + 3, 1e3)
        sens = shape_sensitivity(self.solver, (), self.s)
        cr = point_to_curve(self.pts, sens.s, sens.points, sens.d_points)
        f = (self.force.force - sens.grip_forces["hand"]) / self.force.sigma
        return np.concatenate([cr.residuals.ravel() / SIGMA, f])

    def cost(self, theta: np.ndarray) -> float:
        r = self.residuals(theta)
        u = np.linalg.norm(r[:-3].reshape(-1, 3), axis=1)
        return float(np.sum(np.where(u <= HUBER, 0.5 * u * u, HUBER * u - 0.5 * HUBER ** 2)) + 0.5 * r[-3:] @ r[-3:])


def swarm(objective: Objective, rng: np.random.Generator, particles: int = 50, iterations: int = 20,
          bound: float = 1.0) -> np.ndarray:
    """Global-best particle swarm (inertia 0.72, c1 = c2 = 1.49) in θ ∈ [−bound, bound]²."""
    x = rng.uniform(-bound, bound, (particles, 2))
    v = np.zeros_like(x)
    cost = np.array([objective.cost(p) for p in x])
    best_x, best_c = x.copy(), cost.copy()
    g = best_x[np.argmin(best_c)].copy()
    for _ in range(iterations - 1):
        r1, r2 = rng.uniform(size=(2, particles, 1))
        v = 0.72 * v + 1.49 * r1 * (best_x - x) + 1.49 * r2 * (g - x)
        x = np.clip(x + v, -bound, bound)
        cost = np.array([objective.cost(p) for p in x])
        better = cost < best_c
        best_x[better], best_c[better] = x[better], cost[better]
        g = best_x[np.argmin(best_c)].copy()
    return g


def baselines(seeds: int) -> list[dict]:
    ref = solve_clamped(L, RF, RT, np.zeros(3), tilted(TILT), mode_end="free", D=D)
    start = cantilever_problem(0.6 * RF, 0.6 * D)
    rows = []
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        pts = cloud(ref, L, SIGMA, rng)
        force = ForceObservation("hand", ref.force0 + rng.normal(0.0, SIGMA_F, 3), SIGMA_F)

        def errors(rf: float, d: float) -> tuple[float, float]:
            return abs(rf / RF - 1), abs(d / D - 1)

        t0 = time.perf_counter()
        ours = fit(start, SolverOptions(), ObservationSet((Observation("hang", {}, pts, SIGMA, force),), ("Rf", "D")))
        elapsed = time.perf_counter() - t0
        theta = np.log(np.array([ours.parameters["Rf"].value / (0.6 * RF), ours.parameters["D"].value / (0.6 * D)]))
        rows.append({"seed": seed, "method": "IFT + LM (dlo fit)", "solves": ours.equilibrium_solves, "time": elapsed,
                     "errors": errors(ours.parameters["Rf"].value, ours.parameters["D"].value),
                     "cost": Objective(start, pts, force).cost(theta)})
        t0 = time.perf_counter()
        obj = Objective(start, pts, force)  # the solver build is timed, as it is inside fit()
        ls = least_squares(obj.residuals, np.zeros(2), jac="2-point", loss="huber", f_scale=HUBER, x_scale=1.0)
        rows.append({"seed": seed, "method": "least_squares, finite differences", "solves": obj.solves,
                     "time": time.perf_counter() - t0,
                     "errors": errors(*(np.array([0.6 * RF, 0.6 * D]) * np.exp(ls.x))), "cost": obj.cost(ls.x)})
        t0 = time.perf_counter()
        obj = Objective(start, pts, force)
        best = swarm(obj, np.random.default_rng(seed))
        rows.append({"seed": seed, "method": "particle swarm 50 × 20", "solves": obj.solves,
                     "time": time.perf_counter() - t0,
                     "errors": errors(*(np.array([0.6 * RF, 0.6 * D]) * np.exp(best))), "cost": obj.cost(best)})
    return rows


# ---- report --------------------------------------------------------------------------------------------------
def estimate_cells(value: float, std: float, truth: float) -> str:
    """Table cells: estimate | stated σ | relative error | error / σ."""
    err = value - truth
    return f"{value:.4f} | {std:.4f} | {err / truth * 100:+.2f} % | {err / std:+.2f}"


def report(cov: dict, sheet: dict, base: list[dict], tw: dict, args: argparse.Namespace, total: float) -> str:
    info = machine()
    lines = ["# Identification: σ coverage, the paper's sheet, cost against derivative-free fits (issue 16)", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} CPUs, Python {info.get('python')}, "
             f"{info.get('platform')}; load average at start {tuple(round(x, 2) for x in info.get('load_average', ()))}; "
             f"git {info.get('git', '?')}; generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC; "
             f"total {total:.0f} s. Command: `bash scripts/dlo-env run python bench/perf/fit.py --trials {args.trials} "
             f"--sheet-seeds {args.sheet_seeds} --baseline-seeds {args.baseline_seeds} --twist-trials {args.twist_trials}`. Times are wall-clock on a shared machine: compare them as "
             "ratios within this run.", "",
             "Data: the independent Kirchhoff shooting solver (test/reference/kirchhoff.py), points at random arc "
             "lengths, 30 % of the length occluded, Gaussian noise, shuffled. Fits start 40 % off (module docstring).", "",
             f"## 1. Coverage of the stated σ over {args.trials} seeded trials", "",
             "Cantilever, L = 0.5 m, Rf = 0.02 N·m², D = 0.5 N/m, 1.5 mm noise; force noise 2 mN per component.", "",
             "| quantity | within 1 σ | within 1.645 σ | within 2 σ | median relative error | max relative error |",
             "|---|---|---|---|---|---|"]
    for key in ("D/Rf (shape)", "Rf (force)", "D (force)"):
        z = np.abs(np.array(cov["rows"][key]))
        rel = np.array(cov["rows"][key + " rel"])
        n = np.sum(np.isfinite(z))
        lines.append(f"| {key} | {np.sum(z <= 1)}/{n} | {np.sum(z <= 1.645)}/{n} | {np.sum(z <= 2)}/{n} | "
                     f"{np.nanmedian(rel) * 100:.3f} % | {np.nanmax(rel) * 100:.3f} % |")
    lines += ["", f"Calibrated σ: 68 %, 90 %, 95 %. Equilibrium solves per fit: median {np.median(cov['solves']):.0f}, "
              f"max {max(cov['solves'])}; time per fit median {np.median(cov['times']):.2f} s.", "",
              "## 2. The paper's copy-paper sheet (sec. 5)", "",
              f"L = 200 mm, Rf = 1e4 gw·mm², D = 2e-3 gw/mm, both ends clamped horizontally, chords 180, 140, 70 mm "
              f"(sags {', '.join(f'{x:.1f}' for x in sheet['sag_mm'])} mm), 0.5 mm and 0.1 mm noise; fitted Rf and D from the "
              f"three shapes (only D/Rf determined), start Rf 50 % high. True ρ = D L³/Rf = {sheet['rho_true']:.4f}.", "",
              "| noise [mm] | seed | status | ρ | stated σ | error | error / σ | solves | time [s] | χ²_red |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in sheet["runs"]:
        lines.append(f"| {r['noise'] * 1e3:.1f} | {r['seed']} | {r['status']} | "
                     f"{estimate_cells(r['rho'], r['std'], sheet['rho_true'])} | {r['solves']} | {r['time']:.2f} | "
                     f"{r['chi2']:.3f} |")
    lines += ["", f"## 3. Rt/Rf from three poses with a twisted clamp ({len(tw['runs'])} seeds)", "",
              "Two clamps 0.3 m apart and 5 cm sideways, L = 0.5 m, the right clamp turned by 0, 1.5, 3 rad about the "
              f"tangent; 1.5 mm noise; Rf, Rt, D fitted from Rt 50 % low. True Rt/Rf = {tw['truth']:.3f}, D/Rf = {D / RF:.1f}.", "",
              "| seed | status | Rt/Rf | stated σ | error | error / σ | D/Rf | solves | time [s] |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in tw["runs"]:
        lines.append(f"| {r['seed']} | {r['status']} | {estimate_cells(r['value'], r['std'], tw['truth'])} | "
                     f"{r['d_rf']:.2f} | {r['solves']} | {r['time']:.2f} |")
    lines += ["", "## 4. Cost against derivative-free fits on the same data", "",
              "Cantilever with the clamp's force, fitting Rf and D (both determined). Every method calls the same "
              "warm-started `ShapeSolver`; solves = calls of `solve`.", "",
              "Robust cost: Σ Huber(|r_j|/σ) + ½ Σ (force residual/σ_F)² at each method's answer, evaluated the "
              "same way for all (least_squares applies its Huber loss per residual component, not per point).", "",
              "| seed | method | equilibrium solves | time [s] | Rf error | D error | robust cost |",
              "|---|---|---|---|---|---|---|"]
    for r in base:
        lines.append(f"| {r['seed']} | {r['method']} | {r['solves']} | {r['time']:.2f} | {r['errors'][0] * 100:.3f} % | "
                     f"{r['errors'][1] * 100:.3f} % | {r['cost']:.4f} |")
    by = {}
    for r in base:
        by.setdefault(r["method"], []).append(r)
    ours = by["IFT + LM (dlo fit)"]
    lines += [""]
    for name, rs in by.items():
        if rs is ours:
            continue
        ratio_s = np.mean([b["solves"] / a["solves"] for a, b in zip(ours, rs)])
        ratio_t = np.mean([b["time"] / a["time"] for a, b in zip(ours, rs)])
        lines.append(f"* {name}: {ratio_s:.1f}× the equilibrium solves and {ratio_t:.1f}× the time of the IFT fit "
                     "(mean over seeds).")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--sheet-seeds", type=int, default=5)
    ap.add_argument("--baseline-seeds", type=int, default=3)
    ap.add_argument("--twist-trials", type=int, default=10)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "fit.md"))
    args = ap.parse_args()
    t0 = time.perf_counter()
    base = baselines(args.baseline_seeds)
    print("baselines done", time.perf_counter() - t0, flush=True)
    sheet = paper_sheet(args.sheet_seeds)
    print("sheet done", time.perf_counter() - t0, flush=True)
    tw = twist(args.twist_trials)
    print("twist done", time.perf_counter() - t0, flush=True)
    cov = coverage(args.trials)
    text = report(cov, sheet, base, tw, args, time.perf_counter() - t0)
    Path(args.out).write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
