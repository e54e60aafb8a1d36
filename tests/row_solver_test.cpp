// The constraint solver alone, on small problems with known solutions: a
// one-sided row, a boxed row, a friction row bounded by a normal row's
// impulse, and a friction cone pair (the coupling contacts use).
#include "kernels/row_solver.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

namespace lockstep {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// A normal row (v0 >= 1, lambda0 >= 0) and a friction row (v1 = 0,
// |lambda1| <= 0.5 lambda0) coupled by D = [[2, 0.5], [0.5, 1]], v_free =
// (-1, 3). The friction row saturates: lambda1 = -lambda0 / 2, and
// v0 = -1 + 2 lambda0 - lambda0 / 4 = 1 gives lambda0 = 8/7, lambda1 = -4/7.
RowBlock<double> cone_problem() {
  RowBlock<double> rows(2);
  rows.D = {2.0, 0.5, 0.5, 1.0};
  rows.v_free = {-1.0, 3.0};
  rows.target = {1.0, 0.0};
  rows.target_hi = rows.target;
  rows.lo = {0.0, -kInf};
  rows.hi = {kInf, kInf};
  rows.bound_row[1] = 0;
  rows.mu[1] = 0.5;
  rows.lambda = {0.0, 0.0};
  return rows;
}

TEST(RowSolver, PgsSolvesAFrictionConeProblem) {
  RowBlock<double> rows = cone_problem();
  pgs_solve(rows, 60);  // the Gauss-Seidel contraction here is about 1/8 per sweep
  EXPECT_NEAR(rows.lambda[0], 8.0 / 7.0, 1e-12);
  EXPECT_NEAR(rows.lambda[1], -4.0 / 7.0, 1e-12);
}

TEST(RowSolver, RowsAtRestNeedNoImpulse) {
  RowBlock<double> rows = cone_problem();
  EXPECT_FALSE(rows_at_rest(rows));  // v0 = -1 < 1: the normal row pushes
  rows.v_free = {2.0, 3.0};          // separating: friction has no normal force to lean on
  EXPECT_TRUE(rows_at_rest(rows));
  rows.lo[0] = -1.0;                 // a boxed row that can pull does act
  rows.bound_row[1] = -1;
  rows.lo[1] = -1.0, rows.hi[1] = 1.0;
  EXPECT_FALSE(rows_at_rest(rows));
}

// A one-sided "joint" row 0 (lambda0 >= 0, v0 >= target0) coupled to a
// normal row 1 (v1 >= 1) and a friction row 2 bounded by it; row 0's target
// per lane.
template <class L>
RowBlock<L> joint_and_contact_problem(const std::vector<double>& joint_target) {
  using T = lane::scalar_t<L>;
  RowBlock<L> rows(3);
  const double D[9] = {1.5, 0.6, -0.3, 0.6, 2.0, 0.4, -0.3, 0.4, 1.0};
  for (int i = 0; i < 9; ++i) rows.D[i] = L(T(D[i]));
  rows.v_free = {L(T(0.5)), L(T(-1.0)), L(T(2.0))};
  alignas(64) T target[lane::width_v<L>];  // lane::load is an aligned load
  std::copy(joint_target.begin(), joint_target.end(), target);
  rows.target = {lane::load<L>(target), L(T(1.0)), L(T(0.0))};
  rows.target_hi = {L(std::numeric_limits<T>::infinity()), L(std::numeric_limits<T>::infinity()), L(T(0.0))};
  rows.lo = {L(T(0)), L(T(0)), L(T(-kInf))};
  rows.hi = {L(T(kInf)), L(T(kInf)), L(T(kInf))};
  rows.bound_row[2] = 1;
  rows.mu[2] = L(T(0.5));
  rows.lambda = {L(T(0.1)), L(T(0.2)), L(T(0.0))};  // a warm start
  return rows;
}

// A row held at zero impulse (box [0, 0], lambda 0), as the step holds a
// joint row a lane does not need, changes nothing else: the other rows'
// impulses equal, bit for bit, those of the problem without that row, with
// PGS and with TGS (lambda_sum too). In lanes where the row is free it
// pushes, so holding it is not trivially a no-op.
TEST(RowSolver, RowHeldAtZeroLeavesTheOthersAsWithoutIt) {
  using L = lane::simd<double>;
  constexpr int W = static_cast<int>(lane::width_v<L>);
  const std::vector<double> targets(W, 3.0);  // row 0 must push where it is free
  for (bool tgs : {false, true}) {
    auto solve = [&](RowBlock<L>& rows) {
      if (tgs) tgs_solve(rows, 40, 0.4);
      else pgs_solve(rows, 40);
    };
    RowBlock<L> free_rows = joint_and_contact_problem<L>(targets);
    solve(free_rows);
    EXPECT_GT(free_rows.lambda[0].get(0), 0) << "the row acts where it is free";
    RowBlock<L> held = joint_and_contact_problem<L>(targets);
    held.lo[0] = held.hi[0] = L(0.0);
    held.lambda[0] = L(0.0);
    solve(held);
    // the same problem without row 0: rows 1 and 2 and their block of D
    RowBlock<L> two = joint_and_contact_problem<L>(targets);
    RowBlock<L> without(2);
    for (int r = 0; r < 2; ++r) {
      for (int c = 0; c < 2; ++c) without.D[r * 2 + c] = two.D[(r + 1) * 3 + c + 1];
      without.v_free[r] = two.v_free[r + 1];
      without.target[r] = two.target[r + 1];
      without.target_hi[r] = two.target_hi[r + 1];
      without.lo[r] = two.lo[r + 1];
      without.hi[r] = two.hi[r + 1];
      without.lambda[r] = two.lambda[r + 1];
      without.mu[r] = two.mu[r + 1];
    }
    without.bound_row[1] = 0;  // friction under the normal row, now row 0
    solve(without);
    for (int l = 0; l < W; ++l) {
      EXPECT_EQ(held.lambda[0].get(l), 0.0) << (tgs ? "TGS" : "PGS");
      for (int r = 0; r < 2; ++r) {
        EXPECT_EQ(held.lambda[r + 1].get(l), without.lambda[r].get(l)) << (tgs ? "TGS" : "PGS") << " row " << r + 1;
        if (tgs) EXPECT_EQ(held.lambda_sum[r + 1].get(l), without.lambda_sum[r].get(l)) << "row " << r + 1;
      }
    }
  }
}

// A contact-only block of `slots` slots (normal, cone pair), D = J J^T +
// 0.1 I from a random J over 12 DOFs, per lane: normals pushed in at
// v_free -1, tangential free velocities of `slip` (large: the cones
// project; small: they do not), a random warm start.
template <class L>
RowBlock<L> contact_slot_problem(int slots, double slip, unsigned seed) {
  using T = lane::scalar_t<L>;
  constexpr int W = static_cast<int>(lane::width_v<L>);
  const int m = 3 * slots, dofs = 12;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> J(m * dofs * W);
  for (double& x : J) x = uniform(rng);
  RowBlock<L> rows(m);
  alignas(64) T lanes[W];
  auto per_lane = [&](auto value) {
    for (int l = 0; l < W; ++l) lanes[l] = static_cast<T>(value(l));
    return lane::load<L>(lanes);
  };
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j)
      rows.D[i * m + j] = per_lane([&](int l) {
        double sum = i == j ? 0.1 : 0.0;
        for (int k = 0; k < dofs; ++k) sum += J[(i * dofs + k) * W + l] * J[(j * dofs + k) * W + l];
        return sum;
      });
  for (int c = 0; c < slots; ++c) {
    const int n = 3 * c;
    rows.v_free[n] = per_lane([&](int) { return -1.0 + 0.2 * uniform(rng); });
    rows.target[n] = rows.target_hi[n] = per_lane([&](int) { return 0.05 * uniform(rng); });
    rows.lo[n] = L(T(0));
    rows.hi[n] = L(std::numeric_limits<T>::infinity());
    for (int t = 1; t < 3; ++t) {
      rows.v_free[n + t] = per_lane([&](int) { return slip * uniform(rng); });
      rows.target[n + t] = rows.target_hi[n + t] = L(T(0));
      rows.bound_row[n + t] = n;
      rows.mu[n + t] = per_lane([&](int) { return 0.5 + 0.4 * uniform(rng); });
    }
    rows.cone[n + 1] = 1;
  }
  for (int r = 0; r < m; ++r) rows.lambda[r] = per_lane([&](int) { return 0.1 + 0.1 * uniform(rng); });
  return rows;
}

template <class L>
lane::scalar_t<L> lane_value(const L& x, int l) {
  if constexpr (lane::is_scalar_v<L>) return x;
  else return x.get(l);
}

template <class L>
void expect_same_impulses(const RowBlock<L>& a, const RowBlock<L>& b, const std::string& what) {
  constexpr int W = static_cast<int>(lane::width_v<L>);
  for (int r = 0; r < a.m; ++r)
    for (int l = 0; l < W; ++l)
      ASSERT_EQ(lane_value(a.lambda[r], l), lane_value(b.lambda[r], l)) << what << ", row " << r << ", lane " << l;
}

// pgs_solve's unrolled sweeps of contact-only blocks and pgs_solve_pair's
// interleaved ones give the bits of the plain loop of gauss_seidel_sweep,
// for every number of slots they unroll, with cones that project and that
// do not, for the scalar reference and the SIMD lanes in float and double.
template <class L>
void check_unrolled_sweeps() {
  int saturated = 0, inside = 0;  // cones that end projected, and inside
  for (int slots = 1; slots <= kMaxUnrolledSlots; ++slots)
    for (double slip : {0.01, 3.0}) {
      const std::string what = std::to_string(slots) + " slots, slip " + std::to_string(slip);
      RowBlock<L> loop = contact_slot_problem<L>(slots, slip, 7u * slots);
      ASSERT_TRUE(is_contact_slots(loop));
      RowBlock<L> unrolled = loop, first = loop, second = contact_slot_problem<L>(slots, slip, 7u * slots + 1);
      RowBlock<L> second_alone = second;
      invert_diagonal(loop);
      for (int it = 0; it < 16; ++it) gauss_seidel_sweep(loop);
      pgs_solve(unrolled, 16);
      expect_same_impulses(loop, unrolled, "unrolled, " + what);
      pgs_solve_pair(first, second, 16);
      pgs_solve(second_alone, 16);
      expect_same_impulses(loop, first, "first of a pair, " + what);
      expect_same_impulses(second_alone, second, "second of a pair, " + what);
      const RowBlock<L> start = contact_slot_problem<L>(slots, slip, 7u * slots);
      double moved = 0;
      for (int r = 0; r < loop.m; ++r)
        for (int l = 0; l < static_cast<int>(lane::width_v<L>); ++l)
          moved = std::max(moved, std::abs(double(lane_value(loop.lambda[r], l)) - double(lane_value(start.lambda[r], l))));
      EXPECT_GT(moved, 1e-3) << "the sweeps change the impulses, " << what;
      for (int n = 0; n < loop.m; n += 3)
        for (int l = 0; l < static_cast<int>(lane::width_v<L>); ++l) {
          const double a = lane_value(loop.lambda[n + 1], l), b = lane_value(loop.lambda[n + 2], l);
          const double radius = double(lane_value(loop.mu[n + 1], l)) * lane_value(loop.lambda[n], l);
          if (std::sqrt(a * a + b * b) > radius * (1 - 1e-4)) ++saturated;
          else ++inside;
        }
    }
  EXPECT_GT(saturated, 0) << "some cones project";
  EXPECT_GT(inside, 0) << "some do not";
}

TEST(RowSolver, UnrolledContactSweepsMatchTheLoop) {
  check_unrolled_sweeps<float>();
  check_unrolled_sweeps<double>();
  check_unrolled_sweeps<lane::simd<float>>();
  check_unrolled_sweeps<lane::simd<double>>();
}

// TGS on two blocks side by side (tgs_solve_blocks) gives each block, its
// impulses and lambda_sum, the bits of tgs_solve alone, with positional
// normal rows whose targets follow their displacement, and calls each
// block's substep hook once per substep.
TEST(RowSolver, TgsPairSolvesEachAsAlone) {
  using L = lane::simd<float>;
  auto problem = [](unsigned seed) {
    RowBlock<L> rows = contact_slot_problem<L>(4, 0.5, seed);
    for (int n = 0; n < rows.m; n += 3) {
      rows.positional[n] = 1;
      rows.error[n] = L(-0.002f);  // penetrating: the target pushes out at the rate below
      rows.rate[n] = L(20.0f);
    }
    return rows;
  };
  RowBlock<L> first = problem(11), second = problem(12), first_alone = first, second_alone = second;
  int calls[2] = {0, 0};
  RowBlock<L>* const blocks[2] = {&first, &second};
  tgs_solve_blocks<2>(blocks, 8, 0.01f, [&](int i) { ++calls[i]; });
  tgs_solve(first_alone, 8, 0.01f);
  tgs_solve(second_alone, 8, 0.01f);
  EXPECT_EQ(calls[0], 8);
  EXPECT_EQ(calls[1], 8);
  expect_same_impulses(first_alone, first, "first of a TGS pair");
  expect_same_impulses(second_alone, second, "second of a TGS pair");
  for (int r = 0; r < first.m; ++r)
    for (int l = 0; l < static_cast<int>(lane::width_v<L>); ++l) {
      ASSERT_EQ(first.lambda_sum[r].get(l), first_alone.lambda_sum[r].get(l)) << "row " << r;
      ASSERT_EQ(second.lambda_sum[r].get(l), second_alone.lambda_sum[r].get(l)) << "row " << r;
    }
}

// A pair whose blocks differ in layout (their slots, or boxed rows in one)
// is solved one block after the other, each as pgs_solve solves it alone.
TEST(RowSolver, PairOfDifferentBlocksSolvesEachAlone) {
  using L = lane::simd<float>;
  auto expect_each_alone = [](RowBlock<L> first, RowBlock<L> second, const std::string& what) {
    RowBlock<L> first_alone = first, second_alone = second;
    pgs_solve_pair(first, second, 16);
    pgs_solve(first_alone, 16);
    pgs_solve(second_alone, 16);
    expect_same_impulses(first_alone, first, "first of " + what);
    expect_same_impulses(second_alone, second, "second of " + what);
  };
  expect_each_alone(contact_slot_problem<L>(3, 3.0, 1), contact_slot_problem<L>(4, 3.0, 2), "3 slots and 4");
  RowBlock<L> boxed = contact_slot_problem<L>(2, 0.01, 3);
  for (int r : {1, 2}) {  // the first slot's friction rows boxed at +-0.5 rather than a cone
    boxed.bound_row[r] = -1;
    boxed.cone[r] = 0;
    boxed.lo[r] = L(-0.5f);
    boxed.hi[r] = L(0.5f);
  }
  ASSERT_FALSE(is_contact_slots(boxed));
  expect_each_alone(boxed, contact_slot_problem<L>(2, 0.01, 4), "boxed rows and contacts");
}

// A positional row 0.05 from its limit, approaching at 10 per second over a
// step of 0.01: TGS lets it close the gap exactly and stops there, PGS the
// same in one sweep (the speculative target -e/dt).
TEST(RowSolver, TgsAndPgsCloseAGapExactly) {
  for (bool tgs : {false, true}) {
    RowBlock<double> rows(1);
    rows.D = {0.5};
    rows.v_free = {-10.0};
    rows.error = {0.05};
    rows.positional[0] = 1;
    rows.rate = {0.2 / 0.01};
    rows.target = {positional_target(0.05, 1.0 / 0.01, rows.rate[0])};
    rows.target_hi = rows.target;
    rows.lo = {0.0};
    rows.hi = {kInf};
    rows.lambda = {0.0};
    if (tgs) {
      tgs_solve(rows, 4, 0.01);
      // displacement over the step: the gap, never more
      EXPECT_NEAR(rows.displacement[0], -0.05, 1e-15);
    } else {
      pgs_solve(rows, 1);
      EXPECT_NEAR(-10.0 + 0.5 * rows.lambda[0], -5.0, 1e-12);  // v = -e/dt
    }
  }
}

// A normal row and a cone pair, uncoupled (D = I) so one sweep solves it:
// the normal row settles at lambda_n = 1; the friction pair's unclamped
// impulse -(3, 4) is longer than mu lambda_n = 0.5, so it is scaled onto the
// circle, -(0.3, 0.4), keeping its direction (a pyramid would give
// -(0.5, 0.5)); a small slip -(0.03, 0.04) lies inside and sticks.
TEST(RowSolver, ConePairProjectsRadially) {
  for (double slip : {1.0, 0.01}) {
    RowBlock<double> rows(3);
    rows.D = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    rows.v_free = {-1.0, 3.0 * slip, 4.0 * slip};
    rows.target = {0.0, 0.0, 0.0};
    rows.target_hi = rows.target;
    rows.lo = {0.0, -kInf, -kInf};
    rows.hi = {kInf, kInf, kInf};
    rows.bound_row[1] = rows.bound_row[2] = 0;
    rows.mu[1] = rows.mu[2] = 0.5;
    rows.cone[1] = 1;
    rows.lambda = {0.0, 0.0, 0.0};
    pgs_solve(rows, 2);
    EXPECT_NEAR(rows.lambda[0], 1.0, 1e-15);
    const double scale = slip == 1.0 ? 0.1 : 1.0;
    EXPECT_NEAR(rows.lambda[1], -3.0 * slip * scale, 1e-15) << "slip " << slip;
    EXPECT_NEAR(rows.lambda[2], -4.0 * slip * scale, 1e-15) << "slip " << slip;
  }
}

// A positional row with a floor (restitution's bounce velocity): the target
// is the floor when that is above the positional target, for PGS as set by
// the caller and for TGS as re-evaluated at every substep.
TEST(RowSolver, FloorLiftsAPositionalTarget) {
  RowBlock<double> rows(1);
  rows.D = {0.5};
  rows.v_free = {-2.0};
  rows.error = {0.001};
  rows.positional[0] = 1;
  rows.rate = {20.0};
  rows.floor = {1.0};
  rows.target = rows.target_hi = {1.0};
  rows.lo = {0.0};
  rows.hi = {kInf};
  rows.lambda = {0.0};
  tgs_solve(rows, 4, 0.01);
  EXPECT_NEAR(rows.v_free[0] + rows.D[0] * rows.lambda[0], 1.0, 1e-12);
  EXPECT_NEAR(rows.displacement[0], 0.01, 1e-12);  // every substep moved at the floor velocity 1
}

// A band row (a velocity limit, |v| <= 1) next to a row that pushes its
// joint: the band holds from either side, whichever way the free motion goes.
TEST(RowSolver, BandRowHoldsBothSides) {
  for (double push : {-4.0, 4.0}) {
    RowBlock<double> rows(2);
    rows.D = {1.0, 0.5, 0.5, 1.0};
    rows.v_free = {0.0, 0.2};
    rows.target = {push, -1.0};  // row 0: an equality pushing to v0 = push, dragging row 1 along
    rows.target_hi = {push, 1.0};
    rows.lo = {-kInf, -kInf};
    rows.hi = {kInf, kInf};
    rows.lambda = {0.0, 0.0};
    pgs_solve(rows, 100);
    const double v0 = rows.v_free[0] + rows.D[0] * rows.lambda[0] + rows.D[1] * rows.lambda[1];
    const double v1 = rows.v_free[1] + rows.D[2] * rows.lambda[0] + rows.D[3] * rows.lambda[1];
    EXPECT_NEAR(v0, push, 1e-12);
    EXPECT_NEAR(v1, push > 0 ? 1.0 : -1.0, 1e-12) << "push " << push;
  }
}

}  // namespace
}  // namespace lockstep
