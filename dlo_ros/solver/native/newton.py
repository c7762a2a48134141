"""A warm update as one compiled call: chord Newton steps in C around the compiled KKT function.

``newton.newton_free`` takes its first ``NEWTON_STEPS`` Newton steps in one CasADi call and every
further step in Python.  Here the whole loop is one C function, compiled together with the
generated code of ``StringNLP.kkt_free_split_fn`` and of ``StringNLP.residual_free_fn`` (its r
alone, without K's matrix products: a small fraction of its cost).  The split function is
``kkt_free_fn`` without K's per-node Hessian part Eᵀ W, W = diag(∇²φ_k) E (``assembled.py``), which
it returns instead: CasADi's sparse loops spent three quarters of K's time on that product, and
BLAS dgemm calls on the node map E's dense blocks (``NodeBlocks``, ``dlo_add_node_part``) add it at
a fraction of that.  From u = [z; λ_free] and the Newton system (K, r) at u (carried from the last
answer, or evaluated first in the call) it factors K once and repeats chord steps

    solve (K + diag(δ I_n, −δ I_nf)) Δ = r  (LAPACK dgetrf once, dgetrs per step),  u ← u − Δ,  r ←
    r(u)

evaluating and factoring K anew while the steps exceed ``NEWTON_CHORD_START`` (Newton's own steps,
far from the answer), where a step shrinks by less than ``NEWTON_CHORD_CONTRACTION`` against the
one before, and where a step of an earlier iterate's K would exceed ``NEWTON_MAX_STEP`` (then
Newton's own step from here is taken instead).  It stops once ‖r_dual‖∞ < 1e-9 and ‖r_primal‖∞ <
1e-11 and the last step is below ``NEWTON_CHORD_TOLERANCE`` in every scaled unknown (or no longer
shrinks: round-off), and then evaluates K, ∇f and the energies at the answer, which the next
update's first step uses, and there the stability verdict (``stability.stability_verdict``: the
inertia of K by LAPACK dsytrf, ``dlo_inertia.h``, and where it does not show the shape stable the
eigenvalue, ``stability.min_reduced_eigenvalue``: geqp3, orgqr and syevr on K's blocks; the same
routines as the numpy path, in the same call).  It also stops
at ``NEWTON_CHORD_STEPS`` steps or ``max_steps`` evaluations of K, at a singular matrix, or at a
step larger than ``NEWTON_MAX_STEP`` in any scaled unknown, with the same regularisation
(``update/kkt.py``, ``regularised``) as the Python path.  The answer is the root the
Python path's Newton steps converge to, within round-off: at a grip move of 1 % of L the chord
steps shrink 20–50× each, so about seven steps cost less than one more evaluation of K.  LAPACK and
BLAS are the ones SciPy ships (``scipy.linalg.cython_lapack``, ``cython_blas``), passed in as
function pointers, so nothing is linked.  The call goes through ctypes, which releases the GIL.

At the answer the same call also evaluates what a result needs beyond the loop (``UpdateOutputs``):
the obstacle rows' values, which the contact-free system leaves out (one above its bound: a contact
appeared, and ``newton`` goes on with it active), and then the outputs' function
(``output_function.py``: the published points and orientations, the grip wrenches, the contact
forces and the equilibrium residual). Both are generated functions of their own libraries, called
by address, so that neither arrives later than the loop's library needs.  ``ActiveNewton``, the
loop with obstacle rows active, computes the stability eigenpair and the outputs at its answer in
the same way: a warm update that Newton answers is one compiled call either way.

The C is ``native/newton_free.c`` (and ``newton_active.c`` for ``ActiveNewton``, in
``native.active``), with the headers they include; ``native.build`` reads it from the package,
passes the settings it shares with the Python paths as ``-D`` flags (``native.settings``) and keys
the library, cached beside the KKT function's (``compiled.cache_dir``), by that function's
fingerprint (which also fixes its residual's code) and a digest of the assembled C and those
flags.  The Python side is split by job: ``native.blocks`` (LAPACK by address, the node map's
blocks), ``native.outputs`` (what a converged call also evaluates), ``native.active`` (the
active-set loop) and this module (the contact-free loop, and the names other modules import from
here).
"""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from typing import Any
from pathlib import Path

import casadi as ca
import numpy as np

from .cache_store import UnusableLibrary, load as load_library
from .compiler import compiler, library_lock
from .active import ActiveNewton, ActiveOutcome
from .blocks import CHUNK_WORK, NodeBlocks, WithNodePart, driver_head, eigen_lapack, verdict
from .build import (
    ACTIVE_DRIVERS,
    active_library_path,
    compile_free,
    driver_flags,
    driver_source,
    free_library_path,
)
from .outputs import ComputedOutputs, UpdateOutputs
from ..state import Inertia
from .settings import (
    CONVERGED,
    EVALUATION_FAILED,
    NEWTON_CHORD_CONTRACTION,
    NEWTON_CHORD_START,
    NEWTON_CHORD_STEPS,
    NEWTON_CHORD_TOLERANCE,
    NEWTON_DUAL_TOLERANCE,
    NEWTON_MAX_STEP,
    NEWTON_PRIMAL_TOLERANCE,
    NEWTON_REGULARISATION,
    NOT_CONVERGED,
    SINGULAR,
    STEP_TOO_LARGE,
)

__all__ = [
    "ActiveNewton",
    "ActiveOutcome",
    "CHUNK_WORK",
    "CONVERGED",
    "ComputedOutputs",
    "EVALUATION_FAILED",
    "NOT_CONVERGED",
    "NativeNewton",
    "NewtonOutcome",
    "NodeBlocks",
    "SINGULAR",
    "STEP_TOO_LARGE",
    "UpdateOutputs",
    "WithNodePart",
    "active_flags",
    "active_library_path",
    "active_source",
    "build",
    "cached",
    "library_path",
]


def library_path(fn: ca.Function, kkt_lib: Path | None = None) -> Path:
    """Return where the contact-free driver compiled with ``fn`` is cached.

    Where the contact-free driver compiled with ``fn`` is (or will be) cached
    (``native.build.free_library_path``).
    """
    return free_library_path(fn, kkt_lib)


def active_source(fn: ca.Function, residual: ca.Function) -> str:
    """Return the active-set driver's C, to append to the generated code of ``fn``.

    The active-set driver's C, to append to the generated code of ``fn``
    (``StringNLP.kkt_split_fn``) and ``residual`` (``StringNLP.residual_fn``); compile it with
    ``active_flags``.  With it, the saddle's escape (``native.saddle``), which runs ``fn`` too.
    """
    return driver_source(*ACTIVE_DRIVERS)


def active_flags(fn: ca.Function, residual: ca.Function) -> tuple[str, ...]:
    """Return the compiler flags of ``active_source``.

    The compiler flags of ``active_source``: ``compiled.FLAGS``, the shared settings and the two
    functions' names, as ``-D`` flags.
    """
    return driver_flags(fn, residual)


#: ``dlo_newton_run``'s argument types (``newton_free.c``), in its order: the LAPACK/BLAS pointers
#: and the node map (4), its sizes, n, nf and the step limits (6 ints), the settings (7 doubles),
#: the arrays (6), the counters and the largest step (3), then the eigenpair's pointers (4), the
#: outputs' (1) and whether K and r are given (1 int).
_VP, _IP, _DP = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
_ARGTYPES: list[Any] = [
    *[_VP] * 4,
    *[ctypes.c_int] * 6,
    *[ctypes.c_double] * 7,
    *[_VP] * 6,
    _IP,
    _IP,
    _DP,
    _VP,
    _DP,
    _VP,
    _IP,
    _VP,
    ctypes.c_int,
]


@dataclass
class NewtonOutcome:
    """What one ``NativeNewton`` call returns.

    What one call returns: ``code`` (CONVERGED, …), the last iterate u and K, r, ∇f, energies
    there, the steps taken and the largest |Δz|; once converged, ``eigen``: ``Inertia.STABLE``
    when K's inertia showed the shape stable, else the stability eigenvalue there and its
    eigenvector in z (``stability.min_reduced_eigenvalue`` on K's blocks,
    ``SolverState.reduced_eigen``), None when the free rows leave no freedom or LAPACK failed (the
    numpy path then decides).
    """

    code: int
    u: np.ndarray
    kkt: np.ndarray
    residual: np.ndarray
    gradient: np.ndarray
    energies: np.ndarray
    steps: int
    largest: float
    evaluations: int = 0
    eigen: tuple[float, np.ndarray] | Inertia | None = None
    #: every row's value at the answer, when the call evaluated the obstacle rows
    #: (``UpdateOutputs``)
    g: np.ndarray | None = None
    #: the outputs at the answer, when the call evaluated them (``UpdateOutputs``)
    outputs: ComputedOutputs | None = None


class NativeNewton:
    """The compiled Newton loop of one NLP's contact-free system.

    The compiled Newton loop of one NLP's contact-free system (see the module docstring).  Not
    re-entrant per instance: callers serialise calls (ShapeSolver holds a lock).
    """

    def __init__(self, lib_path: Path, n: int, nf: int, n_p: int, node_map: NodeBlocks):
        # checked by cache_store (UnusableLibrary if refused)
        self._lib = load_library(lib_path, ("dlo_newton_run",))
        self._run = self._lib.dlo_newton_run
        self._run.restype = ctypes.c_int
        self._run.argtypes = _ARGTYPES
        self.n, self.nf, self.n_p = n, nf, n_p
        #: what a converged call also evaluates (``UpdateOutputs``), None: nothing
        self.after: UpdateOutputs | None = None
        N = n + nf
        # the call's arrays, allocated once and passed by their addresses (an ndarray's ctypes
        # pointer costs microseconds per argument and call)
        self._u, self._p, self._K, self._r = (
            np.zeros(N),
            np.zeros(n_p),
            np.zeros((N, N), order="F"),
            np.zeros(N),
        )
        self._grad, self._energies, self._direction = np.zeros(n), np.zeros(5), np.zeros(n)
        self._steps, self._evaluations, self._largest = (
            ctypes.c_int(0),
            ctypes.c_int(0),
            ctypes.c_double(0.0),
        )
        self._eig_value, self._eig_code = ctypes.c_double(0.0), ctypes.c_int(-1)
        self._map = node_map  # kept alive for the calls
        #: the routines the stability verdict calls, kept alive for the calls; ``lapack.inertia =
        #: 0`` makes the loop compute the eigenpair always, as before the inertia (comparisons)
        self.lapack = eigen_lapack()
        self._head = (
            *driver_head(node_map),
            n,
            nf,
        )
        self._tail = (
            NEWTON_CHORD_STEPS,
            NEWTON_MAX_STEP,
            NEWTON_REGULARISATION,
            NEWTON_DUAL_TOLERANCE,
            NEWTON_PRIMAL_TOLERANCE,
            NEWTON_CHORD_TOLERANCE,
            NEWTON_CHORD_CONTRACTION,
            NEWTON_CHORD_START,
            *(
                a.ctypes.data
                for a in (self._u, self._p, self._K, self._r, self._grad, self._energies)
            ),
            ctypes.byref(self._steps),
            ctypes.byref(self._evaluations),
            ctypes.byref(self._largest),
            ctypes.addressof(self.lapack),
            ctypes.byref(self._eig_value),
            self._direction.ctypes.data,
            ctypes.byref(self._eig_code),
        )

    def __call__(
        self,
        u: np.ndarray,
        p: np.ndarray,
        kkt: np.ndarray | None,
        residual: np.ndarray | None,
        max_steps: int,
        prof: np.ndarray | None = None,
    ) -> NewtonOutcome:
        """Run the contact-free Newton loop from u = [z; λ_free] in one compiled call.

        From u = [z; λ_free] with K, r at u (None: evaluated at u in the call, not counted);
        ``max_steps``: the most evaluations of K on the way (the one at the answer is not counted);
        ``prof``: the string's profiles, for the outputs (``after``).
        """
        self._u[:] = u
        self._p[:] = p
        given = kkt is not None
        if given:
            self._K[:] = kkt
            self._r[:] = np.ravel(np.asarray(residual))
        self._energies[:] = np.nan
        after = self.after
        code = self._run(
            *self._head,
            int(max_steps),
            *self._tail,
            after.prepare(prof) if after is not None else None,
            int(given),
        )
        out = NewtonOutcome(
            int(code),
            self._u.copy(),
            self._K.copy(order="F"),
            self._r.copy(),
            self._grad.copy(),
            self._energies.copy(),
            self._steps.value,
            self._largest.value,
            self._evaluations.value,
        )
        if code == CONVERGED:
            out.eigen = verdict(self._eig_code.value, self._eig_value.value, self._direction)
            if after is not None:
                out.g, out.outputs = after.collect(out.u[: self.n], self._p)
        return out


def build(nlp, nice: int = 0, kkt_lib: Path | None = None) -> NativeNewton | None:
    """Return the driver of ``nlp``'s contact-free system, from the cache or built now.

    The driver of ``nlp``'s contact-free system (``StringNLP.kkt_free_split_fn`` and
    ``residual_free_fn`` compiled with it), from the cache or built now (one compiler at a time per
    process); None without a C compiler or if compiling fails.  ``kkt_lib``: the split function's
    own library path, which keys this one.
    """
    cc = compiler()
    if cc is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    lib = free_library_path(nlp.kkt_free_split_fn, kkt_lib)
    loop = _instance(nlp, lib)
    if loop is None:  # missing, damaged or refused: (re)build it
        with library_lock(lib):
            loop = _instance(nlp, lib)
            fn, residual = nlp.kkt_free_split_fn, nlp.residual_free_fn
            if loop is None and compile_free(fn, residual, cc, lib, nice):
                loop = _instance(nlp, lib)
    return loop


def cached(nlp, kkt_lib: Path | None = None) -> NativeNewton | None:
    """Return the driver if the cache holds it (no compiling), else None."""
    if compiler() is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    return _instance(nlp, free_library_path(nlp.kkt_free_split_fn, kkt_lib))


def _instance(nlp, lib: Path) -> NativeNewton | None:
    """Return the loop in ``lib`` if the cache holds it and it passes ``cache_store.load``."""
    try:
        return NativeNewton(
            lib, nlp.z_sym.shape[0], nlp.n_free_rows, nlp.p_sym.shape[0], nlp.node_blocks
        )
    except UnusableLibrary:
        return None
