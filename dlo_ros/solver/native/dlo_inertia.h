/* The stability verdict from the inertia of the held rows' KKT matrix (dlo_ros/solver/results/
   inertia.py, stable_by_inertia, in C beside the loops: the same LAPACK routine on the same
   matrix).  Sylvester's law of inertia: for J (m x n) of full row rank, K = [H J^T; J 0] has
   inertia (positive, negative, zero) = inertia(N^T H N) + (m, m, 0), N a basis of J's null space,
   so N^T H N is positive definite exactly when K has n positive and m negative eigenvalues and no
   zero one.  Bunch-Kaufman's K = P L D L^T P^T (LAPACK dsytrf) gives K's inertia as D's: one sign
   per 1 x 1 pivot, the signs of the two eigenvalues of each 2 x 2 one. */
#ifndef DLO_INERTIA_H
#define DLO_INERTIA_H

#include "dlo_native.h"

typedef void (*dlo_sytrf_t)(char *uplo, int *n, double *a, int *lda, int *ipiv, double *work,
                            int *lwork, int *info);

/* Classify one eigenvalue of D: *tiny when |d| <= tol, else *positive or *negative. */
static void dlo_inertia_count(double d, double tol, int *positive, int *negative, int *tiny) {
  if (!(fabs(d) > tol)) ++*tiny;
  else if (d > 0.0) ++*positive;
  else ++*negative;
}

/* 1 when K = [H J^T; J 0] (H: n x n at leading dimension ldh, J: m x n at ldj) has inertia
   exactly (n, m, 0) with every eigenvalue of D's pivot blocks above DLO_INERTIA_PIVOT_TOLERANCE
   max(1, max|K|) in magnitude: the reduced Hessian is positive definite, stable.  0 otherwise
   (more negative pivots, a tiny one, a rank-deficient J, LAPACK failing): the eigenvalue decides
   (dlo_reduced_eigen).  dsytrf with lwork = n + m: its unblocked algorithm (BLAS 2, as SciPy's
   wrapper by default; no OpenBLAS threads). */
static int dlo_inertia_stable(dlo_sytrf_t sytrf, const double *H, int ldh, const double *J,
                              int ldj, int n, int m) {
  int N = n + m, info = 0, lwork = N > 0 ? N : 1, positive = 0, negative = 0, tiny = 0;
  double *K = malloc(sizeof(double) * ((size_t)N * N + 1)), *work = malloc(sizeof(double) * lwork);
  int *ipiv = malloc(sizeof(int) * ((size_t)N + 1));
  char uplo = 'L';
  double scale = 1.0;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) K[i + (size_t)N * j] = H[i + (size_t)ldh * j];
    for (int k = 0; k < m; ++k) {
      double a = J[k + (size_t)ldj * j];
      K[(n + k) + (size_t)N * j] = a;
      K[j + (size_t)N * (n + k)] = a;
    }
  }
  for (int j = n; j < N; ++j)
    for (int i = n; i < N; ++i) K[i + (size_t)N * j] = 0.0;
  for (size_t e = 0; e < (size_t)N * N; ++e)
    if (fabs(K[e]) > scale) scale = fabs(K[e]);
  double tol = DLO_INERTIA_PIVOT_TOLERANCE * scale;
  sytrf(&uplo, &N, K, &N, ipiv, work, &lwork, &info);
  if (info == 0) {
    for (int k = 0; k < N;) {
      double a = K[k + (size_t)N * k];
      if (ipiv[k] > 0 || k + 1 == N) {  /* a 1 x 1 pivot */
        dlo_inertia_count(a, tol, &positive, &negative, &tiny);
        k += 1;
        continue;
      }
      /* a 2 x 2 pivot [a b; b c]: its larger eigenvalue, then the other as det / larger (no
         cancellation) */
      double b = K[(k + 1) + (size_t)N * k], c = K[(k + 1) + (size_t)N * (k + 1)];
      double mean = 0.5 * (a + c), radius = hypot(0.5 * (a - c), b);
      double large = mean >= 0.0 ? mean + radius : mean - radius;
      double small = large != 0.0 ? (a * c - b * b) / large : 0.0;
      dlo_inertia_count(large, tol, &positive, &negative, &tiny);
      dlo_inertia_count(small, tol, &positive, &negative, &tiny);
      k += 2;
    }
  }
  free(K); free(work); free(ipiv);
  return info == 0 && tiny == 0 && positive == n && negative == m;
}

#endif  /* DLO_INERTIA_H */
