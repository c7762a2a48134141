/* Leaving a saddle by shifted Newton steps in one call (dlo_ros/solver/native/saddle.py,
   NativeSaddle): the loop of update/saddle.py's leave_saddle, around the generated split full KKT
   function DLO_SYSTEM (StringNLP.kkt_split_fn, the one newton_active.c runs), compiled into the
   same library.  DLO_RESIDUAL is named by the build but not called here. */
#include "dlo_native.h"
#include "dlo_common.h"
#include "dlo_fpmode.h"
#include "dlo_full.h"

/* numpy's sum of a[0..n) (pairwise_sum in numpy's loops_utils.h): sequential below 8 terms, eight
   accumulators up to 128, halves above.  The merit compares sums of the Python path's values, so
   the same order keeps a near tie decided the same way. */
static double dlo_numpy_sum(const double *a, int n) {
  if (n < 8) {
    double res = -0.0;
    for (int i = 0; i < n; ++i) res += a[i];
    return res;
  }
  if (n <= 128) {
    double r[8], res;
    int i;
    for (int j = 0; j < 8; ++j) r[j] = a[j];
    for (i = 8; i < n - (n % 8); i += 8)
      for (int j = 0; j < 8; ++j) r[j] += a[i + j];
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for (; i < n; ++i) res += a[i];
    return res;
  }
  int n2 = n / 2;
  n2 -= n2 % 8;
  return dlo_numpy_sum(a, n2) + dlo_numpy_sum(a + n2, n - n2);
}

/* max |a[i]| (0 for n = 0), NaN if any a[i] is: as numpy's max, so that a NaN fails the tests it
   fails there. */
static double dlo_max_abs(const double *a, size_t n) {
  double big = 0.0;
  for (size_t i = 0; i < n; ++i) {
    if (isnan(a[i])) return NAN;
    if (fabs(a[i]) > big) big = fabs(a[i]);
  }
  return big;
}

/* From z (n) and lam (rows, zero off the m rows idx, which are held at bound[k]), at most
   max_steps iterations of update/saddle.py's leave_saddle loop, each one evaluation of the full
   KKT function at (z, p, lam):

     merit = sigma (sum(E[0..3]) - E[4]) + rho sum_k |g[idx_k] - bound_k|;
     uphill from the last accepted point (merit not lower): back to it, mu = growth max(mu, floor
       max|hess L|), and the next iteration evaluates there again;
     else, after an accepted point, mu = mu / decay, or 0 once below floor max|hess L|;
     stop (DLO_CONVERGED) once max|grad f + J_A^T lam_A| < tol_dual and max|g_A - bound| <
       tol_prim;
     else [hess L + mu I, J_A^T; J_A, 0] [dz; dlam] = -[r_dual; r_prim] (regularised as every
       warm update's, update/kkt.py), the step scaled to at most max_step in every z, taken.

   The last iterate is left in z, lam; *steps: the iterations made.  Returns DLO_CONVERGED,
   DLO_NOT_CONVERGED (max_steps made: the caller polishes the point reached all the same),
   DLO_SINGULAR (a singular matrix or a step that is not finite: the caller gives up) or
   DLO_EVALUATION_FAILED. */
CASADI_SYMBOL_EXPORT int dlo_saddle_run(
    dlo_getrf_t getrf, dlo_getrs_t getrs, dlo_gemm_t gemm, const dlo_node_map *map, int rows_e,
    int buf_size, int n, int rows, const int *idx, int m, int max_steps, double max_step,
    double reg, double tol_dual, double tol_prim, double floor, double growth, double decay,
    double sigma, double rho, double mu, double *z, const double *p, double *lam,
    const double *bound, int *steps) {
  dlo_fpmode fp = dlo_fpmode_enter();  /* subnormals as zeros (dlo_fpmode.h) */
  int N = n + m, one = 1, info = 0, code = DLO_NOT_CONVERGED;
  char trans = 'N';
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  dlo_work(DLO_SYSTEM_WORK, DLO_RESIDUAL_WORK, &sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 8 ? sz_res : 8));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  double *W = malloc(sizeof(double) * dlo_full_w_size(map, rows_e, n));
  double *buf = malloc(sizeof(double) * (buf_size > 1 ? buf_size : 1));
  double *grad = malloc(sizeof(double) * n), *g = malloc(sizeof(double) * (rows > 0 ? rows : 1));
  double *jac = malloc(sizeof(double) * ((size_t)rows * n + 1));
  double *hess = malloc(sizeof(double) * (size_t)n * n), energies[5];
  double *A = malloc(sizeof(double) * (size_t)N * N), *rhs = malloc(sizeof(double) * N);
  double *r_prim = malloc(sizeof(double) * (m > 0 ? m : 1));
  double *z_kept = malloc(sizeof(double) * n);
  double *lam_kept = malloc(sizeof(double) * (rows > 0 ? rows : 1));
  int *ipiv = malloc(sizeof(int) * N);
  int kept = 0;  /* z_kept, lam_kept and merit_kept hold the last accepted point */
  double merit_kept = 0.0;
  *steps = 0;
  arg[0] = z; arg[1] = p; arg[2] = lam;
  for (int k = 1; k <= max_steps; ++k) {
    *steps = k;
    res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
    if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) {
      code = DLO_EVALUATION_FAILED;
      break;
    }
    for (int i = 0; i < m; ++i) r_prim[i] = g[idx[i]] - bound[i];
    for (int i = 0; i < m; ++i) rhs[i] = fabs(r_prim[i]);  /* (rhs: scratch until the step) */
    double merit = sigma * (dlo_numpy_sum(energies, 4) - energies[4]) +
                   rho * dlo_numpy_sum(rhs, m);
    if (kept && !(merit < merit_kept)) {  /* uphill: undo, shift more */
      memcpy(z, z_kept, sizeof(double) * n);
      memcpy(lam, lam_kept, sizeof(double) * rows);
      double least = floor * dlo_max_abs(hess, (size_t)n * n);
      mu = growth * (least > mu ? least : mu);  /* Python's max(mu, least) */
      kept = 0;
      continue;
    }
    if (kept) mu = mu >= floor * dlo_max_abs(hess, (size_t)n * n) ? mu / decay : 0.0;
    /* r_dual = grad f + J_A^T lam_A, into rhs[0..n) */
    for (int j = 0; j < n; ++j) {
      double v = 0.0;
      for (int i = 0; i < m; ++i) v += lam[idx[i]] * jac[idx[i] + (size_t)j * rows];
      rhs[j] = grad[j] + v;
    }
    if (dlo_max_abs(rhs, n) < tol_dual && dlo_max_abs(r_prim, m) < tol_prim) {
      /* a stationary point whatever mu was (mu only shapes the steps): the caller polishes it */
      code = DLO_CONVERGED;
      break;
    }
    merit_kept = merit;
    memcpy(z_kept, z, sizeof(double) * n);
    memcpy(lam_kept, lam, sizeof(double) * rows);
    kept = 1;
    for (int j = 0; j < n; ++j) rhs[j] = -rhs[j];
    for (int i = 0; i < m; ++i) rhs[n + i] = -r_prim[i];
    if (dlo_kkt_factor(getrf, hess, jac, idx, n, m, rows, mu, reg, A, ipiv) != 0) {
      code = DLO_SINGULAR;
      break;
    }
    getrs(&trans, &N, &one, A, &N, ipiv, rhs, &N, &info);
    int finite = info == 0;
    for (int i = 0; i < N && finite; ++i) finite = isfinite(rhs[i]);
    if (!finite) { code = DLO_SINGULAR; break; }
    double big = dlo_max_abs(rhs, n);
    /* min(1, max_step / max(big, 1e-300)) as leave_saddle writes it (1e-300: no division by 0) */
    double scale = max_step / (big > 1e-300 ? big : 1e-300);
    if (scale > 1.0) scale = 1.0;
    for (int j = 0; j < n; ++j) z[j] = z[j] + scale * rhs[j];
    for (int i = 0; i < m; ++i) lam[idx[i]] += scale * rhs[n + i];
  }
  free(arg); free(res); free(iw); free(w); free(W); free(buf); free(grad); free(g); free(jac);
  free(hess); free(A); free(rhs); free(r_prim); free(z_kept); free(lam_kept); free(ipiv);
  dlo_fpmode_leave(fp);
  return code;
}
