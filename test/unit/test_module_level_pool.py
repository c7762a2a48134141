"""A script that starts a pool at its top level (no `if __name__ == "__main__":`): #39 measured a
`BrokenProcessPool` and a traceback with nothing saying why.  With 'spawn' every worker runs the
script again while it starts; there the pool call now answers at once with a warning naming the
fix, and the workers go on to serve the script's own call, whose answers are right."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HINT = 'put the call under `if __name__ == "__main__":`'

QUERIES = """
from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver
scene = load_scene("default_cable")
solver = make_solver(scene.problem, scene.options, compile="off")
solver.solve()
answers = solver.query_many([{"right": ([0.55, 0.0, 0.42], [0, 0, 0, 1])}] * 4)
print("ANSWERS", __name__, [r.status for r in answers])
"""

DATASET = """
import sys
from dlo_ros.dataset import build_dataset, plan_from_dict
from dlo_ros.scene import load_scene
box = {"min": [0.5, -0.1, 0.3], "max": [0.7, 0.1, 0.45]}
plan = plan_from_dict({"samples": 8, "seed": 1, "chunk": 4, "grips": {"right": {"position_box": box}}})
summary = build_dataset(load_scene("default_cable"), plan, sys.argv[1], workers=2, progress=False)
print("STORED", __name__, sum(summary.counts.values()), summary.written)
"""


def _run(tmp_path, source, *args):
    script = tmp_path / "script.py"
    script.write_text(source)
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True,
                          env=env, timeout=600, cwd=tmp_path)


def test_query_many_at_module_level_answers_and_says_why(tmp_path):
    r = _run(tmp_path, QUERIES)
    assert r.returncode == 0, r.stderr
    # the script's own call (__main__) is answered; each worker's copy (__mp_main__, printed in any
    # order beside it) says why not
    lines = r.stdout.strip().splitlines()
    assert lines.count("ANSWERS __main__ ['ok', 'ok', 'ok', 'ok']") == 1
    assert all("failed" in line for line in lines if "__mp_main__" in line)
    assert HINT in r.stderr and "Traceback" not in r.stderr and "BrokenProcessPool" not in r.stdout


def test_build_dataset_at_module_level_stores_every_sample_once(tmp_path):
    out = tmp_path / "out"
    r = _run(tmp_path, DATASET, str(out))
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines().count("STORED __main__ 8 8") == 1
    assert HINT in r.stderr and "Traceback" not in r.stderr
    assert len(list((out / "shards").glob("part-*.parquet"))) == 2
