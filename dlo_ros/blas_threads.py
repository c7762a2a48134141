"""One BLAS thread per dlo_ros process: what the ``dlo`` and ``dlo_node`` executables ask for.

The matrices of a solve are small (KKT systems of at most a few hundred unknowns, factored many
times per update), and OpenBLAS's worker threads cost more there than they save: on this 2-core
machine, 150 warm updates of the 283-unknown table mesh of #37's path took a median of 23.7 ms
and a p99 of 152 ms with OpenBLAS's default threads, against 15.0 ms and 19.3 ms with one thread
(``bench/results/auto_vs_full.md``; the thread wake-ups stall an update whenever another process
holds the other core).  OpenBLAS reads its thread count once, when numpy or SciPy loads it, so
the executables set it before they import numpy; a user's own setting is kept.  Importing this
module is that request (``dlo_ros.cli`` imports it first; ``dlo_ros.node.main`` calls
:func:`one_blas_thread`).  A program that imports ``dlo_ros.solver`` itself decides for its own
process (``OPENBLAS_NUM_THREADS=1`` before it imports numpy).
"""

from __future__ import annotations

import os

#: the thread count of the OpenBLAS that numpy's and SciPy's wheels ship (pthreads).  Only that:
#: OMP_NUM_THREADS=1 as well made 23 of the main job's updates on the post run into
#: solver.update_time_limit (IPOPT Maximum_WallTime_Exceeded; 3 runs of `scripts/dlo-env demo`,
#: none with OPENBLAS_NUM_THREADS=1 alone, which settled in 4.5 s)
VARIABLES = ("OPENBLAS_NUM_THREADS",)


def one_blas_thread() -> None:
    """Ask BLAS for one thread (a variable of VARIABLES the user has not set becomes "1")."""
    for name in VARIABLES:
        os.environ.setdefault(name, "1")


one_blas_thread()
