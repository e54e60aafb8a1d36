// StepOptions::conserve_linear_momentum (batch/step_momentum.cpp): a
// floating articulation's linear momentum changes by exactly the impulse of
// the external forces on it, step by step: gravity, link wrenches, a force on
// the base, the ground's contacts. Without it, semi-implicit Euler lets the
// momentum drift by O(h) over a time; those drifts are measured here too, so
// that the tests show the projection doing the work.
#include "batch/copy_dynamics.hpp"
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace lockstep::test {
namespace {

// anymal_b's leg joints under PD (kp 300, kd 8), as the standing tests drive them.
std::vector<DofSettings> leg_drives(const Model& model) {
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 6; k < model.nv; ++k) dofs[k].drive_stiffness = 300, dofs[k].drive_damping = 8;
  return dofs;
}

// anymal_b's velocity thrown and spinning: the base's twist, legs still.
Eigen::VectorXd thrown(const Model& model) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
  v.head<6>() << 0.3, -0.2, 0.1, 0.5, -1.0, 2.0;
  return v;
}

// The stance with every leg joint bent 1.8 times as far.
Eigen::VectorXd crouch(const Model& model) {
  Eigen::VectorXd q = stance(model);
  for (int k = 7; k < model.nq; ++k) q[k] *= 1.8;
  return q;
}

StepOptions options(Precision precision, bool conserve) {
  StepOptions o;
  o.precision = precision;
  o.conserve_linear_momentum = conserve;
  return o;
}

// anymal_b falling freely while its PD drives swing the legs towards a
// crouch, a wrench pushing one foot and a force on the base: after each
// step, P(q1, v1) - P(q0, v0) = h (m g + F_wrench + R0 f_base). Returns the
// worst error of that balance over 0.5 s, relative to |P| at the end.
double free_fall_balance_error(Precision precision, bool conserve) {
  const Model model = load_shared_model("anymal_b", true);
  const std::vector<DofSettings> dofs = leg_drives(model);
  const StepOptions o = options(precision, conserve);
  Simulator sim(model, 1, o, dofs);
  const Eigen::VectorXd stand = stance(model);
  sim.set_state(0, stand, thrown(model));
  sim.set_drive_target(0, crouch(model), Eigen::VectorXd::Zero(model.nv));
  const int foot = model.nbody - 1;
  const Eigen::Vector3d foot_force(3.0, -2.0, 5.0), base_force(-4.0, 1.0, 2.0);
  sim.set_link_wrench(0, foot, (Eigen::Matrix<double, 6, 1>() << foot_force, 0.5, 0.0, -0.2).finished());
  Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
  tau.head<3>() = base_force;  // on the Free joint's linear DOFs: body axes
  sim.set_torque(0, tau);
  const CopyDynamics dyn(model);
  const double mass = model.total_mass();
  double worst = 0, scale = 0;
  for (int i = 0; i < 250; ++i) {
    const Eigen::VectorXd q0 = sim.q(0);
    const Eigen::Vector3d p0 = dyn.linear_momentum(q0, sim.v(0));
    sim.step();
    const Eigen::Matrix3d R0 = Eigen::Quaterniond(q0[3], q0[4], q0[5], q0[6]).normalized().toRotationMatrix();
    const Eigen::Vector3d impulse = o.dt * (mass * model.gravity + foot_force + R0 * base_force);
    const Eigen::Vector3d p1 = dyn.linear_momentum(sim.q(0), sim.v(0));
    worst = std::max(worst, (p1 - p0 - impulse).norm());
    scale = p1.norm();
  }
  EXPECT_EQ(sim.fault(0), Fault::None);
  EXPECT_GT((sim.q(0).tail(12) - stand.tail(12)).norm(), 0.3) << "the legs moved";
  return worst / scale;
}

// Measured: per-step balance error / |P| without the projection 3.1e-4
// (double and float alike: it is the integrator's), with it 5.4e-16 (double)
// and 1.7e-7 (float). Asserted: with it, 1e-12 in double and 1e-6 in float
// (rounding of 13 bodies' momenta, a few eps of |P|); without it, above 1e-5,
// so the scene does exercise the drift the projection removes.
TEST(MomentumProjection, FreeFallChangesMomentumByTheExternalImpulseOnly) {
  for (Precision precision : {Precision::Double, Precision::Float}) {
    const double with = free_fall_balance_error(precision, true), without = free_fall_balance_error(precision, false);
    std::cout << "[ measured ] " << precision_name(precision) << ": balance error " << with << " with the projection, "
              << without << " without\n";
    EXPECT_LT(with, precision == Precision::Double ? 1e-12 : 1e-6) << precision_name(precision);
    EXPECT_GT(without, 1e-5) << precision_name(precision);
  }
}

// anymal_b in flight without gravity for 40 s, thrown and spinning, its
// legs swung between the stance and a crouch every 0.25 s: its momentum
// must stay what it was thrown with. In float the base's velocity takes a
// correction only to ulp(v), and the rows' impulses added to v0 rounded at
// ulp(P): without the remainder carried from step to step and the impulse
// summed on its own, those roundings went the same way along the smooth
// motion and the momentum drifted (measured: 9.8e-6 of |P| over the first
// 10 s, and 4.0e-6 over the 150 steps of
// ContactPrecision.ProjectionKeepsMomentumOverTheWholeCollision).
// What is left is the float evaluation of the momentum itself: the step
// keeps its own float sum of the 13 bodies' momenta exactly, and that sum
// differs from the exact momentum of the same state by a few ulps of its
// terms (each up to about |P| with the spin, turned through up to five
// joint rotations); BatchDynamics' float momentum of the same states errs
// by up to 4.5e-7. It does not grow: measured worst deviation 1.0e-6 of
// |P| after 10 s, 1.5e-6 after 20 s and 1.6e-6 from 25 s to 80 s (double:
// 1.8e-15 to 3.7e-15). Asserted over 40 s: 1e-12 in double, 2.5e-6 in
// float, a quarter of the old drift's in its first 10 s.
TEST(MomentumProjection, FlightKeepsItsMomentumToRoundingForLong) {
  const Model model = load_shared_model("anymal_b", true);
  const CopyDynamics dyn(model);
  for (Precision precision : {Precision::Double, Precision::Float}) {
    Simulator sim(model, 1, options(precision, true), leg_drives(model));
    sim.set_gravity(0, Eigen::Vector3d::Zero());
    const Eigen::VectorXd stand = stance(model), bent = crouch(model);
    sim.set_state(0, stand, thrown(model));
    const Eigen::Vector3d p0 = dyn.linear_momentum(sim.q(0), sim.v(0));
    double worst = 0;
    for (int i = 0; i < 20000; ++i) {
      if (i % 125 == 0) sim.set_drive_target(0, (i / 125) % 2 ? stand : bent, Eigen::VectorXd::Zero(model.nv));
      sim.step();
      worst = std::max(worst, (dyn.linear_momentum(sim.q(0), sim.v(0)) - p0).norm() / p0.norm());
    }
    EXPECT_EQ(sim.fault(0), Fault::None);
    std::cout << "[ measured ] " << precision_name(precision) << ": momentum deviation over 40 s of flight " << worst
              << " of |P|\n";
    EXPECT_LT(worst, precision == Precision::Double ? 1e-12 : 2.5e-6) << precision_name(precision);
  }
}

// The remainder is state: a snapshot carries it, and a restored copy
// replays bit for bit (without it, the replay's momentum corrections differ
// in the last bits and so does its trajectory); a reset clears it.
TEST(MomentumProjection, SnapshotCarriesTheRemainder) {
  const Model model = load_shared_model("anymal_b", true);
  Simulator sim(model, 1, options(Precision::Float, true), leg_drives(model));
  sim.set_state(0, stance(model), thrown(model));
  sim.set_drive_target(0, crouch(model), Eigen::VectorXd::Zero(model.nv));
  sim.step(100);
  const CopySnapshot saved = sim.snapshot(0);
  ASSERT_EQ(saved.momentum_remainder.size(), 3) << "one floating articulation";
  EXPECT_GT(saved.momentum_remainder.norm(), 0) << "float leaves some correction to carry";
  sim.step(100);
  const CopySnapshot first = sim.snapshot(0);
  sim.restore(0, saved);
  sim.step(100);
  const CopySnapshot again = sim.snapshot(0);
  EXPECT_TRUE(same_bits(first.q, again.q));
  EXPECT_TRUE(same_bits(first.v, again.v));
  EXPECT_TRUE(same_bits(first.momentum_remainder, again.momentum_remainder));
  CopySnapshot without = saved;
  without.momentum_remainder.setZero();
  sim.restore(0, without);
  sim.step(100);
  EXPECT_FALSE(same_bits(first.v, sim.v(0))) << "the remainder changes the trajectory";
  sim.reset(0);
  EXPECT_EQ(sim.snapshot(0).momentum_remainder.norm(), 0);
  // across the option: none to carry, and nothing refused
  Simulator plain(model, 1, options(Precision::Float, false), leg_drives(model));
  plain.restore(0, saved);
  EXPECT_TRUE(same_bits(plain.q(0), saved.q));
  EXPECT_EQ(plain.snapshot(0).momentum_remainder.size(), 0);
  sim.restore(0, plain.snapshot(0));
  EXPECT_EQ(sim.snapshot(0).momentum_remainder.norm(), 0);
}

// A copy that faults restarts with reset_on_fault as a fresh one, with no
// remainder left from the motion it had.
TEST(MomentumProjection, ResetOnFaultClearsTheRemainder) {
  const Model model = load_shared_model("anymal_b", true);
  StepOptions o = options(Precision::Float, true);
  o.reset_on_fault = true;
  Simulator sim(model, 1, o, leg_drives(model));
  const Eigen::VectorXd v0 = thrown(model);
  sim.set_state(0, stance(model), v0);
  sim.step(100);
  ASSERT_GT(sim.snapshot(0).momentum_remainder.norm(), 0);
  Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
  tau[8] = std::nan("");
  sim.set_torque(0, tau);
  sim.step();
  EXPECT_EQ(sim.fault(0), Fault::NonFiniteTorque);
  EXPECT_TRUE(same_bits(sim.v(0), v0.cast<float>().cast<double>())) << "restarted";
  EXPECT_EQ(sim.snapshot(0).momentum_remainder.norm(), 0);
}

// anymal_b standing on the ground under PD: the momentum changes by
// h m g plus the contacts' impulses on its feet (Simulator::contacts), to
// rounding, while it stands as well as without the projection.
TEST(MomentumProjection, StandingChangesMomentumByGravityAndTheContacts) {
  const Model model = load_shared_model("anymal_b", true);
  const std::vector<DofSettings> dofs = leg_drives(model);
  StepOptions o = options(Precision::Double, true);
  o.contacts.ground = true;
  Simulator sim(model, 1, o, dofs);
  const Eigen::VectorXd target = stance(model);
  Eigen::VectorXd q = target;
  q[2] -= 0.05;
  sim.set_state(0, q, Eigen::VectorXd::Zero(model.nv));
  sim.set_drive_target(0, target, Eigen::VectorXd::Zero(model.nv));
  const CopyDynamics dyn(model);
  const double mass = model.total_mass();
  double worst = 0;
  int touching = 0;
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d p0 = dyn.linear_momentum(sim.q(0), sim.v(0));
    sim.step();
    Eigen::Vector3d contact = Eigen::Vector3d::Zero();
    for (const Contact& c : sim.contacts(0)) {
      ASSERT_LT(c.body_a, 0) << "only the ground touches";
      contact += c.force;
    }
    touching += contact.norm() > 0;
    const Eigen::Vector3d impulse = o.dt * (mass * model.gravity + contact);
    worst = std::max(worst, (dyn.linear_momentum(sim.q(0), sim.v(0)) - p0 - impulse).norm() / (mass * 9.81 * o.dt));
  }
  std::cout << "[ measured ] standing: balance error " << worst << " of m g h\n";
  EXPECT_GE(touching, 800) << "steps with the feet on the ground (it lands within 0.2 s)";
  EXPECT_LT(worst, 1e-9);
  EXPECT_EQ(sim.fault(0), Fault::None);
  EXPECT_NEAR(sim.q(0)[2], target[2], 0.02) << "standing after 2 s";
}

TEST(MomentumProjection, RefusesWhatItCannotKeepExact) {
  const Model model = load_shared_model("anymal_b", true);
  StepOptions rk4 = options(Precision::Double, true);
  rk4.integrator = Integrator::RK4;
  expect_invalid([&] { Simulator sim(model, 1, rk4); }, "conserve_linear_momentum needs the semi-implicit Euler");
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[3].damping = 0.1;
  expect_invalid([&] { Simulator sim(model, 1, options(Precision::Double, true), dofs); },
                 "DOF 3 (" + model.dof_name[3] + "): conserve_linear_momentum needs a floating base without damping");
  Simulator sim(model, 1, options(Precision::Double, true));
  Eigen::VectorXd armature = Eigen::VectorXd::Zero(model.nv);
  armature[8] = 0.01;  // a leg joint's: fine
  sim.set_armature(0, armature);
  armature[1] = 0.01;
  expect_invalid([&] { sim.set_armature(0, armature); }, "set_armature: DOF 1");
  expect_invalid([&] { sim.set_joint_damping(0, armature); }, "set_joint_damping: DOF 1");
}

}  // namespace
}  // namespace lockstep::test
