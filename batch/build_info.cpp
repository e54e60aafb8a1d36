#include "batch/build_info.hpp"

#include "kernels/lane.hpp"

#include <stdexcept>

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

void check_header_build(const HeaderBuild& caller) {
  const HeaderBuild own;
  if (caller.float_lanes == own.float_lanes && caller.double_lanes == own.double_lanes) return;
  throw std::logic_error("lockstep: this program was compiled for SIMD lanes of " + std::to_string(caller.float_lanes) +
                         " float / " + std::to_string(caller.double_lanes) + " double, but the library is " +
                         build_description() +
                         ": compile the code that includes lockstep's headers with the library's flags "
                         "(CMake's find_package(lockstep) passes them)");
}

}  // namespace lockstep
