// Stiff drives: the driven DOFs whose implicit drive reaches its target
// within one (sub)step, and the line describe_plan gives them beside hard
// constraints (PhysX's "Articulation Drive Stability").
#include "batch/stiff_drives.hpp"
#include "tests/sim_support.hpp"

#include <gtest/gtest.h>

namespace lockstep::test {
namespace {

constexpr double kInertia = 0.01;  // the spinner's moment of inertia about its joint [kg m^2]

// kp 400 N m/rad on a 0.01 kg m^2 wheel at h = 0.01 s: kp h^2 / I = 4.
std::vector<DofSettings> driven(const Model& model, DriveType type, double kp) {
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = kp;
  dofs[0].drive_damping = 1.0;
  dofs[0].drive_type = type;
  return dofs;
}

// Options of a double-precision step of h with `integrator`.
StepOptions double_step(Integrator integrator, double h) {
  StepOptions o;
  o.dt = h;
  o.integrator = integrator;
  o.precision = Precision::Double;
  return o;
}

TEST(StiffDrives, ForceDriveRatioIsItsImplicitInertiaOverTheJoints) {
  const Model model = spinner(kInertia);
  const Eigen::VectorXd q = model.neutral_configuration();
  const std::vector<StiffDrive> stiff = stiff_drives(model, driven(model, DriveType::Force, 400.0), q, 0.01);
  ASSERT_EQ(stiff.size(), 1u);
  EXPECT_EQ(stiff[0].dof, 0);
  EXPECT_NEAR(stiff[0].ratio, 4.0, 1e-12);
  // a quarter of the step: a sixteenth of the ratio, below 1
  EXPECT_TRUE(stiff_drives(model, driven(model, DriveType::Force, 400.0), q, 0.0025).empty());
  // no gain, no drive
  EXPECT_TRUE(stiff_drives(model, default_dof_settings(model), q, 0.01).empty());
}

TEST(StiffDrives, AccelerationDriveRatioIsKpHSquared) {
  const Model model = spinner(kInertia);
  const Eigen::VectorXd q = model.neutral_configuration();
  // kp [1/s^2] h^2 = 2.5e4 * 1e-4 = 2.5, whatever the inertia
  const std::vector<StiffDrive> stiff = stiff_drives(model, driven(model, DriveType::Acceleration, 2.5e4), q, 0.01);
  ASSERT_EQ(stiff.size(), 1u);
  EXPECT_NEAR(stiff[0].ratio, 2.5, 1e-12);
  EXPECT_TRUE(stiff_drives(model, driven(model, DriveType::Acceleration, 400.0), q, 0.01).empty());
}

Simulator driven_simulator(const Model& model, int substeps) {
  StepOptions o;
  o.dt = 0.01;
  o.substeps = substeps;
  return Simulator(model, 1, o, driven(model, DriveType::Force, 400.0));
}

std::string plan_text(const Model& model, int substeps) { return driven_simulator(model, substeps).describe_plan(); }

TEST(StiffDrives, TheSimulatorListsThemBesideHardConstraintsAtItsSubstep) {
  const Model limited = spinner(kInertia, -1.0, 1.0), free = spinner(kInertia);
  const std::vector<StiffDrive> stiff = driven_simulator(limited, 1).stiff_drives();
  ASSERT_EQ(stiff.size(), 1u);
  EXPECT_NEAR(stiff[0].ratio, 4.0, 1e-12);
  EXPECT_TRUE(driven_simulator(limited, 4).stiff_drives().empty());
  EXPECT_TRUE(driven_simulator(free, 1).stiff_drives().empty());
}

TEST(StiffDrives, ThePlanNamesThemBesideHardLimitsOnly) {
  const Model limited = spinner(kInertia, -1.0, 1.0);
  const std::string text = plan_text(limited, 1);
  const std::string line = "  stiff drives: 1 DOF(s) close half or more of their position error in one step (kp h^2 / "
                           "M_kk 4 at " + limited.dof_name[0] + ")";
  EXPECT_NE(text.find(line), std::string::npos) << text;
  // in 4 substeps the ratio is 0.25
  EXPECT_EQ(plan_text(limited, 4).find("stiff drives"), std::string::npos) << plan_text(limited, 4);
  // alone, an implicit drive is stable at any gain: nothing to say
  const Model free = spinner(kInertia);
  EXPECT_EQ(plan_text(free, 1).find("stiff drives"), std::string::npos) << plan_text(free, 1);
}

// Joint modes too fast for the step. The wheel's drive, kp 400 and kd 1 on
// I = 0.01, is an underdamped mode of |lambda| = sqrt(kp / I) = 200 rad/s:
// h |lambda| = 2 at h = 0.01 (within RK4's bound, about 2.8) and 4 at
// h = 0.02. With damping 10 more, b = 1100 / s and c = 4e4 / s^2: the fast
// real root (b + sqrt(b^2 - 4c)) / 2 = 1062 / s, h |lambda| 10.6 at 0.01.
// RK4, which takes them explicitly, is warned exactly where it diverges:
// the warned cases fault within 2 s, the other holds the wheel on its
// target. The trapezoid (implicit trapezoidal rule) stays bounded at any
// gain but rings: kp 1e5, kd 2 sqrt(kp I) = 63 (critical) gives a double
// root at 3162 / s, h |lambda| 31.6 at 0.01, and an error that changes
// sign every step and shrinks towards (x/2 - 1) / (x/2 + 1) = 0.88 per
// step (the double root's n z^n: 0.91 after 40 steps, 0.013 rad left of
// the 0.5 rad); warned, while semi-implicit Euler settles it exactly and
// says nothing.
TEST(StiffDrives, Rk4AndTheTrapezoidWarnOfModesTooFastForTheirStep) {
  const Model wheel = spinner(kInertia);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(1);
  std::vector<DofSettings> damped = driven(wheel, DriveType::Force, 400.0);
  damped[0].damping = 10.0;
  struct Case {
    std::vector<DofSettings> dofs;
    double h, ratio;
  };
  const Case cases[] = {{driven(wheel, DriveType::Force, 400.0), 0.01, 0.0},
                        {driven(wheel, DriveType::Force, 400.0), 0.02, 4.0},
                        {damped, 0.01, 10.6235}};
  auto run = [&](Integrator integrator, const std::vector<DofSettings>& dofs, double h) {
    Simulator sim(wheel, 1, double_step(integrator, h), dofs);
    sim.set_drive_target(0, Eigen::VectorXd::Constant(1, 0.5), Eigen::VectorXd::Zero(1));
    sim.step(static_cast<int>(std::lround(2.0 / h)));
    return sim;
  };
  for (const Case& c : cases) {
    const std::vector<StiffDrive> fast = fast_joint_modes(wheel, c.dofs, q, c.h, kRk4Bound);
    const Simulator sim = run(Integrator::RK4, c.dofs, c.h);
    const std::vector<std::string> warnings = sim.warnings();
    if (c.ratio == 0) {
      EXPECT_TRUE(fast.empty()) << "h " << c.h;
      EXPECT_TRUE(warnings.empty()) << warnings.front();
      EXPECT_EQ(sim.fault(0), Fault::None);
      EXPECT_NEAR(sim.q(0)[0], 0.5, 1e-3);
      continue;
    }
    ASSERT_EQ(fast.size(), 1u) << "h " << c.h;
    EXPECT_NEAR(fast[0].ratio, c.ratio, 1e-4);
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("RK4 takes drives, springs and damping (link damping too) explicitly"), std::string::npos)
        << warnings[0];
    // diverged: non-finite, or 6.7e87 rad after 2 s undamped at h = 0.02
    // (that copy turned non-finite only where the joint's sin and cos once
    // left the unit circle)
    EXPECT_FALSE(std::abs(sim.q(0)[0]) < 1e6) << "h " << c.h << ": diverged to " << sim.q(0)[0];
  }
  std::vector<DofSettings> stiff = driven(wheel, DriveType::Force, 1e5);
  stiff[0].drive_damping = 2 * std::sqrt(1e5 * kInertia);
  const std::vector<StiffDrive> ringing = fast_joint_modes(wheel, stiff, q, 0.01, kTrapezoidRingBound);
  ASSERT_EQ(ringing.size(), 1u);
  EXPECT_NEAR(ringing[0].ratio, 31.6228, 1e-4);
  Simulator trapezoid(wheel, 1, double_step(Integrator::Trapezoid, 0.01), stiff);
  trapezoid.set_drive_target(0, Eigen::VectorXd::Constant(1, 0.5), Eigen::VectorXd::Zero(1));
  trapezoid.step(37);
  double error[3];
  for (double& e : error) trapezoid.step(), e = trapezoid.q(0)[0] - 0.5;
  EXPECT_LT(error[0] * error[1], 0) << "rings";
  EXPECT_LT(error[1] * error[2], 0) << "rings";
  EXPECT_GT(std::abs(error[2]), 1e-2) << "after 0.4 s, where the drive's own time constant is 0.3 ms";
  EXPECT_LT(std::abs(error[2]), 0.5) << "bounded";
  ASSERT_EQ(trapezoid.warnings().size(), 1u);
  EXPECT_NE(trapezoid.warnings()[0].find("the trapezoid takes drives, springs and damping by the implicit trapezoidal "
                                         "rule, and 1 DOF(s) are too stiff"),
            std::string::npos)
      << trapezoid.warnings()[0];
  const Simulator euler = run(Integrator::SemiImplicitEuler, stiff, 0.01);
  EXPECT_TRUE(euler.warnings().empty()) << euler.warnings().front();
  EXPECT_NEAR(euler.q(0)[0], 0.5, 1e-9) << "settled";
}

// RK4 takes joint damping and link damping explicitly, and their rates add:
// the wheel's joint damping 1 N m s on I = 0.01 is 100 / s and its angular
// link damping 200 / s (about its COM, on the axis), each within RK4's
// bound at h = 0.01 (h |lambda| 1 and 2; the Simulator accepts the link
// damping alone), together 300 / s, h |lambda| 3: warned, and the spin
// grows by RK4's |1 - 3 + 9/2 - 27/6 + 81/24| = 1.375 per step.
TEST(StiffDrives, Rk4WarnsOfJointAndLinkDampingTogether) {
  Model wheel = spinner(kInertia);
  wheel.body_angular_damping[0] = 200.0;
  std::vector<DofSettings> dofs = default_dof_settings(wheel);
  dofs[0].damping = 1.0;
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(1);
  EXPECT_TRUE(fast_joint_modes(wheel, dofs, q, 0.01, kRk4Bound).empty()) << "the joint alone is within the bound";
  const std::vector<StiffDrive> fast = fast_joint_modes(wheel, dofs, q, 0.01, kRk4Bound, true);
  ASSERT_EQ(fast.size(), 1u);
  EXPECT_NEAR(fast[0].ratio, 3.0, 1e-12);
  Simulator sim(wheel, 1, double_step(Integrator::RK4, 0.01), dofs);
  sim.set_state(0, q, Eigen::VectorXd::Constant(1, 1.0));
  ASSERT_EQ(sim.warnings().size(), 1u);
  EXPECT_NE(sim.warnings()[0].find("1 DOF(s) are too stiff for its step (h |lambda| 3 at wheel"), std::string::npos)
      << sim.warnings()[0];
  sim.step(50);
  EXPECT_NEAR(sim.v(0)[0], std::pow(1.375, 50), 1e-6 * std::pow(1.375, 50)) << "diverges as predicted";
}

}  // namespace
}  // namespace lockstep::test
