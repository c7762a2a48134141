/* The full KKT function's evaluation with the Hessian's per-node part added: what the drivers
   around StringNLP.kkt_split_fn (newton_active.c, saddle_escape.c) share.  Included by them
   (dlo_ros/solver/native/build.py inlines it into the library's one source, once). */
#ifndef DLO_FULL_H
#define DLO_FULL_H

#include "dlo_native.h"
#include "dlo_common.h"

/* grad f, g, dg/dz, hess L, energies at arg into res[0..4]: the split function (hess L without its
   per-node part), then that part added (dlo_add_node_part); nonzero if the function fails. */
static int dlo_full_eval(const casadi_real **arg, casadi_real **res, casadi_int *iw,
                         casadi_real *w, double *W, dlo_gemm_t gemm, const dlo_node_map *map,
                         int rows_e, int n, double *buf) {
  res[5] = W;
  if (DLO_SYSTEM(arg, res, iw, w, 0) != 0) return 1;
  dlo_add_node_part(gemm, map, W, rows_e, n, res[3], n, buf);
  return 0;
}

#endif  /* DLO_FULL_H */
