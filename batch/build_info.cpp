#include "batch/build_info.hpp"

#include "kernels/lane.hpp"

#ifndef LOCKSTEP_VERSION
#error "the build defines LOCKSTEP_VERSION (CMakeLists.txt)"
#endif
#ifndef LOCKSTEP_ARCH
#error "the build defines LOCKSTEP_ARCH (CMakeLists.txt)"
#endif

namespace lockstep {

const char* lockstep_version() { return LOCKSTEP_VERSION; }

std::string build_description() {
  return std::string("lockstep ") + LOCKSTEP_VERSION + ", " + __VERSION__ + ", -march=" + LOCKSTEP_ARCH +
         ", SIMD lanes: " + std::to_string(lane::width_v<lane::simd<float>>) + " float / " +
         std::to_string(lane::width_v<lane::simd<double>>) + " double, -ffp-contract=off, no fast-math";
}

}  // namespace lockstep
