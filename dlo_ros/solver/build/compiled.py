"""Compile CasADi functions to C once and cache the shared objects on disk.

``compiled(fn)`` loads ``<cache>/<name>_<fingerprint>.so``; only when that file is missing or
refused is C generated for ``fn`` and compiled (gcc, ``FLAGS``).  The cache lives in
$DLO_CACHE_DIR, else $XDG_CACHE_HOME/dlo_ros, else ~/.cache/dlo_ros.  Every load and write goes
through ``cache_store`` (owner, mode and sha256 checks; atomic writes).  Without a C compiler, or
with an unsafe or unwritable cache, the original (interpreted) function is returned, so
everything still works, only slower.

The fingerprint (see ``fingerprint``) identifies the function without generating its C, so a cache
look-up costs an evaluation, never a code generation (bench/results/compile_cost.md has the costs).
"""

from __future__ import annotations

import os
from typing import Any, Callable
from pathlib import Path

import ctypes

import casadi as ca
import numpy as np

from ..native import cache_store
from ..native.cache_store import UnusableLibrary, cache_dir
from ..native.compiler import (
    COMPILER_LOCK,
    FLAGS,
    build_library,
    compiler,
    fingerprint,
    library_lock,
)

__all__ = [
    "FLAGS",
    "COMPILER_LOCK",
    "DeferredFunction",
    "InterpretedFunction",
    "NativeFunction",
    "UnusableLibrary",
    "build_library",
    "cache_dir",
    "cached_library",
    "compiled",
    "compiler",
    "fingerprint",
    "library_path",
    "load_native",
]


def _address(fn: Any) -> int:
    """Return the address of the loaded C function ``fn`` (a ctypes function pointer).

    Never null: ``cache_store.load`` looked the symbol up.
    """
    address = ctypes.cast(fn, ctypes.c_void_p).value
    if address is None:
        raise RuntimeError("a loaded C function has no address")
    return address


class NativeFunction:
    """Calls a CasADi-generated C function through ctypes with preallocated numpy buffers.

    Every output is returned dense (column-major reshaped to its shape) as a fresh array; no DM is
    created or converted (``casadi.Function.__call__`` would).  ctypes releases the GIL during the
    call. Not re-entrant: callers serialise calls (ShapeSolver holds a lock).
    """

    def __init__(self, lib_path: Path, fn: ca.Function):
        """Load ``fn`` from its compiled library ``lib_path``.

        UnusableLibrary if ``cache_store.load`` refuses ``lib_path`` (nothing of it was run).
        """
        name = fn.name()
        self._lib = cache_store.load(lib_path, (name, f"{name}_work"))
        self._fn = getattr(self._lib, name)
        self._work_fn = getattr(self._lib, f"{name}_work")
        sz = [ctypes.c_longlong() for _ in range(4)]
        self._work_fn(*[ctypes.byref(v) for v in sz])
        n_arg, n_res, n_iw, n_w = (v.value for v in sz)
        self._in_shapes = [fn.size_in(i) for i in range(fn.n_in())]
        self._out_shapes = [fn.size_out(i) for i in range(fn.n_out())]
        for i in range(fn.n_out()):
            if fn.nnz_out(i) != fn.numel_out(i):
                raise ValueError(f"{name}: output {i} must be dense for NativeFunction")
        for i in range(fn.n_in()):
            if fn.nnz_in(i) != fn.numel_in(i):
                raise ValueError(f"{name}: input {i} must be dense for NativeFunction")
        self._inputs = [np.zeros(r * c) for r, c in self._in_shapes]
        self._outputs = [np.zeros(r * c) for r, c in self._out_shapes]
        dp = ctypes.POINTER(ctypes.c_double)
        self._arg = (dp * max(n_arg, len(self._inputs)))()
        self._res = (dp * max(n_res, len(self._outputs)))()
        for i, a in enumerate(self._inputs):
            self._arg[i] = a.ctypes.data_as(dp)
        for i, a in enumerate(self._outputs):
            self._res[i] = a.ctypes.data_as(dp)
        self._iw = (ctypes.c_longlong * max(n_iw, 1))()
        self._w = (ctypes.c_double * max(n_w, 1))()

    @property
    def out_shapes(self) -> list[tuple[int, int]]:
        """The outputs' (rows, columns)."""
        return list(self._out_shapes)

    def address(self) -> tuple[int, int]:
        """Return the addresses of the generated function and of its ``_work`` function.

        The addresses of the generated function and of its ``_work`` sizes function, for C that
        calls it (``native.newton.UpdateOutputs``); valid while this object (its library) lives.
        """
        return (
            _address(self._fn),
            _address(self._work_fn),
        )

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        for buf, value in zip(self._inputs, args):
            buf[:] = np.asarray(value, dtype=float).ravel(order="F")
        if self._fn(self._arg, self._res, self._iw, self._w, 0) != 0:
            raise RuntimeError("native CasADi function failed")
        return [
            out.reshape(shape, order="F").copy()
            for out, shape in zip(self._outputs, self._out_shapes)
        ]


class InterpretedFunction:
    """Same interface as NativeFunction, on casadi.Function (used when no C compiler is present).

    Evaluates through ``Function.buffer()`` on preallocated numpy arrays: no DM is created or
    converted (``fn(*args)`` would, for every input and output).  Not re-entrant (one work buffer):
    callers serialise calls, as for NativeFunction.
    """

    def __init__(self, fn: ca.Function):
        self._fn = fn
        for i in range(fn.n_in()):
            if fn.nnz_in(i) != fn.numel_in(i):
                raise ValueError(f"{fn.name()}: input {i} must be dense")
        self._dense_out = all(fn.nnz_out(i) == fn.numel_out(i) for i in range(fn.n_out()))
        if not self._dense_out:  # sparse outputs: the plain call (not used on a hot path)
            return
        self._buffer, self._eval = fn.buffer()
        self._inputs = [np.zeros(fn.numel_in(i)) for i in range(fn.n_in())]
        self._out_shapes = [fn.size_out(i) for i in range(fn.n_out())]
        self._outputs = [np.zeros(r * c) for r, c in self._out_shapes]
        # casadi's stubs want a size that the binding reads from the buffer, and numpy's stubs do
        # not declare ndarray a Buffer: both calls are right as written (the tests call them)
        for i, a in enumerate(self._inputs):
            self._buffer.set_arg(i, memoryview(a))  # type: ignore[call-arg, arg-type]
        for i, a in enumerate(self._outputs):
            self._buffer.set_res(i, memoryview(a))  # type: ignore[call-arg, arg-type]

    @property
    def function(self) -> ca.Function:
        """The casadi.Function this evaluates."""
        return self._fn

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        if not self._dense_out:
            out = self._fn(*args)
            out = out if isinstance(out, (list, tuple)) else [out]
            return [np.asarray(o) for o in out]
        for buf, value in zip(self._inputs, args):
            buf[:] = np.asarray(value, dtype=float).ravel(order="F")
        self._eval()
        return [
            out.reshape(shape, order="F").copy()
            for out, shape in zip(self._outputs, self._out_shapes)
        ]


class DeferredFunction:
    """An :class:`InterpretedFunction` built by ``make`` when it is first called or looked at.

    For an evaluator a solver may never call: the contact-free Newton steps around a compiled
    library (``functions.NlpFunctions``) serve only while that library's own compiled loop is
    missing, and building them took a share of every clone's build (``build/mesh_clone.py``).
    Callers serialise calls, as for the functions it stands for.
    """

    def __init__(self, make: Callable[[], InterpretedFunction]) -> None:
        """Build with ``make`` on first use."""
        self._make = make
        self._built: InterpretedFunction | None = None

    def built(self) -> InterpretedFunction:
        """Return the function, built now if it was not."""
        if self._built is None:
            self._built = self._make()
        return self._built

    @property
    def function(self) -> ca.Function:
        """The casadi.Function this evaluates."""
        return self.built().function

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        return self.built()(*args)


def library_path(fn: ca.Function, flags: tuple[str, ...] = FLAGS) -> Path:
    """Return where the compiled library of ``fn`` is (or will be) cached.

    Where the compiled library of ``fn`` is (or will be) cached:
    ``<cache>/<name>_<fingerprint>.so``.
    """
    return cache_dir() / f"{fn.name()}_{fingerprint(fn, flags)}.so"


def cached_library(fn: ca.Function, flags: tuple[str, ...] = FLAGS) -> Path | None:
    """Return the cached library of ``fn`` if the cache holds it and would load it.

    Path of the compiled library of ``fn`` if the cache holds it and ``cache_store`` would load
    it (directory, owner, mode and sha256 checked), else None (no compiling, no C generated).
    """
    if compiler() is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    lib = library_path(fn, flags)
    return lib if cache_store.is_verified(lib) else None


def load_native(lib: Path, fn: ca.Function) -> NativeFunction | None:
    """Load ``fn``'s compiled library ``lib``; None if it is missing or refused.

    ``fn``'s compiled library ``lib`` if it is in the cache and passes every check, else
    None.
    """
    try:
        return NativeFunction(lib, fn)
    except UnusableLibrary:
        return None


def compiled(
    fn: ca.Function,
    flags: tuple[str, ...] = FLAGS,
    nice: int = 0,
    lib: Path | None = None,
    extra_source: str = "",
    also: tuple[ca.Function, ...] = (),
) -> tuple[NativeFunction | InterpretedFunction, bool]:
    """Return a callable of ``fn``: its library from the cache or built now, else interpreted.

    (callable, compiled?).  Safe to call concurrently from several processes.  ``lib``: the
    ``library_path`` of ``fn``, when the caller has it already (it costs an evaluation of ``fn``);
    ``extra_source``: C appended to ``fn``'s, ``also``: functions compiled into the same library
    (then ``lib`` must be a path keyed by them too).

    ``FLAGS``: see there. ShapeSolver runs it niced in the background; the cache makes it once per
    scene structure and machine.
    """
    cc = compiler()
    if cc is None or os.environ.get("DLO_NO_COMPILE"):
        return InterpretedFunction(fn), False
    lib = lib or library_path(fn, flags)
    native = load_native(lib, fn)
    if native is None:  # missing, damaged or refused: (re)build it
        with library_lock(lib):  # one compiler per process, one build at a time per cache
            native = load_native(lib, fn)  # another thread or process may have built it meanwhile
            if native is None and build_library(fn, lib, cc, flags, nice, extra_source, also):
                native = load_native(lib, fn)
    return (native, True) if native is not None else (InterpretedFunction(fn), False)
