"""Newton with an active set in one compiled call (``ActiveNewton``).

Newton with an active set in one compiled call (``ActiveNewton``): the driver
``native/newton_active.c``, compiled into the full KKT function's library
(``native.build.active_library_path``).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Any
from pathlib import Path

import numpy as np

from .cache_store import load as load_library
from .blocks import NodeBlocks, driver_head, eigen_lapack, verdict
from .outputs import ComputedOutputs, UpdateOutputs
from ..state import Inertia
from .settings import (
    CONVERGED,
    JOIN_TOLERANCE,
    LEAVE_TOLERANCE,
    NEWTON_CHORD_CONTRACTION,
    NEWTON_CHORD_START,
    NEWTON_CHORD_STEPS,
    NEWTON_CHORD_TOLERANCE,
    NEWTON_DUAL_TOLERANCE,
    NEWTON_MAX_STEP,
    NEWTON_PRIMAL_TOLERANCE,
    NEWTON_REGULARISATION,
)


#: ``dlo_newton_active_run``'s argument types (``newton_active.c``), in its order: the LAPACK/BLAS
#: pointers and the node map (4 pointers, 2 ints), n, rows, the active and switchable flags, the
#: switches, step limits and whether ``first`` is given (4 ints), the settings (9 doubles), the
#: arrays (9), the counters (2), then the eigenpair's and the outputs' pointers (6).  The flags'
#: and the arrays' pointers are passed as addresses (``ndarray.ctypes.data``: a typed pointer,
#: ``data_as``, costs twice that per argument and call).
_IP, _VP = ctypes.POINTER(ctypes.c_int), ctypes.c_void_p
_ARGTYPES: list[Any] = [
    *[_VP] * 4,
    *[ctypes.c_int] * 4,
    *[_VP] * 2,
    *[ctypes.c_int] * 4,
    *[ctypes.c_double] * 9,
    *[_VP] * 9,
    *[_IP] * 2,
    *[_VP] * 6,
]
#: the settings the call passes (doubles), in ``dlo_newton_active_run``'s order
_SETTINGS = (
    NEWTON_MAX_STEP,
    NEWTON_REGULARISATION,
    NEWTON_DUAL_TOLERANCE,
    NEWTON_PRIMAL_TOLERANCE,
    NEWTON_CHORD_TOLERANCE,
    NEWTON_CHORD_CONTRACTION,
    NEWTON_CHORD_START,
    JOIN_TOLERANCE,
    LEAVE_TOLERANCE,
)


@dataclass
class ActiveOutcome:
    """What one ``ActiveNewton`` call returns.

    What one ``ActiveNewton`` call returns: ``code`` (CONVERGED, …), the last iterate (z, λ over
    every row), the derivatives [∇f, g, ∂g/∂z, ∇²L, energies] evaluated there, the steps taken and
    the active set there.
    """

    code: int
    z: np.ndarray
    lam: np.ndarray
    gradient: np.ndarray
    g: np.ndarray
    jacobian: np.ndarray
    hessian: np.ndarray
    energies: np.ndarray
    steps: int
    active: np.ndarray
    evaluations: int = 0
    #: once converged, ``Inertia.STABLE`` when the held rows' KKT inertia showed the shape stable,
    #: else the stability eigenvalue there and its eigenvector in z (``SolverState.reduced_eigen``,
    #: on the rows ``stability.held_rows`` holds), None if LAPACK failed
    eigen: tuple[float, np.ndarray] | Inertia | None = None
    #: the outputs at the answer, when the call evaluated them (``UpdateOutputs``)
    outputs: ComputedOutputs | None = None


class ActiveNewton:
    """Newton with an active set in one compiled call.

    Newton with an active set in one compiled call: the inner loop of ``active_set.active_steps``
    (its regularised steps, row switches, convergence test and step limit), whose tail is chord
    steps.  Each step evaluates the full KKT function (Newton's own steps, the same iterates and
    row decisions) until a check of the rows changes none and the steps are below
    ``NEWTON_CHORD_START``.  The rows are checked at the first iterate, which a Newton step reached
    (the residual function's g and the multipliers there are Newton's own: no evaluation needed
    unless a row changes), and at every evaluated iterate.  After that [∇²L J_Aᵀ; J_A 0] stays
    factored and only the residual [∇L; g] is evaluated per step, as in the contact-free loop
    (``NativeNewton``: the same contraction, tolerance and retry rules, the derivatives evaluated
    at the answer, and there the stability eigenpair, on the rows
    ``stability.min_reduced_eigenvalue`` holds, and the outputs, ``after``).  In C around the
    compiled split full KKT function (``StringNLP.kkt_split_fn``: ∇²L's per-node part added by
    BLAS, as in ``NativeNewton``) and its residual, compiled into the full KKT function's library.
    Not re-entrant per instance: callers serialise calls (ShapeSolver holds a lock).
    """

    def __init__(
        self, lib_path: Path, n: int, rows: int, node_map: NodeBlocks, equality: np.ndarray
    ):
        self._lib = load_library(lib_path, ("dlo_newton_active_run",))  # checked, as above
        self._run = self._lib.dlo_newton_active_run
        self._run.restype = ctypes.c_int
        self._run.argtypes = _ARGTYPES
        self._map = node_map  # kept alive for the calls
        #: the routines the stability verdict calls, kept alive for the calls; ``lapack.inertia =
        #: 0`` makes the loop compute the eigenpair always, as before the inertia (comparisons)
        self.lapack = eigen_lapack()
        self._equality = np.ascontiguousarray(equality, dtype=np.intc)
        self._eig_value, self._eig_code, self._direction = (
            ctypes.c_double(0.0),
            ctypes.c_int(-1),
            np.zeros(n),
        )
        self._eigen_args = (
            self._equality.ctypes.data,
            ctypes.addressof(self.lapack),
            ctypes.addressof(self._eig_value),
            self._direction.ctypes.data,
            ctypes.addressof(self._eig_code),
        )
        #: what a converged call also evaluates (``UpdateOutputs``), None: nothing
        self.after: UpdateOutputs | None = None
        self._head = (*driver_head(node_map),)
        self.n, self.rows = n, rows

    def __call__(
        self,
        z: np.ndarray,
        lam: np.ndarray,
        p: np.ndarray,
        active: np.ndarray,
        ub: np.ndarray,
        switchable: np.ndarray,
        switches: int,
        max_steps: int,
        first: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
        prof: np.ndarray | None = None,
    ) -> ActiveOutcome:
        """Run Newton with an active set from (z, λ) in one compiled call.

        From (z, λ) with the rows ``active`` held at ``ub`` (both over every row); up to
        ``switches`` changes among the rows ``switchable``; ``max_steps``: the most evaluations of
        the full KKT function on the way (the one at the answer not counted); ``first``: (∇f, g,
        ∂g/∂z, ∇²L) for the first step instead of an evaluation; ``prof``: the string's profiles,
        for the outputs (``after``).
        """
        n, rows = self.n, self.rows
        z = np.array(z, dtype=float, copy=True)
        lam = np.array(lam, dtype=float, copy=True)
        p = np.ascontiguousarray(p, dtype=float)
        act = np.ascontiguousarray(active, dtype=np.intc).copy()
        switch = np.ascontiguousarray(switchable, dtype=np.intc)
        ub = np.ascontiguousarray(ub, dtype=float)
        grad, g = np.zeros(n), np.zeros(rows)
        jac, hess, energies = np.zeros(rows * n), np.zeros(n * n), np.full(5, np.nan)
        if first is not None:
            grad[:] = np.ravel(first[0])
            g[:] = np.ravel(first[1])
            jac[:] = np.asarray(first[2], dtype=float).ravel(order="F")
            hess[:] = np.asarray(first[3], dtype=float).ravel(order="F")
        steps, evaluations = ctypes.c_int(0), ctypes.c_int(0)
        arrays = (z, p, lam, ub, grad, g, jac, hess, energies)
        code = self._run(
            *self._head,
            n,
            rows,
            act.ctypes.data,
            switch.ctypes.data,
            int(switches),
            int(max_steps),
            NEWTON_CHORD_STEPS,
            int(first is not None),
            *_SETTINGS,
            *(a.ctypes.data for a in arrays),
            ctypes.byref(steps),
            ctypes.byref(evaluations),
            *self._eigen_args,
            self.after.prepare(prof) if self.after is not None else None,
        )
        out = ActiveOutcome(
            int(code),
            z,
            lam,
            grad,
            g,
            jac.reshape(rows, n, order="F"),
            hess.reshape(n, n, order="F"),
            energies,
            steps.value,
            act.astype(bool),
            evaluations.value,
        )
        if code == CONVERGED:
            out.eigen = verdict(self._eig_code.value, self._eig_value.value, self._direction)
            if self.after is not None:
                out.outputs = self.after.collect(z, p)[1]
        return out
