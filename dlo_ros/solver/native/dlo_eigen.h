/* The stability verdict (dlo_ros/solver/results/stability.py, stability_verdict) in C beside the
   loops: the inertia first (dlo_inertia.h), else the smallest eigenvalue (min_reduced_eigenvalue);
   the same LAPACK routines on the same matrices as the numpy path. */
#ifndef DLO_EIGEN_H
#define DLO_EIGEN_H

#include "dlo_native.h"
#include "dlo_inertia.h"

typedef void (*dlo_geqp3_t)(int *m, int *n, double *a, int *lda, int *jpvt, double *tau,
                            double *work, int *lwork, int *info);
typedef void (*dlo_orgqr_t)(int *m, int *n, int *k, double *a, int *lda, double *tau, double *work,
                            int *lwork, int *info);
typedef void (*dlo_syevr_t)(char *jobz, char *range, char *uplo, int *n, double *a, int *lda,
                            double *vl, double *vu, int *il, int *iu, double *abstol, int *m,
                            double *w, double *z, int *ldz, int *isuppz, double *work, int *lwork,
                            int *iwork, int *liwork, int *info);

/* SciPy's LAPACK and BLAS routines the verdict needs; chunk: the most multiplications of one
   dgemm; inertia: 1 to try the inertia first (dlo_stability), 0 for the eigenpair always */
typedef struct {
  dlo_geqp3_t geqp3;
  dlo_orgqr_t orgqr;
  dlo_syevr_t syevr;
  dlo_gemm_t gemm;
  dlo_sytrf_t sytrf;
  int chunk;
  int inertia;
} dlo_eigen_lapack;

/* C = op(A) B column block by column block, each dgemm call within la->chunk multiplications (as
   dlo_add_node_part: OpenBLAS then stays on this thread); op(A) is rows x inner. */
static void dlo_gemm_chunked(const dlo_eigen_lapack *la, char ta, int rows, int cols, int inner,
                             const double *A, int lda, const double *B, int ldb, double *C,
                             int ldc) {
  char no = 'N';
  double one = 1.0, zero = 0.0;
  long per = (long)rows * inner;
  int step = per > 0 ? (int)(la->chunk / per) : cols;
  if (step < 1) step = 1;
  for (int c = 0; c < cols; c += step) {
    int k = cols - c < step ? cols - c : step;
    la->gemm(&ta, &no, &rows, &k, &inner, &one, (double *)A, &lda, (double *)B + (size_t)ldb * c,
             &ldb, &zero, C + (size_t)ldc * c, &ldc);
  }
}

/* The smallest eigenvalue of N^T H N and its eigenvector N v, N an orthonormal basis of the null
   space of the m x n matrix J (leading dimension ldj): LAPACK geqp3 of J^T, rank = number of
   |R_kk| above max(m, n) eps |R_00|, Q from orgqr, N = Q's last n - rank columns; syevr for the
   one eigenpair.  H: n x n at leading dimension ldh.  DLO_EIGEN_FOUND; DLO_EIGEN_NO_FREEDOM (rank
   n); DLO_EIGEN_FAILED: LAPACK failed (the caller's numpy path decides). */
static int dlo_reduced_eigen(const dlo_eigen_lapack *la, const double *H, int ldh, const double *J,
                             int ldj, int n, int m, double *value, double *direction) {
  int k = m < n ? m : n, info = 0, code = DLO_EIGEN_FAILED;
  /* the workspace sizes SciPy's wrappers pass (the unblocked algorithms): blocked ones call BLAS 3
     at sizes where OpenBLAS's threads spin on the other core (a native call's CPU time doubled) */
  int lw_qr = 3 * m + 1, lw_q = n > 1 ? n : 1, lwork = 26 * n + 3 * m + 1, liwork = 10 * n + 1;
  double *qr = malloc(sizeof(double) * ((size_t)n * (m > 0 ? m : 1)));
  double *tau = calloc((size_t)n + 1, sizeof(double));
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
    double big = fabs(qr[0]), eps = DBL_EPSILON, limit = (m > n ? m : n) * eps * big;
    for (int i = 0; i < k; ++i) if (fabs(qr[i + (size_t)n * i]) > limit) ++rank;
    memcpy(Q, qr, sizeof(double) * (size_t)n * k);
  }
  if (rank == n) { code = DLO_EIGEN_NO_FREEDOM; goto done; }
  /* Q from its k reflectors (numpy's path pads tau with zeros to n: identity reflectors, the same
     Q) */
  la->orgqr(&n, &n, &k, Q, &n, tau, work, &lw_q, &info);
  if (info != 0) goto done;
  {
    int r = n - rank, found = 0, il = 1, lw_eig = 26 * r;
    char jobz = 'V', range = 'I', uplo = 'L', tr = 'T', no = 'N';
    double vl = 0.0, vu = 0.0, abstol = 0.0, w[1];
    const double *basis = Q + (size_t)n * rank;
    dlo_gemm_chunked(la, no, n, r, n, H, ldh, basis, n, T, n);      /* T = H N */
    dlo_gemm_chunked(la, tr, r, r, n, basis, n, T, n, M, r);        /* M = N^T H N */
    la->syevr(&jobz, &range, &uplo, &r, M, &r, &vl, &vu, &il, &il, &abstol, &found, w, v, &r,
              isuppz, work, &lw_eig, iwork, &liwork, &info);
    if (info != 0 || found != 1) goto done;
    *value = w[0];
    for (int i = 0; i < n; ++i) {
      double s = 0.0;
      for (int j = 0; j < r; ++j) s += basis[i + (size_t)n * j] * v[j];
      direction[i] = s;
    }
    code = DLO_EIGEN_FOUND;
  }
done:
  free(qr); free(tau); free(Q); free(work); free(T); free(M); free(v); free(jpvt); free(iwork);
  return code;
}

/* The stability verdict at an answer, H and J as dlo_reduced_eigen's: DLO_EIGEN_INERTIA_STABLE
   when the held rows leave freedom (m < n) and [H J^T; J 0] has inertia (n, m, 0) with no tiny
   pivot (dlo_inertia_stable; no eigenpair computed); else dlo_reduced_eigen's code and pair. */
static int dlo_stability(const dlo_eigen_lapack *la, const double *H, int ldh, const double *J,
                         int ldj, int n, int m, double *value, double *direction) {
  if (la->inertia && m < n && dlo_inertia_stable(la->sytrf, H, ldh, J, ldj, n, m))
    return DLO_EIGEN_INERTIA_STABLE;
  return dlo_reduced_eigen(la, H, ldh, J, ldj, n, m, value, direction);
}

#endif  /* DLO_EIGEN_H */
