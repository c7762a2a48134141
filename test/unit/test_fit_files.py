"""Hostile and broken files given to `dlo fit` (observation YAML/JSON, .npy and .ply points)
through the real CLI (a subprocess): each is refused with one line naming the file and the field,
exit code 2, no traceback, in bounded time (a timeout: a FIFO must not hang) and bounded memory
(the child's peak RSS), msg_docs/fitting.md "Limits"."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from dlo_ros.identify.observations import MAX_OBSERVATIONS
from support.cli import assert_one_line_error

ROOT = Path(__file__).resolve().parents[2]
SCENE = {"name": "pair", "string": {"length": 1.0, "bend_stiffness": 0.02,
                                    "weight_per_length": 0.5},
         "grips": [{"name": "a", "s": 0.0, "mode": "clamp", "position": [0, 0, 0]},
                   {"name": "b", "s": 1.0, "mode": "clamp", "position": [0.8, 0, 0]}]}
#: a peak RSS no refusal may exceed [MB] (the CLI with CasADi imported is ~200 MB; the 180 MB PLY
#: took 2.3 GB)
PEAK_MB = 600


def run_fit(path, timeout: float = 60.0):
    """``python -m dlo_ros.cli fit PATH`` in a wrapper whose only child is the CLI: (return code,
    stderr, peak RSS of the CLI in MB)."""
    wrapper = ("import resource, subprocess, sys\n"
               "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "sys.stderr.write(p.stderr)\n"
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
               "sys.exit(p.returncode)\n")
    proc = subprocess.run([sys.executable, "-c", wrapper, sys.executable, "-m", "dlo_ros.cli",
                           "fit", str(path)],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "DLO_NO_COMPILE": "1"})
    return proc.returncode, proc.stderr, int(proc.stdout.strip().splitlines()[-1]) / 1024


def assert_refused(path, *words: str) -> str:
    code, err, peak = run_fit(path)
    assert_one_line_error(code, err, words)
    assert peak < PEAK_MB, f"peak RSS {peak:.0f} MB"
    return err


def case(tmp_path, observations=None, points_file: str | None = None, **top) -> Path:
    """An observation file (obs.yaml) of the two-clamp scene (pair.yaml) in ``tmp_path``."""
    (tmp_path / "pair.yaml").write_text(yaml.safe_dump(SCENE))
    if observations is None:
        observations = [{"name": "o", "points_file": points_file}]
    doc = {"scene": "pair.yaml", "sigma": 0.002, "parameters": ["Rf", "D"],
           "observations": observations, **top}
    path = tmp_path / "obs.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def sag_points(n: int = 60) -> np.ndarray:
    x = np.linspace(0.0, 0.8, n)
    return np.stack([x, np.zeros(n), -0.5 * x * (0.8 - x)], axis=1)


def npy_with_header(path: Path, header: str, body: bytes) -> Path:
    """A version-1.0 .npy file with this header dict text (padded as numpy pads it) and body."""
    text = header + " " * ((64 - (10 + len(header) + 1) % 64) % 64) + "\n"
    head = b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little")
    path.write_bytes(head + text.encode("latin1") + body)
    return path


def test_oversized_observation_file(tmp_path):
    path = case(tmp_path, [{"name": "o", "points": sag_points().tolist()}])
    path.write_text(path.read_text() + "#" * (1 << 20) + "\n")
    assert_refused(path, f"{path}: the file has", "an observation file at most 1048576")


def test_too_many_observations(tmp_path):
    obs = [{"name": f"o{i}",
            "points": sag_points(4).tolist()} for i in range(MAX_OBSERVATIONS + 1)]
    assert_refused(case(tmp_path, obs),
                   f"observations: {MAX_OBSERVATIONS + 1} items, at most {MAX_OBSERVATIONS}")


@pytest.mark.parametrize("which", ["observation file", "points_file"])
def test_fifo_is_refused_without_blocking(tmp_path, which):
    fifo = tmp_path / "pipe.npy"
    os.mkfifo(fifo)
    path = case(tmp_path, points_file="pipe.npy")
    if which == "observation file":
        path = tmp_path / "pipe.yaml"
        os.mkfifo(path)
    assert_refused(path, "not a regular file")


def test_deep_nesting(tmp_path):
    path = tmp_path / "deep.yaml"
    path.write_text("scene: pair.yaml\nsigma: " + "[" * 10_000 + "]" * 10_000 + "\n")
    assert_refused(path, "deep.yaml:2: sigma[0][0]",
                   "over a limit: nested more than 16 levels deep")


def test_400_digit_number(tmp_path):
    path = case(tmp_path, [{"name": "o", "points": sag_points().tolist()}])
    path.write_text(path.read_text().replace("sigma: 0.002", "sigma: 1" + "0" * 400))
    assert_refused(path, "an integer with 401 digits")


def test_lying_npy_header(tmp_path):
    npy_with_header(tmp_path / "p.npy",
                    "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 3), }",
                    np.zeros((10, 3)).tobytes())
    assert_refused(case(tmp_path, points_file="p.npy"), "observations[0].points_file",
                   "over the limit of 200000")
    npy_with_header(tmp_path / "p.npy",
                    "{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 3), }",
                    np.zeros((10, 3)).tobytes())
    assert_refused(case(tmp_path, points_file="p.npy"), "the header promises 100000 × 3 values")


def test_complex_npy(tmp_path):
    np.save(tmp_path / "c.npy", sag_points().astype(complex) + 1e-3j)
    assert_refused(case(tmp_path, points_file="c.npy"), "observations[0].points_file", "complex")


def test_nan_point(tmp_path):
    pts = sag_points()
    pts[7, 1] = np.nan
    np.save(tmp_path / "n.npy", pts)
    assert_refused(case(tmp_path, points_file="n.npy"),
                   "observations[0].points_file[7]: contains NaN")


def test_points_1e30_away(tmp_path):
    np.save(tmp_path / "far.npy", sag_points() + 1e30)
    assert_refused(case(tmp_path, points_file="far.npy"),
                   "observations[0].points_file[0]: a coordinate of 1e+30 m")
    path = case(tmp_path, [{"name": "o", "points": sag_points().tolist(),
                            "grips": {"b": {"position": [1e30, 0, 0], "orientation": [0, 0, 0,
                                                                                      1]}}}])
    assert_refused(path, "observations[0].grips.b.position: a coordinate over the limit")


def test_oversized_point_files(tmp_path):
    """A 180 MB PLY (sparse: its body is zeros) is refused by its size before reading; a small one
    whose header counts 7.5 M vertices by that count."""
    header = b"ply\nformat binary_little_endian 1.0\nelement vertex 7500000\nproperty double x\n" \
             b"property double y\nproperty double z\nend_header\n"
    with open(tmp_path / "big.ply", "wb") as f:
        f.write(header)
        f.truncate(180_000_000)
    assert_refused(case(tmp_path, points_file="big.ply"), "observations[0].points_file",
                   "a point file at most")
    with open(tmp_path / "big.ply", "wb") as f:  # small enough, but a count over the limit
        f.write(header)
        f.truncate(1_000_000)
    assert_refused(case(tmp_path, points_file="big.ply"),
                   "7500000 vertices, over the limit of 200000")
