"""σ coverage of `dlo fit` on varied well-posed cantilevers, and the goodness-of-fit gate's false
alarms.

    bash scripts/dlo-env run python bench/perf/fit_coverage.py [--cases 30] [--seed 0]

Each case draws a cantilever (the independent Kirchhoff shooting solver,
test/reference/kirchhoff.py, which never imports dlo_ros): L in [0.3, 0.8] m, Rf log-uniform in
[0.005, 0.05] N·m², D L³/Rf in [1, 20], the clamp's tangent tilted by [-0.6, 0.3] rad, σ one of
0.5, 1.5, 3 mm, 200-400 points at random arc lengths, 30 % of the length occluded, shuffled.  D/Rf
is fitted from the shape, from a start 40 % off.  Printed: how many cases have |error| ≤ 1.645 σ
with the stated σ (sqrt(χ²_red) inflation undone; ``--stated 0.5`` states half the true noise) and
with the reported σ (inflated when χ²_red > 1), 1 σ and 2 σ likewise, and how many correct clouds
the gate calls a misfit.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "test"))
from reference.kirchhoff import solve_clamped  # noqa: E402

from dlo_ros.identify import Observation, ObservationSet, fit  # noqa: E402
from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties  # noqa: E402
from dlo_ros.model.rotations import matrix_to_quat  # noqa: E402
from dlo_ros.solver import SolverOptions  # noqa: E402


def tilted(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def case(rng: np.random.Generator) -> dict:
    length = rng.uniform(0.3, 0.8)
    bend = float(np.exp(rng.uniform(np.log(0.005), np.log(0.05))))
    weight = rng.uniform(1.0, 20.0) * bend / length ** 3
    return {"L": length, "Rf": bend, "D": weight, "tilt": rng.uniform(-0.6, 0.3),
            "sigma": float(rng.choice([5e-4, 1.5e-3, 3e-3])), "count": int(rng.integers(200, 401))}


def run(c: dict, rng: np.random.Generator,
        stated: float = 1.0) -> tuple[str, float, float, float, float]:
    """(status, error, stated σ, reported σ) of D/Rf and χ²_red; the observation states ``stated``
    × the true noise."""
    frame = tilted(c["tilt"])
    ref = solve_clamped(c["L"], c["Rf"], 0.75 * c["Rf"], np.zeros(3), frame, mode_end="free",
                        D=c["D"])
    s = rng.uniform(0.0, c["L"], c["count"])
    start = rng.uniform(0.05, 0.65) * c["L"]
    s = s[(s < start) | (s > start + 0.3 * c["L"])]
    pts = ref.position(s) + rng.normal(0.0, c["sigma"], (len(s), 3))
    string = StringProperties(c["L"], Profile.constant(c["Rf"]), Profile.constant(0.75 * c["Rf"]),
                              Profile.constant(0.6 * c["D"]))
    grip = Grip("hand", 0.0, "clamp", GripPose(np.zeros(3), matrix_to_quat(frame)))
    problem = Problem(string, (grip,))
    obs = Observation("c", {}, pts[rng.permutation(len(pts))], stated * c["sigma"])
    res = fit(problem, SolverOptions(), ObservationSet((obs,), ("Rf", "D")))
    est = res.ratios.get("D/Rf")
    if est is None:
        return res.status, np.nan, np.nan, np.nan, res.chi2_reduced
    error = est.value - c["D"] / c["Rf"]
    return res.status, error, est.std / res.sigma_scale, est.std, res.chi2_reduced


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stated", type=float, default=1.0,
                    help="the σ the observations state, × the true noise")
    args = ap.parse_args()
    rows = []
    for k in range(args.cases):
        rng = np.random.default_rng(args.seed * 10_000 + k)
        c = case(rng)
        status, err, stated, reported, chi2 = run(c, rng, args.stated)
        rows.append((status, err, stated, reported, chi2))
        ratio = c["D"] * c["L"] ** 3 / c["Rf"]
        print(f"case {k:2d}: L {c['L']:.3f} m, DL³/Rf {ratio:5.2f}, σ {c['sigma'] * 1e3:.1f} mm: "
              f"{status}, χ²_red {chi2:.3f}, error/σ stated {err / stated:+.2f}, "
              f"reported {err / reported:+.2f}", flush=True)
    err, stated, reported = (np.array([r[i] for r in rows]) for i in (1, 2, 3))
    n = len(rows)
    chi2 = np.array([r[4] for r in rows])
    print(f"χ²_red: min {np.nanmin(chi2):.3f}, max {np.nanmax(chi2):.3f}")
    print(f"misfit (false alarms): {sum(r[0] == 'misfit' for r in rows)}/{n}; not ok: "
          f"{sum(r[0] != 'ok' for r in rows)}/{n}")
    for name, sd in (("stated σ", stated), ("reported σ", reported)):
        z = np.abs(err / sd)
        print(f"{name}: within 1 σ {np.sum(z <= 1)}/{n}, 1.645 σ {np.sum(z <= 1.645)}/{n}, "
              f"2 σ {np.sum(z <= 2)}/{n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
