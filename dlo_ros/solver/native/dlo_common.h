/* What both Newton drivers share: the work sizes of two generated functions, the node map's BLAS
   product, the outputs evaluated after convergence and the regularised LU.  Included by
   newton_free.c and newton_active.c (dlo_ros/solver/native/build.py inlines it into the library's
   one source). */
#ifndef DLO_COMMON_H
#define DLO_COMMON_H

#include "dlo_native.h"


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

typedef void (*dlo_gemm_t)(char *ta, char *tb, int *m, int *n, int *k, double *alpha, double *a,
                           int *lda, double *b, int *ldb, double *beta, double *c, int *ldc);

/* The node map E (rows x n) as dense blocks: group g holds E[row[..], col[..]] for its count[2g]
   rows and count[2g + 1] columns (column-major, in block), every other entry of E is zero
   (NodeBlocks). */
typedef struct {
  int groups, chunk;
  const int *count, *row, *col;
  const double *block;
  /* the split full KKT function's curvature blocks (assembled_contact.contact_blocks): how many,
     the rows of D (the sum of their sizes), the doubles of w (the sum of the squares), each size */
  int contact_blocks, contact_rows, contact_wsize;
  const int *contact_size;
} dlo_node_map;

/* The Hessian's per-node part added to a split function's output: H += E^T W, W = diag(hess_k) E
   (rows_w x n, as the split function gives it), H at leading dimension ldh: per group, BLAS dgemm
   of its block against W's rows gathered, at most map->chunk rows a call (small enough that
   OpenBLAS runs it on this thread: its worker threads would spin on the other core).  buf: chunk x
   n + (largest group's columns) x n. */
static void dlo_add_node_part(dlo_gemm_t gemm, const dlo_node_map *map, const double *W,
                              int rows_w, int n, double *H, int ldh, double *buf) {
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

/* The rows' curvature added to H (n x n at leading dimension ldh): H += D_j^T W_j D_j over the
   blocks j whose W_j (b x b, column-major in w) is not zero, D (map->contact_rows x n,
   column-major) and w as the split full KKT function gives them; block j's rows of D and entries
   of w follow the earlier blocks'.  A row's curvature counts where its multiplier does: most
   rows carry none.  tmp: 9 x n (the largest block). */
static inline void dlo_add_contact_part(dlo_gemm_t gemm, const dlo_node_map *map, const double *D,
                                 const double *w, double *tmp, int n, double *H, int ldh) {
  char t = 'T', no = 'N';
  double one = 1.0, zero = 0.0;
  int rows_d = map->contact_rows, row = 0;
  for (int j = 0; j < map->contact_blocks; ++j) {
    int b = map->contact_size[j], nonzero = 0;
    for (int i = 0; i < b * b; ++i)
      if (w[i] != 0.0) { nonzero = 1; break; }
    if (nonzero) {
      gemm(&no, &no, &b, &n, &b, &one, (double *)w, &b, (double *)D + row, &rows_d, &zero, tmp, &b);
      gemm(&t, &no, &n, &n, &b, &one, (double *)D + row, &rows_d, tmp, &b, &one, H, &ldh);
    }
    row += b;
    w += (size_t)b * b;
  }
}

/* A generated CasADi function of another library (the obstacle rows', the outputs'), by its
   address. */
typedef int (*dlo_casadi_t)(const casadi_real **arg, casadi_real **res, casadi_int *iw,
                            casadi_real *w, int mem);

/* What a converged update also evaluates in the same call (see UpdateOutputs in native/newton.py):
   the obstacle rows' values (contact-free loop only: the active-set loop has every row), then, if
   none of them is violated, the outputs' function (output_function.py) at (z, p, lambda_SI, prof).
   A NULL function is skipped.  done: out, bit 1 set when g holds every row's value, bit 2 when the
   outputs were evaluated. */
typedef struct {
  dlo_casadi_t obstacle, outputs;
  dlo_work_t obstacle_work, outputs_work;
  int rows, free_rows;
  const double *ub, *lam_div, *prof;
  double *g, *lam_si;
  double *out[8];
  int done;
} dlo_after;

/* (static inline, as dlo_after_run: a driver that evaluates nothing after its loop, as
   saddle_escape.c, compiles without an unused-function warning) */
static inline int dlo_call(dlo_casadi_t fn, dlo_work_t work, const double **in, double **out) {
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

/* After convergence at (z, p) with multipliers lam (every row if all_rows, else the free rows)
   and, for the contact-free loop, the free rows' values g_free: there a->g gets every row's value,
   and the outputs are evaluated unless an obstacle row exceeds its bound by more than
   DLO_CONTACT_APPEARED_TOLERANCE (a contact appeared: the caller goes on with it active).  The
   active-set loop (g_free NULL) has every row: the outputs. */
static inline void dlo_after_run(dlo_after *a, const double *z, const double *p,
                                 const double *lam, int all_rows, const double *g_free) {
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
    for (int i = a->free_rows; i < a->rows; ++i)
      if (!(a->g[i] <= a->ub[i] + DLO_CONTACT_APPEARED_TOLERANCE)) return;
  }
  if (a->outputs == NULL) return;
  for (int i = 0; i < a->rows; ++i)
    a->lam_si[i] = (all_rows || i < a->free_rows ? lam[i] : 0.0) / a->lam_div[i];
  const double *in[4] = {z, p, a->lam_si, a->prof};
  if (dlo_call(a->outputs, a->outputs_work, in, a->out) == 0) a->done |= 2;
}

typedef void (*dlo_getrf_t)(int *m, int *n, double *a, int *lda, int *ipiv, int *info);
typedef void (*dlo_getrs_t)(char *trans, int *n, int *nrhs, double *a, int *lda, int *ipiv,
                            double *b, int *ldb, int *info);

/* The LU of A + diag(delta I_n, -delta_rows I_(N-n)), in place; LAPACK's info.  A = [H J^T; J 0]
   (column-major), delta = reg max(max|A|, 1), delta_rows = reg max|J|^2 / max(max|H|, 1): the
   rows' shift scaled as the Schur complement J H^-1 J^T it perturbs (update/kkt.py, regularised). */
static int dlo_regularised_lu(dlo_getrf_t getrf, double *A, int *ipiv, int n, int N, double reg) {
  double kmax = 1.0, hmax = 1.0, jmax = 0.0;
  int info = 0;
  for (int c = 0; c < N; ++c)
    for (int r = 0; r < N; ++r) {
      double v = fabs(A[(size_t)c * N + r]);
      if (v > kmax) kmax = v;
      if (c < n && r < n && v > hmax) hmax = v;
      if (c < n && r >= n && v > jmax) jmax = v;
    }
  double delta = reg * kmax, delta_rows = reg * jmax * jmax / hmax;
  for (int i = 0; i < N; ++i) A[(size_t)i * N + i] += (i < n ? delta : -delta_rows);
  getrf(&N, &N, A, &N, ipiv, &info);
  return info;
}

#endif  /* DLO_COMMON_H */
