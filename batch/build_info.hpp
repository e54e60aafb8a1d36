// What this build of lockstep is: its version and how it was compiled, for
// benchmark reports and rollout files.
#pragma once

#include "kernels/lane.hpp"

#include <string>

namespace lockstep {

// The SIMD lane widths of the code that includes lockstep's headers. The
// Simulator and VecEnv constructors take one as a defaulted last argument:
// a default argument is evaluated in the caller's code, so it carries the
// caller's compiler flags. Code built with another -march than the library
// disagrees with it on the layout of every lane type (and of Eigen's
// aligned members) and would crash or compute garbage; the constructors
// check first and throw instead. Leave the argument defaulted.
struct HeaderBuild {
  int float_lanes = static_cast<int>(lane::width_v<lane::simd<float>>);
  int double_lanes = static_cast<int>(lane::width_v<lane::simd<double>>);
};

// Throws std::logic_error naming both builds when `caller` is not this
// library's own.
void check_header_build(const HeaderBuild& caller);

// A class's first member: the check runs before anything else is built.
struct HeaderBuildCheck {
  explicit HeaderBuildCheck(const HeaderBuild& caller) { check_header_build(caller); }
};

const char* lockstep_version();
// e.g. "lockstep 0.1.0, Debian Clang 14.0.6, -march=native, SIMD lanes: 16 float / 8 double,
// -ffp-contract=off, no fast-math"
std::string build_description();

}  // namespace lockstep
