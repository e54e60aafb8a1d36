// A spherical joint's limits on each component of its rotation vector
// r = log(q) (DofSettings lower/upper; docs/conventions.md), the articulated
// actors reference's per-DoF limits and PhysX's limited swing and twist
// axes: spring-dampers with limit_stiffness > 0, hard solver rows with 0.
#include "tests/sim_support.hpp"

#include <gtest/gtest.h>

namespace lockstep::test {
namespace {

StepOptions double_step() {
  StepOptions o;
  o.precision = Precision::Double;
  o.record_applied_torque = true;
  return o;
}

// The rotation vector of a unit quaternion (w x y z).
Eigen::Vector3d rotation_vector(const Eigen::VectorXd& q) {
  const Eigen::AngleAxisd turn(Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized());
  return turn.angle() * turn.axis();
}

// The spherical tree's six ball DOFs limited to +-0.3 rad (with the given
// limit stiffness and damping), 11 copies swinging from rest pose at up to
// 3 rad/s per DOF without gravity for 1 s: the deepest |r_k| any copy
// reaches. The SIMD lanes must reproduce the scalar reference bit for bit.
double deepest_swing(StepOptions o, double limit_stiffness, double limit_damping) {
  const Model model = spherical_tree(true);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  std::vector<int> ball_dofs;
  for (int k = 0; k < model.nv; ++k)
    if (model.body_joint[model.dof_body[k]] == JointType::Spherical) {
      dofs[k].lower = -0.3, dofs[k].upper = 0.3;
      dofs[k].limit_stiffness = limit_stiffness, dofs[k].limit_damping = limit_damping;
      ball_dofs.push_back(k);
    }
  EXPECT_EQ(ball_dofs.size(), 6u);
  Simulator simd(model, 11, o, dofs);
  o.lanes = Lanes::Scalar;
  Simulator scalar(model, 11, o, dofs);
  const std::string plan = limit_stiffness > 0 ? "soft limits: runs (6 DOFs with spring-damper limits)"
                                               : "hard limits: runs (6 DOFs";
  EXPECT_NE(simd.describe_plan().find(plan), std::string::npos) << simd.describe_plan();
  std::mt19937 rng(4);
  for (int c = 0; c < 11; ++c) {
    Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
    for (int k : ball_dofs) v[k] = random_vector(1, rng, 3.0)[0];
    for (Simulator* sim : {&simd, &scalar}) {
      sim->set_gravity(c, Eigen::Vector3d::Zero());
      sim->set_state(c, model.neutral_configuration(), v);
    }
  }
  double deepest = 0;
  for (int i = 0; i < 500; ++i) {
    simd.step();
    scalar.step();
    for (int c = 0; c < 11; ++c)
      for (int b = 0; b < model.nbody; ++b)
        if (model.body_joint[b] == JointType::Spherical)
          deepest = std::max(deepest, rotation_vector(simd.q(c).segment<4>(model.body_q_offset[b])).cwiseAbs().maxCoeff());
  }
  for (int c = 0; c < 11; ++c) EXPECT_TRUE(same_state(simd, c, scalar, c)) << "copy " << c;
  return deepest;
}

// The ball joint (COM on the joint: no gravity torque) pushed by a constant
// torque against limits on two of its components comes to rest where each
// limit's spring balances its component of the torque: r_k = limit_k +
// tau_k / k. At rest the balance is exact, whatever the turn's axes.
// Measured after 10 s: r within 6e-17 of that, |v| 9e-15, the passive torque
// balancing the push to 2e-30. Asserted: 1e-12, a rounding of r (1e-16)
// times the stiffness 100 with room for the settling that remains.
TEST(SphericalLimits, AJointPushedAgainstItsLimitsRestsWhereTheSpringsBalanceTheTorque) {
  const Model model = ball_joint();
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.limit_stiffness = 100.0, d.limit_damping = 0.5, d.damping = 0.05;
  dofs[0].lower = -0.2, dofs[0].upper = 1.0;   // x pushed below its lower limit
  dofs[1].lower = -1.0, dofs[1].upper = 0.25;  // y above its upper one
  dofs[2].lower = dofs[2].upper = 0.0;  // z held at 0 (free, the turns about x and y would carry it along)
  Simulator sim(model, 1, double_step(), dofs);
  const Eigen::Vector3d torque(-0.4, 0.6, 0.0);
  sim.set_torque(0, torque);
  sim.step(5000);  // 10 s
  const Eigen::Vector3d r = rotation_vector(sim.q(0));
  EXPECT_NEAR(r.x(), -0.2 + torque.x() / 100.0, 1e-12);
  EXPECT_NEAR(r.y(), 0.25 + torque.y() / 100.0, 1e-12);
  EXPECT_NEAR(r.z(), 0.0, 1e-12);
  EXPECT_LT(sim.v(0).norm(), 1e-12);
  // the springs' torque is the passive source, and it balances the push
  EXPECT_LT((sim.applied_torque(0).passive + torque).norm(), 1e-12);
}

// Within its range the joint turns freely: the limits give no torque.
TEST(SphericalLimits, WithinTheRangeTheyGiveNothing) {
  const Model model = ball_joint();
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.lower = -0.5, d.upper = 0.5, d.limit_stiffness = 1000.0, d.limit_damping = 5.0;
  Simulator limited(model, 1, double_step(), dofs), free(model, 1, double_step());
  const Eigen::Vector3d v(0.3, -0.2, 0.4);
  for (Simulator* sim : {&limited, &free}) sim->set_state(0, model.neutral_configuration(), v);
  for (int i = 0; i < 100; ++i) {  // 0.2 s: at most 0.08 rad about any axis
    limited.step();
    free.step();
    ASSERT_EQ(limited.applied_torque(0).passive.norm(), 0.0) << "step " << i;
  }
  EXPECT_TRUE(same_state(limited, 0, free, 0));
}

// A joint swinging into a stiff, damped limit stops there and comes back
// inside the range (plus the spring's give), in float and double, and the
// SIMD lanes reproduce the scalar reference bit for bit.
TEST(SphericalLimits, ASwingIntoAStiffLimitStopsAtItInEveryLane) {
  for (Precision precision : {Precision::Double, Precision::Float}) {
    StepOptions o;
    o.precision = precision;
    const double deepest = deepest_swing(o, 2000.0, 10.0);
    // up to 3 rad/s into a limit of 2000 N m/rad on links of about 0.03 kg m^2:
    // the swing stops within 0.1 rad past it
    EXPECT_GT(deepest, 0.3) << precision_name(precision) << ": the swings reached the limits";
    EXPECT_LT(deepest, 0.4) << precision_name(precision);
  }
}

// ---- Hard limits (limit_stiffness 0): a one-sided solver row per DOF ----

// The ball joint pushed by a constant torque against hard limits on two of
// its components comes to rest on them, r_k = limit_k, and the rows' torque
// balances the push. At rest the rows' first-order Jacobian (J = e_k where
// r' = J_r(r)^-1 w) does not enter: the limits hold to rounding. Measured
// after 10 s: double |r_k - limit_k| <= 5.6e-17, |v| 5.6e-15, balance
// 2.9e-15; float 5.5e-8 (two ulps of 0.25), 3.0e-6 and 1.5e-6 (20 ulps of
// the 0.72 N m push: float's rounding of the rows' impulses each step).
// Asserted: double 1e-14, 1e-12, 1e-12; float 2e-7, 1e-5, 1e-5.
TEST(SphericalLimits, AJointPushedAgainstHardLimitsRestsOnThem) {
  const Model model = ball_joint();
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.damping = 0.5, d.lower = -1.0, d.upper = 1.0;
  dofs[0].lower = -0.2;  // x pushed below its lower limit
  dofs[1].upper = 0.25;  // y above its upper one
  const Eigen::Vector3d torque(-0.4, 0.6, 0.0);
  for (Precision precision : {Precision::Double, Precision::Float})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      const bool dbl = precision == Precision::Double;
      StepOptions o;
      o.precision = precision;
      o.solver = solver;
      o.record_applied_torque = true;
      Simulator sim(model, 1, o, dofs);
      EXPECT_NE(sim.describe_plan().find("hard limits: runs (3 DOFs"), std::string::npos) << sim.describe_plan();
      sim.set_torque(0, torque);
      sim.step(5000);  // 10 s
      const Eigen::Vector3d r = rotation_vector(sim.q(0));
      const std::string what = std::string(precision_name(precision)) + " " + solver_name(solver);
      EXPECT_NEAR(r.x(), -0.2, dbl ? 1e-14 : 2e-7) << what;
      EXPECT_NEAR(r.y(), 0.25, dbl ? 1e-14 : 2e-7) << what;
      EXPECT_LT(sim.v(0).norm(), dbl ? 1e-12 : 1e-5) << what;
      // the rows' torque is the limits source, and it balances the push
      EXPECT_LT((sim.applied_torque(0).limits + torque).norm(), dbl ? 1e-12 : 1e-5) << what;
    }
}

// Joints swinging at up to 3 rad/s about each axis into hard limits of
// +-0.3 rad stop at them. The rows are speculative, so a component of r
// passes its limit only by what their first-order Jacobian misjudges of its
// motion within one step: r' = J_r(r)^-1 w = w + (r x w) / 2 + O(|r|^2 |w|),
// at most |r| |w| h / 2 = 0.52 x 5.2 x 0.002 / 2 = 2.7e-3 rad here (|r| <=
// 0.3 sqrt 3, |w| <= 3 sqrt 3), which the next step's row takes back.
// Measured deepest: 0.30280 (PGS) and 0.30293 (TGS), in double and float
// alike; asserted 0.3 + 1.1 x 2.7e-3. The SIMD lanes reproduce the scalar
// reference bit for bit.
TEST(SphericalLimits, SwingsIntoHardLimitsStopAtThemInEveryLane) {
  for (Precision precision : {Precision::Double, Precision::Float})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      const std::string what = std::string(precision_name(precision)) + " " + solver_name(solver);
      StepOptions o;
      o.precision = precision;
      o.solver = solver;
      const double deepest = deepest_swing(o, 0.0, 0.0);
      EXPECT_GT(deepest, 0.3 - 1e-6) << what << ": the swings reached the limits";
      EXPECT_LT(deepest, 0.3 + 1.1 * 2.7e-3) << what;
    }
}

}  // namespace
}  // namespace lockstep::test
