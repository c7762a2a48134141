"""Seeded random scenes, the long version (issue #12, "Random scenes"): every verdict checked.

    bash scripts/dlo-env run python bench/suite/random_scenes.py              # 200 seeds → bench/results/random_scenes.md
    bash scripts/dlo-env run python bench/suite/random_scenes.py --seeds 20   # a quick look (writes the same file)

Scenes from test/random_scenes.py (seeds 0 … N−1), each solved cold twice: ``model: auto`` with the
library defaults (``make_solver(problem)``: background checks; derivatives interpreted, ``compile='off'``,
as everywhere in bench/) and the fixed full 3D model (``model: full``, order 16, default director
rotation).  Time per scene = building the solver + the cold solve (what a caller waits for).

Checks, each against something other than the answer itself:

* every ``ok`` has a finite stability eigenvalue and an equilibrium residual ≤ the tolerance (1e-3·L);
  its shape holds the grips and stays clear of the obstacles (measured on the returned points);
* every ``ok`` agrees with the same scene at a higher order (the full model at 24, or the next order
  above the answer's: 32, 40), warm-started from the answer (same branch), within the tolerance;
* every ``unreachable``, ``invalid`` or ``infeasible`` verdict is false if the scene has a feasible
  point: the curve the generator built the scene around holds every grip (positions and frames are
  taken from it), is of the string's length and is measured here against each obstacle (signed
  distance).  It is also tried with the other model and cold at order 24; an ``ok`` there (checked as
  above) is a second proof.  An ``infeasible`` must carry a witness (the most violated row).
  Such a verdict is proven true when a grip's target lies inside an obstacle.
* ``failed`` and ``unverified`` are true statements about a solve; each is listed with the other
  model's and the order-24 answer, and for a cantilever (one clamp at s = 0) with the independent
  shooting reference (test/reference, loads raised from zero by continuation): if it finds an
  equilibrium clear of the obstacles, the scene was solvable.

    bash scripts/dlo-env run python bench/suite/random_scenes.py --only 98 141   # reproduce some seeds (prints)
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "test" / "unit"))  # test modules the bench reuses (references, set-ups)
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402
from reference.kirchhoff import blas_threads, continuation, solve_clamped  # noqa: E402

# test/random_scenes.py shares this script's name: load it by its path
_spec = importlib.util.spec_from_file_location("scene_generator", ROOT / "test" / "random_scenes.py")
scene_generator = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(scene_generator)
scene_and_curve = scene_generator.scene_and_curve

from dlo_ros.model.rotations import quat_to_matrix  # noqa: E402
from dlo_ros.solver.auto import make_solver  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.results.result import STATUSES  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402

MODELS = ("auto", "full")
FALSE_VERDICTS = ("unreachable", "invalid", "infeasible")
FINE_ORDERS = (24, 32, 40)  # the second order: the first of these above the answer's
REFERENCE_SECONDS = 60.0  # the shooting reference of a failed cantilever gives up after this long


# ---- the independent feasibility witness -------------------------------------------------------------
def signed_distance(ob, x: np.ndarray) -> np.ndarray:
    """Distance [m] of points x (K, 3) outside the obstacle (negative inside), written out here (not the
    solver's h) for the two kinds the generator makes."""
    if ob.type == "halfspace":
        return (x - ob.point) @ ob.normal
    if ob.type == "sphere":
        return np.linalg.norm(x - ob.centre, axis=1) - ob.radius
    raise NotImplementedError(ob.type)


def grip_errors(problem, s: np.ndarray, x: np.ndarray) -> float:
    """Largest distance [m] between a grip's target and the shape at the grip's arc length."""
    return max(float(np.linalg.norm(np.array([np.interp(g.s, s, x[:, k]) for k in range(3)]) - g.pose.position))
               for g in problem.grips)


def clearance(problem, x: np.ndarray) -> float:
    """Smallest signed distance [m] of the points x to any obstacle (inf without obstacles)."""
    return min((float(np.min(signed_distance(ob, x))) for ob in problem.obstacles), default=np.inf)


@dataclass
class Witness:
    """The generating curve as a feasible point: reach slack (min over grip pairs of arc length between
    them minus their distance), grip error, obstacle clearance, length shortfall of the sampled curve."""

    reach_slack: float
    grip_error: float
    clearance: float
    length_error: float
    grip_clearance: float  # smallest signed distance of a grip's target position to an obstacle

    @property
    def feasible(self) -> bool:
        return self.reach_slack >= 0 and self.grip_error <= 1e-12 and self.clearance > 0

    def text(self) -> str:
        return (f"generating curve: reach slack {self.reach_slack:.3g} m, grip error {self.grip_error:.1e} m, "
                f"obstacle clearance {self.clearance:.3g} m")


def witness(problem, curve) -> Witness:
    s, x, _ = curve
    grips = problem.grips
    slack = min((abs(a.s - b.s) - float(np.linalg.norm(a.pose.position - b.pose.position))
                 for i, a in enumerate(grips) for b in grips[i + 1:]), default=np.inf)
    length = float(np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1)))
    grip_x = np.array([g.pose.position for g in grips])
    return Witness(slack, grip_errors(problem, s, x), clearance(problem, x), problem.string.length - length,
                   clearance(problem, grip_x))


# ---- solving -----------------------------------------------------------------------------------------
@dataclass
class Run:
    model: str
    status: str
    message: str
    order: int
    residual: float
    eig: float | None
    stable: bool | None
    ms: float  # build + cold solve
    solve_ms: float
    tolerance: float
    problems: list[str] = field(default_factory=list)  # failed checks of an ok answer
    fine_diff: float = float("nan")  # max |Δx| against the second order [m]
    fine_order: int = 0
    verification: str = ""  # for a non-ok answer
    false_verdict: bool = False
    true_verdict: bool = False  # proven true (a grip inside an obstacle)


def solve(problem, model: str):
    """(the ShapeSolver holding the answer, the answer, build + solve ms)."""
    t0 = time.perf_counter()
    if model == "auto":
        solver = make_solver(problem, SolverOptions(), compile="off")
        result = solver.solve()
        ms = (time.perf_counter() - t0) * 1e3
        solver.close()  # waits for its background check, so that it does not run into the next timing
        return solver.inner, result, ms
    solver = ShapeSolver(problem, SolverOptions(model="full"), compile="off")
    result = solver.solve()
    return solver, result, (time.perf_counter() - t0) * 1e3


def run_of(model: str, result, ms: float, tolerance: float) -> Run:
    order = int(result.model.order if result.model is not None else result.order)
    return Run(model, result.status, result.message, order, float(result.equilibrium_residual_m),
               result.min_eigenvalue, result.stable, ms, result.solve_time_ms, tolerance)


class Fine:
    """The scene at a higher order, one solver per order, built when first needed."""

    def __init__(self, problem):
        self.problem, self.solvers = problem, {}

    def solver(self, order: int) -> ShapeSolver:
        if order not in self.solvers:
            self.solvers[order] = ShapeSolver(self.problem, SolverOptions(model="full", order=order), compile="off")
        return self.solvers[order]

    def warm_from(self, source: ShapeSolver, order: int):
        fine = self.solver(order)
        if not fine.adopt_warm_start(source):
            return None
        return fine.solve()

    def cold(self, order: int = FINE_ORDERS[0]):
        return self.solver(order).solve(warm=False)


def shape_problems(problem, result, tolerance: float) -> list[str]:
    """What is wrong with an ok answer, measured on its returned points (empty: nothing)."""
    out = []
    if result.min_eigenvalue is None or not np.isfinite(result.min_eigenvalue):
        out.append(f"eigenvalue {result.min_eigenvalue}")
    if not result.equilibrium_residual_m <= tolerance:
        out.append(f"residual {result.equilibrium_residual_m:.3g} m > tolerance {tolerance:.3g} m")
    err = grip_errors(problem, result.s, result.points)
    if err > tolerance:
        out.append(f"shape misses a grip by {err:.3g} m")
    # between the 51 returned points a chord may cut an obstacle a little: allow the tolerance
    if clearance(problem, result.points) < -tolerance:
        out.append(f"shape enters an obstacle by {-clearance(problem, result.points):.3g} m")
    return out


def check_ok(run: Run, problem, source: ShapeSolver, result, fine: Fine) -> None:
    run.problems += shape_problems(problem, result, run.tolerance)
    run.fine_order = next(o for o in FINE_ORDERS if o > run.order)
    r2 = fine.warm_from(source, run.fine_order)
    if r2 is None or not r2.ok:
        run.problems.append(f"order {run.fine_order} from this answer: "
                            f"{'no warm start' if r2 is None else r2.status + ' (' + r2.message[:120] + ')'}")
        return
    run.fine_diff = float(np.max(np.linalg.norm(r2.points - result.points, axis=1)))
    if not run.fine_diff <= run.tolerance:
        run.problems.append(f"order {run.fine_order} lies {run.fine_diff:.3g} m away (tolerance {run.tolerance:.3g} m)")


def verify(run: Run, other: Run, problem, wit: Witness, fine: Fine, cold24, reference_cache: dict) -> None:
    """Why a non-ok verdict is true or false (run.verification, run.false_verdict)."""
    notes = []
    if run.status == "infeasible" and "most violated" not in run.message:
        notes.append("NO WITNESS in the message")
    proofs, truths = [], []
    if run.status in FALSE_VERDICTS:
        if wit.feasible:
            proofs.append("the generating curve is feasible")
        if wit.grip_clearance < 0:
            truths.append(f"a grip's target lies {-wit.grip_clearance:.3g} m inside an obstacle")
    if other.status == "ok" and not other.problems:
        proofs.append(f"{other.model} solves it (ok, checked)")
    if cold24 is not None and cold24.ok and not shape_problems(problem, cold24, run.tolerance):
        proofs.append(f"full order {FINE_ORDERS[0]} cold solves it (ok, checked)")
    if run.status == "failed" and len(problem.grips) == 1 and problem.grips[0].mode == "clamp" and \
            problem.grips[0].s == 0.0:
        ref = reference_cache.setdefault(id(problem), cantilever_reference(problem))
        if ref is not None and (not problem.obstacles or clearance(problem, ref.x) > 0):
            proofs.append("the shooting reference finds an equilibrium (loads raised from 0 in 20 steps; "
                          f"obstacle clearance {clearance(problem, ref.x):.3g} m)")
        else:
            notes.append("shooting reference (loads raised from 0): " +
                         ("no equilibrium found" if ref is None else "its equilibrium enters an obstacle"))
    notes.append(wit.text())
    notes.append(f"{other.model}: {other.status}")
    notes.append(f"full {FINE_ORDERS[0]} cold: {cold24.status if cold24 is not None else '—'}")
    if run.status in FALSE_VERDICTS:
        run.false_verdict = bool(proofs)
        run.true_verdict = bool(truths) and not proofs
        verdict = ("FALSE: " + "; ".join(proofs)) if proofs else ("TRUE: " + "; ".join(truths)) if truths else \
            "not disproved"
    else:
        verdict = ("a solution exists: " + "; ".join(proofs)) if proofs else "no ok answer found by any means"
    run.verification = verdict + " — " + "; ".join(notes)


def cantilever_reference(problem):
    """A Kirchhoff equilibrium of a cantilever scene (one clamp at s = 0, dead weight and point loads with
    their moments), independent of the solver: shooting (test/reference) with the loads raised from 0
    in 20 steps, each solve started from the previous; None when it does not converge within
    REFERENCE_SECONDS."""
    grip = problem.grips[0]
    st = problem.string
    loads = [(ld.s, ld.force, ld.moment) for ld in problem.loads]

    deadline = time.perf_counter() + REFERENCE_SECONDS

    def solve_at(fraction, guess):
        if time.perf_counter() > deadline:
            raise RuntimeError("out of time")
        return solve_clamped(st.length, st.bend_stiffness.maximum, st.twist_stiffness.maximum, grip.pose.position,
                             quat_to_matrix(grip.pose.orientation), mode_end="free",
                             D=fraction * st.weight_per_length.maximum, g=problem.gravity,
                             loads=[(s, fraction * f, fraction * m) for s, f, m in loads], guess=guess,
                             s_eval=np.linspace(0.0, st.length, 401))

    try:
        with blas_threads(1):
            return continuation(solve_at, np.linspace(0.0, 1.0, 21), guess=(np.zeros(3), np.zeros(3)))[-1][1]
    except RuntimeError:
        return None


def describe(problem) -> str:
    st = problem.string
    modes = "/".join(g.mode for g in problem.grips)
    load = ""
    if problem.loads:
        ld = problem.loads[0]
        load = " F" + ("+M" if np.any(ld.moment) else "")
    obs = "".join(f" {ob.name}" for ob in problem.obstacles)
    weight = st.weight_per_length.maximum
    return f"L {st.length:.2f} {modes}{load}{obs}" + (f" D {weight:.2f}" if weight else "")


def one_seed(seed: int):
    problem, curve = scene_and_curve(seed)
    tol = 1e-3 * problem.string.length
    wit = witness(problem, curve)
    fine = Fine(problem)
    runs, sources, results = {}, {}, {}
    for model in MODELS:
        sources[model], results[model], ms = solve(problem, model)
        runs[model] = run_of(model, results[model], ms, tol)
    for model in MODELS:
        if runs[model].status == "ok":
            check_ok(runs[model], problem, sources[model], results[model], fine)
    if any(r.status != "ok" for r in runs.values()):
        cold24, cache = fine.cold(), {}
        for model, other in (("auto", "full"), ("full", "auto")):
            if runs[model].status != "ok":
                verify(runs[model], runs[other], problem, wit, fine, cold24, cache)
    return problem, wit, runs


# ---- report --------------------------------------------------------------------------------------------
def fmt(v, spec=".2e") -> str:
    return "—" if v is None or (isinstance(v, float) and np.isnan(v)) else format(v, spec)


def report(rows, args, info, wall_s: float, load_end) -> str:
    lines = ["# Random scenes, the long version (issue #12)", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other engineers' jobs; load "
             f"average {', '.join(f'{v:.2f}' for v in info.get('load_average', ()))} at the start, "
             f"{', '.join(f'{v:.2f}' for v in load_end)} at the end), Python {info.get('python')}; git {info.get('git', '?')}.",
             f"Command: `bash scripts/dlo-env run python bench/suite/random_scenes.py "
             f"{'--only ' + ' '.join(map(str, args.only)) if args.only else '--seeds ' + str(args.seeds)}` "
             f"({len(rows)} seeds; wall time {wall_s / 60:.1f} min).", "",
             "Each scene (test/random_scenes.py) solved cold by `model: auto` (library defaults: `make_solver(problem)`,"
             " background checks) and by the fixed full 3D model (`model: full`, order 16, director).  Derivatives"
             " interpreted (`compile='off'`).  Tolerance 1e-3·L.  Checks and their independent means: see the"
             " module docstring of bench/suite/random_scenes.py.", ""]
    lines += ["## Status counts", "", "| model | " + " | ".join(STATUSES) + " | total |",
              "|---|" + "---|" * (len(STATUSES) + 1)]
    for model in MODELS:
        statuses = [r[2][model].status for r in rows]
        lines.append(f"| {model} | " + " | ".join(str(statuses.count(s)) for s in STATUSES) + f" | {len(statuses)} |")
    lines += ["", "## Checks", "",
              "| model | ok | finite eigenvalue | stable / unstable | residual ≤ tol | agrees with the higher order |"
              " ok with a failed check | false verdicts (unreachable/invalid/infeasible disproved) | verdicts proven true |"
              " infeasible without witness | failed although an equilibrium is known |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for model in MODELS:
        runs = [r[2][model] for r in rows]
        ok = [r for r in runs if r.status == "ok"]
        finite = sum(r.eig is not None and np.isfinite(r.eig) for r in ok)
        stable = sum(r.stable is True for r in ok)
        unstable = sum(r.stable is False for r in ok)
        res = sum(r.residual <= r.tolerance for r in ok)
        agree = sum(r.fine_diff <= r.tolerance for r in ok)
        bad = sum(bool(r.problems) for r in ok)
        false = sum(r.false_verdict for r in runs)
        nowit = sum(r.status == "infeasible" and "most violated" not in r.message for r in runs)
        true = sum(r.true_verdict for r in runs)
        solvable = sum(r.status in ("failed", "unverified") and r.verification.startswith("a solution exists") for r in runs)
        lines.append(f"| {model} | {len(ok)} | {finite} | {stable} / {unstable} | {res} | {agree} | {bad} | {false} | "
                     f"{true} | {nowit} | {solvable} |")
    moments = [r for r in rows if any(np.any(ld.moment) for ld in r[1].loads)]
    for model in MODELS:
        failed = [r[2][model] for r in rows if r[2][model].status == "failed"]
        lines.append(f"\n{model}: {len(failed)} failed, {sum(f.message.startswith('point moments') for f in failed)} of them "
                     f"in the point moments' re-centring; {sum(r[2][model].status == 'failed' for r in moments)} of the "
                     f"{len(moments)} scenes with a point moment failed.")
    lines += ["", "## Time per scene (build + cold solve, ms)", "", "| model | median | p90 | max | median of the solve alone |",
              "|---|---|---|---|---|"]
    for model in MODELS:
        t = np.array([r[2][model].ms for r in rows])
        ts = np.array([r[2][model].solve_ms for r in rows])
        lines.append(f"| {model} | {np.median(t):.0f} | {np.percentile(t, 90):.0f} | {t.max():.0f} | {np.median(ts):.0f} |")
    lines += ["", "## Every non-ok answer", ""]
    nonok = [(seed, problem, run) for seed, problem, runs, _ in rows for run in runs.values() if run.status != "ok"]
    if not nonok:
        lines.append("None.")
    else:
        lines += ["| seed | scene | model | status | message | verification |", "|---|---|---|---|---|---|"]
        for seed, problem, run in nonok:
            msg = run.message.replace("|", "/")[:240]
            lines.append(f"| {seed} | {describe(problem)} | {run.model} | {run.status} | {msg} | {run.verification.replace('|', '/')} |")
    lines += ["", "## ok answers that failed a check", ""]
    badok = [(seed, problem, run) for seed, problem, runs, _ in rows for run in runs.values()
             if run.status == "ok" and run.problems]
    if not badok:
        lines.append("None.")
    else:
        lines += ["| seed | scene | model | order | residual m | failed checks |", "|---|---|---|---|---|---|"]
        for seed, problem, run in badok:
            lines.append(f"| {seed} | {describe(problem)} | {run.model} | {run.order} | {fmt(run.residual)} | "
                         f"{'; '.join(run.problems)} |")
    lines += ["", "## Every scene", "",
              "Per model: status, order, equilibrium residual [m], min eigenvalue, build + solve [ms], and for an ok"
              " answer max |Δx| [m] to the higher order.", "",
              "| seed | scene | tol m | auto | full | curve clearance m |", "|---|---|---|---|---|---|"]
    for seed, problem, runs, wit in rows:
        cells = []
        for model in MODELS:
            r = runs[model]
            cells.append(f"{r.status} {r.order} res {fmt(r.residual)} eig {fmt(r.eig, '.3g')} {r.ms:.0f} ms"
                         + (f" Δ{r.fine_order} {fmt(r.fine_diff)}" if r.status == "ok" else ""))
        clear = "—" if not np.isfinite(wit.clearance) else f"{wit.clearance:.3g}"
        lines.append(f"| {seed} | {describe(problem)} | {1e-3 * problem.string.length:.1e} | {cells[0]} | {cells[1]} | {clear} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=200, help="seeds 0 … N−1 (default 200)")
    ap.add_argument("--only", type=int, nargs="+", help="just these seeds (a reproducer; prints, writes only with --out)")
    ap.add_argument("--out", type=Path, default=None, help="default: bench/results/random_scenes.md (not with --only)")
    args = ap.parse_args()
    if args.out is None and not args.only:
        args.out = ROOT / "bench" / "results" / "random_scenes.md"
    info = machine()
    t0 = time.perf_counter()
    rows = []
    for seed in args.only or range(args.seeds):
        t1 = time.perf_counter()
        problem, wit, runs = one_seed(seed)
        rows.append((seed, problem, runs, wit))
        line = "  ".join(f"{m} {r.status} {r.order} res {fmt(r.residual)} eig {fmt(r.eig, '.3g')} "
                         f"{'; '.join(r.problems) or r.verification[:100]}" for m, r in runs.items())
        print(f"seed {seed:3d} ({time.perf_counter() - t1:5.1f} s) {describe(problem)}: {line}", flush=True)
        if args.out is not None and len(rows) % 10 == 0:  # a run cut short still leaves its rows
            args.out.write_text(report(rows, args, info, time.perf_counter() - t0, os.getloadavg()))
    text = report(rows, args, info, time.perf_counter() - t0, os.getloadavg())
    if args.out is None:
        print(text)
        return
    args.out.write_text(text)
    print(f"wrote {args.out} ({(time.perf_counter() - t0) / 60:.1f} min)")


if __name__ == "__main__":
    main()
