// Flush-to-zero and denormals-are-zero while a step runs on this thread
// (x86's MXCSR bits 15 and 6), the caller's setting restored after.
//
// A copy holding a pose has joint velocities that decay towards zero, and
// their products (v x w, v^2 in the bias forces) fall below the smallest
// normal float (1.2e-38); every operation on such a value takes a microcode
// assist of about a hundred cycles. On the bare anymal_b step holding its
// pose that was a fifth of the step (docs/performance.md). Values below
// 1e-38 (float) or 1e-308 (double) do nothing to a rigid-body simulation;
// PhysX runs its solver under the same setting (PxSIMDGuard). Every lane and
// the scalar reference step under it alike, so their bits still agree.
#pragma once

#if defined(__SSE__)
#include <xmmintrin.h>
#endif

namespace lockstep {

class DenormalGuard {
 public:
#if defined(__SSE__)
  DenormalGuard() : saved_(_mm_getcsr()) { _mm_setcsr(saved_ | kFlushToZero | kDenormalsAreZero); }
  ~DenormalGuard() { _mm_setcsr(saved_); }

 private:
  static constexpr unsigned kFlushToZero = 1u << 15;
  static constexpr unsigned kDenormalsAreZero = 1u << 6;
  unsigned saved_;
#else
  DenormalGuard() = default;
#endif
 public:
  DenormalGuard(const DenormalGuard&) = delete;
  DenormalGuard& operator=(const DenormalGuard&) = delete;
};

}  // namespace lockstep
