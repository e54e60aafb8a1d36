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
// normal row 1 (v1 >= 1) and a friction row 2 bounded by it, in lanes where
// row 0's target is far below (slack) or above (it must push) its velocity.
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

// PGS (40 sweeps) or TGS (40 substeps of 0.01 s) on rows [first, m);
// returns the lanes where rows [0, first) stayed slack.
template <class L>
lane::mask_t<L> solve_rows_from(RowBlock<L>& rows, bool tgs, int first) {
  if (tgs) return tgs_solve(rows, 40, 0.4, first);
  pgs_solve(rows, 40, first);
  return rows_slack(rows, first);
}

// Lanes whose joint row stays slack take the contacts-only solve (and it
// solves the whole problem); the others take the full solve, bit for bit
// as the solver gives it, whatever their neighbours; PGS and TGS.
TEST(RowSolver, SlackFirstSolvesEachLaneOnItsOwn) {
  using L = lane::simd<double>;
  constexpr int W = static_cast<int>(lane::width_v<L>);
  std::vector<double> targets(W);
  for (int l = 0; l < W; ++l) targets[l] = l % 2 ? 3.0 : -50.0;  // odd lanes: row 0 must push
  for (bool tgs : {false, true}) {
    RowBlock<L> two_phase = joint_and_contact_problem<L>(targets);
    std::vector<L> start(3), partial(6);
    auto solve = [&](int first) { return solve_rows_from(two_phase, tgs, first); };
    two_phase.D[0] = L(std::numeric_limits<double>::quiet_NaN());  // phase one reads no D among rows [0, 1)
    const lane::mask_t<L> slack = slack_first_phase(two_phase, 1, start, solve);
    two_phase.D[0] = L(1.5);
    slack_second_phase(two_phase, slack, start, partial, solve);
    for (int l = 0; l < W; ++l) {
      RowBlock<double> full = joint_and_contact_problem<double>({targets[l]});
      RowBlock<double> contacts_only = joint_and_contact_problem<double>({targets[l]});
      solve_rows_from(full, tgs, 0);
      contacts_only.lambda[0] = 0;
      solve_rows_from(contacts_only, tgs, 1);
      const RowBlock<double>& expected = l % 2 ? full : contacts_only;
      for (int r = 0; r < 3; ++r) {
        EXPECT_EQ(two_phase.lambda[r].get(l), expected.lambda[r]) << (tgs ? "TGS" : "PGS") << " lane " << l;
        EXPECT_NEAR(two_phase.lambda[r].get(l), full.lambda[r], 1e-9) << (tgs ? "TGS" : "PGS") << " lane " << l;
        if (tgs) EXPECT_EQ(two_phase.lambda_sum[r].get(l), expected.lambda_sum[r]) << "lane " << l << " row " << r;
      }
      EXPECT_EQ(two_phase.lambda[0].get(l) > 0, l % 2 == 1) << "lane " << l;
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
