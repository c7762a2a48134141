"""A warm update as one compiled call: chord Newton steps in C around the compiled KKT function.

``newton.newton_free`` takes its first ``NEWTON_STEPS`` Newton steps in one CasADi call and every further
step in Python.  Here the whole loop is one C function, compiled together with the generated code of
``StringNLP.kkt_free_split_fn`` and of ``StringNLP.residual_free_fn`` (its r alone, without K's matrix
products: a small fraction of its cost).  The split function is ``kkt_free_fn`` without K's per-node
Hessian part Eᵀ W, W = diag(∇²φ_k) E (``assembled.py``), which it returns instead: CasADi's sparse
loops spent three quarters of K's time on that product, and BLAS dgemm calls on the node map E's dense
blocks (``NodeBlocks``, ``dlo_add_node_part``) add it at a fraction of that.  From u = [z; λ_free] and
the Newton system (K, r) at u (carried from the last answer, or evaluated first in the call) it factors K
once and repeats chord steps

    solve (K + diag(δ I_n, −δ I_nf)) Δ = r  (LAPACK dgetrf once, dgetrs per step),  u ← u − Δ,  r ← r(u)

evaluating and factoring K anew while the steps exceed ``NEWTON_CHORD_START`` (Newton's own steps, far
from the answer), where a step shrinks by less than ``NEWTON_CHORD_CONTRACTION`` against the one
before, and where a step of an earlier iterate's K would exceed ``NEWTON_MAX_STEP`` (then Newton's own
step from here is taken instead).  It stops once ‖r_dual‖∞ < 1e-9 and ‖r_primal‖∞ < 1e-11 and the last step is
below ``NEWTON_CHORD_TOLERANCE`` in every scaled unknown (or no longer shrinks: round-off), and then
evaluates K, ∇f and the energies at the answer, which the next update's first step uses, and there the
stability eigenvalue (``stability.min_reduced_eigenvalue``: the same LAPACK routines, geqp3, orgqr and
syevr, on K's blocks, in the same call).  It also stops at ``NEWTON_CHORD_STEPS`` steps or
``max_steps`` evaluations of K, at a singular matrix, or at a step larger than ``NEWTON_MAX_STEP`` in
any scaled unknown, with the same
regularisation δ = NEWTON_REGULARISATION · max(max|K|, 1) as the Python path.  The answer is the root the
Python path's Newton steps converge to, within round-off: at a grip move of 1 % of L the chord steps
shrink 20–50× each, so about seven steps cost less than one more evaluation of K.  LAPACK and BLAS are
the ones SciPy ships (``scipy.linalg.cython_lapack``, ``cython_blas``), passed in as function pointers,
so nothing is linked.  The
call goes through ctypes, which releases the GIL.

At the answer the same call also evaluates what a result needs beyond the loop (``UpdateOutputs``): the
obstacle rows' values, which the contact-free system leaves out (one above its bound: a contact appeared,
and ``newton`` goes on with it active), and then the outputs' function (``output_function.py``: the
published points and orientations, the grip wrenches, the contact forces and the equilibrium residual).
Both are generated functions of their own libraries, called by address, so that neither arrives later
than the loop's library needs.  ``ActiveNewton``, the loop with obstacle rows active, computes the
stability eigenpair and the outputs at its answer in the same way: a warm update that Newton answers is
one compiled call either way.

The library is cached beside the KKT function's (``compiled.cache_dir``), keyed by that function's
fingerprint (which also fixes its residual's code) and this module's C source.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from .cache_store import UnusableLibrary, load as load_library
from .compiled import COMPILER_LOCK, build_library, cache_dir, compiler, fingerprint
from .nlp import (JOIN_TOLERANCE, LEAVE_TOLERANCE, NEWTON_CHORD_CONTRACTION, NEWTON_CHORD_START,
                  NEWTON_CHORD_STEPS, NEWTON_CHORD_TOLERANCE, NEWTON_DUAL_TOLERANCE, NEWTON_MAX_STEP,
                  NEWTON_PRIMAL_TOLERANCE, NEWTON_REGULARISATION)

#: return codes of dlo_newton_run
CONVERGED, NOT_CONVERGED, SINGULAR, STEP_TOO_LARGE, EVALUATION_FAILED = 0, 1, 2, 3, 4

#: C both drivers begin with: the headers, and the larger of two generated functions' work sizes
_C_COMMON = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef int (*dlo_work_t)(casadi_int *, casadi_int *, casadi_int *, casadi_int *);

static void dlo_work(dlo_work_t first, dlo_work_t second, casadi_int *sz_arg, casadi_int *sz_res,
                     casadi_int *sz_iw, casadi_int *sz_w) {
  casadi_int a, r, i, w;
  first(sz_arg, sz_res, sz_iw, sz_w);
  second(&a, &r, &i, &w);
  if (a > *sz_arg) *sz_arg = a;
  if (r > *sz_res) *sz_res = r;
  if (i > *sz_iw) *sz_iw = i;
  if (w > *sz_w) *sz_w = w;
}

typedef void (*dlo_gemm_t)(char *ta, char *tb, int *m, int *n, int *k, double *alpha, double *a, int *lda, double *b,
                           int *ldb, double *beta, double *c, int *ldc);

/* The node map E (rows x n) as dense blocks: group g holds E[row[..], col[..]] for its count[2g] rows and
   count[2g + 1] columns (column-major, in block), every other entry of E is zero (NodeBlocks). */
typedef struct {
  int groups, chunk;
  const int *count, *row, *col;
  const double *block;
} dlo_node_map;

/* The Hessian's per-node part added to a split function's output: H += E^T W, W = diag(hess_k) E (rows_w x
   n, as the split function gives it), H at leading dimension ldh: per group, BLAS dgemm of its block
   against W's rows gathered, at most map->chunk rows a call (small enough that OpenBLAS runs it on this
   thread: its worker threads would spin on the other core).  buf: chunk x n + (largest group's columns) x n. */
static void dlo_add_node_part(dlo_gemm_t gemm, const dlo_node_map *map, const double *W, int rows_w, int n,
                              double *H, int ldh, double *buf) {
  char t = 'T', no = 'N';
  double one = 1.0, zero = 0.0;
  const int *row = map->row, *col = map->col;
  const double *block = map->block;
  for (int g = 0; g < map->groups; ++g) {
    int R = map->count[2 * g], C = map->count[2 * g + 1];
    double *wg = buf, *out = buf + (size_t)map->chunk * n;
    for (int start = 0; start < R; start += map->chunk) {
      int k = R - start < map->chunk ? R - start : map->chunk;
      for (int c = 0; c < n; ++c)
        for (int i = 0; i < k; ++i) wg[i + (size_t)k * c] = W[row[start + i] + (size_t)rows_w * c];
      gemm(&t, &no, &C, &n, &k, &one, (double *)block + start, &R, wg, &k, &zero, out, &C);
      for (int c = 0; c < n; ++c)
        for (int j = 0; j < C; ++j) H[col[j] + (size_t)ldh * c] += out[j + (size_t)C * c];
    }
    row += R; col += C; block += (size_t)R * C;
  }
}

/* A generated CasADi function of another library (the obstacle rows', the outputs'), by its address. */
typedef int (*dlo_casadi_t)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);

/* What a converged update also evaluates in the same call (see UpdateOutputs in native_newton.py): the
   obstacle rows' values (contact-free loop only: the active-set loop has every row), then, if none of them
   is violated, the outputs' function (output_function.py) at (z, p, lambda_SI, prof).  A NULL function is
   skipped.  done: out, bit 1 set when g holds every row's value, bit 2 when the outputs were evaluated. */
typedef struct {
  dlo_casadi_t obstacle, outputs;
  dlo_work_t obstacle_work, outputs_work;
  int rows, free_rows;
  const double *ub, *lam_div, *prof;
  double *g, *lam_si;
  double *out[8];
  int done;
} dlo_after;

static int dlo_call(dlo_casadi_t fn, dlo_work_t work, const double **in, double **out) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 4 ? sz_arg : 4));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 8 ? sz_res : 8));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  for (int i = 0; i < 4; ++i) arg[i] = in[i];
  for (int i = 0; i < 8; ++i) res[i] = out[i];
  int code = fn(arg, res, iw, w, 0);
  free(arg); free(res); free(iw); free(w);
  return code;
}

/* After convergence at (z, p) with multipliers lam (every row if all_rows, else the free rows) and, for
   the contact-free loop, the free rows' values g_free: there a->g gets every row's value, and the
   outputs are evaluated unless an obstacle row exceeds its bound by more than 1e-9 (a contact appeared:
   the caller goes on with it active).  The active-set loop (g_free NULL) has every row: the outputs. */
static void dlo_after_run(dlo_after *a, const double *z, const double *p, const double *lam, int all_rows,
                          const double *g_free) {
  a->done = 0;
  if (g_free != NULL) {  /* the contact-free loop: its obstacle rows, and none of them violated */
    memcpy(a->g, g_free, sizeof(double) * a->free_rows);
    if (a->rows > a->free_rows) {
      if (a->obstacle == NULL) return;
      const double *in[4] = {z, p, NULL, NULL};
      double *out[8] = {a->g + a->free_rows, NULL, NULL, NULL, NULL, NULL, NULL, NULL};
      if (dlo_call(a->obstacle, a->obstacle_work, in, out) != 0) return;
    }
    a->done = 1;
    for (int i = a->free_rows; i < a->rows; ++i) if (!(a->g[i] <= a->ub[i] + 1e-9)) return;
  }
  if (a->outputs == NULL) return;
  for (int i = 0; i < a->rows; ++i) a->lam_si[i] = (all_rows || i < a->free_rows ? lam[i] : 0.0) / a->lam_div[i];
  const double *in[4] = {z, p, a->lam_si, a->prof};
  if (dlo_call(a->outputs, a->outputs_work, in, a->out) == 0) a->done |= 2;
}

typedef void (*dlo_getrf_t)(int *m, int *n, double *a, int *lda, int *ipiv, int *info);
typedef void (*dlo_getrs_t)(char *trans, int *n, int *nrhs, double *a, int *lda, int *ipiv, double *b, int *ldb,
                            int *info);

/* The LU of A + diag(delta I_n, -delta I_(N-n)), delta = reg max(max|A|, 1), in place; LAPACK's info. */
static int dlo_regularised_lu(dlo_getrf_t getrf, double *A, int *ipiv, int n, int N, double reg) {
  double kmax = 1.0;
  int info = 0;
  for (int i = 0; i < N * N; ++i) if (fabs(A[i]) > kmax) kmax = fabs(A[i]);
  double delta = reg * kmax;
  for (int i = 0; i < N; ++i) A[i * N + i] += (i < n ? delta : -delta);
  getrf(&N, &N, A, &N, ipiv, &info);
  return info;
}
"""

#: The stability eigenvalue (``stability.min_reduced_eigenvalue``) of the contact-free answer, in C beside
#: the loop: the same LAPACK routines on the same matrices as the numpy path.
_C_EIGEN = r"""
typedef void (*dlo_geqp3_t)(int *m, int *n, double *a, int *lda, int *jpvt, double *tau, double *work, int *lwork,
                            int *info);
typedef void (*dlo_orgqr_t)(int *m, int *n, int *k, double *a, int *lda, double *tau, double *work, int *lwork,
                            int *info);
typedef void (*dlo_syevr_t)(char *jobz, char *range, char *uplo, int *n, double *a, int *lda, double *vl, double *vu,
                            int *il, int *iu, double *abstol, int *m, double *w, double *z, int *ldz, int *isuppz,
                            double *work, int *lwork, int *iwork, int *liwork, int *info);

/* SciPy's LAPACK and BLAS routines the eigenvalue needs; chunk: the most multiplications of one dgemm */
typedef struct {
  dlo_geqp3_t geqp3;
  dlo_orgqr_t orgqr;
  dlo_syevr_t syevr;
  dlo_gemm_t gemm;
  int chunk;
} dlo_eigen_lapack;

/* C = op(A) B column block by column block, each dgemm call within la->chunk multiplications (as
   dlo_add_node_part: OpenBLAS then stays on this thread); op(A) is rows x inner. */
static void dlo_gemm_chunked(const dlo_eigen_lapack *la, char ta, int rows, int cols, int inner, const double *A,
                             int lda, const double *B, int ldb, double *C, int ldc) {
  char no = 'N';
  double one = 1.0, zero = 0.0;
  long per = (long)rows * inner;
  int step = per > 0 ? (int)(la->chunk / per) : cols;
  if (step < 1) step = 1;
  for (int c = 0; c < cols; c += step) {
    int k = cols - c < step ? cols - c : step;
    la->gemm(&ta, &no, &rows, &k, &inner, &one, (double *)A, &lda, (double *)B + (size_t)ldb * c, &ldb, &zero,
             C + (size_t)ldc * c, &ldc);
  }
}

/* The smallest eigenvalue of N^T H N and its eigenvector N v, N an orthonormal basis of the null space of
   the m x n matrix J (leading dimension ldj): LAPACK geqp3 of J^T, rank = number of |R_kk| above
   max(m, n) eps |R_00|, Q from orgqr, N = Q's last n - rank columns; syevr for the one eigenpair.  H: n x n
   at leading dimension ldh.  0: done; 1: no freedom (rank n); -1: LAPACK failed (the caller's numpy path
   decides). */
static int dlo_reduced_eigen(const dlo_eigen_lapack *la, const double *H, int ldh, const double *J, int ldj, int n,
                             int m, double *value, double *direction) {
  int k = m < n ? m : n, info = 0, code = -1;
  /* the workspace sizes SciPy's wrappers pass (the unblocked algorithms): blocked ones call BLAS 3 at
     sizes where OpenBLAS's threads spin on the other core (a native call's CPU time doubled) */
  int lw_qr = 3 * m + 1, lw_q = n > 1 ? n : 1, lwork = 26 * n + 3 * m + 1, liwork = 10 * n + 1;
  double *qr = malloc(sizeof(double) * ((size_t)n * (m > 0 ? m : 1))), *tau = calloc((size_t)n + 1, sizeof(double));
  double *Q = calloc((size_t)n * n, sizeof(double)), *work = malloc(sizeof(double) * lwork);
  double *T = malloc(sizeof(double) * (size_t)n * n), *M = malloc(sizeof(double) * (size_t)n * n);
  double *v = malloc(sizeof(double) * ((size_t)n + 1));
  int *jpvt = calloc((size_t)m + 1, sizeof(int)), *iwork = malloc(sizeof(int) * liwork), isuppz[2];
  int rank = 0;
  if (m > 0) {
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < n; ++i) qr[i + (size_t)n * j] = J[j + (size_t)ldj * i];
    la->geqp3(&n, &m, qr, &n, jpvt, tau, work, &lw_qr, &info);
    if (info != 0) goto done;
    double big = fabs(qr[0]), eps = 2.220446049250313e-16, limit = (m > n ? m : n) * eps * big;
    for (int i = 0; i < k; ++i) if (fabs(qr[i + (size_t)n * i]) > limit) ++rank;
    memcpy(Q, qr, sizeof(double) * (size_t)n * k);
  }
  if (rank == n) { code = 1; goto done; }
  /* Q from its k reflectors (numpy's path pads tau with zeros to n: identity reflectors, the same Q) */
  la->orgqr(&n, &n, &k, Q, &n, tau, work, &lw_q, &info);
  if (info != 0) goto done;
  {
    int r = n - rank, found = 0, il = 1, lw_eig = 26 * r;
    char jobz = 'V', range = 'I', uplo = 'L', tr = 'T', no = 'N';
    double vl = 0.0, vu = 0.0, abstol = 0.0, w[1];
    const double *basis = Q + (size_t)n * rank;
    dlo_gemm_chunked(la, no, n, r, n, H, ldh, basis, n, T, n);      /* T = H N */
    dlo_gemm_chunked(la, tr, r, r, n, basis, n, T, n, M, r);        /* M = N^T H N */
    la->syevr(&jobz, &range, &uplo, &r, M, &r, &vl, &vu, &il, &il, &abstol, &found, w, v, &r, isuppz, work, &lw_eig,
              iwork, &liwork, &info);
    if (info != 0 || found != 1) goto done;
    *value = w[0];
    for (int i = 0; i < n; ++i) {
      double s = 0.0;
      for (int j = 0; j < r; ++j) s += basis[i + (size_t)n * j] * v[j];
      direction[i] = s;
    }
    code = 0;
  }
done:
  free(qr); free(tau); free(Q); free(work); free(T); free(M); free(v); free(jpvt); free(iwork);
  return code;
}
"""

DRIVER = _C_COMMON + _C_EIGEN + r"""

static int dlo_converged(const double *r, int n, int m, double tol_dual, double tol_prim) {
  for (int i = 0; i < n; ++i) if (!(fabs(r[i]) < tol_dual)) return 0;
  for (int i = n; i < n + m; ++i) if (!(fabs(r[i]) < tol_prim)) return 0;
  return 1;
}

/* K, r, grad, energies at arg into res[0..3]: the split function (K without its per-node Hessian part),
   then that part added (dlo_add_node_part); nonzero if the function fails. */
static int dlo_kkt_eval(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, double *W,
                        dlo_gemm_t gemm, const dlo_node_map *map, int rows_e, int n, int N, double *buf) {
  res[4] = W;
  if (KKT(arg, res, iw, w, 0) != 0) return 1;
  dlo_add_node_part(gemm, map, W, rows_e, n, res[0], N, buf);
  return 0;
}

/* The regularised LU of K into A (dlo_regularised_lu); LAPACK's info. */
static int dlo_factor(dlo_getrf_t getrf, const double *K, double *A, int *ipiv, int n, int N, double reg) {
  memcpy(A, K, sizeof(double) * N * N);
  return dlo_regularised_lu(getrf, A, ipiv, n, N, reg);
}

/* Chord Newton on the contact-free KKT system; see dlo_ros/solver/native_newton.py.  u, K, r: in at the
   start, out at the last iterate; grad, energies: out there (the last call evaluates K at it). */
CASADI_SYMBOL_EXPORT int dlo_newton_run(dlo_getrf_t dgetrf, dlo_getrs_t dgetrs, dlo_gemm_t dgemm,
    const dlo_node_map *map, int rows_e, int buf_size, int n, int m, int max_evaluations,
    int max_steps, double max_step, double reg, double tol_dual, double tol_prim, double tol_step,
    double contraction, double chord_start, double *u, const double *p, double *K, double *r, double *grad,
    double *energies, int *steps, int *evaluations, double *largest, const dlo_eigen_lapack *eigen,
    double *eig_value, double *eig_direction, int *eig_code, dlo_after *after, int given) {
  int N = n + m, one = 1, info = 0, code = 1;
  char trans = 'N';
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  dlo_work(KKT_work, RESIDUAL_work, &sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 5 ? sz_res : 5));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  double *A = malloc(sizeof(double) * N * N), *step = malloc(sizeof(double) * N);
  double *W = malloc(sizeof(double) * rows_e * n), *buf = malloc(sizeof(double) * (buf_size > 1 ? buf_size : 1));
  int *ipiv = malloc(sizeof(int) * N);
  double previous = INFINITY;  /* the last step's max |dz| since K was factored */
  int fresh = 1;               /* K, grad and energies belong to u */
  int here = 1;                /* the factored K is u's */
  *steps = 0; *evaluations = 0; *largest = 0.0;
  if (!given) {  /* K and r at the start, not carried from an earlier answer: evaluated here (not counted) */
    arg[0] = u; arg[1] = p; arg[2] = u + n;
    res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
  }
  if (!given && dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) code = 4;
  else if (dlo_factor(dgetrf, K, A, ipiv, n, N, reg) != 0) code = 2;
  else for (;;) {
    if (*steps == max_steps) { code = 1; break; }
    memcpy(step, r, sizeof(double) * N);
    dgetrs(&trans, &N, &one, A, &N, ipiv, step, &N, &info);
    if (info != 0) { code = 2; break; }
    double big = 0.0;
    int finite = 1;
    for (int i = 0; i < N; ++i) {
      if (!isfinite(step[i])) finite = 0;
      if (i < n && fabs(step[i]) > big) big = fabs(step[i]);
    }
    arg[0] = u; arg[1] = p; arg[2] = u + n;
    res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
    if (!finite || big > max_step) {
      if (here || *evaluations >= max_evaluations) { code = 3; *largest = big; break; }
      /* a step of an earlier iterate's K: Newton's own step, from K evaluated here */
      if (dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) { code = 4; break; }
      ++*evaluations;
      if (dlo_factor(dgetrf, K, A, ipiv, n, N, reg) != 0) { code = 2; break; }
      here = fresh = 1;
      previous = INFINITY;
      continue;
    }
    if (big > *largest) *largest = big;
    for (int i = 0; i < N; ++i) u[i] -= step[i];
    ++*steps;
    here = 0;
    int shrinking = big <= contraction * previous;
    if ((big > chord_start || (!shrinking && !(big <= tol_step))) && *evaluations < max_evaluations) {
      /* Newton's own steps while they are above chord_start, then chord steps; or too slow for the
         factored K: evaluate and factor it here */
      if (dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) { code = 4; break; }
      ++*evaluations;
      if (dlo_factor(dgetrf, K, A, ipiv, n, N, reg) != 0) { code = 2; break; }
      previous = INFINITY;
      here = fresh = 1;
    } else {
      res[0] = r;
      if (RESIDUAL(arg, res, iw, w, 0) != 0) { code = 4; break; }
      previous = big;
      fresh = 0;
    }
    /* converged: r within tolerance, and the last step below tol_step (u then within about
       contraction * tol_step of the root) or no longer shrinking (round-off) */
    if (dlo_converged(r, n, m, tol_dual, tol_prim) && (big <= tol_step || !shrinking)) {
      if (!fresh) {  /* the derivatives at the answer */
        res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
        if (dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) { code = 4; break; }
        ++*evaluations;
      }
      code = dlo_converged(r, n, m, tol_dual, tol_prim) ? 0 : 1;
      break;
    }
  }
  *eig_code = -1;
  if (code == 0) {  /* the stability eigenvalue at the answer: H = K's top-left block, J its bottom-left */
    *eig_code = dlo_reduced_eigen(eigen, K, N, K + n, N, n, m, eig_value, eig_direction);
    if (after != NULL) dlo_after_run(after, u, p, u + n, 0, r + n);
  }
  free(arg); free(res); free(iw); free(w); free(A); free(step); free(ipiv); free(W); free(buf);
  return code;
}
"""


def _lapack_pointer(name: str) -> int:
    """The address of SciPy's LAPACK (or, for dgemm, BLAS) routine ``name`` (from the PyCapsules
    scipy.linalg.cython_lapack and cython_blas export)."""
    from scipy.linalg import cython_blas, cython_lapack

    capsule = (cython_blas if name == "dgemm" else cython_lapack).__pyx_capi__[name]
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype, get_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    return int(get_pointer(capsule, get_name(capsule)))


class _EigenLapackStruct(ctypes.Structure):
    """dlo_eigen_lapack in the driver's C."""

    _fields_ = [("geqp3", ctypes.c_void_p), ("orgqr", ctypes.c_void_p), ("syevr", ctypes.c_void_p),
                ("gemm", ctypes.c_void_p), ("chunk", ctypes.c_int)]


def _eigen_lapack() -> _EigenLapackStruct:
    return _EigenLapackStruct(*(_lapack_pointer(name) for name in ("dgeqp3", "dorgqr", "dsyevr", "dgemm")),
                              CHUNK_WORK)


class _NodeMapStruct(ctypes.Structure):
    """dlo_node_map in the drivers' C."""

    _fields_ = [("groups", ctypes.c_int), ("chunk", ctypes.c_int), ("count", ctypes.c_void_p),
                ("row", ctypes.c_void_p), ("col", ctypes.c_void_p), ("block", ctypes.c_void_p)]


class NodeBlocks:
    """The node map E (d·M × n, ``StringNLP.node_map``) as dense blocks for the drivers' ``dlo_add_node_part``
    (H += Eᵀ W): E's columns grouped by the per-node components (row mod d) they reach, each group with
    the rows any of its columns reaches.  For the default 3D model, four groups (one per quaternion
    component) of 16 columns and 48 rows: a quarter of the multiplications of Eᵀ W as one dense product.
    ``chunk``: the most rows one dgemm call takes, so that OpenBLAS runs it on the calling thread."""

    def __init__(self, node_map: np.ndarray, width: int):
        E = np.asarray(node_map, dtype=float)
        n = E.shape[1]
        groups: dict[tuple, list[int]] = {}
        for c in range(n):
            support = np.flatnonzero(E[:, c])
            if support.size:
                groups.setdefault(tuple(sorted(set((support % width).tolist()))), []).append(c)
        #: (rows, columns, E[rows, columns]) of each group
        self.groups = []
        for members in groups.values():
            reached = np.flatnonzero(np.any(E[:, members] != 0, axis=1))
            self.groups.append((reached, np.array(members), E[np.ix_(reached, members)]))
        rows, cols, blocks = ([group[i] for group in self.groups] for i in range(3))
        self.count = np.array([(r.size, c.size) for r, c, _ in self.groups], dtype=np.intc).ravel()
        self.row = np.ascontiguousarray(np.concatenate(rows), dtype=np.intc)
        self.col = np.ascontiguousarray(np.concatenate(cols), dtype=np.intc)
        self.block = np.concatenate([b.ravel(order="F") for b in blocks])
        widest, deepest = max(len(c) for c in cols), max(r.size for r in rows)
        self.rows_w = E.shape[0]
        self.chunk = max(1, min(deepest, CHUNK_WORK // (widest * n)))
        self.buf_size = (self.chunk + widest) * n
        self.struct = _NodeMapStruct(len(groups), self.chunk, self.count.ctypes.data, self.row.ctypes.data,
                                     self.col.ctypes.data, self.block.ctypes.data)


class WithNodePart:
    """A compiled split function (``StringNLP.kkt_free_split_fn``, ``kkt_split_fn``) called as the whole one:
    its last output W dropped and Eᵀ W added to the top-left n × n block of output ``target`` (K, ∇²L),
    one product per ``NodeBlocks`` group (numpy: each below OpenBLAS's threshold for threads), so that the
    evaluations Python makes (a saddle's escape, the derivatives at an adopted start, the stability check
    of a state without them) take the same shortcut as the compiled loops.  Not re-entrant (the split
    function's buffers): callers serialise calls, as for ``compiled.NativeFunction``."""

    def __init__(self, split, blocks: NodeBlocks, target: int):
        self._split, self._target = split, target
        self._groups = [(rows, cols, np.ascontiguousarray(block.T)) for rows, cols, block in blocks.groups]

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        *out, weighted = self._split(*args)
        h = out[self._target]
        n = weighted.shape[1]
        for rows, cols, block_t in self._groups:
            h[cols, :n] += block_t @ weighted[rows]
        return out


#: the most multiplications (m·n·k) of one dgemm in ``dlo_add_node_part``: below OpenBLAS's threshold for
#: threads (65536 · 4), whose workers would spin on the other core between calls
CHUNK_WORK = 150_000


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
    the steps taken and the largest |Δz|; once converged, ``eigen``: the stability eigenvalue there and
    its eigenvector in z (``stability.min_reduced_eigenvalue`` on K's blocks, ``SolverState.reduced_eigen``),
    None when the free rows leave no freedom or LAPACK failed (the numpy path then decides)."""

    code: int
    u: np.ndarray
    kkt: np.ndarray
    residual: np.ndarray
    gradient: np.ndarray
    energies: np.ndarray
    steps: int
    largest: float
    evaluations: int = 0
    eigen: tuple[float, np.ndarray] | None = None
    #: every row's value at the answer, when the call evaluated the obstacle rows (``UpdateOutputs``)
    g: np.ndarray | None = None
    #: the outputs at the answer, when the call evaluated them (``UpdateOutputs``)
    outputs: ComputedOutputs | None = None


@dataclass
class ComputedOutputs:
    """The outputs' function's values (``output_function.OutputFunction``: points, orientations, grip forces
    and torques, contact forces, residual, flip) as a converged loop evaluated them, with the inputs it
    evaluated them at: a result uses them only for the same (z, p, λ_SI, prof) (``matches``)."""

    z: np.ndarray
    p: np.ndarray
    lam_si: np.ndarray
    prof: np.ndarray
    values: list[np.ndarray]

    def matches(self, z: np.ndarray, p: np.ndarray, lam_si: np.ndarray, prof: np.ndarray) -> bool:
        return (np.array_equal(self.z, z) and np.array_equal(self.p, p) and np.array_equal(self.lam_si, lam_si)
                and (self.prof is prof or np.array_equal(self.prof, prof)))


class _AfterStruct(ctypes.Structure):
    """dlo_after in the drivers' C."""

    _fields_ = [("obstacle", ctypes.c_void_p), ("outputs", ctypes.c_void_p), ("obstacle_work", ctypes.c_void_p),
                ("outputs_work", ctypes.c_void_p), ("rows", ctypes.c_int), ("free_rows", ctypes.c_int),
                ("ub", ctypes.c_void_p), ("lam_div", ctypes.c_void_p),
                ("prof", ctypes.c_void_p), ("g", ctypes.c_void_p), ("lam_si", ctypes.c_void_p),
                ("out", ctypes.c_void_p * 8), ("done", ctypes.c_int)]


class UpdateOutputs:
    """What a converged loop evaluates in the same call, so that a warm update is one compiled call: the
    obstacle rows' values (``StringNLP.obstacle_g_fn``; the contact-free loop, whose system leaves them
    out) and, when none is violated, the outputs' function (``output_function.py``) at the answer, with
    λ_SI = λ / (row_scale · σ) and the string's profiles ``prof``.  Both are generated functions of their
    own libraries (``compiled.NativeFunction``), called by address: neither loop's library is rebuilt when
    they arrive.  Either may be None (not compiled yet): the caller then evaluates what is missing.  Not
    re-entrant: the loops' callers serialise calls."""

    def __init__(self, nlp, obstacle, outputs):
        rows = int(nlp.lbg.size)
        self.rows = rows
        self._ub = np.ascontiguousarray(nlp.ubg, dtype=float)
        # λ_SI = λ / (row_scale · σ), divided as ShapeOutputs divides (the same rounding: ComputedOutputs.matches)
        self._div = np.ascontiguousarray(nlp.row_scale * nlp.sigma, dtype=float) if rows else np.zeros(0)
        self._g, self._lam_si = np.zeros(max(rows, 1)), np.zeros(max(rows, 1))
        self._prof: np.ndarray | None = None
        self._shapes = outputs.out_shapes if outputs is not None else []
        self._out = [np.zeros(max(r * c, 1)) for r, c in self._shapes]
        self._struct = _AfterStruct()
        st = self._struct
        st.rows, st.free_rows = rows, nlp.n_free_rows
        st.ub, st.lam_div, st.g, st.lam_si = (a.ctypes.data for a in (self._ub, self._div, self._g, self._lam_si))
        for i, a in enumerate(self._out):
            st.out[i] = a.ctypes.data
        self._functions = (obstacle, outputs)  # kept alive for the addresses
        self.obstacle = obstacle.address() if obstacle is not None else None
        self.outputs = outputs.address() if outputs is not None else None
        if self.obstacle is not None:
            st.obstacle, st.obstacle_work = self.obstacle
        self.address = ctypes.addressof(st)

    def prepare(self, prof: np.ndarray | None) -> int:
        """Before a call: the outputs are evaluated when ``prof`` is given (the profiles of the string being
        solved for); the struct's address."""
        st = self._struct
        st.done = 0
        if prof is None or self.outputs is None:
            st.outputs = st.outputs_work = None
            self._prof = None
        else:
            st.outputs, st.outputs_work = self.outputs
            self._prof = prof = np.ascontiguousarray(prof, dtype=float)
            st.prof = prof.ctypes.data
        return self.address

    def collect(self, z: np.ndarray, p: np.ndarray) -> tuple[np.ndarray | None, ComputedOutputs | None]:
        """After a converged call at (z, p): (every row's value, the outputs), each None if not evaluated (the
        values only from the contact-free loop, which evaluates its obstacle rows)."""
        done = self._struct.done
        g = self._g[:self.rows].copy() if done & 1 else None
        if not done & 2:
            return g, None
        values = [out[:r * c].reshape((r, c), order="F").copy() for out, (r, c) in zip(self._out, self._shapes)]
        return g, ComputedOutputs(z.copy(), np.array(p, dtype=float), self._lam_si[:self.rows].copy(), self._prof,
                                  values)


class NativeNewton:
    """The compiled Newton loop of one NLP's contact-free system (see the module docstring).  Not
    re-entrant per instance: callers serialise calls (ShapeSolver holds a lock)."""

    def __init__(self, lib_path: Path, n: int, nf: int, n_p: int, node_map: NodeBlocks):
        # checked by cache_store (UnusableLibrary if refused)
        self._lib = load_library(lib_path, ("dlo_newton_run",))
        self._run = self._lib.dlo_newton_run
        vp, ip = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)
        self._run.restype = ctypes.c_int
        self._run.argtypes = [vp, vp, vp, vp, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                              ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                              ctypes.c_double, ctypes.c_double, ctypes.c_double, vp, vp, vp, vp, vp, vp, ip, ip,
                              ctypes.POINTER(ctypes.c_double), vp, ctypes.POINTER(ctypes.c_double), vp, ip, vp,
                              ctypes.c_int]
        self.n, self.nf, self.n_p = n, nf, n_p
        #: what a converged call also evaluates (``UpdateOutputs``), None: nothing
        self.after: UpdateOutputs | None = None
        N = n + nf
        # the call's arrays, allocated once and passed by their addresses (an ndarray's ctypes pointer costs
        # microseconds per argument and call)
        self._u, self._p, self._K, self._r = np.zeros(N), np.zeros(n_p), np.zeros((N, N), order="F"), np.zeros(N)
        self._grad, self._energies, self._direction = np.zeros(n), np.zeros(5), np.zeros(n)
        self._steps, self._evaluations, self._largest = ctypes.c_int(0), ctypes.c_int(0), ctypes.c_double(0.0)
        self._eig_value, self._eig_code = ctypes.c_double(0.0), ctypes.c_int(-1)
        self._map, self._lapack = node_map, _eigen_lapack()  # kept alive for the calls
        self._head = (_lapack_pointer("dgetrf"), _lapack_pointer("dgetrs"), _lapack_pointer("dgemm"),
                      ctypes.addressof(node_map.struct), node_map.rows_w, node_map.buf_size, n, nf)
        self._tail = (NEWTON_CHORD_STEPS, NEWTON_MAX_STEP, NEWTON_REGULARISATION, NEWTON_DUAL_TOLERANCE,
                      NEWTON_PRIMAL_TOLERANCE, NEWTON_CHORD_TOLERANCE, NEWTON_CHORD_CONTRACTION, NEWTON_CHORD_START,
                      *(a.ctypes.data for a in (self._u, self._p, self._K, self._r, self._grad, self._energies)),
                      ctypes.byref(self._steps), ctypes.byref(self._evaluations), ctypes.byref(self._largest),
                      ctypes.addressof(self._lapack), ctypes.byref(self._eig_value), self._direction.ctypes.data,
                      ctypes.byref(self._eig_code))

    def __call__(self, u: np.ndarray, p: np.ndarray, kkt: np.ndarray | None, residual: np.ndarray | None,
                 max_steps: int, prof: np.ndarray | None = None) -> NewtonOutcome:
        """From u = [z; λ_free] with K, r at u (None: evaluated at u in the call, not counted);
        ``max_steps``: the most evaluations of K on the way (the one at the answer is not counted);
        ``prof``: the string's profiles, for the outputs (``after``)."""
        self._u[:] = u
        self._p[:] = p
        given = kkt is not None
        if given:
            self._K[:] = kkt
            self._r[:] = np.ravel(residual)
        self._energies[:] = np.nan
        after = self.after
        code = self._run(*self._head, int(max_steps), *self._tail, after.prepare(prof) if after is not None else None,
                         int(given))
        out = NewtonOutcome(int(code), self._u.copy(), self._K.copy(order="F"), self._r.copy(), self._grad.copy(),
                            self._energies.copy(), self._steps.value, self._largest.value, self._evaluations.value)
        if code == CONVERGED:
            if self._eig_code.value == 0:
                out.eigen = (self._eig_value.value, self._direction.copy())
            if after is not None:
                out.g, out.outputs = after.collect(out.u[:self.n], self._p)
        return out


def build(nlp, nice: int = 0, kkt_lib: Path | None = None) -> NativeNewton | None:
    """The driver of ``nlp``'s contact-free system (``StringNLP.kkt_free_split_fn`` and ``residual_free_fn``
    compiled with it), from the cache or built now (one compiler at a time per process); None without a C
    compiler or if compiling fails.  ``kkt_lib``: the split function's own library path, which keys this one."""
    cc = compiler()
    if cc is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    lib = library_path(nlp.kkt_free_split_fn, kkt_lib)
    loop = _instance(nlp, lib)
    if loop is None:  # missing, damaged or refused: (re)build it
        with COMPILER_LOCK:
            loop = _instance(nlp, lib)
            fn, residual = nlp.kkt_free_split_fn, nlp.residual_free_fn
            if loop is None and _compile(fn, residual, cc, lib, nice):
                loop = _instance(nlp, lib)
    return loop


def cached(nlp, kkt_lib: Path | None = None) -> NativeNewton | None:
    """The driver if the cache holds it (no compiling), else None."""
    if compiler() is None or os.environ.get("DLO_NO_COMPILE"):
        return None
    return _instance(nlp, library_path(nlp.kkt_free_split_fn, kkt_lib))


def _instance(nlp, lib: Path) -> NativeNewton | None:
    """The loop in ``lib`` if the cache holds it and it passes ``cache_store.load``'s checks."""
    try:
        return NativeNewton(lib, nlp.z_sym.shape[0], nlp.n_free_rows, nlp.p_sym.shape[0],
                            nlp.node_blocks)
    except UnusableLibrary:
        return None


def _compile(fn: ca.Function, residual: ca.Function, cc: str, lib: Path, nice: int) -> bool:
    driver = DRIVER
    for token, name in (("KKT", fn.name()), ("RESIDUAL", residual.name())):
        driver = driver.replace(f"{token}_work", f"{name}_work").replace(f"{token}(", f"{name}(")
    return build_library(fn, lib, cc, nice=nice, extra_source=driver, also=(residual,))


#: Newton with an active set on the full KKT function (``StringNLP.kkt_fn``), appended to its generated
#: code.  See ``ActiveNewton``.
ACTIVE_DRIVER = _C_COMMON + _C_EIGEN + r"""

/* grad f, g, dg/dz, hess L, energies at arg into res[0..4]: the split function (hess L without its per-node
   part), then that part added (dlo_add_node_part); nonzero if the function fails. */
static int dlo_full_eval(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, double *W,
                         dlo_gemm_t gemm, const dlo_node_map *map, int rows_e, int n, double *buf) {
  res[5] = W;
  if (FUNCTION(arg, res, iw, w, 0) != 0) return 1;
  dlo_add_node_part(gemm, map, W, rows_e, n, res[3], n, buf);
  return 0;
}

/* The regularised LU (dlo_regularised_lu) of [H J_A^T; J_A 0] of the m rows idx, into A (N = n + m). */
static int dlo_active_factor(dlo_getrf_t getrf, const double *hess, const double *jac, const int *idx, int n,
                             int m, int rows, double reg, double *A, int *ipiv) {
  int N = n + m;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) A[i + (size_t)j * N] = hess[i + (size_t)j * n];
  for (int k = 0; k < m; ++k) {
    for (int j = 0; j < n; ++j) {
      double a = jac[idx[k] + (size_t)j * rows];
      A[(n + k) + (size_t)j * N] = a;
      A[j + (size_t)(n + k) * N] = a;
    }
    for (int l = 0; l < m; ++l) A[(n + k) + (size_t)(n + l) * N] = 0.0;
  }
  return dlo_regularised_lu(getrf, A, ipiv, n, N, reg);
}

/* Newton, then chord, steps on [H J_A^T; J_A 0] for the rows with active[i] (held at ub[i]); see
   dlo_ros/solver/native_newton.py (ActiveNewton) and newton.py (_active_steps, the same row switches).
   Each step's matrix is evaluated (Newton's own steps) until an iterate where the rows are checked
   changes no row and the steps are below chord_start; after that the factored matrix is kept while the
   steps shrink by the contraction factor, the residual function giving grad L and g in between.  The
   rows are checked at the first iterate (a Newton step reached it: its g and multipliers are Newton's
   own) and at each evaluated iterate after it: while switches remain, one row of those with
   switchable[i] changes, the most violated inactive one joining, else the active one with the most
   negative multiplier leaving (its multiplier set to 0), and the matrix is evaluated there; an iterate
   where a row changed is not converged.  z (n), lam (rows), active
   (rows): in at the start, out at the answer.  grad, g, jac (rows x n, column-major), hess (n x n),
   energies: out at the answer (evaluated there); with given = 1 they are in as well, the first step's
   derivatives. */
CASADI_SYMBOL_EXPORT int dlo_newton_active_run(dlo_getrf_t getrf, dlo_getrs_t getrs, dlo_gemm_t gemm,
    const dlo_node_map *map, int rows_e, int buf_size, int n, int rows, int *active,
    const int *switchable, int switches, int max_evaluations, int max_steps, int given, double max_step,
    double reg, double tol_dual, double tol_prim, double tol_step, double contraction, double chord_start,
    double join_tol, double leave_tol, double *z, const double *p, double *lam, const double *ub, double *grad, double *g,
    double *jac, double *hess, double *energies, int *steps, int *evaluations, const int *equality,
    const dlo_eigen_lapack *eigen, double *eig_value, double *eig_direction, int *eig_code, dlo_after *after) {
  int one = 1, info = 0, code = 1;
  char trans = 'N';
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  dlo_work(FUNCTION_work, RESIDUAL_work, &sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 6 ? sz_res : 6));
  double *W = malloc(sizeof(double) * rows_e * n), *buf = malloc(sizeof(double) * (buf_size > 1 ? buf_size : 1));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  int most = 0;  /* rows that can be active: the matrix is sized for them, not for every row */
  for (int i = 0; i < rows; ++i) most += active[i] || switchable[i];
  int *idx = malloc(sizeof(int) * (most > 1 ? most : 1));
  double *A = malloc(sizeof(double) * (n + most) * (n + most)), *rhs = malloc(sizeof(double) * (n + most));
  double *lgrad = malloc(sizeof(double) * (n + rows));  /* the residual function's [grad L; g] */
  int *ipiv = malloc(sizeof(int) * (n + most));
  int fresh = 0, m = 0, factored = 0, here = 0;  /* here: the factored matrix is this iterate's */
  int settled = switches == 0;  /* a check of the rows changed none (or none may change) */
  double previous = INFINITY, big = 0.0;
  int shrinking = 1;
  *steps = 0; *evaluations = 0;
  arg[0] = z; arg[1] = p; arg[2] = lam;
  if (!given) {
    res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
    if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) { code = 4; goto done; }
    ++*evaluations;
    fresh = 1;
  }
  for (;;) {
    int switched = 0;
    /* rows switch where the derivatives are evaluated, and at the first iterate, which a Newton step
       reached whatever the start (there the residual function's g and the multipliers are Newton's own) */
    if (*steps > 0 && switches > 0 && (fresh || *steps == 1)) {
      int join = -1, leave = -1;
      double excess = join_tol, negative = -leave_tol;
      for (int i = 0; i < rows; ++i) {
        if (!switchable[i]) continue;
        if (!active[i] && g[i] - ub[i] > excess) { excess = g[i] - ub[i]; join = i; }
        if (active[i] && lam[i] < negative) { negative = lam[i]; leave = i; }
      }
      if (join >= 0) { active[join] = 1; switched = 1; }
      else if (leave >= 0) { active[leave] = 0; lam[leave] = 0.0; switched = 1; }
      switches -= switched;
      settled = !switched;
      if (switched && !fresh) {
        /* the changed set's matrix from derivatives evaluated here: with the start's, a row joining
           beside an active sample (their Jacobians nearly equal) sent steps over max_step */
        res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
        if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) { code = 4; break; }
        ++*evaluations;
        fresh = 1;
      }
    }
    m = 0;
    for (int i = 0; i < rows; ++i) if (active[i]) idx[m++] = i;
    int N = n + m, converged = !switched;
    /* the residual: from the last evaluation (grad f + J_A^T lam_A) where it is fresh, else the
       residual function's grad L (lam is 0 on every inactive row) */
    for (int j = 0; j < n; ++j) {
      double v;
      if (fresh || *steps == 0) {  /* the start's derivatives, given or evaluated */
        v = grad[j];
        for (int k = 0; k < m; ++k) v += lam[idx[k]] * jac[idx[k] + (size_t)j * rows];
      } else {
        v = lgrad[j];
      }
      rhs[j] = -v;
      if (!(fabs(v) < tol_dual)) converged = 0;
    }
    for (int k = 0; k < m; ++k) {
      double v = g[idx[k]] - ub[idx[k]];
      rhs[n + k] = -v;
      if (!(fabs(v) < tol_prim)) converged = 0;
    }
    if (converged && (fresh || (*steps > 0 && (big <= tol_step || !shrinking)))) {
      if (fresh) { code = 0; break; }
      /* the derivatives at the answer, and the test once more on them */
      res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
      if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) { code = 4; break; }
      ++*evaluations;
      fresh = 1;
      continue;
    }
    if (*steps == max_steps) { code = 1; break; }
    if (!factored || switched) {
      if (dlo_active_factor(getrf, hess, jac, idx, n, m, rows, reg, A, ipiv) != 0) { code = 2; break; }
      factored = 1;
      here = fresh || *steps == 0;
      previous = INFINITY;
    }
    getrs(&trans, &N, &one, A, &N, ipiv, rhs, &N, &info);
    if (info != 0) { code = 2; break; }
    big = 0.0;
    int finite = 1;
    for (int i = 0; i < N; ++i) {
      if (!isfinite(rhs[i])) finite = 0;
      if (i < n && fabs(rhs[i]) > big) big = fabs(rhs[i]);
    }
    if (!finite || big > max_step) {
      if (here || *evaluations >= max_evaluations) { code = 3; break; }
      /* a step of the matrix of an earlier iterate: Newton's own step, from derivatives evaluated here */
      res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
      if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) { code = 4; break; }
      ++*evaluations;
      if (dlo_active_factor(getrf, hess, jac, idx, n, m, rows, reg, A, ipiv) != 0) { code = 2; break; }
      here = fresh = 1;
      previous = INFINITY;
      continue;
    }
    for (int j = 0; j < n; ++j) z[j] += rhs[j];
    for (int k = 0; k < m; ++k) lam[idx[k]] += rhs[n + k];
    ++*steps;
    here = 0;
    shrinking = big <= contraction * previous;
    if (((!settled && *steps > 1) || big > chord_start || (!shrinking && !(big <= tol_step))) &&
        *evaluations < max_evaluations) {
      /* Newton's own steps (the same iterates and row decisions as _active_steps) until a check of the
         rows changes none and the steps are below chord_start, then chord steps; or too slow for the
         factored matrix: evaluate and factor it here */
      res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
      if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) { code = 4; break; }
      ++*evaluations;
      if (dlo_active_factor(getrf, hess, jac, idx, n, m, rows, reg, A, ipiv) != 0) { code = 2; break; }
      previous = INFINITY;
      here = fresh = 1;
    } else {
      res[0] = lgrad;
      if (RESIDUAL(arg, res, iw, w, 0) != 0) { code = 4; break; }
      memcpy(g, lgrad + n, sizeof(double) * rows);
      previous = big;
      fresh = 0;
    }
  }
  *eig_code = -1;
  if (code == 0) {
    /* the stability eigenvalue at the answer, on the rows stability.min_reduced_eigenvalue holds: the
       equalities, and the rows with |lambda| > 1e-9 or within 1e-9 of their bound */
    int held = 0, *rows_held = malloc(sizeof(int) * (rows > 0 ? rows : 1));
    for (int i = 0; i < rows; ++i)
      if (equality[i] || fabs(lam[i]) > 1e-9 || g[i] > ub[i] - 1e-9) rows_held[held++] = i;
    double *J = malloc(sizeof(double) * ((size_t)held * n + 1));
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < held; ++k) J[k + (size_t)held * j] = jac[rows_held[k] + (size_t)rows * j];
    *eig_code = dlo_reduced_eigen(eigen, hess, n, J, held > 0 ? held : 1, n, held, eig_value, eig_direction);
    free(J); free(rows_held);
    if (after != NULL) dlo_after_run(after, z, p, lam, 1, NULL);
  }
done:
  free(arg); free(res); free(iw); free(w); free(idx); free(A); free(rhs); free(lgrad); free(ipiv); free(W);
  free(buf);
  return code;
}
"""


def active_source(fn: ca.Function, residual: ca.Function) -> str:
    """The active-set driver's C, bound to the generated functions ``fn`` (``StringNLP.kkt_split_fn``) and
    ``residual`` (``StringNLP.residual_fn``)."""
    source = ACTIVE_DRIVER
    for token, name in (("FUNCTION", fn.name()), ("RESIDUAL", residual.name())):
        source = source.replace(f"{token}_work", f"{name}_work").replace(f"{token}(", f"{name}(")
    return source


def active_library_path(fn: ca.Function) -> Path:
    """Where ``fn``'s library with the active-set driver appended is (or will be) cached."""
    digest = hashlib.sha256(ACTIVE_DRIVER.encode()).hexdigest()[:8]
    return cache_dir() / f"{fn.name()}_{fingerprint(fn)}_active_{digest}.so"


@dataclass
class ActiveOutcome:
    """What one ``ActiveNewton`` call returns: ``code`` (CONVERGED, …), the last iterate (z, λ over every
    row), the derivatives [∇f, g, ∂g/∂z, ∇²L, energies] evaluated there, the steps taken and the active
    set there."""

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
    #: once converged, the stability eigenvalue there and its eigenvector in z (``SolverState.reduced_eigen``,
    #: on the rows ``stability.min_reduced_eigenvalue`` holds), None if LAPACK failed
    eigen: tuple[float, np.ndarray] | None = None
    #: the outputs at the answer, when the call evaluated them (``UpdateOutputs``)
    outputs: ComputedOutputs | None = None


class ActiveNewton:
    """Newton with an active set in one compiled call: the inner loop of ``newton._active_steps`` (its
    regularised steps, row switches, convergence test and step limit), whose tail is chord steps.  Each
    step evaluates the full KKT function (Newton's own steps, the same iterates and row decisions) until
    a check of the rows changes none and the steps are below ``NEWTON_CHORD_START``.  The rows are
    checked at the first iterate, which a Newton step reached (the residual function's g and the
    multipliers there are Newton's own: no evaluation needed unless a row changes), and at every
    evaluated iterate.  After that [∇²L J_Aᵀ; J_A 0] stays factored and only the residual [∇L; g] is
    evaluated per step, as in the contact-free loop (``NativeNewton``: the same contraction, tolerance and
    retry rules, the derivatives evaluated at the answer, and there the stability eigenpair, on the rows
    ``stability.min_reduced_eigenvalue`` holds, and the outputs, ``after``).  In C around the compiled split full KKT
    function (``StringNLP.kkt_split_fn``: ∇²L's per-node part added by BLAS, as in ``NativeNewton``) and
    its residual, compiled into the full KKT function's library.  Not re-entrant per instance: callers serialise calls
    (ShapeSolver holds a lock)."""

    def __init__(self, lib_path: Path, n: int, rows: int, node_map: NodeBlocks, equality: np.ndarray):
        self._lib = load_library(lib_path, ("dlo_newton_active_run",))  # checked, as above
        self._run = self._lib.dlo_newton_active_run
        dp, ip, c_int, c_double = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int), ctypes.c_int, \
            ctypes.c_double
        vp = ctypes.c_void_p
        self._run.restype = ctypes.c_int
        self._run.argtypes = [vp, vp, vp, vp, c_int, c_int, c_int, c_int, ip, ip, c_int, c_int, c_int, c_int,
                              c_double, c_double, c_double, c_double, c_double, c_double, c_double, c_double,
                              c_double, dp, dp, dp, dp, dp, dp, dp, dp, dp, ip, ip, vp, vp, vp, vp, vp, vp]
        self._map, self._lapack = node_map, _eigen_lapack()  # kept alive for the calls
        self._equality = np.ascontiguousarray(equality, dtype=np.intc)
        self._eig_value, self._eig_code, self._direction = ctypes.c_double(0.0), ctypes.c_int(-1), np.zeros(n)
        self._eigen_args = (self._equality.ctypes.data, ctypes.addressof(self._lapack),
                            ctypes.addressof(self._eig_value), self._direction.ctypes.data,
                            ctypes.addressof(self._eig_code))
        #: what a converged call also evaluates (``UpdateOutputs``), None: nothing
        self.after: UpdateOutputs | None = None
        self._head = (_lapack_pointer("dgetrf"), _lapack_pointer("dgetrs"), _lapack_pointer("dgemm"),
                      ctypes.addressof(node_map.struct), node_map.rows_w, node_map.buf_size)
        self.n, self.rows = n, rows

    def __call__(self, z: np.ndarray, lam: np.ndarray, p: np.ndarray, active: np.ndarray, ub: np.ndarray,
                 switchable: np.ndarray, switches: int, max_steps: int,
                 first: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
                 prof: np.ndarray | None = None) -> ActiveOutcome:
        """From (z, λ) with the rows ``active`` held at ``ub`` (both over every row); up to ``switches``
        changes among the rows ``switchable``; ``max_steps``: the most evaluations of the full KKT function
        on the way (the one at the answer not counted); ``first``: (∇f, g, ∂g/∂z, ∇²L) for the first step
        instead of an evaluation; ``prof``: the string's profiles, for the outputs (``after``)."""
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
        dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
        code = self._run(*self._head, n, rows, act.ctypes.data_as(ip), switch.ctypes.data_as(ip),
                         int(switches), int(max_steps), NEWTON_CHORD_STEPS, int(first is not None), NEWTON_MAX_STEP,
                         NEWTON_REGULARISATION, NEWTON_DUAL_TOLERANCE, NEWTON_PRIMAL_TOLERANCE, NEWTON_CHORD_TOLERANCE,
                         NEWTON_CHORD_CONTRACTION, NEWTON_CHORD_START, JOIN_TOLERANCE, LEAVE_TOLERANCE,
                         z.ctypes.data_as(dp),
                         p.ctypes.data_as(dp), lam.ctypes.data_as(dp), ub.ctypes.data_as(dp),
                         grad.ctypes.data_as(dp), g.ctypes.data_as(dp), jac.ctypes.data_as(dp),
                         hess.ctypes.data_as(dp), energies.ctypes.data_as(dp), ctypes.byref(steps),
                         ctypes.byref(evaluations), *self._eigen_args,
                         self.after.prepare(prof) if self.after is not None else None)
        out = ActiveOutcome(int(code), z, lam, grad, g, jac.reshape(rows, n, order="F"),
                            hess.reshape(n, n, order="F"), energies, steps.value, act.astype(bool), evaluations.value)
        if code == CONVERGED:
            if self._eig_code.value == 0:
                out.eigen = (self._eig_value.value, self._direction.copy())
            if self.after is not None:
                out.outputs = self.after.collect(z, p)[1]
        return out
