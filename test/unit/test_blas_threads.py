"""The executables ask for one BLAS thread before numpy loads (``dlo_ros/blas_threads.py``).

OpenBLAS reads its thread count once, when numpy loads it, so the request must come first: a
fresh interpreter importing ``dlo_ros.cli`` (what ``dlo`` and ``python -m dlo_ros.cli`` do) has
the variables set and imported ``dlo_ros.blas_threads`` before numpy; a value the user set is
kept; ``dlo_ros.node.main`` asks too.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from dlo_ros.blas_threads import VARIABLES


def clean_env(**extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in VARIABLES}
    env.update(extra)
    return env


def run(code: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )


def test_cli_asks_before_numpy_loads():
    out = run(
        "import dlo_ros.cli, os; print([os.environ.get(v) for v in %r])" % (VARIABLES,),
        clean_env(),
    )
    assert out.stdout.strip() == str(["1"] * len(VARIABLES))
    order = [line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines() if "|" in line]
    assert order.index("dlo_ros.blas_threads") < order.index("numpy")


def test_a_users_choice_is_kept():
    out = run(
        "import dlo_ros.cli, os; print(os.environ['OPENBLAS_NUM_THREADS'])",
        clean_env(OPENBLAS_NUM_THREADS="2"),
    )
    assert out.stdout.strip() == "2"


def test_node_main_asks(monkeypatch):
    import dlo_ros.node as node

    for v in VARIABLES:
        monkeypatch.delenv(v, raising=False)
    # the signal handling main installs belongs to a node process, not to this test's
    monkeypatch.setattr(node, "stop_on_first_signal", lambda: None)
    monkeypatch.setattr(node, "ignore_signals_at_exit", lambda: None)
    called = []
    monkeypatch.setattr("dlo_ros.node.run.main", lambda argv, prog: called.append(argv) or 0)
    assert node.main(["--check"]) == 0
    assert called and all(os.environ.get(v) == "1" for v in VARIABLES)


# Reads and sets the loaded OpenBLAS libraries' thread counts with its own ctypes calls (not the
# module's), in a fresh interpreter that loaded numpy and SciPy before dlo_ros, as a planner's
# program does.
LOADED_COUNTS = """
import ctypes, sys
import numpy, scipy.linalg
def libs():
    names = {l.split()[-1] for l in open('/proc/self/maps') if len(l.split()) >= 6}
    out = []
    for path in sorted(n for n in names if 'openblas' in n.lower()):
        lib = ctypes.CDLL(path)
        for stem in ('scipy_openblas_%s_num_threads64_', 'scipy_openblas_%s_num_threads',
                     'openblas_%s_num_threads64_', 'openblas_%s_num_threads'):
            if hasattr(lib, stem % 'get'):
                out.append((getattr(lib, stem % 'get'), getattr(lib, stem % 'set')))
                break
    return out
for get, put in libs():
    put(2)
before = [get() for get, _ in libs()]
import dlo_ros.solver
print(before, [get() for get, _ in libs()])
"""


def loaded_counts(env: dict) -> tuple[list[int], list[int]]:
    out = subprocess.run(
        [sys.executable, "-c", LOADED_COUNTS],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    before, after = out.stdout.strip().split("] [")
    as_ints = lambda text: [int(v) for v in text.strip("[]").split(",") if v.strip()]  # noqa: E731
    return as_ints(before), as_ints(after)


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or (os.cpu_count() or 1) < 2,
    reason="reads /proc/self/maps; needs two cores for a count above one",
)
def test_importing_the_solver_sets_loaded_blas_to_one_thread():
    before, after = loaded_counts(clean_env())
    assert len(before) >= 2, "numpy's and SciPy's OpenBLAS were not found"  # both wheels ship one
    assert before == [2] * len(before)
    assert after == [1] * len(before)


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or (os.cpu_count() or 1) < 2,
    reason="reads /proc/self/maps; needs two cores for a count above one",
)
def test_a_users_thread_count_is_kept_at_import():
    before, after = loaded_counts(clean_env(OPENBLAS_NUM_THREADS="2"))
    assert after == before == [2] * len(before)
