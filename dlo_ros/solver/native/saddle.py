"""Leaving a saddle by shifted Newton steps in one compiled call (``NativeSaddle``).

The loop of ``update/saddle.py``'s ``leave_saddle`` (the steps on [∇²L + μ I, J_Aᵀ; J_A, 0], the
merit, its undo and the shift's rules, the stop on a small residual) as the C function
``dlo_saddle_run`` (``native/saddle_escape.c``), appended with the active-set loop to the full KKT
function's library (``native.build.ACTIVE_DRIVERS``): it evaluates the same compiled function
(``StringNLP.kkt_split_fn`` with the Hessian's per-node part added by BLAS) and factors with the
same LAPACK as the Python loop, so the points reached agree to round-off.  Python keeps the
loop's set-up and the polish by ``update.newton.newton`` that follows.  The call goes through
ctypes, which releases the GIL.
"""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .blocks import NodeBlocks, driver_head
from .cache_store import load as load_library
from .settings import (
    CONVERGED,
    NEWTON_REGULARISATION,
    NOT_CONVERGED,
    SADDLE_DUAL_TOLERANCE,
    SADDLE_PRIMAL_TOLERANCE,
    SADDLE_SHIFT_DECAY,
    SADDLE_SHIFT_FLOOR,
    SADDLE_SHIFT_GROWTH,
    SADDLE_STEP,
    SADDLE_STEPS,
)

if TYPE_CHECKING:  # (for the annotations only: build.nlp's module imports far more)
    from ..build.nlp import StringNLP

#: ``dlo_saddle_run``'s argument types (``saddle_escape.c``), in its order: the LAPACK/BLAS
#: pointers and the node map (4), its sizes, n and the rows (4 ints), the held rows and their
#: count, the most steps (int), the settings (7 doubles), σ, ρ and μ (3 doubles), z, p, λ and the
#: bounds (4), the steps' counter.
_VP, _IP = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)
_ARGTYPES: list[Any] = [
    *[_VP] * 4,
    *[ctypes.c_int] * 4,
    _VP,
    ctypes.c_int,
    ctypes.c_int,
    *[ctypes.c_double] * 10,
    *[_VP] * 4,
    _IP,
]
#: the settings the call passes (doubles), in ``dlo_saddle_run``'s order
_SETTINGS = (
    SADDLE_STEP,
    NEWTON_REGULARISATION,
    SADDLE_DUAL_TOLERANCE,
    SADDLE_PRIMAL_TOLERANCE,
    SADDLE_SHIFT_FLOOR,
    SADDLE_SHIFT_GROWTH,
    SADDLE_SHIFT_DECAY,
)


class NativeSaddle:
    """The shifted Newton steps of ``leave_saddle`` in one compiled call (module docstring).

    Not re-entrant per instance: callers serialise calls (ShapeSolver holds a lock).
    """

    def __init__(self, lib_path: Path, n: int, rows: int, node_map: NodeBlocks):
        self._lib = load_library(lib_path, ("dlo_saddle_run",))  # checked by cache_store
        self._run = self._lib.dlo_saddle_run
        self._run.restype = ctypes.c_int
        self._run.argtypes = _ARGTYPES
        self._map = node_map  # kept alive for the calls
        self._head = (
            *driver_head(node_map),
            n,
            rows,
        )
        self.n, self.rows = n, rows

    def __call__(
        self,
        nlp: StringNLP,
        fns: object,
        z: np.ndarray,
        lam: np.ndarray,
        p: np.ndarray,
        idx: np.ndarray,
        bound: np.ndarray,
        rho: float,
        mu: float,
    ) -> tuple[bool, np.ndarray, np.ndarray, int]:
        """Take the shifted steps from (z, λ) with the rows ``idx`` held at ``bound``.

        As ``update.saddle.shifted_steps`` (the same arguments; ``fns`` unused: the library holds
        the function): z, n scaled unknowns; λ, every row's multiplier (zero off ``idx``); ρ, the
        merit's weight on ‖g_A − bound‖₁; μ, the first shift; the objective's scale σ is
        ``nlp.sigma``.  Returns (ok, z, λ, steps): ``ok`` False where the steps gave up (a
        singular matrix, a step that is not finite, a failed evaluation); else (z, λ) is the
        point ``newton`` polishes, whether or not its residual got below the tolerances.
        """
        z = np.array(z, dtype=float, copy=True)
        lam = np.array(lam, dtype=float, copy=True)
        p = np.ascontiguousarray(p, dtype=float)
        rows = np.ascontiguousarray(idx, dtype=np.intc)
        bound = np.ascontiguousarray(bound, dtype=float)
        steps = ctypes.c_int(0)
        code = self._run(
            *self._head,
            rows.ctypes.data,
            int(rows.size),
            SADDLE_STEPS,
            *_SETTINGS,
            float(nlp.sigma),
            float(rho),
            float(mu),
            z.ctypes.data,
            p.ctypes.data,
            lam.ctypes.data,
            bound.ctypes.data,
            ctypes.byref(steps),
        )
        return code in (CONVERGED, NOT_CONVERGED), z, lam, steps.value


def load(lib_path: Path, nlp: StringNLP) -> NativeSaddle | None:
    """Return the escape in the full KKT function's library ``lib_path``, None if not loadable."""
    try:
        return NativeSaddle(lib_path, nlp.z_sym.shape[0], int(nlp.lbg.size), nlp.node_blocks)
    except (OSError, AttributeError):
        return None
