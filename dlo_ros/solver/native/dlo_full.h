/* The full KKT function's evaluation with the Hessian's per-node part added, and the factor of
   the Newton matrix of its held rows: what the drivers around StringNLP.kkt_split_fn
   (newton_active.c, saddle_escape.c) share.  Included by them
   (dlo_ros/solver/native/build.py inlines it into the library's one source, once). */
#ifndef DLO_FULL_H
#define DLO_FULL_H

#include "dlo_native.h"
#include "dlo_common.h"

/* The doubles a driver allocates for W and, after it, the curvature blocks and their scratch. */
static size_t dlo_full_w_size(const dlo_node_map *map, int rows_e, int n) {
  return (size_t)(rows_e + map->contact_rows + 9) * n + (size_t)map->contact_wsize;
}

/* grad f, g, dg/dz, hess L, energies at arg into res[0..4]: the split function (hess L without its
   per-node part and the rows' curvature), then both added (dlo_add_node_part,
   dlo_add_contact_part); W: dlo_full_w_size doubles; nonzero if the function fails. */
static int dlo_full_eval(const casadi_real **arg, casadi_real **res, casadi_int *iw,
                         casadi_real *w, double *W, dlo_gemm_t gemm, const dlo_node_map *map,
                         int rows_e, int n, double *buf) {
  double *D = W + (size_t)rows_e * n, *blocks = D + (size_t)map->contact_rows * n;
  double *tmp = blocks + map->contact_wsize;
  res[5] = W;
  res[6] = D;
  res[7] = blocks;
  if (DLO_SYSTEM(arg, res, iw, w, 0) != 0) return 1;
  dlo_add_node_part(gemm, map, W, rows_e, n, res[3], n, buf);
  dlo_add_contact_part(gemm, map, D, blocks, tmp, n, res[3], n);
  return 0;
}

/* The regularised LU (dlo_regularised_lu) of [H + shift I, J_A^T; J_A, 0] of the m rows idx into
   A (N = n + m), as update/kkt.py's kkt_step builds it: the active-set loop's Newton matrix
   (shift 0) and the saddle's shifted steps. */
static int dlo_kkt_factor(dlo_getrf_t getrf, const double *hess, const double *jac,
                          const int *idx, int n, int m, int rows, double shift, double reg,
                          double *A, int *ipiv) {
  int N = n + m;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) A[i + (size_t)j * N] = hess[i + (size_t)j * n];
    if (shift != 0.0) A[j + (size_t)j * N] += shift;
  }
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

#endif  /* DLO_FULL_H */
