"""The compiled-derivative cache: its key tells NLPs apart without generating C, and a cached library
is found and used without generating C (generating it costs seconds for a 3D scene, and a model
switch in a streaming node must not pay that; issue 6's stalls)."""
from __future__ import annotations

import gc
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from dlo_ros.model import Obstacle
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build import compiled
from dlo_ros.solver.native import compiler as native_compiler
from dlo_ros.solver.update.newton import derivatives
from dlo_ros.solver.build.nlp import StringNLP
from dlo_ros.solver.options import SolverOptions

from support.problems import clamped_pair

# order 6 is far from the 1 mm tolerance: these tests compare compiled and interpreted paths, not accuracy
PLANAR = SolverOptions(model="planar", order=6, quadrature_nodes=20, error_tolerance=1.0)


def _key(problem, options=PLANAR) -> str:
    return compiled.fingerprint(StringNLP(problem, options).kkt_fn)


def test_the_key_is_stable_and_tells_apart_every_baked_in_constant():
    base = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)
    assert _key(base) == _key(clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1))  # a fresh NLP, same scene
    # the reference frame R0 follows the chord at build time; σ = L / max Rf scales the objective
    assert _key(clamped_pair(right=(0.6, 0.0, 0.1), weight=0.1)) != _key(base)
    assert _key(clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1, bend=2.0)) != _key(base)
    assert _key(base, replace(PLANAR, order=7)) != _key(base)
    assert _key(base, replace(PLANAR, model="full")) != _key(base)
    # parameters (here the grip target along the chord) are inputs, not constants: same key
    assert _key(clamped_pair(right=(0.7, 0.0, 0.0), weight=0.1)) == _key(base)


def test_the_key_holds_the_flags_the_name_and_the_sources(monkeypatch):
    """The key hashes the compiler flags, the function's name and the sources that build NLPs, besides
    the function's values: a change of any of them is a different library."""
    x = ca.SX.sym("x", 2)
    f, g = ca.Function("f", [x], [x * x]), ca.Function("g", [x], [x * x])  # same values, two names
    key = native_compiler.fingerprint(f)
    assert native_compiler.fingerprint(g) != key
    assert native_compiler.fingerprint(f, native_compiler.FLAGS + ("-DDLO_OTHER",)) != key
    monkeypatch.setattr(native_compiler, "_source_digest", lambda: b"edited sources")
    assert native_compiler.fingerprint(f) != key



def test_a_function_is_fingerprinted_once_while_it_lives(monkeypatch):
    """A clone on another mesh shares its template's functions (build/mesh_clone.py): their keys
    are computed once per function object, per flags and sources, and forgotten with it."""
    calls = []
    real = native_compiler._fingerprint
    monkeypatch.setattr(native_compiler, "_fingerprint", lambda fn, flags: calls.append(fn.name()) or real(fn, flags))
    x = ca.SX.sym("x", 2)
    f = ca.Function("f_once", [x], [x * x])
    key = native_compiler.fingerprint(f)
    assert native_compiler.fingerprint(f) == key and len(calls) == 1
    assert native_compiler.fingerprint(f, native_compiler.FLAGS + ("-DDLO_OTHER",)) != key and len(calls) == 2
    twin = ca.Function("f_once", [x], [x * x])  # equal, another object: computed again, the same key
    assert native_compiler.fingerprint(twin) == key and len(calls) == 3
    gone = id(f)
    assert sum(key[0] == gone for key in native_compiler._KNOWN) == 2  # its two flags
    del f
    gc.collect()
    assert not any(key[0] == gone for key in native_compiler._KNOWN)  # its entries went with it
    assert native_compiler.fingerprint(twin) == key and len(calls) == 3


def test_the_optimisation_level_is_dlo_optimize_and_the_release_level_compiles_alike(tmp_path, monkeypatch):
    """``$DLO_OPTIMIZE`` picks gcc's level (default -O3; a bad one: a warning naming it, and -O3).
    The suite compiles at -O0 (test/conftest.py); the release level builds the same function and
    gives the same values, to rounding."""
    assert native_compiler.optimize_flags(None) == ("-O3",)
    assert native_compiler.optimize_flags("0") == ("-O0",)
    assert native_compiler.optimize_flags(" ") == ("-O3",)  # set but empty: the default
    with pytest.warns(UserWarning, match="DLO_OPTIMIZE='-O9; rm'"):
        assert native_compiler.optimize_flags("-O9; rm") == ("-O3",)
    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv("DLO_NO_COMPILE")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    nlp = StringNLP(clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1), PLANAR)
    args = [np.linspace(0.1, 0.9, nlp.kkt_fn.size1_in(i)) for i in range(nlp.kkt_fn.n_in())]
    exact = [np.asarray(ca.DM(v).full()) for v in nlp.kkt_fn(*args)]
    for flags in (("-O3",), native_compiler.FLAGS):
        native, ok = compiled.compiled(nlp.kkt_fn, flags=flags)
        assert ok, flags
        for got, want in zip(native(*args), exact):
            np.testing.assert_allclose(np.reshape(got, want.shape), want, rtol=1e-13, atol=1e-13)
    assert len(list(tmp_path.glob("dlo_kkt_*.so"))) == (1 if native_compiler.FLAGS == ("-O3",) else 2)

def test_a_cached_library_is_found_and_used_without_generating_c(tmp_path, monkeypatch):
    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv("DLO_NO_COMPILE")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    table = Obstacle("halfspace", np.array([0.0, 0.0, -0.5, 0.0, 0.0, 1.0]), "table")
    problem = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1, obstacles=(table,))
    first = ShapeSolver(problem, PLANAR, compile="blocking")
    # two functions: with the obstacle rows' derivatives, and without them (used while nothing touches)
    assert first.kkt_compiled and len(list(tmp_path.glob("dlo_kkt_*.so"))) == 2

    def no_codegen(*_):
        raise AssertionError("C was generated for a cached function")

    monkeypatch.setattr(native_compiler, "generate", no_codegen)
    again = ShapeSolver(problem, PLANAR, compile="cached")  # a fresh NLP finds the library by its key
    assert again.kkt_compiled
    interpreted = ShapeSolver(problem, PLANAR, compile="off")
    z = np.linspace(-0.3, 0.4, again.model.layout.size)
    p = interpreted.pack_parameters(problem, z)
    lam = np.linspace(0.1, 1.0, interpreted.nlp.lbg.size)
    for contact in (True, False):  # every row active (the full function), or none (the contact-free one)
        active = np.full(lam.size, contact)
        for native, exact in zip(derivatives(again.nlp, again.functions, z, p, lam, active),
                                 derivatives(interpreted.nlp, interpreted.functions, z, p, lam, active)):
            np.testing.assert_allclose(native, exact, rtol=1e-12, atol=1e-12)
    target = {"right": ((0.5, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0))}
    a, b = again.solve(target), interpreted.solve(target)
    assert a.ok and b.ok
    np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    # small moves: Newton updates, whose steps run in one call around the compiled library
    # (casadi.external of the split function inside newton_fn) for the compiled solver, around the
    # assembled MX function (solver/build/assembled_euler.py) for the other
    def kkt_classes(solver, name):
        return {f.class_name() for f in solver.functions.newton_step.function.find_functions() if f.name() == name}

    assert again.fused_newton and kkt_classes(again, "dlo_kkt_free_split") == {"External"}
    assert kkt_classes(interpreted, "dlo_kkt_free") == {"MXFunction"}
    for k in range(1, 6):
        target = {"right": ((0.5 - 0.005 * k, 0.0, 0.1 + 0.003 * k), (0.0, 0.0, 0.0, 1.0))}
        a, b = again.solve(target), interpreted.solve(target)
        assert a.ok and b.ok and a.ipopt_status == b.ipopt_status == "Newton"
        np.testing.assert_allclose(a.points, b.points, atol=1e-10)


def test_without_a_compiler_the_interpreted_function_is_used(monkeypatch, tmp_path):
    monkeypatch.delenv("DLO_NO_COMPILE")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    fn = ca.Function("f", [x := ca.SX.sym("x", 2)], [ca.sin(x)])
    assert compiled.cached_library(fn) is None
    native, ok = compiled.compiled(fn)
    assert not ok and isinstance(native, compiled.InterpretedFunction)
    assert not list(tmp_path.iterdir())  # nothing generated, nothing cached


def test_never_two_compilers_at_once_in_one_process(tmp_path, monkeypatch):
    """Several threads needing new libraries run the compiler one at a time (#14: six gcc at once,
    1.1 GB).  The compiler is replaced by a recorder that fails after a moment (so the callers fall back
    to interpreted functions): at most one runs at any time."""
    import threading
    import time
    from types import SimpleNamespace

    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    running, peak, lock = [0], [0], threading.Lock()

    def fake_run(cmd, **kwargs):
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        time.sleep(0.2)
        with lock:
            running[0] -= 1
        return SimpleNamespace(returncode=1, stdout="", stderr="")

    monkeypatch.setattr(native_compiler.subprocess, "run", fake_run)
    x = ca.SX.sym("x")
    fns = [ca.Function(f"f{i}", [x], [ca.sin(x) * (i + 1)]) for i in range(4)]
    results = []
    threads = [threading.Thread(target=lambda f=f: results.append(compiled.compiled(f))) for f in fns]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert len(results) == 4 and not any(ok for _, ok in results)
    assert peak[0] == 1


def test_a_cached_solver_takes_up_libraries_compiled_after_it_started(tmp_path, monkeypatch):
    """A solver that may not compile ('cached': a query worker) swaps in the libraries another solver
    compiled after it started, at its next look into the cache, and answers as before."""
    from dlo_ros.solver.build import functions

    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv("DLO_NO_COMPILE")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(functions, "CACHE_RECHECK_S", 0.0)
    problem = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)
    waiting = ShapeSolver(problem, PLANAR, compile="cached")
    interpreted = ShapeSolver(problem, PLANAR, compile="off")
    first = waiting.solve()
    assert first.ok and first.derivatives == "interpreted" and not waiting.kkt_compiled
    assert ShapeSolver(problem, PLANAR, compile="blocking").kkt_compiled  # another solver compiles
    np.testing.assert_allclose(first.points, interpreted.solve().points, atol=1e-9)
    for k in range(1, 4):
        target = {"right": ((0.6 - 0.01 * k, 0.0, 0.02 * k), (0.0, 0.0, 0.0, 1.0))}
        a, b = waiting.solve(target), interpreted.solve(target)
        assert a.ok and b.ok and a.derivatives == "compiled" and b.derivatives == "interpreted"
        np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    assert waiting.functions.newton_native is not None and not waiting.functions.waiting  # all swapped in


def test_the_model_answering_queries_is_compiled_in_the_background(tmp_path, monkeypatch):
    """An auto solver on a planar stream answers out-of-plane queries with its 3D model; that model is
    compiled in the background (never blocking a query), and the compiled answers equal the first ones."""
    import time

    from dlo_ros.solver import make_solver

    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv("DLO_NO_COMPILE")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    problem = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)
    solver = make_solver(problem, SolverOptions(order=8, error_tolerance=1.0), compile="background", checks="sync")
    assert solver.solve().model.planar
    query = {"right": ((0.55, 0.05, 0.05), (0.0, 0.0, 0.0, 1.0))}
    first = solver.solve(query, commit=False)
    assert first.ok and not first.model.planar and first.derivatives == "interpreted"
    deadline = time.monotonic() + 300
    answer = first
    while answer.derivatives != "compiled" and time.monotonic() < deadline:
        time.sleep(0.2)
        answer = solver.solve(query, commit=False)
        assert answer.ok and not answer.model.planar
    assert answer.derivatives == "compiled"
    np.testing.assert_allclose(answer.points, first.points, atol=1e-9)


def test_a_model_whose_outputs_alone_are_not_cached_compiles_them(tmp_path, monkeypatch):
    """A new version that changes only the outputs' function finds its derivatives in the cache and not its
    outputs' library: starting a compile (what a stream, or auto's compile-ahead for the query model,
    does) compiles that library, and the outputs then run compiled.  Before, a solver whose derivatives
    were compiled started no compile, and every query of auto's 3D model built its outputs interpreted
    (0.5 ms each on default_cable)."""
    if compiled.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv("DLO_NO_COMPILE")
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path))
    problem = clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)
    assert ShapeSolver(problem, PLANAR, compile="blocking").all_compiled
    outputs = list(tmp_path.glob("dlo_outputs_*.so"))
    assert len(outputs) == 1
    outputs[0].unlink()
    solver = ShapeSolver(problem, PLANAR, compile="cached")
    assert solver.kkt_compiled and not solver.functions.outputs_compiled and not solver.all_compiled
    solver.start_compile("background")
    solver.wait_for_compile(300)
    assert solver.functions.outputs_compiled and solver.all_compiled and outputs[0].exists()
