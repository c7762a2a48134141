/* What the Newton drivers (newton_free.c, newton_active.c) need from the library they are compiled
   into, and the settings they share with the Python paths.  In the library, the drivers are
   appended to CasADi's generated code (dlo_ros/solver/native/build.py), which defines casadi_real,
   casadi_int, CASADI_SYMBOL_EXPORT and the functions DLO_SYSTEM and DLO_RESIDUAL stand for;
   compiled on their own (test/unit/test_native_c_warnings.py) the defaults below stand in for it.
   Every DLO_ setting is a -D flag from dlo_ros/solver/native/settings.py, the one place its value
   is written: a build without one fails here rather than using a second copy. */
#ifndef DLO_NATIVE_H
#define DLO_NATIVE_H

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef casadi_real
#define casadi_real double
#endif
#ifndef casadi_int
#define casadi_int long long int
#endif
#ifndef CASADI_SYMBOL_EXPORT
#define CASADI_SYMBOL_EXPORT
#endif

#if !defined(DLO_SYSTEM) || !defined(DLO_SYSTEM_WORK) || !defined(DLO_RESIDUAL) || \
    !defined(DLO_RESIDUAL_WORK)
#error "the generated functions' names: -D flags from dlo_ros/solver/native/build.py"
#endif
#if !defined(DLO_CONVERGED) || !defined(DLO_NOT_CONVERGED) || !defined(DLO_SINGULAR) || \
    !defined(DLO_STEP_TOO_LARGE) || !defined(DLO_EVALUATION_FAILED)
#error "the return codes: -D flags from dlo_ros/solver/native/settings.py"
#endif
#if !defined(DLO_EIGEN_FOUND) || !defined(DLO_EIGEN_NO_FREEDOM) || !defined(DLO_EIGEN_FAILED) || \
    !defined(DLO_EIGEN_INERTIA_STABLE) || !defined(DLO_INERTIA_PIVOT_TOLERANCE)
#error "the eigenvalue's codes: -D flags from dlo_ros/solver/native/settings.py"
#endif
#if !defined(DLO_CONTACT_APPEARED_TOLERANCE) || !defined(DLO_STABILITY_MULTIPLIER_TOLERANCE) || \
    !defined(DLO_STABILITY_BOUND_TOLERANCE)
#error "the thresholds: -D flags from dlo_ros/solver/native/settings.py"
#endif

/* The generated functions the driver runs (CasADi's calling convention). */
int DLO_SYSTEM(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w,
               int mem);
int DLO_SYSTEM_WORK(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);
int DLO_RESIDUAL(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w,
                 int mem);
int DLO_RESIDUAL_WORK(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);

#endif  /* DLO_NATIVE_H */
