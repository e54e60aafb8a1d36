// Gravity switched off per body (LinkSpec::gravity, Model::body_gravity, a
// scene's links_without_gravity; docs/conventions.md). The kernels cancel
// a0's gravity on such a body with its weight, so its dynamics must equal
// those of the same body under gravity with the wrench -m g at its COM.
#include "batch/copy_dynamics.hpp"
#include "io/scene_file.hpp"
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace lockstep::test {
namespace {

namespace fs = std::filesystem;

// `model` with gravity switched off on every second body, from `first`.
Model alternate_bodies_without_gravity(Model model, int first) {
  for (int b = first; b < model.nbody; b += 2) model.body_gravity[b] = 0;
  return model;
}

// The wrench rows that cancel gravity on the bodies `without` has it off
// on: -m g at each one's COM (rows [force; torque about the COM]).
Eigen::MatrixXd weight_cancelling_wrench(const Model& without) {
  Eigen::MatrixXd wrench = Eigen::MatrixXd::Zero(without.nbody, 6);
  for (int b = 0; b < without.nbody; ++b)
    if (!without.body_gravity[b]) wrench.row(b).head<3>() = -without.body_mass[b] * without.gravity.transpose();
  return wrench;
}

double relative_error(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(1.0, b.cwiseAbs().maxCoeff());
}

// ---- the model

ArticulationSpec arm_with_glove(bool arm_gravity, bool glove_gravity) {
  ArticulationSpec spec;
  spec.name = "arm";
  spec.links.push_back(massive_link("base", "", JointType::Fixed, Eigen::Vector3d::UnitZ(), 2.0));
  spec.links.push_back(massive_link("arm", "base", JointType::Revolute, Eigen::Vector3d::UnitY(), 1.0));
  spec.links.push_back(massive_link("glove", "arm", JointType::Fixed, Eigen::Vector3d::UnitZ(), 0.3,
                                    Eigen::Vector3d(0, 0, -0.4)));
  spec.links[0].gravity = false;  // fixed to the world: allowed, and moves nothing
  spec.links[1].gravity = arm_gravity;
  spec.links[2].gravity = glove_gravity;
  return spec;
}

TEST(LinkGravity, BuilderKeepsEachBodysSwitch) {
  const Model on = build(arm_with_glove(true, true));
  EXPECT_EQ(on.body_gravity, std::vector<std::uint8_t>{1});
  const Model off = build(arm_with_glove(false, false));
  EXPECT_EQ(off.body_gravity, std::vector<std::uint8_t>{0});
  // the default of every shared model: gravity on every body
  const Model anymal = load_shared_model("anymal_b", true);
  EXPECT_EQ(anymal.body_gravity, std::vector<std::uint8_t>(anymal.nbody, 1));
}

TEST(LinkGravity, ALinkWithMassFusedIntoABodyMustAgreeWithIt) {
  ModelBuilder builder;
  EXPECT_MODEL_ERROR(builder.add_articulation(arm_with_glove(true, false)), "link 'glove'", "gravity off",
                     "fixed to link 'arm', which has gravity on", "gravity is set per moving body");
  EXPECT_MODEL_ERROR(builder.add_articulation(arm_with_glove(false, true)), "link 'glove'", "gravity on",
                     "which has gravity off");
  // a massless frame has no weight to switch: the body takes the arm's
  ArticulationSpec frame = arm_with_glove(false, true);
  frame.links[2].inertial = InertialSpec{};
  EXPECT_EQ(build(frame).body_gravity, std::vector<std::uint8_t>{0});
}

// ---- the dynamics: switched off == the weight cancelled by a wrench
//
// Both sides evaluate the same forces in a different order (the weight
// rotated into the body, or the wrench), so they agree to rounding: the
// largest difference over the outputs, relative to the largest entry,
// measured at most 2.9e-15 in double (talos_reduced) and 9.0e-7 in float
// (anymal_b, whose joint forces and accelerations sum body forces of
// several hundred N): a few hundred ulps. Asserted: 1e-12 and 1e-5.
class LinkGravityModels : public ::testing::TestWithParam<ModelCase> {};

TEST_P(LinkGravityModels, SwitchedOffEqualsTheWeightCancelledByAWrench) {
  const Model with = load_model_case(GetParam());
  for (int first : {0, 1}) {
    const Model without = alternate_bodies_without_gravity(with, first);
    const Eigen::MatrixXd cancel = weight_cancelling_wrench(without);
    for (Precision precision : {Precision::Double, Precision::Float}) {
      const double tolerance = precision == Precision::Double ? 1e-12 : 1e-5;
      const CopyDynamics on(with, precision), off(without, precision);
      std::mt19937 rng(5 + first);
      for (int trial = 0; trial < 3; ++trial) {
        const Eigen::VectorXd q = random_configuration(with, rng), v = random_vector(with.nv, rng, 2.0);
        const Eigen::VectorXd tau = random_vector(with.nv, rng, 5.0), a = random_vector(with.nv, rng, 3.0);
        const std::string at = std::string(precision_name(precision)) + ", from body " + std::to_string(first) +
                               ", trial " + std::to_string(trial);
        EXPECT_LT(relative_error(off.forward_dynamics(q, v, tau), on.forward_dynamics(q, v, tau, &cancel)), tolerance)
            << "forward_dynamics, " << at;
        EXPECT_LT(relative_error(off.inverse_dynamics(q, v, a), on.inverse_dynamics(q, v, a, &cancel)), tolerance)
            << "inverse_dynamics, " << at;
        const Eigen::VectorXd held = on.gravity_force(q) - on.external_force(q, cancel);
        EXPECT_LT(relative_error(off.gravity_force(q), held), tolerance) << "gravity_force, " << at;
        EXPECT_LT(relative_error(off.bias_force(q, v), on.bias_force(q, v) - on.external_force(q, cancel)), tolerance)
            << "bias_force, " << at;
        EXPECT_LT(relative_error(off.incoming_joint_forces(q, v, tau), on.incoming_joint_forces(q, v, tau, &cancel)),
                  tolerance)
            << "incoming_joint_forces, " << at;
      }
    }
  }
}

// V = -sum m g . c over the bodies gravity acts on only.
TEST_P(LinkGravityModels, PotentialEnergyCountsOnlyTheBodiesGravityActsOn) {
  const Model with = load_model_case(GetParam());
  const Model without = alternate_bodies_without_gravity(with, 1);
  const CopyDynamics off(without);
  std::mt19937 rng(9);
  const Eigen::VectorXd q = random_configuration(with, rng);
  const std::vector<Eigen::Isometry3d> poses = off.body_poses(q);
  double expected = 0;
  for (int b = 0; b < with.nbody; ++b)
    if (without.body_gravity[b]) expected -= with.body_mass[b] * with.gravity.dot(poses[b] * with.body_com[b]);
  EXPECT_NEAR(off.potential_energy(q), expected, 1e-12 * std::max(1.0, std::abs(expected)));
  EXPECT_NE(off.potential_energy(q), CopyDynamics(with).potential_energy(q)) << "the switch changed nothing";
}

std::vector<ModelCase> gravity_cases() {
  return {{"anymal_b", true}, {"panda", false}, {"talos_reduced", true}, {"spherical_tree", true},
          {"spherical_tree", false}};
}

INSTANTIATE_TEST_SUITE_P(Models, LinkGravityModels, ::testing::ValuesIn(gravity_cases()),
                         [](const auto& info) { return case_name(info.param); });

// With every body's gravity off, RNEA's held force and ABA's acceleration at
// rest are zero up to the rounding of a0 against the weight.
TEST(LinkGravity, AModelWithoutAnyGravityNeedsNoForceToHold) {
  Model model = load_shared_model("anymal_b", true);
  for (auto& on : model.body_gravity) on = 0;
  const CopyDynamics dyn(model);
  std::mt19937 rng(3);
  const Eigen::VectorXd q = random_configuration(model, rng), zero = Eigen::VectorXd::Zero(model.nv);
  EXPECT_LT(dyn.gravity_force(q).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT(dyn.forward_dynamics(q, zero, zero).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(dyn.potential_energy(q), 0.0);
}

// ---- the step

// anymal_b without gravity on any body, its legs held by PD: it stays where
// it was put, in float and double, SIMD and scalar lanes alike.
TEST(LinkGravity, ARobotWithoutGravityStaysWhereItIs) {
  Model model = load_shared_model("anymal_b", true);
  for (auto& on : model.body_gravity) on = 0;
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 6; k < model.nv; ++k) dofs[k].drive_stiffness = 300, dofs[k].drive_damping = 8;
  for (Precision precision : {Precision::Double, Precision::Float}) {
    StepOptions o;
    o.precision = precision;
    Simulator sim(model, 3, o, dofs);
    const std::string all = std::to_string(model.nbody);
    EXPECT_NE(sim.describe_plan().find("ABA with gravity: always (switched off on " + all + " of " + all + " bodies)"),
              std::string::npos)
        << sim.describe_plan();
    const Eigen::VectorXd stand = stance(model);
    sim.set_state_all(stand, Eigen::VectorXd::Zero(model.nv));
    for (int c = 0; c < 3; ++c) sim.set_drive_target(c, stand, Eigen::VectorXd::Zero(model.nv));
    for (int i = 0; i < 500; ++i) sim.step();
    // measured after 1 s: |q - stance| 2.5e-16 and |v| 5.0e-16 in double,
    // 1.5e-8 and 6.6e-8 in float (the weight cancels a0 to rounding); with
    // gravity the robot falls 4.9 m. Asserted: 1e-6
    for (int c = 0; c < 3; ++c) {
      EXPECT_LT((sim.q(c) - stand).cwiseAbs().maxCoeff(), 1e-6) << precision_name(precision) << " copy " << c;
      EXPECT_LT(sim.v(c).cwiseAbs().maxCoeff(), 1e-6) << precision_name(precision) << " copy " << c;
    }
  }
}

// The step with gravity off on every second body of anymal_b against the
// same robot with gravity on and those bodies' weight cancelled by link
// wrenches, each integrator, PD holding the legs: the same motion to
// rounding (measured after 200 steps: q within 1.1e-16, v within 5.6e-16;
// asserted 1e-10, room for other compilers' rounding over 200 steps).
TEST(LinkGravity, AStepWithoutGravityOnSomeBodiesEqualsTheWeightCancelledByWrenches) {
  const Model with = load_shared_model("anymal_b", true);
  const Model without = alternate_bodies_without_gravity(with, 1);
  const Eigen::MatrixXd cancel = weight_cancelling_wrench(without);
  std::vector<DofSettings> dofs = default_dof_settings(with);
  for (int k = 6; k < with.nv; ++k) dofs[k].drive_stiffness = 300, dofs[k].drive_damping = 8;
  for (Integrator integrator :
       {Integrator::SemiImplicitEuler, Integrator::Trapezoid, Integrator::RK4, Integrator::ExplicitEuler}) {
    StepOptions o;
    o.precision = Precision::Double;
    o.integrator = integrator;
    o.force(Stage::HardLimits, StageMode::Off).force(Stage::VelocityLimits, StageMode::Off);  // RK4 takes no rows
    Simulator off(without, 1, o, dofs), on(with, 1, o, dofs);
    std::mt19937 rng(8);
    const Eigen::VectorXd v = random_vector(with.nv, rng, 1.0);
    for (Simulator* sim : {&off, &on}) {
      sim->set_state(0, stance(with), v);
      sim->set_drive_target(0, stance(with), Eigen::VectorXd::Zero(with.nv));
    }
    for (int b = 0; b < with.nbody; ++b) on.set_link_wrench(0, b, cancel.row(b).transpose());
    off.step(200);
    on.step(200);
    const std::string name = integrator_name(integrator);
    EXPECT_LT((off.q(0) - on.q(0)).cwiseAbs().maxCoeff(), 1e-10) << name;
    EXPECT_LT((off.v(0) - on.v(0)).cwiseAbs().maxCoeff(), 1e-10) << name;
    EXPECT_GT((off.q(0) - stance(with)).norm(), 0.1) << name << ": the robot moved";
  }
}

// With conserve_linear_momentum, the momentum of a falling anymal_b whose
// legs have no gravity changes per step by h g times the base's mass only
// (momentum_projection_test.cpp's balance, with that weight).
TEST(LinkGravity, MomentumBalanceCountsOnlyTheWeightThatActs) {
  const Model with = load_shared_model("anymal_b", true);
  Model model = with;
  for (int b = 1; b < model.nbody; ++b) model.body_gravity[b] = 0;
  StepOptions o;
  o.conserve_linear_momentum = true;
  o.precision = Precision::Double;  // float keeps the balance to 1e-6 of |P| (momentum_projection_test.cpp)
  Simulator sim(model, 1, o);
  sim.set_state(0, stance(model), Eigen::VectorXd::Zero(model.nv));
  const CopyDynamics dyn(model);
  const Eigen::Vector3d impulse = o.dt * model.body_mass[0] * model.gravity;
  double worst = 0;
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d p0 = dyn.linear_momentum(sim.q(0), sim.v(0));
    sim.step();
    worst = std::max(worst, (dyn.linear_momentum(sim.q(0), sim.v(0)) - p0 - impulse).norm());
  }
  // measured 2.1e-14 kg m/s per step (2.7e-14 with gravity on every body and
  // the whole weight); the whole robot's weight would be off by
  // h g (m - m_base) = 0.27 kg m/s
  EXPECT_LT(worst, 1e-12 * with.total_mass());
  EXPECT_NEAR(dyn.linear_momentum(sim.q(0), sim.v(0)).z(), 100 * impulse.z(), 1e-9);
}

// ---- scenes

class LinkGravityScene : public SceneFileTest {
 protected:
  std::string scene_text(const std::string& model, bool floating, const std::string& links) {
    return "{\"model\": \"" + fs::absolute(model).string() + "\", \"floating_base\": " +
           (floating ? "true" : "false") + ", \"links_without_gravity\": [" + links + "]}";
  }
};

TEST_F(LinkGravityScene, NamedLinksLoseGravityAndTheSceneWritesThemBack) {
  const Scene s = load_scene(write(scene_text(shared_model_path("anymal_b"), true, "\"LF_SHANK\", \"RH_THIGH\"")));
  const Model& m = s.model;
  int off = 0;
  for (int b = 0; b < m.nbody; ++b) {
    const std::string& link = m.frame_name[m.body_frame[b]];
    EXPECT_EQ(m.body_gravity[b], link == "LF_SHANK" || link == "RH_THIGH" ? 0 : 1) << link;
    off += m.body_gravity[b] == 0;
  }
  EXPECT_EQ(off, 2);
  const std::string text = scene_to_json(s);
  EXPECT_NE(text.find("\"links_without_gravity\": [\"LF_SHANK\", \"RH_THIGH\"]"), std::string::npos) << text;
  EXPECT_EQ(load_scene(write(text)).model.body_gravity, m.body_gravity);
}

// A URDF's own switch (Gazebo's <gravity>) and the scene's list add up; a
// link both name is no error, and the written scene reads back the same.
TEST_F(LinkGravityScene, TheUrdfsSwitchAndTheScenesListAddUp) {
  const std::string inertial =
      R"(<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>)";
  std::string urdf = "<robot name=\"bot\">\n<link name=\"base\">" + inertial + "</link>\n";
  for (const char* name : {"arm", "hand"})
    urdf += std::string("<link name=\"") + name + "\">" + inertial + "</link>\n";
  urdf += R"(<joint name="shoulder" type="continuous"><parent link="base"/><child link="arm"/></joint>
<joint name="wrist" type="continuous"><parent link="arm"/><child link="hand"/></joint>
<gazebo reference="arm"><gravity>false</gravity></gazebo>
</robot>
)";
  const std::string urdf_path = (dir_ / "bot.urdf").string();
  std::ofstream(urdf_path) << urdf;
  const Scene s = load_scene(write(scene_text(urdf_path, false, "\"hand\", \"arm\"")));
  EXPECT_EQ(s.model.body_gravity, (std::vector<std::uint8_t>{0, 0}));
  const Scene urdf_only = load_scene(write(scene_text(urdf_path, false, "")));
  EXPECT_EQ(urdf_only.model.body_gravity, (std::vector<std::uint8_t>{0, 1}));
  EXPECT_EQ(load_scene(write(scene_to_json(urdf_only))).model.body_gravity, urdf_only.model.body_gravity);
}

TEST_F(LinkGravityScene, ALinkFixedToTheWorldIsRefused) {
  const std::string root = load_shared_model("panda", false).frame_name[0];
  EXPECT_THROW_WITH(load_scene(write(scene_text(shared_model_path("panda"), false, "\"" + root + "\""))), SceneError,
                    "links_without_gravity[0]: link \"" + root + "\" is fixed to the world");
}

}  // namespace
}  // namespace lockstep::test
