// Compiled for baseline x86-64 (see cmake/LockstepFlags.cmake): nothing here
// may use an instruction the check has not yet confirmed.
#include "tools/cpu_check.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>

#ifndef LOCKSTEP_REQUIRED_ISA
#define LOCKSTEP_REQUIRED_ISA ""
#endif
#ifndef LOCKSTEP_ARCH_FLAGS
#define LOCKSTEP_ARCH_FLAGS ""
#endif

namespace lockstep {

namespace {

std::vector<std::string> split_csv(const char* text) {
  std::vector<std::string> out;
  std::string item;
  std::istringstream in(text);
  while (std::getline(in, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

}  // namespace

std::vector<std::string> cpu_required_features() { return split_csv(LOCKSTEP_REQUIRED_ISA); }

bool cpu_supports(const std::string& feature) {
  // __builtin_cpu_supports takes only string literals, hence the table.
#define LOCKSTEP_FEATURE(macro_name, builtin_name) \
  if (feature == macro_name) return __builtin_cpu_supports(builtin_name) != 0;
  LOCKSTEP_FEATURE("SSSE3", "ssse3")
  LOCKSTEP_FEATURE("SSE4_1", "sse4.1")
  LOCKSTEP_FEATURE("SSE4_2", "sse4.2")
  LOCKSTEP_FEATURE("POPCNT", "popcnt")
  LOCKSTEP_FEATURE("AVX", "avx")
  LOCKSTEP_FEATURE("AVX2", "avx2")
  LOCKSTEP_FEATURE("FMA", "fma")
  LOCKSTEP_FEATURE("BMI", "bmi")
  LOCKSTEP_FEATURE("BMI2", "bmi2")
  LOCKSTEP_FEATURE("AVX512F", "avx512f")
  LOCKSTEP_FEATURE("AVX512BW", "avx512bw")
  LOCKSTEP_FEATURE("AVX512DQ", "avx512dq")
  LOCKSTEP_FEATURE("AVX512VL", "avx512vl")
  LOCKSTEP_FEATURE("AVX512CD", "avx512cd")
  LOCKSTEP_FEATURE("AVX512IFMA", "avx512ifma")
  LOCKSTEP_FEATURE("AVX512VBMI", "avx512vbmi")
  LOCKSTEP_FEATURE("AVX512VBMI2", "avx512vbmi2")
  LOCKSTEP_FEATURE("AVX512VNNI", "avx512vnni")
  LOCKSTEP_FEATURE("AVX512BITALG", "avx512bitalg")
  LOCKSTEP_FEATURE("AVX512VPOPCNTDQ", "avx512vpopcntdq")
  LOCKSTEP_FEATURE("AVX512BF16", "avx512bf16")
  LOCKSTEP_FEATURE("GFNI", "gfni")
  LOCKSTEP_FEATURE("VPCLMULQDQ", "vpclmulqdq")
#undef LOCKSTEP_FEATURE
  return false;
}

std::vector<std::string> cpu_missing_features(const std::vector<std::string>& required,
                                              const std::function<bool(const std::string&)>& supports) {
  std::vector<std::string> missing;
  for (const std::string& feature : required)
    if (!supports(feature)) missing.push_back(feature);
  return missing;
}

std::string cpu_check_message(const std::vector<std::string>& missing) {
  if (missing.empty()) return "";
  std::string list;
  for (const std::string& feature : missing) list += (list.empty() ? "" : " ") + feature;
  return "lockstep: this CPU lacks instruction-set extensions the program was built for (" LOCKSTEP_ARCH_FLAGS
         "): " + list + ". Rebuild on this machine, or configure with -DLOCKSTEP_PORTABLE=ON.\n";
}

namespace {

// Priority 101 runs before every default-priority initialiser of the program
// (the linker orders .init_array by priority). LOCKSTEP_CPU_CHECK_PRETEND_MISSING
// (a comma-separated list) treats extensions as missing: it lets tests see
// the failure path on a CPU that has them all.
__attribute__((constructor(101))) void check_cpu_before_main() {
  __builtin_cpu_init();
  std::vector<std::string> pretend;
  if (const char* env = std::getenv("LOCKSTEP_CPU_CHECK_PRETEND_MISSING")) pretend = split_csv(env);
  const auto supports = [&pretend](const std::string& feature) {
    for (const std::string& p : pretend)
      if (p == feature) return false;
    return cpu_supports(feature);
  };
  const std::string message = cpu_check_message(cpu_missing_features(cpu_required_features(), supports));
  if (message.empty()) return;
  std::fputs(message.c_str(), stderr);
  std::fflush(stderr);
  std::_Exit(kCpuCheckExitCode);
}

}  // namespace

}  // namespace lockstep
