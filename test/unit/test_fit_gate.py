"""The goodness-of-fit gate of `dlo fit` (dlo_ros/identify/gate.py, msg_docs/fitting.md "When the
fit does not fit"): points the scene's string cannot explain give status `misfit` naming the cause,
exit code 1 with one line on stderr, and no `--write-scene`; points it can explain still pass.

Every cloud comes from the independent Kirchhoff shooting solver (test/reference/kirchhoff.py) or a
closed form: a cantilever clamped at the origin, its tangent 0.3 rad below horizontal, hanging
under its weight, 1.5 mm noise.  The scene says L = 0.5 m.
"""
from __future__ import annotations

import re

import numpy as np
import pytest
import yaml

from reference.kirchhoff import solve_clamped

from dlo_ros import cli
from dlo_ros.identify import Observation, ObservationSet, fit
from dlo_ros.identify.gate import MODEL_ERROR_FLOOR, arc_length, threshold
from dlo_ros.model import Grip, GripPose, Problem, Profile, StringProperties
from dlo_ros.model.rotations import matrix_to_quat
from dlo_ros.solver import SolverOptions

L, RF, RT, D, TILT, SIGMA = 0.5, 0.02, 0.015, 0.5, -0.3, 1.5e-3


def frame(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def scene() -> Problem:
    string = StringProperties(L, Profile.constant(RF), Profile.constant(RT), Profile.constant(0.3))
    return Problem(string, (Grip("hand", 0.0, "clamp", GripPose(np.zeros(3),
                                                                matrix_to_quat(frame(TILT)))),))


def points_of(length: float, seed: int = 0, count: int = 300) -> np.ndarray:
    """Noisy unordered points of a cantilever of ``length`` (the scene's material)."""
    ref = solve_clamped(length, RF, RT, np.zeros(3), frame(TILT), mode_end="free", D=D)
    rng = np.random.default_rng(seed)
    return ref.position(rng.uniform(0.0, length, count)) + rng.normal(0.0, SIGMA, (count, 3))


def helix(arc: float = 0.45, seed: int = 0, count: int = 300, radius: float = 0.03,
          pitch: float = 0.01) -> np.ndarray:
    """Points of a helix of arc length ``arc`` (radius 3 cm, pitch 1 cm per turn) starting at the
    clamp: no hanging string of length L takes this shape."""
    rng = np.random.default_rng(seed)
    rise = pitch / (2 * np.pi)
    t = rng.uniform(0.0, arc / np.hypot(radius, rise), count)
    pts = np.stack([radius * np.sin(t), radius * (1 - np.cos(t)), -rise * t], axis=1)
    return pts + rng.normal(0.0, SIGMA, (count, 3))


def fitted(points: np.ndarray):
    data = ObservationSet((Observation("cable", {}, points, SIGMA),), ("Rf", "D"))
    return fit(scene(), SolverOptions(), data)


def test_the_right_cloud_passes():
    result = fitted(points_of(L))
    assert result.status == "ok", result.message
    assert result.chi2_reduced <= result.chi2_threshold == MODEL_ERROR_FLOOR
    assert abs(result.ratios["D/Rf"].value / (D / RF) - 1) < 0.01


def test_threshold_is_the_chi2_quantile_with_a_floor():
    """The 0.999 quantile of χ²(k)/k: for k = 2 it is −2 ln(0.001) / 2 (closed form), above the
    floor."""
    assert threshold(2) == pytest.approx(-np.log(1e-3), rel=1e-9)
    assert threshold(1000) == MODEL_ERROR_FLOOR


def test_arc_length_of_a_noisy_cloud():
    """Against a helix's exact length (radius 5 cm, pitch 10 cm, 1000 points): a lower bound within
    a few per cent.  Coils closer than the estimate's voxel (2 cm here) merge: then it is a lower
    bound only."""
    estimate = arc_length(helix(0.8, count=1000, radius=0.05, pitch=0.1), SIGMA, 1.0)
    assert 0.95 * 0.8 < estimate < 1.01 * 0.8
    assert arc_length(helix(0.8, count=1000), SIGMA, 1.0) < 0.8


@pytest.mark.parametrize("points, cause", [
    (lambda: points_of(0.65),
     "wrong length? observation 'cable': the points follow a curve about"),
    (lambda: points_of(L) * 1000.0, "wrong units? observation 'cable': the points span"),
    (lambda: points_of(L) + [3.0, 0.0, 0.0], "far from the grips: observation 'cable'"),
    (lambda: helix(), "the fitted shape does not explain the points"),
], ids=["wrong-length", "millimetres", "far", "helix"])
def test_points_the_string_cannot_explain_are_a_misfit(points, cause):
    result = fitted(points())
    assert result.status == "misfit" and not result.ok, result.message
    assert result.message.startswith("misfit: ") and cause in result.message, result.message


def write_case(tmp_path, points: np.ndarray) -> str:
    np.save(tmp_path / "cable.npy", points)
    doc = {"name": "cantilever", "string": {"length": L, "bend_stiffness": RF,
                                            "twist_stiffness": RT,
                                            "weight_per_length": 0.3},
           "grips": [{"name": "hand", "s": 0.0, "mode": "clamp", "position": [0, 0, 0],
                      "orientation": matrix_to_quat(frame(TILT)).tolist()}]}
    (tmp_path / "cantilever.yaml").write_text(yaml.safe_dump(doc))
    obs = {"scene": "cantilever.yaml", "sigma": SIGMA, "parameters": ["Rf", "D"],
           "observations": [{"name": "cable", "points_file": "cable.npy"}]}
    (tmp_path / "obs.yaml").write_text(yaml.safe_dump(obs))
    return str(tmp_path / "obs.yaml")


@pytest.mark.parametrize("points, cause", [(lambda: points_of(0.65), "wrong length?"),
                                           (lambda: points_of(L) * 1000.0, "wrong units?"),
                                           (lambda: helix(), "does not explain the points")],
                         ids=["wrong-length", "millimetres", "helix"])
def test_cli_exits_1_with_one_line_and_writes_no_scene(tmp_path, capsys, points, cause):
    path = write_case(tmp_path, points())
    out = tmp_path / "fitted.yaml"
    assert cli.main(["fit", path, "--write-scene", str(out)]) == 1
    captured = capsys.readouterr()
    assert captured.out.startswith("status: misfit (misfit: ")
    err = captured.err.strip().splitlines()
    assert err[-1].startswith(("dlo fit: misfit: reduced chi2 ", "dlo fit: misfit: wrong units"))
    assert cause in err[-1] and "Traceback" not in captured.err
    assert "--write-scene: not written: the fit is a misfit" in captured.err and not out.exists()


def test_cli_right_cloud_exits_0_and_writes_the_scene(tmp_path, capsys):
    path = write_case(tmp_path, points_of(L, seed=3))
    out = tmp_path / "fitted.yaml"
    assert cli.main(["fit", path, "--write-scene", str(out)]) == 0
    assert capsys.readouterr().out.startswith("status: ok") and out.exists()


def test_outliers_beyond_the_robust_loss():
    """10 % gross outliers (2-5 cm off) are forgiven (noted, D/Rf within 1 %, σ from the other
    points); 35 % are a misfit naming the outliers."""
    rng = np.random.default_rng(5)
    pts = points_of(L, seed=5)
    off = rng.normal(size=(len(pts), 3))
    off *= rng.uniform(0.02, 0.05, (len(pts), 1)) / np.linalg.norm(off, axis=1, keepdims=True)
    some = pts.copy()
    some[:30] += off[:30]
    result = fitted(some)
    found = re.search(r"(\d+) of 300 points lie beyond 2.5 σ: outliers", result.message)
    assert result.status == "ok" and found, result.message
    assert 30 <= int(found[1]) <= 30 + 25  # and Gaussian noise's 4.4 % of the rest
    assert abs(result.ratios["D/Rf"].value / (D / RF) - 1) < 0.01 and result.sigma_scale < 1.2
    many = pts.copy()
    many[:105] += off[:105]
    result = fitted(many)
    assert result.status == "misfit" and "outliers: " in result.message, result.message
