"""One BLAS thread per dlo_ros process: what the ``dlo`` and ``dlo_node`` executables ask for.

The matrices of a solve are small (KKT systems of at most a few hundred unknowns, factored many
times per update), and OpenBLAS's worker threads cost more there than they save: on this 2-core
machine, 150 warm updates of the 283-unknown table mesh of #37's path took a median of 23.7 ms
and a p99 of 152 ms with OpenBLAS's default threads, against 15.0 ms and 19.3 ms with one thread
(``bench/results/auto_vs_full.md``; the thread wake-ups stall an update whenever another process
holds the other core).  OpenBLAS reads its thread count once, when numpy or SciPy loads it, so
the executables set it before they import numpy; a user's own setting is kept.  Importing this
module is that request (``dlo_ros.cli`` imports it first; ``dlo_ros.node.main`` calls
:func:`one_blas_thread`).

A program that imports ``dlo_ros.solver`` itself (a planner calling ``make_solver``) has loaded
numpy before it, too late for the variable; and ``auto``'s background checks run LAPACK beside
the stream's updates, two threads each asking OpenBLAS for both cores.  So importing
``dlo_ros.solver`` sets the OpenBLAS libraries already loaded (numpy's and SciPy's each ship
their own) to one thread through their ``*_set_num_threads`` call (:func:`one_blas_thread_now`),
unless the user set ``OPENBLAS_NUM_THREADS``: the main job's recording streamed in-process at
50 Hz took 40–190 ms per update on the post while a check ran (one null-space QR 65 ms instead of
under 1 ms) and 10–20 ms with one thread (``bench/results/blas_threads.md``).  It changes the
whole process's OpenBLAS, so a program's own large products run on one core too, as they would
under the executables; setting the variable keeps its own choice.
"""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from pathlib import Path

#: the thread count of the OpenBLAS that numpy's and SciPy's wheels ship (pthreads).  Only that:
#: OMP_NUM_THREADS=1 as well made 23 of the main job's updates on the post run into
#: solver.update_time_limit (IPOPT Maximum_WallTime_Exceeded; 3 runs of `scripts/dlo-env demo`,
#: none with OPENBLAS_NUM_THREADS=1 alone, which settled in 4.5 s)
VARIABLES = ("OPENBLAS_NUM_THREADS",)


#: whether ``one_blas_thread`` set OPENBLAS_NUM_THREADS itself (then it is no choice of the user's)
_asked_here = False


def one_blas_thread() -> None:
    """Ask BLAS for one thread (a variable of VARIABLES the user has not set becomes "1")."""
    global _asked_here
    for name in VARIABLES:
        if name not in os.environ:
            os.environ[name] = "1"
            _asked_here = True


one_blas_thread()

#: (get, set) thread-count symbols of the OpenBLAS builds numpy's and SciPy's wheels ship
#: (scipy-openblas, with and without 64-bit integers) and of a system OpenBLAS
SYMBOLS = (
    ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
    ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
    ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
    ("openblas_get_num_threads", "openblas_set_num_threads"),
)


@dataclass(frozen=True)
class BlasLibrary:
    """One OpenBLAS library loaded in this process: its file and its thread count now."""

    path: str
    threads: int


def _loaded_paths() -> list[str]:
    """Return the files of the OpenBLAS libraries mapped into this process (Linux; else none)."""
    maps = Path("/proc/self/maps")
    try:
        lines = maps.read_text().splitlines()
    except OSError:
        return []
    paths = {line.split()[-1] for line in lines if len(line.split()) >= 6}
    return sorted(p for p in paths if "openblas" in Path(p).name.lower())


def _thread_calls(path: str):
    """Return the library's (get, set) thread-count functions, or None when it has neither."""
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    for get, put in SYMBOLS:
        if hasattr(lib, get) and hasattr(lib, put):
            getter, setter = getattr(lib, get), getattr(lib, put)
            getter.restype, getter.argtypes = ctypes.c_int, []
            setter.restype, setter.argtypes = None, [ctypes.c_int]
            return getter, setter
    return None


def loaded_blas() -> list[BlasLibrary]:
    """Return the OpenBLAS libraries loaded in this process and their thread counts."""
    found = []
    for path in _loaded_paths():
        calls = _thread_calls(path)
        if calls is not None:
            found.append(BlasLibrary(path, int(calls[0]())))
    return found


def one_blas_thread_now() -> list[BlasLibrary]:
    """Set the OpenBLAS libraries loaded now to one thread, unless the user chose a count.

    A user's ``OPENBLAS_NUM_THREADS`` is kept (nothing changes).  Returns the libraries as they
    are afterwards.  Call it while no other thread of the process is inside BLAS: OpenBLAS resizes
    its thread pool here.
    """
    if "OPENBLAS_NUM_THREADS" not in os.environ or _asked_here:
        for path in _loaded_paths():
            calls = _thread_calls(path)
            if calls is not None and calls[0]() != 1:
                calls[1](1)
    return loaded_blas()
