"""A contact-free warm update as one compiled call: the Newton loop in C around the compiled KKT function.

``newton.newton_free`` takes its first ``NEWTON_STEPS`` steps in one CasADi call and every further step
in Python.  Here the whole loop is one C function, compiled together with the generated code of
``StringNLP.kkt_free_fn``: from u = [z; λ_free] and the Newton system (K, r) at u it repeats

    solve (K + diag(δ I_n, −δ I_nf)) Δ = r  (LAPACK dgesv),  u ← u − Δ,  (K, r, ∇f, energies) ← kkt_free(u)

taking at least ``NEWTON_STEPS`` steps (as the fused CasADi call does), then stopping once
‖r_dual‖∞ < 1e-9 and ‖r_primal‖∞ < 1e-11, at ``max_steps``, at a singular matrix, or at a step larger than
``NEWTON_MAX_STEP`` in any scaled unknown — the same rules and the same regularisation δ =
NEWTON_REGULARISATION · max(max|K|, 1) as the Python path.  LAPACK's dgesv is the one SciPy ships
(``scipy.linalg.cython_lapack``), passed in as a function pointer, so nothing is linked.  The call goes
through ctypes, which releases the GIL.

The library is cached beside the KKT function's (``compiled.cache_dir``), keyed by that function's
fingerprint and this module's C source.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from .compiled import COMPILER_LOCK, build_library, cache_dir, compiler, fingerprint
from .nlp import NEWTON_DUAL_TOLERANCE, NEWTON_MAX_STEP, NEWTON_PRIMAL_TOLERANCE, NEWTON_REGULARISATION, NEWTON_STEPS

#: return codes of dlo_newton_run
CONVERGED, NOT_CONVERGED, SINGULAR, STEP_TOO_LARGE, EVALUATION_FAILED = 0, 1, 2, 3, 4

DRIVER = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef void (*dlo_dgesv_t)(int *n, int *nrhs, double *a, int *lda, int *ipiv, double *b, int *ldb, int *info);

static int dlo_converged(const double *r, int n, int m, double tol_dual, double tol_prim) {
  for (int i = 0; i < n; ++i) if (!(fabs(r[i]) < tol_dual)) return 0;
  for (int i = n; i < n + m; ++i) if (!(fabs(r[i]) < tol_prim)) return 0;
  return 1;
}

/* Newton on the contact-free KKT system; see dlo_ros/solver/native_newton.py.  u, K, r: in at the
   start, out at the last iterate; grad, energies: out at the last evaluation. */
CASADI_SYMBOL_EXPORT int dlo_newton_run(dlo_dgesv_t dgesv, int n, int m, int min_steps, int max_steps,
    double max_step, double reg, double tol_dual, double tol_prim, double *u, const double *p, double *K,
    double *r, double *grad, double *energies, int *steps, double *largest) {
  int N = n + m, one = 1, info = 0, code = 1;
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  FUNCTION_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 4 ? sz_res : 4));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  double *A = malloc(sizeof(double) * N * N), *step = malloc(sizeof(double) * N);
  int *ipiv = malloc(sizeof(int) * N);
  *steps = 0; *largest = 0.0;
  for (int it = 0; ; ++it) {
    if (it >= min_steps && dlo_converged(r, n, m, tol_dual, tol_prim)) { code = 0; break; }
    if (it == max_steps) { code = 1; break; }
    double kmax = 1.0;
    for (int i = 0; i < N * N; ++i) { A[i] = K[i]; if (fabs(K[i]) > kmax) kmax = fabs(K[i]); }
    double delta = reg * kmax;
    for (int i = 0; i < N; ++i) { A[i * N + i] += (i < n ? delta : -delta); step[i] = r[i]; }
    dgesv(&N, &one, A, &N, ipiv, step, &N, &info);
    if (info != 0) { code = 2; break; }
    double big = 0.0;
    int finite = 1;
    for (int i = 0; i < N; ++i) {
      if (!isfinite(step[i])) finite = 0;
      if (i < n && fabs(step[i]) > big) big = fabs(step[i]);
    }
    if (!finite || big > max_step) { code = 3; *largest = big; break; }
    if (big > *largest) *largest = big;
    for (int i = 0; i < N; ++i) u[i] -= step[i];
    arg[0] = u; arg[1] = p; arg[2] = u + n;
    res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
    if (FUNCTION(arg, res, iw, w, 0) != 0) { code = 4; break; }
    *steps = it + 1;
  }
  free(arg); free(res); free(iw); free(w); free(A); free(step); free(ipiv);
  return code;
}
"""


def _dgesv_pointer() -> int:
    """The address of SciPy's LAPACK dgesv (from the PyCapsule scipy.linalg.cython_lapack exports)."""
    from scipy.linalg import cython_lapack

    capsule = cython_lapack.__pyx_capi__["dgesv"]
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype, get_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    return int(get_pointer(capsule, get_name(capsule)))


def library_path(fn: ca.Function, kkt_lib: Path | None = None) -> Path:
    """Where the driver compiled with ``fn`` is (or will be) cached.  ``kkt_lib``: ``fn``'s own
    ``compiled.library_path``, when the caller has it (its name carries the fingerprint, which otherwise
    costs an evaluation of ``fn``)."""
    digest = hashlib.sha256(DRIVER.encode()).hexdigest()[:8]
    key = kkt_lib.stem.rsplit("_", 1)[1] if kkt_lib is not None else fingerprint(fn)
    return cache_dir() / f"dlo_newton_{key}_{digest}.so"


@dataclass
class NewtonOutcome:
    """What one call returns: ``code`` (CONVERGED, …), the last iterate u and K, r, ∇f, energies there,
    the steps taken and the largest |Δz|."""

    code: int
    u: np.ndarray
    kkt: np.ndarray
    residual: np.ndarray
    gradient: np.ndarray
    energies: np.ndarray
    steps: int
    largest: float


class NativeNewton:
    """The compiled Newton loop of one NLP's contact-free system (see the module docstring).  Not
    re-entrant per instance: callers serialise calls (ShapeSolver holds a lock)."""

    def __init__(self, lib_path: Path, n: int, nf: int, n_p: int):
        self._lib = ctypes.CDLL(str(lib_path))
        self._run = self._lib.dlo_newton_run
        dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
        self._run.restype = ctypes.c_int
        self._run.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                              ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                              dp, dp, dp, dp, dp, dp, ip, dp]
        self._dgesv = _dgesv_pointer()
        self.n, self.nf, self.n_p = n, nf, n_p

    def __call__(self, u: np.ndarray, p: np.ndarray, kkt: np.ndarray, residual: np.ndarray,
                 max_steps: int) -> NewtonOutcome:
        n, nf = self.n, self.nf
        N = n + nf
        u = np.array(u, dtype=float, copy=True)
        p = np.ascontiguousarray(p, dtype=float)
        K = np.array(kkt, dtype=float, copy=True, order="F").reshape(N * N, order="F")
        r = np.array(residual, dtype=float, copy=True).ravel()
        grad, energies = np.zeros(n), np.full(5, np.nan)
        steps, largest = ctypes.c_int(0), ctypes.c_double(0.0)
        dp = ctypes.POINTER(ctypes.c_double)
        code = self._run(self._dgesv, n, nf, NEWTON_STEPS, int(max_steps), NEWTON_MAX_STEP, NEWTON_REGULARISATION,
                         NEWTON_DUAL_TOLERANCE, NEWTON_PRIMAL_TOLERANCE, u.ctypes.data_as(dp), p.ctypes.data_as(dp),
                         K.ctypes.data_as(dp), r.ctypes.data_as(dp), grad.ctypes.data_as(dp),
                         energies.ctypes.data_as(dp), ctypes.byref(steps), ctypes.byref(largest))
        return NewtonOutcome(int(code), u, K.reshape(N, N, order="F"), r, grad, energies, steps.value,
                             largest.value)


def build(fn: ca.Function, n: int, nf: int, n_p: int, nice: int = 0,
          kkt_lib: Path | None = None) -> NativeNewton | None:
    """The driver compiled with ``fn`` (the contact-free KKT function), from the cache or built now (one
    compiler at a time per process); None without a C compiler or if compiling fails."""
    cc = compiler()
    if cc is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    lib = library_path(fn, kkt_lib)
    if not lib.exists():
        with COMPILER_LOCK:
            if not lib.exists() and not _compile(fn, cc, lib, nice):
                return None
    return NativeNewton(lib, n, nf, n_p)


def cached(fn: ca.Function, n: int, nf: int, n_p: int, kkt_lib: Path | None = None) -> NativeNewton | None:
    """The driver if the cache holds it (no compiling), else None."""
    if compiler() is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    lib = library_path(fn, kkt_lib)
    return NativeNewton(lib, n, nf, n_p) if lib.exists() else None


def _compile(fn: ca.Function, cc: str, lib: Path, nice: int) -> bool:
    driver = DRIVER.replace("FUNCTION_work", f"{fn.name()}_work").replace("FUNCTION(", f"{fn.name()}(")
    return build_library(fn, lib, cc, nice=nice, extra_source=driver)
