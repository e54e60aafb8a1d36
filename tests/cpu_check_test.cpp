#include "tools/cpu_check.hpp"

#include <gtest/gtest.h>

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
  EXPECT_EQ(cpu_check_message({}), "");
}

TEST(CpuCheck, MessageNamesTheMissingFeaturesAndTheWayOut) {
  const std::string message = cpu_check_message({"AVX2", "AVX512F"});
  EXPECT_NE(message.find("AVX2 AVX512F"), std::string::npos) << message;
  EXPECT_NE(message.find("LOCKSTEP_PORTABLE=ON"), std::string::npos) << message;
}

TEST(CpuCheck, UnknownFeatureNamesCountAsUnsupported) {
  EXPECT_FALSE(cpu_supports("NOT_A_FEATURE"));
  EXPECT_FALSE(cpu_supports(""));
}

// This test program itself passed the check before main, so the machine
// running it supports everything the build requires.
TEST(CpuCheck, ThisMachineHasEverythingTheBuildRequires) {
  for (const std::string& feature : cpu_required_features()) EXPECT_TRUE(cpu_supports(feature)) << feature;
  const auto real = [](const std::string& f) { return cpu_supports(f); };
  EXPECT_TRUE(cpu_missing_features(cpu_required_features(), real).empty());
}

}  // namespace
}  // namespace lockstep
