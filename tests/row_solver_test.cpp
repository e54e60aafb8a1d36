// The constraint solver alone, on small problems with known solutions: a
// one-sided row, a boxed row, a friction row bounded by a normal row's
// impulse, and a friction cone pair (the coupling contacts use).
#include "kernels/row_solver.hpp"

#include <gtest/gtest.h>

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
