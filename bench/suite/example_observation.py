"""Writes the shipped example for ``dlo fit``: config/observations/default_cable_hanging.yaml (+ .npy).

    bash scripts/dlo-env run python bench/suite/example_observation.py

A cable like ``default_cable`` but heavier and stiffer than the scene says (Rf = 0.03 N·m², D = 0.7 N/m
instead of 0.02 and 0.5) hangs between the scene's two clamps.  Its shape comes from the independent
Kirchhoff shooting solver (test/reference/kirchhoff.py, weight raised from 0), not from the package's
solver; the "camera" sees it with 1.5 mm noise per coordinate, misses 30 % of the length, and returns
the points in random order.  A force/torque sensor on the left gripper reads its force with 0.01 N noise.
``dlo fit`` on the file should recover Rf and D within their stated σ.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(ROOT / "test" / "unit"))  # test modules the bench reuses (references, set-ups)

from reference.kirchhoff import continuation, solve_clamped  # noqa: E402

RF, RT, D = 0.03, 0.015, 0.7  # the "real" cable [N·m², N·m², N/m]
SIGMA, FORCE_SIGMA = 1.5e-3, 0.01
OUT = ROOT / "config" / "observations"


def main() -> None:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    rng = np.random.default_rng(7)
    left, right = np.array([0.0, 0.0, 0.4]), np.array([0.6, 0.0, 0.4])

    def at(fraction, guess):
        return solve_clamped(1.0, RF, RT, left, np.eye(3), right, np.eye(3), mode_end="clamp", D=fraction * D,
                             g=(0.0, 0.0, -1.0), guess=guess, s_eval=np.linspace(0.0, 1.0, 2001))

    # start: the weightless clamped-clamped elastica buckled downward (x-z plane), small-amplitude guess
    lam, k = 2 * np.pi, np.sqrt(1 - 0.6)
    guess = (np.array([-lam**2 * RF, 0.0, 0.0]), np.array([0.0, 2 * k * lam * RF, 0.0]))
    sol = continuation(at, np.linspace(0.0, 1.0, 11), guess=guess)[-1][1]
    assert sol.x[:, 2].min() < 0.4 - 0.1, "the reference buckled upward"
    assert sol.residual < 1e-9
    visible = (sol.s < 0.35) | (sol.s > 0.65)  # 30 % of the length occluded
    picks = rng.choice(np.flatnonzero(visible), 300, replace=False)
    points = sol.x[picks] + rng.normal(scale=SIGMA, size=(300, 3))
    rng.shuffle(points)
    force = sol.force0 + rng.normal(scale=FORCE_SIGMA, size=3)
    OUT.mkdir(exist_ok=True)
    np.save(OUT / "default_cable_hanging.npy", points)
    doc = {
        "scene": "default_cable",
        "sigma": SIGMA,
        "parameters": ["Rf", "D"],
        "observations": [{"name": "hanging", "points_file": "default_cable_hanging.npy",
                          "force": {"grip": "left", "force": [round(float(f), 5) for f in force],
                                    "sigma": FORCE_SIGMA}}],
    }
    header = ("# Example for `dlo fit` (msg_docs/fitting.md), written by bench/suite/example_observation.py: default_cable's\n"
              f"# clamps holding a cable with Rf = {RF} N m^2 and D = {D} N/m (the scene says 0.02 and 0.5), shape from\n"
              "# the independent Kirchhoff shooting solver, 1.5 mm noise, 30 % occluded, shuffled; left grip force\n"
              "# with 0.01 N noise.\n")
    (OUT / "default_cable_hanging.yaml").write_text(header + yaml.safe_dump(doc, sort_keys=False))
    print(f"wrote {OUT / 'default_cable_hanging.yaml'} (+ .npy); true force at the left grip {sol.force0}")


if __name__ == "__main__":
    main()
