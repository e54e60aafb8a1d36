// What this build of lockstep is: its version and how it was compiled, for
// benchmark reports and rollout files.
#pragma once

#include <string>

namespace lockstep {

const char* lockstep_version();
// e.g. "lockstep 0.1.0, Debian Clang 14.0.6, -march=native, SIMD lanes: 16 float / 8 double,
// -ffp-contract=off, no fast-math"
std::string build_description();

}  // namespace lockstep
