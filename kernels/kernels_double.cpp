// Instantiates every kernel for the double lanes: the scalar reference and SIMD.
#include "kernels/kernels.hpp"

namespace lockstep {
LOCKSTEP_KERNEL_TEMPLATES(, double)
LOCKSTEP_KERNEL_TEMPLATES(, lane::simd<double>)
}  // namespace lockstep
