// The step runs with denormals flushed (batch/denormal_guard.hpp) and gives
// the caller's thread its floating-point setting back.
#include "batch/denormal_guard.hpp"
#include "tests/sim_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace lockstep {
namespace {

#if defined(__SSE__)
TEST(DenormalGuard, FlushesInsideAndRestoresTheCallersSetting) {
  const unsigned before = _mm_getcsr();
  volatile float tiny = std::numeric_limits<float>::min();  // the smallest normal float
  {
    const DenormalGuard guard;
    EXPECT_EQ(_mm_getcsr() & 0x8040u, 0x8040u);
    const float half = tiny * 0.5f;  // a denormal, flushed
    EXPECT_EQ(half, 0.0f);
  }
  EXPECT_EQ(_mm_getcsr(), before);
  const float half = tiny * 0.5f;
  EXPECT_GT(half, 0.0f) << "outside the guard denormals are kept again";
  EXPECT_EQ(std::fpclassify(half), FP_SUBNORMAL);
}

// The control bits (6-15); bits 0-5 are sticky exception flags that any
// arithmetic may raise.
TEST(DenormalGuard, StepLeavesTheCallersSetting) {
  constexpr unsigned kControl = ~0x3Fu;
  const unsigned before = _mm_getcsr() & kControl;
  const Model model = test::load_shared_model("anymal_b", true);
  Simulator sim(model, 20, StepOptions{});
  sim.step(3);
  EXPECT_EQ(_mm_getcsr() & kControl, before);
  EXPECT_EQ(before & 0x8040u, 0u) << "the test's thread starts without flushing";
}
#endif

}  // namespace
}  // namespace lockstep
