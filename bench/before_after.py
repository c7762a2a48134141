"""Before against after in one run: a bench's worker process on another revision's ``dlo_ros``.

A bench that compares two trees (``perf/inertia_verdict.py``, ``perf/update_python.py``) runs its
own script as a worker (``--worker``) once on this checkout and once on ``dlo_ros`` of an earlier
revision, extracted with ``git archive`` into a temporary folder put first on the worker's
``PYTHONPATH``.  Worker and bench speak one JSON line per request and per answer; the worker's
first line says which ``dlo_ros`` it imported (``{"file": dlo_ros.__file__}``).  Both trees run
the same machine at the same time, so their times are compared as ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent  # the repository


def revision(before: str) -> tuple[str, str]:
    """Return (the revision to compare with, its short hash); '' means ``merge-base main HEAD``."""
    git = ["git", "-C", str(ROOT)]
    if not before:
        base = subprocess.run([*git, "merge-base", "main", "HEAD"], capture_output=True, text=True)
        before = base.stdout.strip()
    short = subprocess.run([*git, "rev-parse", "--short", before], capture_output=True, text=True)
    return before, short.stdout.strip()


def extract(rev: str, folder: str) -> None:
    """Write ``dlo_ros`` of git revision ``rev`` into ``folder`` (``git archive`` | ``tar -x``)."""
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", rev, "dlo_ros"], capture_output=True, check=True
    )
    subprocess.run(["tar", "-x", "-C", folder], input=archive.stdout, check=True)


def start(script: str, path: str, args: list[str]) -> subprocess.Popen:
    """Start ``script --worker *args`` with ``path`` first on its PYTHONPATH; wait for its hello."""
    env = {**os.environ, "PYTHONPATH": path, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, script, "--worker", *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None
    ready = json.loads(proc.stdout.readline())
    print(f"{path} {args}: {ready['file']}", file=sys.stderr)
    # a worker that imported another tree's dlo_ros compares that tree with itself
    if not Path(ready["file"]).resolve().is_relative_to(Path(path).resolve()):
        proc.kill()
        raise RuntimeError(f"the worker for {path} imported {ready['file']}: not that tree's")
    return proc


def ask(proc: subprocess.Popen, request: list) -> dict:
    """Send one request (a JSON list) to a worker and return its one-line JSON answer."""
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write(json.dumps(request) + "\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())


def arguments(doc: str, out: str, rounds: int, **counts: int) -> argparse.Namespace:
    """Parse a before/after bench's command line: --before, --rounds, --out, --worker, and
    ``counts`` (name → default) as more integer options (``--updates 2000``)."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    for name, default in counts.items():
        ap.add_argument(f"--{name}", type=int, default=default)
    ap.add_argument("--rounds", type=int, default=rounds)
    ap.add_argument("--before", default="", help="git revision (default: merge-base main HEAD)")
    ap.add_argument("--out", default=out)
    ap.add_argument("--worker", action="store_true")
    return ap.parse_args()
