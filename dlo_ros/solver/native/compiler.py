"""Compile generated C to shared libraries: the compiler, its flags and lock, the cache key.

``build_library`` generates C for CasADi functions (plus C appended to it: the Newton drivers),
compiles it with ``compiler()`` and ``FLAGS`` and stores it through ``cache_store``;
``fingerprint`` keys a function without generating its C.  ``build.compiled`` loads and calls the
libraries; the Newton drivers (``native.build``, ``native.newton``) are compiled here too, so no
module of ``native`` imports the NLP's room ``build``.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import warnings
import weakref
from pathlib import Path
from typing import Iterator

import casadi as ca
import numpy as np

from . import cache_store


#: gcc's optimisation levels ``$DLO_OPTIMIZE`` may name (the default: 3)
LEVELS = ("0", "1", "2", "3", "s")


def optimize_flags(level: str | None) -> tuple[str, ...]:
    """Return gcc's flags for the optimisation level ``level`` (``$DLO_OPTIMIZE``; None, '': 3).

    The assembled KKT functions run faster at -O3 (bench/results/compile_cost.md); -O0 compiles
    the default cable's libraries in a third of the time (the test suite's choice: its solves
    compare compiled with interpreted code, and IEEE arithmetic is the same at every level
    without -ffast-math).  A level not in LEVELS gives one warning naming it, and -O3.
    """
    chosen = (level or "").strip() or "3"
    if chosen in LEVELS:
        return (f"-O{chosen}",)
    warnings.warn(
        f"DLO_OPTIMIZE={level!r} is not one of {', '.join(LEVELS)}: compiling with -O3",
        stacklevel=2,
    )
    return ("-O3",)


#: gcc's flags, chosen once per process (``optimize_flags``); part of every cache key
FLAGS = optimize_flags(os.environ.get("DLO_OPTIMIZE"))


def compiler() -> str | None:
    """Return the C compiler: $CC, else gcc, cc or clang on the PATH; None if there is none."""
    return (
        os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc") or shutil.which("clang")
    )


_SOURCE_DIGEST: bytes | None = None


def _source_digest() -> bytes:
    """Hash the dlo_ros sources that build the compiled functions.

    These are every module of ``model/`` and ``solver/build/`` (the NLP, its assembled
    derivatives, the outputs' function), ``solver/options.py``, and the outputs' grid and
    wrenches (``solver/results/residual.py``, ``wrenches.py``).
    """
    global _SOURCE_DIGEST
    if _SOURCE_DIGEST is None:
        solver = Path(__file__).resolve().parent.parent
        package = solver.parent
        files = (
            sorted((package / "model").glob("*.py"))
            + sorted((solver / "build").glob("*.py"))
            + [solver / "options.py"]
            + [solver / "results" / n for n in ("residual.py", "wrenches.py")]
        )
        h = hashlib.sha256()
        for f in files:
            h.update(f.name.encode() + f.read_bytes())
        _SOURCE_DIGEST = h.digest()
    return _SOURCE_DIGEST


#: fingerprints already computed, by (id of the function, flags, source digest): the function's
#: weak reference and its key.  A function is immutable, so its key is computed once per process:
#: every clone of an NLP on another mesh shares the template's functions (``build/mesh_clone.py``)
#: and each clone looked their libraries up again, evaluating each function twice (a check on the
#: main job's post clones a moved mesh in most checks).  An entry goes with its function.  No
#: lock: each access is one dict operation (atomic under the GIL), and the weak reference's
#: callback may run from the garbage collector on any thread, inside any code.
_KNOWN: dict[tuple, tuple[weakref.ref, str]] = {}


def fingerprint(fn: ca.Function, flags: tuple[str, ...] = FLAGS) -> str:
    """Return a cache key of ``fn`` that needs no code generation (computed once per function).

    It hashes the CasADi version, the compiler flags, the dlo_ros sources that build NLPs, the
    function's name, input/output shapes and instruction count, and its outputs at two fixed
    pseudo-random inputs in [0.5, 1.5].  Constants baked into the expressions (the reference frame
    R0, the objective scale σ, the basis and quadrature matrices) change those outputs, so two NLPs
    that differ in any of them get different keys.
    """
    key = (id(fn), tuple(flags), _source_digest())
    known = _KNOWN.get(key)
    if known is not None and known[0]() is fn:
        return known[1]
    digest = _fingerprint(fn, flags)

    def forget(_: weakref.ref, key: tuple = key) -> None:
        _KNOWN.pop(key, None)

    _KNOWN[key] = (weakref.ref(fn, forget), digest)
    return digest


def _fingerprint(fn: ca.Function, flags: tuple[str, ...]) -> str:
    """Compute ``fingerprint``'s key of ``fn`` (it evaluates ``fn`` twice)."""
    h = hashlib.sha256()
    version = ca.__version__  # type: ignore[attr-defined]  # casadi's stubs omit it
    h.update(version.encode() + " ".join(flags).encode() + _source_digest() + fn.name().encode())
    shapes = [fn.size_in(i) for i in range(fn.n_in())]
    h.update(
        repr((shapes, [fn.size_out(i) for i in range(fn.n_out())], fn.n_instructions())).encode()
    )
    rng = np.random.default_rng(20261122)
    for _ in range(2):
        out = fn(*[rng.uniform(0.5, 1.5, (r, c)) for r, c in shapes])
        for o in out if isinstance(out, (list, tuple)) else [out]:
            h.update(np.ascontiguousarray(np.asarray(o, dtype=float)).tobytes())
    return h.hexdigest()[:16]


#: Held while a compiler runs: never more than one per process (concurrent compiles multiply the
#: memory).
COMPILER_LOCK = threading.Lock()


@contextlib.contextmanager
def library_lock(lib: Path) -> Iterator[None]:
    """Hold COMPILER_LOCK and the cross-process lock of ``lib`` (``cache_store.build_lock``).

    Look for ``lib`` in the cache again inside, then build it if it is still missing: another
    process (a query worker beside this one) may have built it meanwhile.
    """
    with COMPILER_LOCK, cache_store.build_lock(lib):
        yield


def generate(fn: ca.Function, tmp: str, also: tuple[ca.Function, ...] = ()) -> bytes:
    """Generate the C of ``fn`` and the functions ``also`` in ``tmp``; return its bytes."""
    gen = ca.CodeGenerator(f"{fn.name()}.c", {"with_header": False})
    for f in (fn, *also):
        gen.add(f)
    gen.generate(tmp + os.sep)
    return Path(tmp, f"{fn.name()}.c").read_bytes()


def build_library(
    fn: ca.Function,
    lib: Path,
    cc: str,
    flags: tuple[str, ...] = FLAGS,
    nice: int = 0,
    extra_source: str = "",
    also: tuple[ca.Function, ...] = (),
) -> bool:
    """Generate C for ``fn``, compile it to ``lib`` and store it in the cache.

    Generate C for ``fn`` and the functions ``also`` (plus ``extra_source`` appended), compile
    it to the shared object ``lib`` in a private temporary directory and store it with its sha256
    record (``cache_store.store``: atomic, 0600; concurrent processes never load a half-written
    file); False if the cache is unsafe or unwritable (one warning) or the compiler fails.  Callers
    hold COMPILER_LOCK.
    """
    if not cache_store.writable_dir(lib.parent):  # before spending a compile on it
        return False
    try:
        with tempfile.TemporaryDirectory() as tmp:
            source = Path(tmp, f"{fn.name()}.c")
            source.write_bytes(generate(fn, tmp, also) + extra_source.encode())
            tmp_lib = Path(tmp, lib.name)
            cmd = [cc, "-shared", "-fPIC", *flags, "-o", str(tmp_lib), str(source), "-lm"]
            if nice and shutil.which("nice"):
                cmd = ["nice", "-n", str(nice), *cmd]
            if subprocess.run(cmd, capture_output=True, text=True).returncode != 0:
                return False
            return cache_store.store(lib, tmp_lib.read_bytes())
    except (OSError, RuntimeError) as e:  # the temporary directory is full or unwritable
        # (CasADi's code generator reports a failed write as RuntimeError)
        reason = getattr(e, "strerror", None) or e
        cache_store.warn_once(lib.parent, f"C cannot be generated ({reason})")
        return False
