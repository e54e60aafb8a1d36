// The start-up check that this CPU has every instruction-set extension the
// binary was compiled for (LOCKSTEP_REQUIRED_ISA, from cmake/LockstepFlags.cmake).
// cpu_check.cpp is compiled for baseline x86-64 and linked into every
// executable (target lockstep_cpu_check); a constructor that runs before main
// and before other static initialisers prints the missing extensions and exits
// with kCpuCheckExitCode instead of letting the program die of SIGILL.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace lockstep {

inline constexpr int kCpuCheckExitCode = 3;

// The extensions the build requires, as the compiler's macro names without
// underscores ("AVX2", "AVX512F", ...), in the order cmake listed them.
std::vector<std::string> cpu_required_features();

// Whether this CPU supports `feature` (a name as above). Unknown names count
// as unsupported.
bool cpu_supports(const std::string& feature);

// The entries of `required` that `supports` rejects, in order.
std::vector<std::string> cpu_missing_features(const std::vector<std::string>& required,
                                              const std::function<bool(const std::string&)>& supports);

// The message printed when `missing` is not empty ("" otherwise).
std::string cpu_check_message(const std::vector<std::string>& missing);

}  // namespace lockstep
