// Compiled for baseline x86-64 (see cmake/LockstepFlags.cmake): nothing the
// constructor runs may use an instruction the check has not yet confirmed,
// so its path uses only libc and the plain-C functions below.
#include "tools/cpu_check.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>

#ifndef LOCKSTEP_REQUIRED_ISA
#define LOCKSTEP_REQUIRED_ISA ""
#endif
#ifndef LOCKSTEP_ARCH_FLAGS
#define LOCKSTEP_ARCH_FLAGS ""
#endif

namespace lockstep {

namespace {

constexpr std::size_t kMaxFeatureName = 64;

// Whether `name` is an entry of the comma-separated `list`.
bool csv_contains(const char* list, const char* name) {
  const std::size_t n = std::strlen(name);
  for (const char* p = list; *p;) {
    const char* end = std::strchr(p, ',');
    const std::size_t len = end ? std::size_t(end - p) : std::strlen(p);
    if (len == n && std::strncmp(p, name, n) == 0) return true;
    if (!end) break;
    p = end + 1;
  }
  return false;
}

// The non-empty items of `text` separated by `separator` (not for use
// before the check has passed).
std::vector<std::string> split(const char* text, char separator) {
  std::vector<std::string> items;
  std::string item;
  for (const char* p = text;; ++p) {
    if (*p == separator || *p == '\0') {
      if (!item.empty()) items.push_back(item);
      item.clear();
      if (*p == '\0') return items;
    } else {
      item += *p;
    }
  }
}

}  // namespace

const char* cpu_required_features_csv() { return LOCKSTEP_REQUIRED_ISA; }

bool cpu_supports(const char* feature) {
  // __builtin_cpu_supports takes only string literals, hence the table.
#define LOCKSTEP_FEATURE(macro_name, builtin_name) \
  if (std::strcmp(feature, macro_name) == 0) return __builtin_cpu_supports(builtin_name) != 0;
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

int cpu_find_missing(const char* required, CpuSupportsFn supports, const void* context, char* missing,
                     std::size_t missing_size) {
  int count = 0;
  std::size_t used = 0;
  if (missing_size > 0) missing[0] = '\0';
  for (const char* p = required; *p;) {
    const char* end = std::strchr(p, ',');
    const std::size_t len = end ? std::size_t(end - p) : std::strlen(p);
    if (len > 0) {
      char name[kMaxFeatureName] = {};
      std::memcpy(name, p, len < kMaxFeatureName ? len : kMaxFeatureName - 1);
      if (!supports(name, context)) {
        ++count;
        const int written = std::snprintf(missing + used, missing_size - used, "%s%s", used ? " " : "", name);
        if (written > 0) used = used + std::size_t(written) < missing_size ? used + std::size_t(written) : missing_size - 1;
      }
    }
    if (!end) break;
    p = end + 1;
  }
  return count;
}

std::vector<std::string> cpu_required_features() { return split(cpu_required_features_csv(), ','); }

std::vector<std::string> cpu_missing_features(const std::vector<std::string>& required,
                                              const std::function<bool(const std::string&)>& supports) {
  std::string csv;
  for (const std::string& feature : required) csv += (csv.empty() ? "" : ",") + feature;
  const auto trampoline = [](const char* feature, const void* context) {
    return (*static_cast<const std::function<bool(const std::string&)>*>(context))(feature);
  };
  std::vector<char> text(csv.size() + 1);
  cpu_find_missing(csv.c_str(), trampoline, &supports, text.data(), text.size());
  return split(text.data(), ' ');
}

namespace {

// LOCKSTEP_CPU_CHECK_PRETEND_MISSING (comma-separated names) counts those
// extensions as missing: it lets tests see the failure path on a CPU that
// has them all.
bool supported_unless_pretended(const char* feature, const void* pretend) {
  if (pretend && csv_contains(static_cast<const char*>(pretend), feature)) return false;
  return cpu_supports(feature);
}

// Priority 101 runs before every default-priority initialiser of the program
// (the linker orders .init_array by priority).
__attribute__((constructor(101))) void check_cpu_before_main() {
  __builtin_cpu_init();
  char missing[1024];
  if (cpu_find_missing(cpu_required_features_csv(), supported_unless_pretended,
                       std::getenv("LOCKSTEP_CPU_CHECK_PRETEND_MISSING"), missing, sizeof missing) == 0)
    return;
  std::fprintf(stderr,
               "lockstep: this CPU lacks instruction-set extensions the program was built for (" LOCKSTEP_ARCH_FLAGS
               "): %s. Rebuild on this machine, or configure with -DLOCKSTEP_PORTABLE=ON.\n",
               missing);
  std::fflush(stderr);
  std::_Exit(kCpuCheckExitCode);
}

}  // namespace

}  // namespace lockstep
