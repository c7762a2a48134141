"""Seeded random scenes under the default model at two tolerances (issue #37, "200 random scenes").

    bash scripts/dlo-env run python bench/suite/random_scenes.py              # 200 seeds → bench/results/random_scenes.md
    bash scripts/dlo-env run python bench/suite/random_scenes.py --seeds 20   # a quick look (writes the same file)
    bash scripts/dlo-env run python bench/suite/random_scenes.py --only 31 57 # reproduce some seeds (prints)

Scenes from test/random_scenes.py (seeds 0 … N−1), each solved cold by ``solver.model: auto`` (library
defaults, checked inline as ``dlo solve`` does: ``make_solver(problem, checks='sync')``; derivatives
interpreted, ``compile='off'``, as everywhere in bench/) twice: ``error_tolerance`` 1e-3·L and 1e-4·L,
each on a fresh solver.  Time per scene = building the solver + the cold solve.

Checks, each against something other than the answer's own claim:

* **every ok is verified**: its equilibrium residual ≤ its tolerance; its returned points hold every grip
  within the tolerance and stay clear of the obstacles (signed distances written out here, not the
  solver's); it carries a stability verdict (``stable`` not None, with a finite eigenvalue or, when the
  constraints leave the shape no freedom, the message saying so).
* **no infeasible without a witness**: an ``infeasible`` message names its most violated row; and every
  ``unreachable``/``invalid``/``infeasible`` verdict is tested against the curve the generator built the
  scene around (it holds every grip, has the string's length, and is measured against each obstacle):
  when that curve is feasible, the verdict is false.
* **the two tolerances agree**: when both answers are ok, the largest distance between their centrelines
  on the same arc-length samples (both results are sampled at the same ``output_points`` arc lengths) is
  at most 1e-3·L + 1e-4·L.  Why that bound: an answer that meets its tolerance lies within it of the
  exact equilibrium on its branch, so two such answers lie within the sum of the two tolerances of each
  other (triangle inequality); the 1e-4·L is the margin on top of the looser tolerance, and a pair over
  it means one of the two claims is false (or the two are on different branches, which is listed).
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
from scipy.interpolate import CubicSpline

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402

# test/random_scenes.py shares this script's name: load it by its path
_spec = importlib.util.spec_from_file_location(
    "scene_generator", ROOT / "test" / "random_scenes.py"
)
scene_generator = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(scene_generator)
scene_and_curve = scene_generator.scene_and_curve

from dlo_ros.solver.auto import make_solver  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.results.result import STATUSES  # noqa: E402

TOLERANCES = (1e-3, 1e-4)  # error_tolerance / L
#: centreline samples per answer: L/400 apart, so that the spline through them (grip check) is
#: within 1e-6 m of the shape even where a moment winds it into turns (seed 130 at 51 samples:
#: 2e-4 m off a grip the shape holds to 5e-7 m)
OUTPUT_POINTS = 401
FALSE_VERDICTS = ("unreachable", "invalid", "infeasible")


# ---- the independent feasibility witness -------------------------------------------------------
def signed_distance(ob, x: np.ndarray) -> np.ndarray:
    """Distance [m] of points x (K, 3) outside the obstacle (negative inside), written out here (not
    the solver's h) for the two kinds the generator makes."""
    if ob.type == "halfspace":
        return (x - ob.point) @ ob.normal
    if ob.type == "sphere":
        return np.linalg.norm(x - ob.centre, axis=1) - ob.radius
    raise NotImplementedError(ob.type)


def grip_errors(problem, s: np.ndarray, x: np.ndarray) -> float:
    """Largest distance [m] between a grip's target and the shape at the grip's arc length.

    The shape between its samples by a cubic spline through them: a chord (linear interpolation)
    of samples L/50 apart missed a curved string by h²κ/8, up to 5e-4 m here, over the 1e-4·L
    tolerance; the spline's error is O(h⁴κ³): with OUTPUT_POINTS samples under 1e-6 m.
    """
    spline = CubicSpline(s, x, axis=0)
    return max(float(np.linalg.norm(spline(g.s) - g.pose.position)) for g in problem.grips)


def clearance(problem, x: np.ndarray) -> float:
    """Smallest signed distance [m] of the points x to any obstacle (inf without obstacles)."""
    return min((float(np.min(signed_distance(ob, x))) for ob in problem.obstacles), default=np.inf)


@dataclass
class Witness:
    """The generating curve as a feasible point: reach slack (min over grip pairs of arc length
    between them minus their distance), grip error, obstacle clearance."""

    reach_slack: float
    grip_error: float
    clearance: float
    grip_clearance: float  # smallest signed distance of a grip's target position to an obstacle

    @property
    def feasible(self) -> bool:
        return self.reach_slack >= 0 and self.grip_error <= 1e-12 and self.clearance > 0

    def text(self) -> str:
        return (
            f"generating curve: reach slack {self.reach_slack:.3g} m, grip error "
            f"{self.grip_error:.1e} m, obstacle clearance {self.clearance:.3g} m"
        )


def witness(problem, curve) -> Witness:
    s, x, _ = curve
    grips = problem.grips
    slack = min(
        (
            abs(a.s - b.s) - float(np.linalg.norm(a.pose.position - b.pose.position))
            for i, a in enumerate(grips)
            for b in grips[i + 1 :]
        ),
        default=np.inf,
    )
    grip_x = np.array([g.pose.position for g in grips])
    return Witness(
        slack, grip_errors(problem, s, x), clearance(problem, x), clearance(problem, grip_x)
    )


# ---- one answer --------------------------------------------------------------------------------
@dataclass
class Run:
    """One cold auto answer at one tolerance, and what the checks found."""

    relative: float  # error_tolerance / L
    tolerance: float  # [m]
    status: str
    message: str
    model: str  # e.g. 'full 16' or 'planar elements 3×8'
    residual: float
    eig: float | None
    stable: bool | None
    estimate: float | None
    tolerance_met: bool | None
    ms: float
    points: np.ndarray
    problems: list[str] = field(default_factory=list)  # failed checks of an ok answer
    false_verdict: bool = False
    true_verdict: bool = False  # proven true: a grip's target lies inside an obstacle
    no_witness: bool = False

    @property
    def verified(self) -> bool:
        return self.status == "ok" and not self.problems


def model_name(result) -> str:
    """E.g. 'planar 12', 'full 16×3' (order × elements)."""
    m = result.model
    if m is None:
        return f"{result.basis} {result.order}"
    return (
        ("planar" if m.planar else "full")
        + f" {m.order}"
        + (f"×{m.elements}" if m.elements else "")
    )


def solve(problem, relative: float) -> Run:
    tolerance = relative * problem.string.length
    t0 = time.perf_counter()
    solver = make_solver(
        problem,
        SolverOptions(error_tolerance=tolerance, output_points=OUTPUT_POINTS),
        compile="off",
        checks="sync",
    )
    r = solver.solve()
    ms = (time.perf_counter() - t0) * 1e3
    solver.close()
    summary = r.model.as_dict() if r.model is not None else {}
    return Run(
        relative,
        tolerance,
        r.status,
        r.message,
        model_name(r),
        float(r.equilibrium_residual_m),
        r.min_eigenvalue,
        r.stable,
        summary.get("estimated_error_m"),
        summary.get("tolerance_met"),
        ms,
        np.asarray(r.points),
        [] if not r.ok else ok_problems(problem, r, tolerance),
    )


def ok_problems(problem, result, tolerance: float) -> list[str]:
    """What is wrong with an ok answer, measured on its returned points (empty: nothing)."""
    out = []
    if result.stable is None:
        out.append("no stability verdict")
    elif result.min_eigenvalue is not None and not np.isfinite(result.min_eigenvalue):
        out.append(f"eigenvalue {result.min_eigenvalue}")
    if not result.equilibrium_residual_m <= tolerance:
        out.append(f"residual {result.equilibrium_residual_m:.3g} m > {tolerance:.3g} m")
    err = grip_errors(problem, result.s, result.points)
    if err > tolerance:
        out.append(f"misses a grip by {err:.3g} m")
    # between the returned points a chord may cut an obstacle a little: allow the tolerance
    if clearance(problem, result.points) < -tolerance:
        out.append(f"enters an obstacle by {-clearance(problem, result.points):.3g} m")
    return out


def judge_verdict(run: Run, wit: Witness) -> None:
    if run.status == "infeasible" and "most violated" not in run.message:
        run.no_witness = True
    if run.status in FALSE_VERDICTS and wit.feasible:
        run.false_verdict = True
    if run.status in FALSE_VERDICTS and wit.grip_clearance < 0:
        run.true_verdict = True


@dataclass
class Row:
    seed: int
    problem: object
    wit: Witness
    runs: tuple[Run, ...]

    @property
    def distance(self) -> float:
        """Largest distance [m] between the two tolerances' centrelines (NaN unless both ok)."""
        a, b = self.runs
        if not (a.status == b.status == "ok") or a.points.shape != b.points.shape:
            return float("nan")
        return float(np.max(np.linalg.norm(a.points - b.points, axis=1)))

    @property
    def bound(self) -> float:
        return sum(r.tolerance for r in self.runs)

    @property
    def disagree(self) -> bool:
        return bool(self.distance > self.bound)


def one_seed(seed: int) -> Row:
    problem, curve = scene_and_curve(seed)
    wit = witness(problem, curve)
    runs = tuple(solve(problem, rel) for rel in TOLERANCES)
    for run in runs:
        judge_verdict(run, wit)
    return Row(seed, problem, wit, runs)


# ---- report ------------------------------------------------------------------------------------
def fmt(v, spec=".2e") -> str:
    return "—" if v is None or (isinstance(v, float) and np.isnan(v)) else format(v, spec)


def describe(problem) -> str:
    st = problem.string
    modes = "/".join(g.mode for g in problem.grips)
    load = ""
    if problem.loads:
        load = " F" + ("+M" if np.any(problem.loads[0].moment) else "")
    obs = "".join(f" {ob.name}" for ob in problem.obstacles)
    weight = st.weight_per_length.maximum
    return f"L {st.length:.2f} {modes}{load}{obs}" + (f" D {weight:.2f}" if weight else "")


def header(rows, args, info, wall_s: float, load_end) -> list[str]:
    load = ", ".join(f"{v:.2f}" for v in info.get("load_average", ()))
    argv = "--only " + " ".join(map(str, args.only)) if args.only else f"--seeds {args.seeds}"
    return [
        "# Random scenes under the default model, two tolerances (issue #37)",
        "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores (shared with other jobs; load "
        f"average {load} at the start, {', '.join(f'{v:.2f}' for v in load_end)} at the end), "
        f"Python {info.get('python')}; git {info.get('git', '?')}.",
        f"Command: `nice bash scripts/dlo-env run python bench/suite/random_scenes.py {argv}` "
        f"({len(rows)} seeds; wall time {wall_s / 60:.1f} min).",
        "",
        "Each scene (test/random_scenes.py) solved cold by `model: auto` (checked inline, as "
        "`dlo solve`: `make_solver(problem, checks='sync')`; `compile='off'`) at `error_tolerance` "
        "1e-3·L and 1e-4·L.  Checks and their independent means: the module docstring of "
        "bench/suite/random_scenes.py.",
        "",
    ]


def totals(rows) -> list[str]:
    lines = [
        "## Totals",
        "",
        "| tolerance | "
        + " | ".join(STATUSES)
        + " | ok verified | ok with a stability verdict (stable / unstable) | tolerance_met true "
        "/ false / none | false verdicts | verdicts proven true | infeasible without witness | "
        "median ms | max ms |",
        "|---|" + "---|" * (len(STATUSES) + 8),
    ]
    for k, rel in enumerate(TOLERANCES):
        runs = [row.runs[k] for row in rows]
        st = [r.status for r in runs]
        ok = [r for r in runs if r.status == "ok"]
        met = [r.tolerance_met for r in ok]
        ms = np.array([r.ms for r in runs])
        lines.append(
            f"| {rel:.0e}·L | "
            + " | ".join(str(st.count(s)) for s in STATUSES)
            + f" | {sum(r.verified for r in ok)} of {len(ok)}"
            f" | {sum(r.stable is not None for r in ok)} ({sum(r.stable is True for r in ok)} / "
            f"{sum(r.stable is False for r in ok)})"
            f" | {met.count(True)} / {met.count(False)} / {met.count(None)}"
            f" | {sum(r.false_verdict for r in runs)} | {sum(r.true_verdict for r in runs)}"
            f" | {sum(r.no_witness for r in runs)}"
            f" | {np.median(ms):.0f} | {ms.max():.0f} |"
        )
    both = [row for row in rows if np.isfinite(row.distance)]
    d = np.array([row.distance / row.problem.string.length for row in both])
    lines += [
        "",
        f"Both tolerances ok: {len(both)} scenes; the distance between their centrelines "
        f"(same arc lengths) over L: median {fmt(np.median(d) if d.size else None)}, max "
        f"{fmt(d.max() if d.size else None)}; over the bound 1.1e-3·L: "
        f"{sum(row.disagree for row in both)}.",
        "",
    ]
    return lines


def proven(r: Run, wit: Witness) -> str:
    """The verdict's independent proof, for the table ('' when none)."""
    if r.true_verdict:
        return f"; TRUE: a grip's target lies {-wit.grip_clearance:.3g} m inside an obstacle"
    if r.false_verdict:
        return "; FALSE: the generating curve is feasible"
    return ""


def run_cell(r: Run) -> str:
    eig = fmt(r.eig, ".3g")
    cell = f"{r.status} {r.model} res {fmt(r.residual)} est {fmt(r.estimate)} eig {eig}"
    cell += f" st {r.stable} met {r.tolerance_met} {r.ms:.0f} ms"
    return cell.replace("|", "/")


def details(rows) -> list[str]:
    lines = ["## Every answer that is not a verified ok, or a pair that disagrees", ""]
    bad = [
        (row, r)
        for row in rows
        for r in row.runs
        if not r.verified or (r is row.runs[0] and row.disagree)
    ]
    if not bad:
        lines.append("None.")
    else:
        lines += ["| seed | scene | tolerance | status | message / failed checks | curve |"]
        lines += ["|---|---|---|---|---|---|"]
        for row, r in bad:
            why = "; ".join(r.problems) or r.message[:240]
            if r.status == "ok" and row.disagree:
                why += f"; the two tolerances lie {row.distance:.3g} m apart"
            lines.append(
                f"| {row.seed} | {describe(row.problem)} | {r.relative:.0e}·L | {r.status} | "
                f"{why.replace('|', '/')} | {row.wit.text()}{proven(r, row.wit)} |"
            )
    lines += [
        "",
        "## Every scene",
        "",
        "Per tolerance: status, model, equilibrium residual [m], estimated error [m], min "
        "eigenvalue, stable, tolerance_met, build + solve [ms]; Δ = max distance between the two "
        "answers over L.",
        "",
        "| seed | scene | 1e-3·L | 1e-4·L | Δ/L |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        a, b = row.runs
        delta = fmt(row.distance / row.problem.string.length)
        lines.append(
            f"| {row.seed} | {describe(row.problem)} | {run_cell(a)} | {run_cell(b)} | {delta} |"
        )
    return lines


def report(rows, args, info, wall_s: float, load_end) -> str:
    lines = header(rows, args, info, wall_s, load_end) + totals(rows) + details(rows)
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=200, help="seeds 0 … N−1 (default 200)")
    ap.add_argument(
        "--only", type=int, nargs="+", help="just these seeds (prints; --out to write)"
    )
    ap.add_argument(
        "--out", type=Path, default=None, help="default: bench/results/random_scenes.md"
    )
    args = ap.parse_args()
    if args.out is None and not args.only:
        args.out = ROOT / "bench" / "results" / "random_scenes.md"
    info = machine()
    t0 = time.perf_counter()
    rows = []
    for seed in args.only or range(args.seeds):
        t1 = time.perf_counter()
        row = one_seed(seed)
        rows.append(row)
        cells = "  ".join(
            f"[{r.relative:.0e}] {run_cell(r)} {'; '.join(r.problems) or r.message[:80]}"
            for r in row.runs
        )
        dist = fmt(row.distance / row.problem.string.length)
        print(
            f"seed {seed:3d} ({time.perf_counter() - t1:5.1f} s) {describe(row.problem)}: "
            f"{cells}  Δ/L {dist}",
            flush=True,
        )
        if args.out is not None and len(rows) % 10 == 0:  # a run cut short still leaves its rows
            args.out.write_text(
                report(rows, args, info, time.perf_counter() - t0, os.getloadavg())
            )
    text = report(rows, args, info, time.perf_counter() - t0, os.getloadavg())
    if args.out is None:
        print(text)
        return
    args.out.write_text(text)
    print(f"wrote {args.out} ({(time.perf_counter() - t0) / 60:.1f} min)")


if __name__ == "__main__":
    main()
