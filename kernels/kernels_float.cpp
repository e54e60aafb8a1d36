// Instantiates every kernel for the float lanes: the scalar reference and SIMD.
#include "kernels/kernels.hpp"

namespace lockstep {
LOCKSTEP_KERNEL_TEMPLATES(, float)
LOCKSTEP_KERNEL_TEMPLATES(, lane::simd<float>)
}  // namespace lockstep
