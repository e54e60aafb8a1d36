// The counter-based generator and the randomisation ranges.
#include "batch/counter_rng.hpp"
#include "batch/randomization.hpp"

#include <gtest/gtest.h>

#include <set>

namespace lockstep {
namespace {

// Known-answer vectors of Random123's kat_vectors for philox4x32_10.
TEST(CounterRng, MatchesPhiloxKnownAnswers) {
  EXPECT_EQ(philox4x32({0, 0, 0, 0}, 0), (PhiloxCounter{0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8}));
  EXPECT_EQ(philox4x32({0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff}, 0xffffffffffffffffull),
            (PhiloxCounter{0x408f276d, 0x41c83b0e, 0xa20bc7c6, 0x6d5451fd}));
  EXPECT_EQ(philox4x32({0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344}, 0x299f31d0a4093822ull),
            (PhiloxCounter{0xd16cfe09, 0x94fdcceb, 0x5001e420, 0x24126ea1}));
}

TEST(CounterRng, UnitDoubleSpansZeroToOneExclusive) {
  EXPECT_EQ(unit_double(0, 0), 0.0);
  EXPECT_LT(unit_double(0xffffffff, 0xffffffff), 1.0);
  EXPECT_EQ(unit_double(0x80000000, 0), 0.5);
}

TEST(Randomization, DrawsAreUniformInTheRangeAndDependOnEveryCounterWord) {
  const UniformRange range{-2.0, 3.0};
  std::set<double> seen;
  double sum = 0;
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    const double x = draw(range, 7, 3, 1, 2, k);
    ASSERT_GE(x, -2.0);
    ASSERT_LE(x, 3.0);
    seen.insert(x);
    sum += x;
  }
  EXPECT_EQ(seen.size(), static_cast<std::size_t>(n));
  // mean 0.5, standard error 5/sqrt(12 n) = 0.0102: 5 sigma
  EXPECT_NEAR(sum / n, 0.5, 0.051);
  const double base = draw(range, 7, 3, 1, 2, 0);
  EXPECT_EQ(draw(range, 7, 3, 1, 2, 0), base);  // a pure function
  EXPECT_NE(draw(range, 8, 3, 1, 2, 0), base);  // seed
  EXPECT_NE(draw(range, 7, 4, 1, 2, 0), base);  // copy
  EXPECT_NE(draw(range, 7, 3, 2, 2, 0), base);  // reset
  EXPECT_NE(draw(range, 7, 3, 1, 3, 0), base);  // field
  EXPECT_EQ(draw({1.5, 1.5}, 7, 3, 1, 2, 0), 1.5);
}

TEST(Randomization, DefaultIsIdentityAndEveryFieldIsNamed) {
  Randomization r;
  EXPECT_TRUE(r.is_identity());
  EXPECT_EQ(randomization_fields().size(), 15u);
  for (const RandomizationField& f : randomization_fields()) {
    Randomization changed;
    (changed.*f.range).high += 0.5;
    EXPECT_FALSE(changed.is_identity()) << f.name;
    EXPECT_NO_THROW(validate_randomization(changed)) << f.name;
  }
  r.randomize_ground_friction = true;
  EXPECT_FALSE(r.is_identity());
}

void expect_rejected(const Randomization& r, const std::string& piece) {
  try {
    validate_randomization(r);
    ADD_FAILURE() << "accepted; expected an error with \"" << piece << "\"";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(piece), std::string::npos) << e.what();
  }
}

TEST(Randomization, RejectsBadRangesNamingTheField) {
  Randomization r;
  r.com_offset = {0.1, -0.1};
  expect_rejected(r, "randomization.com_offset: low");
  r = {};
  r.mass_scale = {0.0, 1.0};
  expect_rejected(r, "randomization.mass_scale: low must be > 0");
  r = {};
  r.ground_friction = {-0.1, 1.0};
  expect_rejected(r, "randomization.ground_friction");
  r = {};
  r.root_yaw_noise = {-1.0, std::nan("")};
  expect_rejected(r, "randomization.root_yaw_noise: the range's bounds must be finite");
  r = {};
  r.armature_add = {-0.01, 0.0};
  expect_rejected(r, "randomization.armature_add");
  // the bounds as written, not rounded to six decimals (which read
  // "low 0.900000 is above high 0.900000" and "got -0.000000")
  r = {};
  r.mass_scale = {0.9000001, 0.9};
  expect_rejected(r, "randomization.mass_scale: low 0.9000001 is above high 0.9");
  r = {};
  r.kp_scale = {-1e-9, 1.0};
  expect_rejected(r, "randomization.kp_scale: low must be >= 0, got -1e-09");
}

}  // namespace
}  // namespace lockstep
