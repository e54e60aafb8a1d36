// The stage plan: a feature a scene does not use costs nothing, so forcing
// its stage on or off gives bit-identical states; describe_plan names every
// stage with its decision and reason; set_drive_gains and set_link_wrench
// switch their stages on, and a link wrench acts as a world force and torque
// at the body's COM.
#include "tests/sim_support.hpp"

#include <algorithm>
#include <cctype>

namespace lockstep {
namespace {

using test::same_bits;
using test::same_state;

constexpr int kCopies = 24;  // float: 2 blocks (8 padding lanes); double: 3 blocks
constexpr int kSteps = 8;

Stage stage_at(int i) { return static_cast<Stage>(i); }

// The 12 leg DOFs of anymal_b (scene_model) with every joint effect except the one
// of `unused` (Stage::Count: none): damping, springs, spring-damper limits on
// even legs DOFs and hard limits [-0.3, 0.3] on odd ones, velocity limits of
// 5 rad/s, Coulomb friction on every third DOF and Stribeck friction on the
// next. A scene without hard (velocity) limits keeps them, 3 rad (1000
// rad/s) away: never reached. Drives and wrenches come per copy, except
// without per-copy joint parameters: then the drives are the scene's.
std::vector<DofSettings> scene_dofs(const Model& model, Stage unused) {
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 0, leg = 0; k < model.nv; ++k) {
    if (model.body_joint[model.dof_body[k]] == JointType::Free) continue;
    DofSettings& d = dofs[k];
    d.damping = unused == Stage::Damping ? 0.0 : 0.2;
    d.spring_stiffness = unused == Stage::Springs ? 0.0 : 4.0;
    d.spring_rest = 0.1;
    const bool soft = leg % 2 == 0 && unused != Stage::SoftLimits;
    const double range = !soft && unused == Stage::HardLimits ? 3.0 : 0.3;
    d.lower = -range;
    d.upper = range;
    if (soft) d.limit_stiffness = 400.0, d.limit_damping = 4.0;
    d.velocity_limit = unused == Stage::VelocityLimits ? 1e3 : 5.0;
    if (unused == Stage::PerCopyJointParameters) d.drive_stiffness = 50.0, d.drive_damping = 1.5;
    if (leg % 3 == 0 && unused != Stage::CoulombFriction) d.friction = 0.3;
    if (leg % 3 == 1 && unused != Stage::StribeckFriction) {
      d.friction_model = FrictionModel::Stribeck;
      d.friction = 0.3;
      d.stiction_extra = 0.2;
      d.stribeck_velocity = 0.5;
    }
    ++leg;
  }
  return dofs;
}

// anymal_b floating with link damping on every body but the base (its
// legs' linear 0.3 and angular 0.6 per second), the right hind knee
// mimicking the left front one (multiplier -1, offset 0.1) and a tendon
// tying the hind hips' flexion (a spring and length limits of +-0.2),
// unless `unused` is the stage.
Model scene_model(Stage unused) {
  Model model = test::load_shared_model("anymal_b", true);
  if (unused != Stage::LinkDamping)
    for (int b = 1; b < model.nbody; ++b) model.body_linear_damping[b] = 0.3, model.body_angular_damping[b] = 0.6;
  if (unused != Stage::MimicJoints)
    model.mimics.push_back({model.dof_index("RH_KFE"), model.dof_index("LF_KFE"), -1.0, 0.1});
  if (unused != Stage::FixedTendons) {
    FixedTendon hips;
    hips.name = "hind hips";
    hips.joints = {{model.dof_index("LH_HFE"), 1.0}, {model.dof_index("RH_HFE"), -1.0}};
    hips.stiffness = 20.0, hips.damping = 0.5, hips.lower_limit = -0.2, hips.upper_limit = 0.2;
    model.fixed_tendons.push_back(hips);
  }
  return model;
}

// The scene's simulator with per-copy states, torques, targets and (unless
// unused) drive gains, link wrenches, heavier bases and more armature in odd
// copies, and the ground, stepped kSteps times.
Simulator run_scene(const Model& model, Stage unused, StepOptions options) {
  const std::vector<DofSettings> dofs = scene_dofs(model, unused);
  options.contacts.ground = unused != Stage::Contacts;
  Simulator sim(model, kCopies, options, dofs);
  for (int c = 0; c < kCopies; ++c) {
    test::CopyInputs in = test::random_copy_inputs(model, dofs, 300u + static_cast<unsigned>(c), 2.0);
    if (unused == Stage::Drives) in.kp.setZero(), in.kd.setZero();
    if (unused == Stage::PerCopyJointParameters)
      for (int k = 0; k < model.nv; ++k) in.kp[k] = dofs[k].drive_stiffness, in.kd[k] = dofs[k].drive_damping;
    in.push = unused != Stage::ExternalWrenches;
    test::apply_copy_inputs(sim, c, in);
    if (unused != Stage::PerCopyInertia && c % 2 == 1)  // a heavier base in odd copies
      sim.set_body_inertia(c, 0, 1.1 * model.body_mass[0], model.body_com[0], 1.1 * model.body_inertia[0]);
    if (unused != Stage::PerCopyJointParameters && c % 2 == 1) {  // rotors on the legs' DOFs in odd copies
      Eigen::VectorXd armature = Eigen::Map<const Eigen::VectorXd>(model.dof_armature.data(), model.nv);
      for (int k = 0; k < model.nv; ++k)
        if (model.body_joint[model.dof_body[k]] != JointType::Free) armature[k] += 0.01;
      sim.set_armature(c, armature);
    }
  }
  sim.step(kSteps);
  return sim;
}

std::string stage_test_name(const ::testing::TestParamInfo<int>& info) {
  std::string name = stage_name(stage_at(info.param));
  std::replace_if(name.begin(), name.end(), [](char c) { return !std::isalnum(static_cast<unsigned char>(c)); }, '_');
  return name;
}

class StepStages : public ::testing::TestWithParam<int> {};

// A scene without the stage's feature gives the same bits with the stage
// forced on, forced off, or left to the plan; every other stage runs.
TEST_P(StepStages, UnusedStageCostsNothing) {
  const Stage unused = stage_at(GetParam());
  const Model model = scene_model(unused);
  for (Precision precision : {Precision::Float, Precision::Double})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      const std::string where = std::string(precision_name(precision)) + " " + solver_name(solver);
      StepOptions o = test::scene_options(precision, solver);
      const Simulator automatic = run_scene(model, unused, o);
      const Simulator on = run_scene(model, unused, o.force(unused, StageMode::On));
      const Simulator off = run_scene(model, unused, o.force(unused, StageMode::Off));
      for (int s = 0; s < kStageCount; ++s)
        if (s != GetParam()) EXPECT_TRUE(automatic.plan()[s].runs) << where << ": " << stage_name(stage_at(s));
      EXPECT_TRUE(on.plan()[GetParam()].runs) << where;
      EXPECT_FALSE(off.plan()[GetParam()].runs) << where;
      EXPECT_GT(test::copies_with_impulses(on), 0) << where << ": the solver pushes";
      for (int c = 0; c < kCopies; ++c) {
        EXPECT_TRUE(same_state(on, c, off, c)) << where << ", forced on against off: copy " << c;
        EXPECT_TRUE(same_state(automatic, c, off, c)) << where << ", automatic against off: copy " << c;
      }
      EXPECT_EQ(on.fault_count(), 0) << where;
    }
}

INSTANTIATE_TEST_SUITE_P(, StepStages, ::testing::Range(0, kStageCount), stage_test_name);

// Every stage has one line: its name, runs or skipped, and why.
TEST(StepStagesPlan, DescribePlanListsEveryStageWithItsReason) {
  const Model model = scene_model(Stage::Count);
  const Simulator full = run_scene(model, Stage::Count, test::scene_options(Precision::Float, SolverType::PGS));
  StepOptions o;
  o.force(Stage::Damping, StageMode::On).force(Stage::HardLimits, StageMode::Off);
  const Simulator bare(model, 4, o);
  for (const Simulator* sim : {&full, &bare}) {
    const std::string text = sim->describe_plan();
    ASSERT_EQ(sim->plan().size(), static_cast<std::size_t>(kStageCount));
    for (int s = 0; s < kStageCount; ++s) {
      const StageDecision& d = sim->plan()[s];
      EXPECT_EQ(d.stage, stage_at(s));
      EXPECT_FALSE(d.reason.empty()) << stage_name(d.stage);
      const std::string line = std::string("  ") + stage_name(d.stage) + ": " + (d.runs ? "runs" : "skipped") + " (" +
                               d.reason + ")\n";
      EXPECT_NE(text.find(line), std::string::npos) << "no line '" << line << "' in\n" << text;
      if (sim == &full) EXPECT_TRUE(d.runs) << stage_name(d.stage);
    }
  }
  const std::string text = bare.describe_plan();
  for (const char* line : {"  drives: skipped (no DOFs with drive gains)\n",
                           "  damping: runs (forced on (no DOFs with damping))\n",
                           "  hard limits: skipped (forced off (12 DOFs with hard position limits))\n",
                           "  velocity limits: runs (12 DOFs with velocity limits)\n",
                           "  external wrenches: skipped (no calls of set_link_wrench)\n",
                           "  link damping: runs (12 bodies with link damping)\n"})
    EXPECT_NE(text.find(line), std::string::npos) << "no line '" << line << "' in\n" << text;
}

// Gains given to one copy switch the drives on for the scene; they act on
// that copy only, and every copy without gains is as without the stage.
TEST(StepStagesPlan, DriveGainsOnOneCopyTurnDrivesOn) {
  const Model model = test::load_shared_model("anymal_b", true);
  const int driven = 9;
  auto make = [&] {
    Simulator sim(model, kCopies, test::scene_options(Precision::Float, SolverType::PGS));
    std::mt19937 rng(11);
    for (int c = 0; c < kCopies; ++c) {
      sim.set_state(c, test::random_configuration(model, rng), test::random_vector(model.nv, rng, 1.0));
      sim.set_drive_target(c, test::random_configuration(model, rng), Eigen::VectorXd::Zero(model.nv));
    }
    return sim;
  };
  Simulator reference = make();
  Simulator sim = make();
  const int drives = static_cast<int>(Stage::Drives);
  EXPECT_FALSE(sim.plan()[drives].runs);
  sim.set_drive_gains(driven, Eigen::VectorXd::Zero(model.nv), Eigen::VectorXd::Zero(model.nv));
  EXPECT_FALSE(sim.plan()[drives].runs) << "zero gains are no drive";
  Eigen::VectorXd kp = Eigen::VectorXd::Constant(model.nv, 50.0), kd = Eigen::VectorXd::Constant(model.nv, 2.0);
  kp.head(6).setZero();  // the floating base takes no drive
  kd.head(6).setZero();
  sim.set_drive_gains(driven, kp, kd);
  EXPECT_TRUE(sim.plan()[drives].runs);
  EXPECT_NE(sim.describe_plan().find("  drives: runs ("), std::string::npos) << sim.describe_plan();
  reference.step(kSteps);
  sim.step(kSteps);
  for (int c = 0; c < kCopies; ++c)
    if (c != driven) EXPECT_TRUE(same_state(sim, c, reference, c)) << "copy " << c;
  EXPECT_FALSE(same_state(sim, driven, reference, driven)) << "the drive did not act";
}

// set_link_wrench switches the stage on, and the wrench is a world force and
// a torque about the COM: from rest without gravity one step gives the body
// twist (R^T F / m, I^-1 R^T n) dt and moves the COM by F / m dt^2.
TEST(StepStagesPlan, LinkWrenchActsAsWorldForceAndTorque) {
  const double mass = 2.0, dt = 0.01;
  const Eigen::Vector3d half(0.1, 0.2, 0.3);
  const Model model = test::free_box(half, mass);
  StepOptions o = test::scene_options(Precision::Double, SolverType::PGS);
  o.dt = dt;
  Simulator sim(model, 3, o);
  const int wrenches = static_cast<int>(Stage::ExternalWrenches);
  EXPECT_FALSE(sim.plan()[wrenches].runs);
  const Eigen::Quaterniond turn = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, -1).normalized()));
  const Eigen::Matrix3d R = turn.toRotationMatrix();
  Eigen::VectorXd q = model.neutral_configuration();
  q.segment<3>(0) = Eigen::Vector3d(0.5, -0.2, 1.0);
  q.segment<4>(3) << turn.w(), turn.x(), turn.y(), turn.z();
  Eigen::Matrix<double, 6, 1> wrench;
  wrench << 3.0, -4.0, 5.0, 0.2, -0.1, 0.3;
  for (int c = 0; c < 3; ++c) {
    sim.set_state(c, q, Eigen::VectorXd::Zero(6));
    sim.set_gravity(c, Eigen::Vector3d::Zero());
  }
  sim.set_link_wrench(0, 0, wrench);
  sim.set_link_wrench(1, 0, Eigen::Matrix<double, 6, 1>::Zero());
  EXPECT_TRUE(sim.plan()[wrenches].runs);
  sim.set_gravity(2, Eigen::Vector3d(0, 0, -9.81));  // copy 2: gravity alone
  sim.step();
  const Eigen::Vector3d s = half.cwiseAbs2();
  const Eigen::Vector3d inertia = mass / 3.0 * Eigen::Vector3d(s.y() + s.z(), s.x() + s.z(), s.x() + s.y());
  const Eigen::Vector3d force = wrench.head<3>(), torque = wrench.tail<3>();
  const Eigen::VectorXd v = sim.v(0);
  // the linear velocity in the body frame at the end of the step
  const Eigen::Quaterniond end(sim.q(0)[3], sim.q(0)[4], sim.q(0)[5], sim.q(0)[6]);
  EXPECT_LT((end * Eigen::Vector3d(v.head<3>()) - force / mass * dt).cwiseAbs().maxCoeff(), 1e-14) << v.transpose();
  EXPECT_LT((v.tail<3>() - (R.transpose() * torque).cwiseQuotient(inertia) * dt).cwiseAbs().maxCoeff(), 1e-13)
      << v.transpose();
  EXPECT_LT((sim.q(0).head<3>() - (q.head<3>() + force / mass * dt * dt)).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_TRUE(same_bits(sim.v(1), Eigen::VectorXd::Zero(6))) << "a zero wrench moved copy 1";
  EXPECT_TRUE(same_bits(sim.q(2).tail<4>(), q.tail<4>())) << "gravity alone turned copy 2";
  EXPECT_LT((R * sim.v(2).head<3>() - Eigen::Vector3d(0, 0, -9.81 * dt)).cwiseAbs().maxCoeff(), 1e-14);
}

// A wrench written straight into the batch acts once the stage is forced on
// (the plan counts only set_link_wrench calls).
TEST(StepStagesPlan, BatchWrenchActsWithTheStageForcedOn) {
  const double mass = 2.0, dt = 0.01;
  const Model model = test::free_box(Eigen::Vector3d(0.1, 0.2, 0.3), mass);
  for (StageMode mode : {StageMode::Auto, StageMode::On}) {
    StepOptions o = test::scene_options(Precision::Double, SolverType::PGS);
    o.dt = dt;
    o.force(Stage::ExternalWrenches, mode);
    Simulator sim(model, 2, o);
    sim.set_gravity(1, Eigen::Vector3d::Zero());
    sim.batch<double>().state.wrench.at(1, 0) = 4.0;  // copy 1, body 0, force x
    sim.step();
    const double expected = mode == StageMode::On ? 4.0 / mass * dt : 0.0;
    EXPECT_NEAR(sim.v(1)[0], expected, 1e-15) << (mode == StageMode::On ? "forced on" : "automatic");
  }
}

// Copies step with one shared block of the model's inertias until some
// copy gets its own (set_body_inertia with other values than the model's,
// or a restore carrying them); such a copy then steps exactly as a copy of a
// model with those inertias, and the model's inertias set or restored share
// the block again.
TEST(StepStagesPlan, PerCopyInertiaFollowsSetBodyInertiaAndRestore) {
  const Model model = test::load_shared_model("anymal_b", true);
  Model heavy = model;  // the base 10 % heavier
  heavy.body_mass[0] *= 1.1;
  heavy.body_inertia[0] *= 1.1;
  const int inertia = static_cast<int>(Stage::PerCopyInertia), copies = 40, own = 37;  // own: in the last block
  const StepOptions o = test::scene_options(Precision::Float, SolverType::PGS);
  const std::vector<DofSettings> dofs = scene_dofs(model, Stage::Contacts);
  Simulator sim(model, copies, o, dofs), fresh(model, copies, o, dofs), reference(heavy, 1, o, dofs);
  EXPECT_FALSE(sim.plan()[inertia].runs) << sim.describe_plan();
  sim.set_body_inertia(own, 0, model.body_mass[0], model.body_com[0], model.body_inertia[0]);
  EXPECT_FALSE(sim.plan()[inertia].runs) << "the model's own values, set";
  const CopySnapshot plain = sim.snapshot(own);
  sim.set_body_inertia(own, 1, heavy.body_mass[1], heavy.body_com[1], 2.0 * heavy.body_inertia[1]);
  sim.set_body_inertia(own, 0, heavy.body_mass[0], heavy.body_com[0], heavy.body_inertia[0]);
  sim.set_body_inertia(own, 1, model.body_mass[1], model.body_com[1], model.body_inertia[1]);
  EXPECT_TRUE(sim.plan()[inertia].runs) << "body 0 still heavier\n" << sim.describe_plan();
  const test::CopyInputs in = test::random_copy_inputs(model, dofs, 77u, 2.0);
  for (int c = 0; c < copies; ++c) test::apply_copy_inputs(sim, c, in);
  test::apply_copy_inputs(reference, 0, in);
  sim.step(20);
  reference.step(20);
  EXPECT_TRUE(same_state(sim, own, reference, 0)) << "the copy with the heavier base";
  EXPECT_FALSE(same_state(sim, own, sim, 0)) << "the heavier base changed nothing";
  // its snapshot carries the inertias into a simulator that shared them;
  // the step takes the plan up itself (the plan is not read before it)
  fresh.restore(5, sim.snapshot(own));
  fresh.step(10);
  reference.step(10);
  EXPECT_TRUE(same_state(fresh, 5, reference, 0)) << "restored into another simulator";
  EXPECT_TRUE(fresh.plan()[inertia].runs) << fresh.describe_plan();
  // and the model's inertias restored share the block again
  sim.restore(own, plain);
  EXPECT_FALSE(sim.plan()[inertia].runs) << sim.describe_plan();
  // forced off, every copy steps with the model's, whatever block 0 holds
  StepOptions off = o;
  off.force(Stage::PerCopyInertia, StageMode::Off);
  Simulator shared(model, copies, off, dofs);
  shared.set_body_inertia(1, 0, heavy.body_mass[0], heavy.body_com[0], heavy.body_inertia[0]);
  for (int c : {0, 1, own}) test::apply_copy_inputs(shared, c, in);
  shared.step(20);
  EXPECT_TRUE(same_state(shared, 1, shared, 0)) << "copy 1 in block 0, stage forced off";
  EXPECT_TRUE(same_state(shared, own, shared, 0)) << "a copy in the last block, stage forced off";
  // and setting the model's values again shares the block as well
  sim.set_body_inertia(own, 0, heavy.body_mass[0], heavy.body_com[0], heavy.body_inertia[0]);
  ASSERT_TRUE(sim.plan()[inertia].runs);
  sim.set_body_inertia(own, 0, model.body_mass[0], model.body_com[0], model.body_inertia[0]);
  EXPECT_FALSE(sim.plan()[inertia].runs) << sim.describe_plan();
}

// Likewise the per-DOF parameters: every copy steps with one block of the
// scene's drive gains, damping, armature and joint friction until a setter
// gives some copy values of its own. That copy then steps exactly as in a
// scene with those values; the scene's values set or restored again share
// the block.
TEST(StepStagesPlan, PerCopyJointParametersFollowTheSettersAndRestore) {
  const Model model = test::load_shared_model("anymal_b", true);
  Model rotors = model;  // 0.02 more armature on every leg DOF
  Eigen::VectorXd armature = Eigen::Map<const Eigen::VectorXd>(model.dof_armature.data(), model.nv);
  const Eigen::VectorXd scene_armature = armature;
  for (int k = 0; k < model.nv; ++k)
    if (model.body_joint[model.dof_body[k]] != JointType::Free) armature[k] += 0.02;
  rotors.dof_armature.assign(armature.data(), armature.data() + model.nv);
  const int stage = static_cast<int>(Stage::PerCopyJointParameters), copies = 40, own = 37;  // own: in the last block
  const StepOptions o = test::scene_options(Precision::Float, SolverType::PGS);
  std::vector<DofSettings> dofs = scene_dofs(model, Stage::Contacts);
  for (int k = 0; k < model.nv; ++k)
    if (model.body_joint[model.dof_body[k]] != JointType::Free) dofs[k].drive_stiffness = 60, dofs[k].drive_damping = 2;
  Simulator sim(model, copies, o, dofs), reference(rotors, 1, o, dofs);
  test::CopyInputs in = test::random_copy_inputs(model, dofs, 91u, 2.0);
  for (int k = 0; k < model.nv; ++k) in.kp[k] = dofs[k].drive_stiffness, in.kd[k] = dofs[k].drive_damping;
  for (int c = 0; c < copies; ++c) test::apply_copy_inputs(sim, c, in);  // the scene's gains, set per copy
  test::apply_copy_inputs(reference, 0, in);
  EXPECT_FALSE(sim.plan()[stage].runs) << "the scene's gains, set\n" << sim.describe_plan();
  const CopySnapshot plain = sim.snapshot(own);
  sim.set_armature(own, armature);
  EXPECT_TRUE(sim.plan()[stage].runs) << sim.describe_plan();
  sim.step(20);
  reference.step(20);
  EXPECT_TRUE(same_state(sim, own, reference, 0)) << "the copy with more armature";
  EXPECT_FALSE(same_state(sim, own, sim, 0)) << "the armature changed nothing";
  sim.restore(own, plain);
  EXPECT_FALSE(sim.plan()[stage].runs) << "the scene's values restored\n" << sim.describe_plan();
  // each setter counts: damping on, armature back to the scene's, damping
  // back: the stage follows the last copy with any value of its own
  Eigen::VectorXd damping = Eigen::VectorXd::Zero(model.nv);
  for (int k = 0; k < model.nv; ++k) damping[k] = dofs[k].damping;
  sim.set_armature(own, armature);
  sim.set_joint_damping(own, 2.0 * damping);
  sim.set_armature(own, scene_armature);
  EXPECT_TRUE(sim.plan()[stage].runs) << "damping still its own";
  sim.set_joint_damping(own, damping);
  EXPECT_FALSE(sim.plan()[stage].runs) << sim.describe_plan();
  // forced off, every copy steps with the scene's, whatever its own
  StepOptions off = o;
  off.force(Stage::PerCopyJointParameters, StageMode::Off);
  Simulator shared(model, copies, off, dofs);
  for (int c : {0, 1, own}) test::apply_copy_inputs(shared, c, in);
  shared.set_armature(1, armature);
  shared.set_armature(own, armature);
  shared.step(20);
  EXPECT_TRUE(same_state(shared, 1, shared, 0)) << "copy 1 in block 0, stage forced off";
  EXPECT_TRUE(same_state(shared, own, shared, 0)) << "a copy in the last block, stage forced off";
}

}  // namespace
}  // namespace lockstep
