/* Newton with an active set in one call (dlo_ros/solver/native/active.py, ActiveNewton), around
   the generated split full KKT function DLO_SYSTEM (StringNLP.kkt_split_fn) and its residual
   DLO_RESIDUAL (StringNLP.residual_fn), both given as -D names by native/build.py. */
#include "dlo_native.h"
#include "dlo_common.h"
#include "dlo_fpmode.h"
#include "dlo_eigen.h"
#include "dlo_full.h"
/* Evaluate the full KKT function here into out = (grad f, g, dg/dz, hess L, energies), counted
   in *evaluations, and factor [H J_A^T; J_A 0] of the m rows idx there (dlo_kkt_factor, no
   shift): 0, or the code to stop with (DLO_EVALUATION_FAILED, DLO_SINGULAR). */
static int dlo_evaluate_and_factor(const casadi_real **arg, casadi_real **res, casadi_int *iw,
                                   casadi_real *w, double *W, dlo_gemm_t gemm,
                                   const dlo_node_map *map, int rows_e, int n, double *buf,
                                   double *const out[5], int *evaluations, dlo_getrf_t getrf,
                                   const int *idx, int m, int rows, double reg, double *A,
                                   int *ipiv) {
  res[0] = out[0]; res[1] = out[1]; res[2] = out[2]; res[3] = out[3]; res[4] = out[4];
  if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0)
    return DLO_EVALUATION_FAILED;
  ++*evaluations;
  if (dlo_kkt_factor(getrf, out[3], out[2], idx, n, m, rows, 0.0, reg, A, ipiv) != 0)
    return DLO_SINGULAR;
  return 0;
}

/* Newton, then chord, steps on [H J_A^T; J_A 0] for the rows with active[i] (held at ub[i]); see
   dlo_ros/solver/native/active.py (ActiveNewton) and update/active_set.py (active_steps, the row
   switches). Each step's matrix is evaluated (Newton's own steps) until an iterate where the rows
   are checked changes no row and the steps are below chord_start; after that the factored matrix
   is kept while the steps shrink by the contraction factor, the residual function giving grad L
   and g in between.  The rows are checked at the first iterate (a Newton step reached it: its g
   and multipliers are Newton's own) and at each evaluated iterate after it: while switches remain,
   one row of those with switchable[i] changes, the most violated inactive one joining, else the
   active one with the most negative multiplier leaving (its multiplier set to 0), and the matrix
   is evaluated there; an iterate where a row changed is not converged.  z (n), lam (rows), active
   (rows): in at the start, out at the answer.  grad, g, jac (rows x n, column-major), hess (n x
   n), energies: out at the answer (evaluated there); with given = 1 they are in as well, the first
   step's derivatives. */
CASADI_SYMBOL_EXPORT int dlo_newton_active_run(
    dlo_getrf_t getrf, dlo_getrs_t getrs, dlo_gemm_t gemm, const dlo_node_map *map, int rows_e,
    int buf_size, int n, int rows, int *active, const int *switchable, int switches,
    int max_evaluations, int max_steps, int given, double max_step, double reg, double tol_dual,
    double tol_prim, double tol_step, double contraction, double chord_start, double join_tol,
    double leave_tol, double *z, const double *p, double *lam, const double *ub, double *grad,
    double *g, double *jac, double *hess, double *energies, int *steps, int *evaluations,
    const int *equality, const dlo_eigen_lapack *eigen, double *eig_value, double *eig_direction,
    int *eig_code, dlo_after *after) {
  dlo_fpmode fp = dlo_fpmode_enter();  /* subnormals as zeros (dlo_fpmode.h) */
  int one = 1, info = 0, code = DLO_NOT_CONVERGED;
  char trans = 'N';
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  dlo_work(DLO_SYSTEM_WORK, DLO_RESIDUAL_WORK, &sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc(sizeof(casadi_real *) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real **res = malloc(sizeof(casadi_real *) * (sz_res > 8 ? sz_res : 8));
  double *W = malloc(sizeof(double) * dlo_full_w_size(map, rows_e, n));
  double *buf = malloc(sizeof(double) * (buf_size > 1 ? buf_size : 1));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw > 1 ? sz_iw : 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w > 1 ? sz_w : 1));
  int most = 0;  /* rows that can be active: the matrix is sized for them, not for every row */
  for (int i = 0; i < rows; ++i) most += active[i] || switchable[i];
  int *idx = malloc(sizeof(int) * (most > 1 ? most : 1));
  double *A = malloc(sizeof(double) * (n + most) * (n + most));
  double *rhs = malloc(sizeof(double) * (n + most));
  double *lgrad = malloc(sizeof(double) * (n + rows));  /* the residual function's [grad L; g] */
  int *ipiv = malloc(sizeof(int) * (n + most));
  int fresh = 0, m = 0, factored = 0, here = 0;  /* here: the factored matrix is this iterate's */
  int settled = switches == 0;  /* a check of the rows changed none (or none may change) */
  double previous = INFINITY, big = 0.0;
  int shrinking = 1;
  double *const out[5] = {grad, g, jac, hess, energies};  /* what an evaluation writes */
  *steps = 0; *evaluations = 0;
  arg[0] = z; arg[1] = p; arg[2] = lam;
  if (!given) {
    res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
    if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) {
      code = DLO_EVALUATION_FAILED;
      goto done;
    }
    ++*evaluations;
    fresh = 1;
  }
  for (;;) {
    int switched = 0;
    /* rows switch where the derivatives are evaluated, and at the first iterate, which a Newton
       step reached whatever the start (there the residual function's g and the multipliers are
       Newton's own) */
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
        /* the changed set's matrix from derivatives evaluated here: with the start's, a row
           joining beside an active sample (their Jacobians nearly equal) sent steps over
           max_step */
        res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
        if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) {
          code = DLO_EVALUATION_FAILED;
          break;
        }
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
      if (fresh) { code = DLO_CONVERGED; break; }
      /* the derivatives at the answer, and the test once more on them */
      res[0] = grad; res[1] = g; res[2] = jac; res[3] = hess; res[4] = energies;
      if (dlo_full_eval(arg, res, iw, w, W, gemm, map, rows_e, n, buf) != 0) {
        code = DLO_EVALUATION_FAILED;
        break;
      }
      ++*evaluations;
      fresh = 1;
      continue;
    }
    if (*steps == max_steps) { code = DLO_NOT_CONVERGED; break; }
    if (!factored || switched) {
      if (dlo_kkt_factor(getrf, hess, jac, idx, n, m, rows, 0.0, reg, A, ipiv) != 0) {
        code = DLO_SINGULAR;
        break;
      }
      factored = 1;
      here = fresh || *steps == 0;
      previous = INFINITY;
    }
    getrs(&trans, &N, &one, A, &N, ipiv, rhs, &N, &info);
    if (info != 0) { code = DLO_SINGULAR; break; }
    big = 0.0;
    int finite = 1;
    for (int i = 0; i < N; ++i) {
      if (!isfinite(rhs[i])) finite = 0;
      if (i < n && fabs(rhs[i]) > big) big = fabs(rhs[i]);
    }
    if (!finite || big > max_step) {
      if (here || *evaluations >= max_evaluations) { code = DLO_STEP_TOO_LARGE; break; }
      /* a step of the matrix of an earlier iterate: Newton's own step, from derivatives evaluated
         here */
      int failed = dlo_evaluate_and_factor(arg, res, iw, w, W, gemm, map, rows_e, n, buf, out,
                                           evaluations, getrf, idx, m, rows, reg, A, ipiv);
      if (failed) { code = failed; break; }
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
      /* Newton's own steps (the same iterates and row decisions as active_steps) until a check of
         the rows changes none and the steps are below chord_start, then chord steps; or too slow
         for the factored matrix: evaluate and factor it here */
      int failed = dlo_evaluate_and_factor(arg, res, iw, w, W, gemm, map, rows_e, n, buf, out,
                                           evaluations, getrf, idx, m, rows, reg, A, ipiv);
      if (failed) { code = failed; break; }
      previous = INFINITY;
      here = fresh = 1;
    } else {
      res[0] = lgrad;
      if (DLO_RESIDUAL(arg, res, iw, w, 0) != 0) { code = DLO_EVALUATION_FAILED; break; }
      memcpy(g, lgrad + n, sizeof(double) * rows);
      previous = big;
      fresh = 0;
    }
  }
  *eig_code = DLO_EIGEN_FAILED;
  if (code == DLO_CONVERGED) {
    /* the stability verdict at the answer (dlo_stability), on the rows stability.held_rows holds:
       the equalities, the rows within DLO_STABILITY_BOUND_TOLERANCE of their bound, and those
       with |lambda| above DLO_STABILITY_MULTIPLIER_TOLERANCE and above their slack
       (stability.held_rows) */
    int held = 0, *rows_held = malloc(sizeof(int) * (rows > 0 ? rows : 1));
    for (int i = 0; i < rows; ++i)
      if (equality[i] || g[i] > ub[i] - DLO_STABILITY_BOUND_TOLERANCE ||
          (fabs(lam[i]) > DLO_STABILITY_MULTIPLIER_TOLERANCE && fabs(lam[i]) > ub[i] - g[i]))
        rows_held[held++] = i;
    double *J = malloc(sizeof(double) * ((size_t)held * n + 1));
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < held; ++k) J[k + (size_t)held * j] = jac[rows_held[k] + (size_t)rows *
          j];
    *eig_code = dlo_stability(eigen, hess, n, J, held > 0 ? held : 1, n, held, eig_value,
                              eig_direction);
    free(J); free(rows_held);
    if (after != NULL) dlo_after_run(after, z, p, lam, 1, NULL);
  }
done:
  free(arg); free(res); free(iw); free(w); free(idx); free(A); free(rhs); free(lgrad); free(ipiv);
      free(W);
  free(buf);
  dlo_fpmode_leave(fp);
  return code;
}
