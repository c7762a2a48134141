"""Run the linters ament_python packages run, on dlo_ros/: ruff, pydocstyle and mypy.

ruff checks flake8's rules at 99 columns and the formatting; pydocstyle checks PEP 257 as
ament_pep257 does; mypy checks the types. Settings: ruff.toml and setup.cfg.

Each test runs one tool from the test venv (requirements-test.txt pins them) over the package and
fails with the tool's own findings, so `bash scripts/dlo-env test` is also the lint command.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent


def _run(tool: str, *args: str) -> subprocess.CompletedProcess[str]:
    exe = BIN / tool
    assert exe.exists(), f"{tool} is not installed in {BIN}: it is pinned in requirements-test.txt"
    env = dict(os.environ, MYPY_CACHE_DIR=str(ROOT / ".mypy_cache"))
    return subprocess.run(
        [str(exe), *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600
    )


def _assert_clean(proc: subprocess.CompletedProcess[str], tool: str) -> None:
    findings = (proc.stdout + proc.stderr).strip()
    assert proc.returncode == 0, f"{tool} found problems in dlo_ros/:\n{findings[-6000:]}"


def test_ruff_check() -> None:
    _assert_clean(_run("ruff", "check", "dlo_ros"), "ruff check")


def test_ruff_format() -> None:
    _assert_clean(_run("ruff", "format", "--check", "dlo_ros"), "ruff format --check")


def test_pydocstyle() -> None:
    _assert_clean(_run("pydocstyle", "dlo_ros"), "pydocstyle")


def test_mypy() -> None:
    _assert_clean(_run("mypy"), "mypy")
