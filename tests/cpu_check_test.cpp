#include "tools/cpu_check.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <set>

namespace lockstep {
namespace {

TEST(CpuCheck, ReportsExactlyTheUnsupportedFeaturesInOrder) {
  const std::set<std::string> present = {"AVX", "FMA", "AVX512F"};
  const auto supports = [&](const std::string& f) { return present.count(f) > 0; };
  const std::vector<std::string> required = {"AVX", "AVX2", "FMA", "AVX512F", "AVX512BW"};
  EXPECT_EQ(cpu_missing_features(required, supports), (std::vector<std::string>{"AVX2", "AVX512BW"}));
}

TEST(CpuCheck, NothingMissingWhenAllSupportedOrNothingRequired) {
  const auto all = [](const std::string&) { return true; };
  const auto none = [](const std::string&) { return false; };
  EXPECT_TRUE(cpu_missing_features({"AVX2", "FMA"}, all).empty());
  EXPECT_TRUE(cpu_missing_features({}, none).empty());
}

// The plain-C core the constructor runs: counts every missing feature and
// never writes past the buffer, however small.
TEST(CpuCheck, CoreCountsAndTruncatesSafely) {
  const auto none = [](const char*, const void*) { return false; };
  char text[8];
  std::memset(text, 'x', sizeof text);
  EXPECT_EQ(cpu_find_missing("AVX2,,AVX512F,FMA", none, nullptr, text, sizeof text), 3);
  EXPECT_EQ(std::string(text), "AVX2 AV");
  const auto with_context = [](const char* f, const void* ctx) { return std::strcmp(f, static_cast<const char*>(ctx)) != 0; };
  char full[64];
  EXPECT_EQ(cpu_find_missing("AVX,BMI2,FMA", with_context, "BMI2", full, sizeof full), 1);
  EXPECT_EQ(std::string(full), "BMI2");
  EXPECT_EQ(cpu_find_missing("", none, nullptr, full, sizeof full), 0);
  EXPECT_EQ(std::string(full), "");
}

TEST(CpuCheck, UnknownFeatureNamesCountAsUnsupported) {
  EXPECT_FALSE(cpu_supports("NOT_A_FEATURE"));
  EXPECT_FALSE(cpu_supports(""));
}

// This test program itself passed the check before main, so the machine
// running it supports everything the build requires.
TEST(CpuCheck, ThisMachineHasEverythingTheBuildRequires) {
  for (const std::string& feature : cpu_required_features()) EXPECT_TRUE(cpu_supports(feature.c_str())) << feature;
  const auto real = [](const std::string& f) { return cpu_supports(f.c_str()); };
  EXPECT_TRUE(cpu_missing_features(cpu_required_features(), real).empty());
}

}  // namespace
}  // namespace lockstep
