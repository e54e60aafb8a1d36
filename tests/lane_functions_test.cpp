// The transcendental functions of lane.hpp: accurate against libm, and the
// same bits on the scalar and the SIMD lane types.
#include "kernels/lane.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace lockstep {
namespace {

template <class T>
void check_function(T lo, T hi, T (*reference)(T), lane::simd<T> (*simd_f)(const lane::simd<T>&),
                    T (*scalar_f)(const T&), double max_ulps, const char* name) {
  using S = lane::simd<T>;
  constexpr std::size_t W = S::size;
  std::mt19937 rng(7);
  std::uniform_real_distribution<T> dist(lo, hi);
  alignas(64) T in[W], out[W];
  double worst = 0;
  for (int round = 0; round < 2000; ++round) {
    for (std::size_t i = 0; i < W; ++i) in[i] = dist(rng);
    simd_f(S::load_aligned(in)).store_aligned(out);
    for (std::size_t i = 0; i < W; ++i) {
      const T scalar = scalar_f(in[i]);
      ASSERT_EQ(std::memcmp(&scalar, &out[i], sizeof(T)), 0) << name << "(" << in[i] << "): SIMD and scalar differ";
      const T ref = reference(in[i]);
      const double ulp = std::abs(static_cast<double>(ref)) * std::numeric_limits<T>::epsilon();
      worst = std::max(worst, std::abs(static_cast<double>(scalar) - static_cast<double>(ref)) / ulp);
    }
  }
  EXPECT_LE(worst, max_ulps) << name << " worst error in ulps of the result";
}

template <class L>
L exp_of(const L& x) { return lane::exp(x); }
template <class L>
L sin_of(const L& x) { L s, c; lane::sincos(x, s, c); return s; }

// exp: Cody-Waite reduction plus a polynomial, 2 ulps at most (the
// reduction's rounding and the polynomial's, each under one ulp). The
// Stribeck friction uses it on [-80, 0]; checked over the whole range.
TEST(LaneFunctions, ExpIsAccurateAndLaneIndependent) {
  check_function<float>(-87.0f, 88.0f, [](float x) { return std::exp(x); }, exp_of, exp_of, 2.0, "exp float");
  check_function<double>(-700.0, 700.0, [](double x) { return std::exp(x); }, exp_of, exp_of, 2.0, "exp double");
}

// sin on joint-angle arguments; cos shares the code path. Errors in ulps of
// the result grow near the zeros of sin, so the bound is absolute there:
// arguments are kept in [0.1, 3.0] where |sin| >= 0.09.
TEST(LaneFunctions, SincosIsAccurateAndLaneIndependent) {
  check_function<float>(0.1f, 3.0f, [](float x) { return std::sin(x); }, sin_of, sin_of, 2.0, "sin float");
  check_function<double>(0.1, 3.0, [](double x) { return std::sin(x); }, sin_of, sin_of, 2.0, "sin double");
}

// Beyond the reduction's range (|x| up to the largest finite value) sin and
// cos stay a point of the unit circle, the same on both lane types, where
// they once left it (float: s^2 + c^2 = 2e7 at x = 1e8, inf from 3e12;
// double: 1.14 at 3e16), and a rotation by a spinning joint's angle with
// them. Non-finite x gives NaN. Asserted: |s^2 + c^2 - 1| <= 4 eps.
template <class T>
void check_sincos_far(const char* name) {
  using S = lane::simd<T>;
  constexpr std::size_t W = S::size;
  alignas(64) T in[W], sines[W], cosines[W];
  const int top = std::numeric_limits<T>::max_exponent10;
  for (int decade = 0; decade <= top; ++decade)
    for (int i = 0; i < 64; ++i) {
      for (std::size_t j = 0; j < W; ++j) {
        const T x = std::pow(T(10), T(decade) + T(i * W + j) / T(64 * W));
        in[j] = std::isfinite(x) ? ((i + j) % 2 ? -x : x) : std::numeric_limits<T>::max();
      }
      S s, c;
      lane::sincos(S::load_aligned(in), s, c);
      s.store_aligned(sines);
      c.store_aligned(cosines);
      for (std::size_t j = 0; j < W; ++j) {
        T ss, cc;
        lane::sincos<T>(in[j], ss, cc);
        ASSERT_EQ(std::memcmp(&ss, &sines[j], sizeof(T)), 0) << name << "(" << in[j] << "): SIMD and scalar differ";
        ASSERT_EQ(std::memcmp(&cc, &cosines[j], sizeof(T)), 0) << name << "(" << in[j] << "): SIMD and scalar differ";
        ASSERT_LE(std::abs(ss * ss + cc * cc - T(1)), 4 * std::numeric_limits<T>::epsilon()) << name << "(" << in[j] << ")";
      }
    }
  for (T x : {std::numeric_limits<T>::quiet_NaN(), std::numeric_limits<T>::infinity(),
              -std::numeric_limits<T>::infinity()}) {
    T ss, cc;
    lane::sincos<T>(x, ss, cc);
    EXPECT_TRUE(std::isnan(ss) && std::isnan(cc)) << name << "(" << x << ")";
  }
}

TEST(LaneFunctions, SincosStaysOnTheUnitCircleForAnyArgument) {
  check_sincos_far<float>("sincos float");
  check_sincos_far<double>("sincos double");
}

// atan2 over all four quadrants: arguments uniform in [-10, 10]^2, with
// one of them scaled down by up to 2^-40 (results near 0 and near +-pi/2)
// or x within 0.1 % of y (the tan(pi/8) reduction and the pi/4 diagonal).
// 2 ulps at most against long double atan2l (measured: 1.4 in both
// precisions; t's division, the reduction and the polynomial each round).
template <class T>
void check_atan2(const char* name) {
  using S = lane::simd<T>;
  constexpr std::size_t W = S::size;
  std::mt19937 rng(5);
  std::uniform_real_distribution<T> dist(-10, 10);
  alignas(64) T ys[W], xs[W], out[W];
  double worst = 0;
  for (int round = 0; round < 20000; ++round) {
    for (std::size_t i = 0; i < W; ++i) {
      T y = dist(rng), x = dist(rng);
      switch ((round + i) % 4) {
        case 1: y = std::ldexp(y, -static_cast<int>(rng() % 41)); break;
        case 2: x = std::ldexp(x, -static_cast<int>(rng() % 41)); break;
        case 3: x = y * (T(1) + T(1e-3) * dist(rng)); break;
        default: break;
      }
      ys[i] = y;
      xs[i] = x;
    }
    lane::atan2(S::load_aligned(ys), S::load_aligned(xs)).store_aligned(out);
    for (std::size_t i = 0; i < W; ++i) {
      const T scalar = lane::atan2<T>(ys[i], xs[i]);
      ASSERT_EQ(std::memcmp(&scalar, &out[i], sizeof(T)), 0)
          << name << "(" << ys[i] << ", " << xs[i] << "): SIMD and scalar differ";
      const long double ref = atan2l(ys[i], xs[i]);
      const double ulp = std::fabs(static_cast<double>(ref)) * std::numeric_limits<T>::epsilon();
      worst = std::max(worst, static_cast<double>(std::fabs(static_cast<long double>(scalar) - ref)) / ulp);
    }
  }
  EXPECT_LE(worst, 2.0) << name << " worst error in ulps of the result";
}

TEST(LaneFunctions, Atan2IsAccurateAndLaneIndependent) {
  check_atan2<float>("atan2 float");
  check_atan2<double>("atan2 double");
}

// The axes and the origin, exactly: the quadrant logic, not the polynomial.
TEST(LaneFunctions, Atan2OnTheAxes) {
  EXPECT_EQ(lane::atan2(0.0, 0.0), 0.0);
  EXPECT_EQ(lane::atan2(0.0, 2.0), 0.0);
  EXPECT_EQ(lane::atan2(0.0, -2.0), 3.1415926535897931);
  EXPECT_EQ(lane::atan2(2.0, 0.0), 1.5707963267948966);
  EXPECT_EQ(lane::atan2(-2.0, 0.0), -1.5707963267948966);
  EXPECT_EQ(lane::atan2(1.0, 1.0), 0.78539816339744828);
  EXPECT_EQ(lane::atan2(0.0f, -2.0f), 3.14159274f);
  EXPECT_EQ(lane::atan2(-2.0f, 0.0f), -1.57079637f);
}

}  // namespace
}  // namespace lockstep
