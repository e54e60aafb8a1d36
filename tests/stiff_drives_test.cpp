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

}  // namespace
}  // namespace lockstep::test
