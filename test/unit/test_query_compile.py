"""Query workers compile what the cache lacks ('on_query'), and a library is built once per machine.

#38: on an empty cache, workers that never compiled answered interpreted for the pool's whole life
(236 queries/s on `default_cable`, /tmp measurement in the closing note).  Now a worker whose
query finds a library missing builds it in the background; a process that misses a library another
process is building waits for that build and loads it (`native.cache_store.build_lock`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.parallel.batch import process_pool, query_many, stop_pool

from support.problems import clamped_pair

# order 6, far from the tolerance: these tests compare compiled and interpreted paths, not accuracy
PLANAR = SolverOptions(model="planar", order=6, quadrature_nodes=20, error_tolerance=1.0)
QUERIES = [{"right": ((0.6 - 0.01 * k, 0.0, 0.02 * k), (0.0, 0.0, 0.0, 1.0))} for k in range(1, 5)]



def test_an_on_query_solver_compiles_once_it_answers_a_query(empty_cache):
    """'on_query' compiles nothing for a committed solve (a worker's held shape), starts on its first
    query, never blocks that query, and its compiled answers equal the interpreted ones."""
    problem = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)
    solver = ShapeSolver(problem, PLANAR, compile="on_query")
    interpreted = ShapeSolver(problem, PLANAR, compile="off")
    held = solver.solve()
    assert held.ok and solver.compile_thread is None and not list(empty_cache.glob("*.so"))
    interpreted.solve()
    first = solver.solve(QUERIES[0], commit=False)
    assert first.ok and first.derivatives == "interpreted" and solver.compile_thread is not None
    assert solver.wait_for_compile(300)
    for query in QUERIES:
        a, b = solver.solve(query, commit=False), interpreted.solve(query, commit=False)
        assert a.ok and b.ok and a.derivatives == "compiled" and b.derivatives == "interpreted"
        np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    assert solver.functions.newton_native is not None and solver.functions.outputs_compiled


def test_a_cached_solver_still_never_compiles(empty_cache):
    """'cached' (the node's query workers) never starts a compiler, queries or not."""
    solver = ShapeSolver(clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1), PLANAR, compile="cached")
    solver.solve()
    assert all(solver.solve(q, commit=False).derivatives == "interpreted" for q in QUERIES)
    assert solver.compile_thread is None and not list(empty_cache.glob("*.so"))


_BUILDER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    import casadi as ca
    from dlo_ros.solver.build import compiled
    from dlo_ros.solver.native import compiler

    log, start = Path(sys.argv[1]), Path(sys.argv[2])
    build = compiler.build_library

    def logged(*args, **kwargs):
        with log.open("a") as f:
            f.write("build\\n")
        return build(*args, **kwargs)

    compiled.build_library = logged
    x = ca.SX.sym("x", 40)
    y = x
    for k in range(60):  # enough C that the two builds would overlap
        y = ca.sin(y) * (1.0 + 0.01 * k) + ca.cos(x) * y
    fn = ca.Function("lock_probe", [x], [y])
    while not start.exists():  # both processes start together
        time.sleep(0.005)
    native, ok = compiled.compiled(fn)
    print("compiled" if ok and isinstance(native, compiled.NativeFunction) else "interpreted")
    """
)


def test_two_processes_missing_one_library_build_it_once(empty_cache, tmp_path_factory):
    """Two processes that miss the same library at the same moment: one builds it, the other waits
    for that build and loads it (without the lock both ran gcc)."""
    work = tmp_path_factory.mktemp("probe")
    log, start = work / "builds.log", work / "start"
    script = work / "builder.py"
    script.write_text(_BUILDER)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": f"{root}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    procs = [
        subprocess.Popen(
            [sys.executable, str(script), str(log), str(start)],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    time.sleep(3.0)  # both imported and waiting
    start.touch()
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), [err for _, err in outs]
    assert [out.strip() for out, _ in outs] == ["compiled", "compiled"]
    assert log.read_text().count("build") == 1
    assert len(list(empty_cache.glob("lock_probe_*.so"))) == 1


def test_a_first_batch_on_an_empty_cache_is_answered_by_compiled_code(empty_cache):
    """query_many's default: a worker on an empty cache answers at once (interpreted), compiles the
    model its queries use, and answers compiled within a bounded time, the same answers."""
    problem = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)
    reference = ShapeSolver(problem, PLANAR, compile="off")
    reference.solve()
    expected = [reference.solve(q, commit=False) for q in QUERIES]
    pool = process_pool(1)
    try:
        first = query_many(ShapeSolver, problem, PLANAR, QUERIES, pool)
        assert [r.derivatives for r in first] == ["interpreted"] * len(QUERIES)
        deadline, answers = time.monotonic() + 300, first
        while answers[0].derivatives != "compiled" and time.monotonic() < deadline:
            time.sleep(0.5)
            answers = query_many(ShapeSolver, problem, PLANAR, QUERIES, pool)
        assert [r.derivatives for r in answers] == ["compiled"] * len(QUERIES)
        for got, want in zip(answers, expected):
            assert got.ok and want.ok
            np.testing.assert_allclose(got.points, want.points, atol=1e-9)
    finally:
        stop_pool(pool)
