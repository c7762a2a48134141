/* Subnormal numbers flushed to zero for the length of a driver's call (x86-64: the MXCSR's
   flush-to-zero and denormals-are-zero bits, set on entry and restored on return, so the caller's
   thread keeps its own mode).  The in-plane saddle of a cable on its table holds out-of-plane
   unknowns of ~1e-310 after Newton's steps; on those the generated KKT function ran 19x slower
   (4.5 ms against 0.24 ms an evaluation, bench/results/snap_through.md), each operation on a
   subnormal taking the CPU's microcode path.  A subnormal is below 2.3e-308 in scaled units: as a
   zero it changes no result above that.  Elsewhere (no MXCSR) the mode is left as it is. */
#ifndef DLO_FPMODE_H
#define DLO_FPMODE_H

#if defined(__x86_64__) || defined(__SSE2__)
#include <xmmintrin.h>
#define DLO_MXCSR_FLUSH 0x8040u /* FTZ (bit 15) | DAZ (bit 6) */
typedef unsigned int dlo_fpmode;
static inline dlo_fpmode dlo_fpmode_enter(void) {
  dlo_fpmode saved = _mm_getcsr();
  _mm_setcsr(saved | DLO_MXCSR_FLUSH);
  return saved;
}
static inline void dlo_fpmode_leave(dlo_fpmode saved) { _mm_setcsr(saved); }
#else
typedef int dlo_fpmode;
static inline dlo_fpmode dlo_fpmode_enter(void) { return 0; }
static inline void dlo_fpmode_leave(dlo_fpmode saved) { (void)saved; }
#endif

#endif  /* DLO_FPMODE_H */
