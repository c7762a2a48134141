/* Chord Newton on the contact-free KKT system in one call (dlo_ros/solver/native/newton.py,
   NativeNewton), around the generated split function DLO_SYSTEM (StringNLP.kkt_free_split_fn) and
   its residual DLO_RESIDUAL (StringNLP.residual_free_fn), both given as -D names by
   native/build.py. */
#include "dlo_native.h"
#include "dlo_common.h"
#include "dlo_fpmode.h"
#include "dlo_eigen.h"
static int dlo_converged(const double *r, int n, int m, double tol_dual, double tol_prim) {
  for (int i = 0; i < n; ++i) if (!(fabs(r[i]) < tol_dual)) return 0;
  for (int i = n; i < n + m; ++i) if (!(fabs(r[i]) < tol_prim)) return 0;
  return 1;
}

/* K, r, grad, energies at arg into res[0..3]: the split function (K without its per-node Hessian
   part), then that part added (dlo_add_node_part); nonzero if the function fails. */
static int dlo_kkt_eval(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w,
                        double *W, dlo_gemm_t gemm, const dlo_node_map *map, int rows_e, int n,
                        int N, double *buf) {
  res[4] = W;
  if (DLO_SYSTEM(arg, res, iw, w, 0) != 0) return 1;
  dlo_add_node_part(gemm, map, W, rows_e, n, res[0], N, buf);
  return 0;
}

/* The regularised LU of K into A (dlo_regularised_lu); LAPACK's info. */
static int dlo_factor(dlo_getrf_t getrf, const double *K, double *A, int *ipiv, int n, int N,
                      double reg) {
  memcpy(A, K, sizeof(double) * N * N);
  return dlo_regularised_lu(getrf, A, ipiv, n, N, reg);
}

/* Chord Newton on the contact-free KKT system; see dlo_ros/solver/native/newton.py.  u, K, r: in
   at the start, out at the last iterate; grad, energies: out there (the last call evaluates K at
   it). */
CASADI_SYMBOL_EXPORT int dlo_newton_run(dlo_getrf_t dgetrf, dlo_getrs_t dgetrs, dlo_gemm_t dgemm,
                                        const dlo_node_map *map, int rows_e, int buf_size, int n,
                                        int m, int max_evaluations, int max_steps, double max_step,
                                        double reg, double tol_dual, double tol_prim,
                                        double tol_step, double contraction, double chord_start,
                                        double *u, const double *p, double *K, double *r,
                                        double *grad, double *energies, int *steps,
                                        int *evaluations, double *largest,
                                        const dlo_eigen_lapack *eigen, double *eig_value,
                                        double *eig_direction, int *eig_code, dlo_after *after,
                                        int given) {
  dlo_fpmode fp = dlo_fpmode_enter();  /* subnormals as zeros (dlo_fpmode.h) */
  int N = n + m, one = 1, info = 0, code = DLO_NOT_CONVERGED;
  char trans = 'N';
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  dlo_work(DLO_SYSTEM_WORK, DLO_RESIDUAL_WORK, &sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 5 ? sz_res : 5));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  double *A = malloc(sizeof(double) * N * N), *step = malloc(sizeof(double) * N);
  double *W = malloc(sizeof(double) * rows_e * n);
  double *buf = malloc(sizeof(double) * (buf_size > 1 ? buf_size : 1));
  int *ipiv = malloc(sizeof(int) * N);
  double previous = INFINITY;  /* the last step's max |dz| since K was factored */
  int fresh = 1;               /* K, grad and energies belong to u */
  int here = 1;                /* the factored K is u's */
  *steps = 0; *evaluations = 0; *largest = 0.0;
  /* K and r at the start, not carried from an earlier answer: evaluated here (not counted) */
  if (!given) {
    arg[0] = u; arg[1] = p; arg[2] = u + n;
    res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
  }
  if (!given && dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0)
    code = DLO_EVALUATION_FAILED;
  else if (dlo_factor(dgetrf, K, A, ipiv, n, N, reg) != 0) code = DLO_SINGULAR;
  else for (;;) {
    if (*steps == max_steps) { code = DLO_NOT_CONVERGED; break; }
    memcpy(step, r, sizeof(double) * N);
    dgetrs(&trans, &N, &one, A, &N, ipiv, step, &N, &info);
    if (info != 0) { code = DLO_SINGULAR; break; }
    double big = 0.0;
    int finite = 1;
    for (int i = 0; i < N; ++i) {
      if (!isfinite(step[i])) finite = 0;
      if (i < n && fabs(step[i]) > big) big = fabs(step[i]);
    }
    arg[0] = u; arg[1] = p; arg[2] = u + n;
    res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
    if (!finite || big > max_step) {
      if (here || *evaluations >= max_evaluations) {
        code = DLO_STEP_TOO_LARGE;
        *largest = big;
        break;
      }
      /* a step of an earlier iterate's K: Newton's own step, from K evaluated here */
      if (dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) {
        code = DLO_EVALUATION_FAILED;
        break;
      }
      ++*evaluations;
      if (dlo_factor(dgetrf, K, A, ipiv, n, N, reg) != 0) { code = DLO_SINGULAR; break; }
      here = fresh = 1;
      previous = INFINITY;
      continue;
    }
    if (big > *largest) *largest = big;
    for (int i = 0; i < N; ++i) u[i] -= step[i];
    ++*steps;
    here = 0;
    int shrinking = big <= contraction * previous;
    if ((big > chord_start || (!shrinking && !(big <= tol_step))) &&
        *evaluations < max_evaluations) {
      /* Newton's own steps while they are above chord_start, then chord steps; or too slow for the
         factored K: evaluate and factor it here */
      if (dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) {
        code = DLO_EVALUATION_FAILED;
        break;
      }
      ++*evaluations;
      if (dlo_factor(dgetrf, K, A, ipiv, n, N, reg) != 0) { code = DLO_SINGULAR; break; }
      previous = INFINITY;
      here = fresh = 1;
    } else {
      res[0] = r;
      if (DLO_RESIDUAL(arg, res, iw, w, 0) != 0) { code = DLO_EVALUATION_FAILED; break; }
      previous = big;
      fresh = 0;
    }
    /* converged: r within tolerance, and the last step below tol_step (u then within about
       contraction * tol_step of the root) or no longer shrinking (round-off) */
    if (dlo_converged(r, n, m, tol_dual, tol_prim) && (big <= tol_step || !shrinking)) {
      if (!fresh) {  /* the derivatives at the answer */
        res[0] = K; res[1] = r; res[2] = grad; res[3] = energies;
        if (dlo_kkt_eval(arg, res, iw, w, W, dgemm, map, rows_e, n, N, buf) != 0) {
          code = DLO_EVALUATION_FAILED;
          break;
        }
        ++*evaluations;
      }
      code = dlo_converged(r, n, m, tol_dual, tol_prim) ? DLO_CONVERGED : DLO_NOT_CONVERGED;
      break;
    }
  }
  *eig_code = DLO_EIGEN_FAILED;
  if (code == DLO_CONVERGED) {
    /* the stability verdict at the answer (dlo_stability): H = K's top-left block, J its
       bottom-left */
    *eig_code = dlo_stability(eigen, K, N, K + n, N, n, m, eig_value, eig_direction);
    if (after != NULL) dlo_after_run(after, u, p, u + n, 0, r + n);
  }
  free(arg); free(res); free(iw); free(w); free(A); free(step); free(ipiv); free(W); free(buf);
  dlo_fpmode_leave(fp);
  return code;
}
