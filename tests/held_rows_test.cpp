// TGS skips testing the joint rows a round holds at zero while every DOF
// stays below row_speed_bound (StepEngine::check_held_rows), and
// joint_rows_all_at_rest skips a row's own test below the same bound. That
// is sound only if the bound is sufficient: at any DOF velocity |w| <= V and
// any displacement of the round |D| <= h V, the row is at rest at every
// substep size. These tests hold each row kind to that, in float and
// double, at the bound's edges where rounding would show, and check that
// just past the bound the row can leave its band (so the checks can fail).
#include "kernels/joint_rows.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace lockstep {
namespace {

template <class T>
struct HeldRow {
  JointRowSpec<T> spec;
  JointRowScratch<T> scratch{1, 1, 1};
  bool slack = false;  // at rest at the free velocity (build_joint_rows's test)
  // row_speed_bound of the built row over the (sub)step h
  T bound(T h) const { return row_speed_bound<T>(spec, scratch.rows.error[0], scratch.rows.hi[0], h); }
};

// Row 0 of one DOF at q with free velocity u, built as the step builds it.
template <class T>
HeldRow<T> held_row(JointRowKind kind, T a, T b, T q, T u, T friction, T h) {
  HeldRow<T> r;
  r.spec = JointRowSpec<T>{kind, 0, 0, 0, a, b};
  std::vector<lane::mask_t<T>> slack(1);
  r.slack = build_joint_rows<T>({r.spec}, &q, &u, &friction, h, T(0.2), r.scratch, slack);
  return r;
}

// At rest after `substeps` substeps of h / substeps, at DOF velocity w
// and round displacement D (check_held_rows's test).
template <class T>
bool at_rest(const HeldRow<T>& r, T w, T D, int substeps, T h) {
  const RowBlock<T>& rows = r.scratch.rows;
  const T sigma = r.scratch.sigma[0];
  const bool positional = rows.positional[0] != 0;
  const T inv_substep = T(substeps) / h;
  const T target = positional ? tgs_target(rows, 0, sigma * D, inv_substep) : rows.target[0];
  const T target_hi = positional ? target : rows.target_hi[0];
  return row_at_rest(sigma * w, target, target_hi, rows.lo[0], rows.hi[0], rows.error[0], positional);
}

// Every corner and a grid of (w, D) within |w| <= V, |D| <= h V.
template <class T>
void expect_at_rest_below_bound(const HeldRow<T>& r, T h, const char* what) {
  const T V = r.bound(h);
  ASSERT_TRUE(std::isfinite(V)) << what;
  for (int substeps : {1, 2, 16, 96, 4096})
    for (int i = -8; i <= 8; ++i)
      for (int j = -8; j <= 8; ++j) {
        const T w = V * T(i) / T(8), D = h * V * T(j) / T(8);
        EXPECT_TRUE(at_rest(r, w, D, substeps, h))
            << what << ": V " << V << ", w " << w << ", D " << D << ", " << substeps << " substeps";
      }
}

template <class T>
void position_limit_case() {
  const T h = T(1) / T(60);
  // limits [-1, 2]: near each limit and moving towards it, far from both,
  // and a hair inside the upper one (the bound then tiny)
  for (T q : {T(-0.9), T(1.95), T(0.5), T(2) - T(1e-4)})
    for (T u : {T(-3), T(0), T(2)}) {
      const HeldRow<T> r = held_row<T>(JointRowKind::PositionLimit, T(-1), T(2), q, u, T(0), h);
      if (r.scratch.rows.error[0] < T(0)) continue;
      expect_at_rest_below_bound(r, h, sizeof(T) == 4 ? "position limit, float" : "position limit, double");
    }
  // past the bound the row can act: heading for the upper limit 0.05 away
  // at w with w h_sub > 0.05 crosses it within one substep
  const HeldRow<T> r = held_row<T>(JointRowKind::PositionLimit, T(-1), T(2), T(1.95), T(0), T(0), h);
  const T V = r.bound(h);
  EXPECT_NEAR(V, T(0.05) / (T(4) * h), T(1e-3));
  EXPECT_FALSE(at_rest(r, T(0.06) / h, T(0), 1, h));
}

template <class T>
void velocity_limit_case() {
  const T h = T(0.002);
  const HeldRow<T> r = held_row<T>(JointRowKind::VelocityLimit, T(7.5), T(0), T(0), T(1), T(0), h);
  EXPECT_EQ(r.bound(h), T(7.5));
  expect_at_rest_below_bound(r, h, sizeof(T) == 4 ? "velocity limit, float" : "velocity limit, double");
  const T past = std::nextafter(T(7.5), T(8));
  EXPECT_FALSE(at_rest(r, past, T(0), 16, h));
  EXPECT_FALSE(at_rest(r, -past, T(0), 16, h));
}

template <class T>
void friction_case() {
  const T h = T(0.002);
  const HeldRow<T> r = held_row<T>(JointRowKind::Friction, T(0), T(0), T(0), T(0), T(0.8), h);
  EXPECT_EQ(r.bound(h), T(0));
  EXPECT_TRUE(at_rest(r, T(0), T(0), 16, h));
  EXPECT_FALSE(at_rest(r, std::numeric_limits<T>::min(), T(0), 16, h));
  // without friction the row never acts: no bound
  const HeldRow<T> frictionless = held_row<T>(JointRowKind::Friction, T(0), T(0), T(0), T(0), T(0), h);
  EXPECT_EQ(frictionless.bound(h),
            std::numeric_limits<T>::infinity());
  EXPECT_TRUE(at_rest(frictionless, T(100), T(0), 16, h));
}

template <class T>
void no_limit_case() {
  const T h = T(0.002);
  HeldRow<T> r = held_row<T>(JointRowKind::PositionLimit, T(-1), T(2), T(2.01), T(0), T(0), h);
  ASSERT_LT(r.scratch.rows.error[0], T(0));
  const T V = r.bound(h);
  EXPECT_FALSE(T(0) <= V);  // even w = 0 is not below it
  r.scratch.rows.error[0] = std::numeric_limits<T>::quiet_NaN();
  EXPECT_FALSE(T(0) <= r.bound(h));
}

// joint_rows_all_at_rest skips a row's own test below row_speed_bound (the
// error the distance to the nearer limit): it must decide as the built
// rows do, over positions inside, at and past the limits and speeds from
// zero to far past every bound.
template <class T>
void all_at_rest_case() {
  const T h = T(0.002);
  for (JointRowKind kind : {JointRowKind::PositionLimit, JointRowKind::VelocityLimit, JointRowKind::Friction})
    for (T friction : {T(0), T(0.8)})
      for (T q : {T(-1.1), T(-1), T(-0.999), T(0), T(1.9999), T(2), T(2.5)})
        for (T u : {T(0), T(1e-6), T(-0.5), T(2.5), T(-7.5), T(7.5), T(12.4), T(-30), T(300)}) {
          const T a = kind == JointRowKind::VelocityLimit ? T(7.5) : T(-1), b = T(2);
          const HeldRow<T> r = held_row<T>(kind, a, b, q, u, friction, h);
          EXPECT_EQ(joint_rows_all_at_rest<T>({r.spec}, &q, &u, &friction, h, T(0.2)), r.slack)
              << "kind " << static_cast<int>(kind) << ", q " << q << ", u " << u << ", friction " << friction;
        }
}

TEST(HeldRowSpeedBound, LeavesTheFreeVelocitysRestTestAsItWas) {
  all_at_rest_case<float>();
  all_at_rest_case<double>();
}

TEST(HeldRowSpeedBound, KeepsAPositionLimitAtRest) {
  position_limit_case<float>();
  position_limit_case<double>();
}

TEST(HeldRowSpeedBound, IsAVelocityLimitsOwnBand) {
  velocity_limit_case<float>();
  velocity_limit_case<double>();
}

TEST(HeldRowSpeedBound, HoldsFrictionOnlyAtZeroSpeed) {
  friction_case<float>();
  friction_case<double>();
}

TEST(HeldRowSpeedBound, GivesNoSpeedPastOrWithoutALimit) {
  no_limit_case<float>();
  no_limit_case<double>();
}

}  // namespace
}  // namespace lockstep
