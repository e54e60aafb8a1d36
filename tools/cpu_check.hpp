// The start-up check that this CPU has every instruction-set extension the
// binary was compiled for (LOCKSTEP_REQUIRED_ISA, from cmake/LockstepFlags.cmake).
// cpu_check.cpp is compiled for baseline x86-64 and linked into every
// executable (target lockstep_cpu_check); a constructor that runs before main
// and before other static initialisers prints the missing extensions and exits
// with kCpuCheckExitCode instead of letting the program die of SIGILL.
//
// Feature names are the compiler's macro names without underscores ("AVX2",
// "AVX512F", ...).
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace lockstep {

inline constexpr int kCpuCheckExitCode = 3;

// The required extensions, comma-separated, in the order cmake listed them.
const char* cpu_required_features_csv();

// Whether this CPU supports `feature`; unknown names count as unsupported.
bool cpu_supports(const char* feature);

// The check itself, in plain C so that the constructor runs no inline C++
// library code, of which the linker may keep a copy compiled for the full
// instruction set. Writes the names in the comma-separated `required` that
// `supports` rejects into `missing` (space-separated, NUL-terminated,
// truncated to `missing_size`) and returns how many there are.
using CpuSupportsFn = bool (*)(const char* feature, const void* context);
int cpu_find_missing(const char* required, CpuSupportsFn supports, const void* context, char* missing,
                     std::size_t missing_size);

// The same for tests and tools (not for use before main).
std::vector<std::string> cpu_required_features();
std::vector<std::string> cpu_missing_features(const std::vector<std::string>& required,
                                              const std::function<bool(const std::string&)>& supports);

}  // namespace lockstep
