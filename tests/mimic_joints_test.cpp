// Mimic joints (Stage::MimicJoints): a URDF mimic tag q_f = m q_l + c as
// the solver's equality row q_f - m q_l - c = 0 (PhysX's q_A + G q_B +
// offset = 0). Checked against the constrained dynamics of two sliders by
// hand, the error reduction's exact decay, panda's fingers, and the SIMD
// lanes against the scalar path.
#include "batch/vec_env.hpp"
#include "tests/sim_support.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace lockstep::test {
namespace {

constexpr double kGravity = 9.81;

// Two sliders on a fixed base, both along world z under gravity -z, masses
// m_leader and m_follower, the follower's joint tagged q_f = m q_l + c.
Model sliders(double m_leader, double m_follower, double multiplier, double offset) {
  ArticulationSpec spec;
  spec.name = "sliders";
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  for (const auto& [name, mass] : {std::pair<std::string, double>{"leader", m_leader}, {"follower", m_follower}}) {
    LinkSpec link = joint_link(name, "base", JointType::Prismatic, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero());
    link.inertial.mass = mass;
    link.inertial.inertia = mass * Eigen::Matrix3d::Identity();
    spec.links.push_back(link);
  }
  spec.links[2].joint.mimic = {"leader_joint", multiplier, offset};
  return build(spec);
}

StepOptions options(Precision precision, SolverType solver) {
  StepOptions o;
  o.dt = 0.002;
  o.precision = precision;
  o.solver = solver;
  return o;
}

// Relative rounding of one step's velocity: a few operations in the
// solver's one row (PGS and TGS solve a single row exactly in one sweep)
// and ABA, each within an ulp; 64 eps leaves room for their sums.
double step_tolerance(Precision p) {
  return 64 * (p == Precision::Float ? std::numeric_limits<float>::epsilon() : std::numeric_limits<double>::epsilon());
}

// With q_f = m q_l + c the pair is one body of mass m_l + m^2 m_f pushed by
// -g (m_l + m m_f) along q_l: a_l = -g (m_l + m m_f) / (m_l + m^2 m_f), a_f =
// m a_l. From rest on the constraint, one step of semi-implicit Euler
// gives v_l = h a_l, v_f = m v_l; then q = q0 + h v. Only with the row:
// alone the sliders fall at -g each.
TEST(MimicJoints, TwoSlidersFallAsOneBodyOfTheirConstrainedMass) {
  const double m_l = 2.0, m_f = 3.0, multiplier = -0.5, offset = 0.1;
  const Model model = sliders(m_l, m_f, multiplier, offset);
  const double a_l = -kGravity * (m_l + multiplier * m_f) / (m_l + multiplier * multiplier * m_f);
  for (Precision precision : {Precision::Float, Precision::Double})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      const std::string what = std::string(precision_name(precision)) + " " + solver_name(solver);
      Simulator sim(model, 1, options(precision, solver));
      const double h = sim.options().dt;
      sim.set_state(0, Eigen::Vector2d(0.0, offset), Eigen::Vector2d::Zero());
      sim.step();
      const Eigen::VectorXd v = sim.v(0), q = sim.q(0);
      const double tol = step_tolerance(precision) * std::abs(h * a_l);
      EXPECT_NEAR(v[0], h * a_l, tol) << what;
      EXPECT_NEAR(v[1], multiplier * h * a_l, tol) << what;
      // q carries its own rounding: an ulp of the offset in float
      const double eps = step_tolerance(precision) / 64;
      EXPECT_NEAR(q[1] - multiplier * q[0] - offset, 0.0, 4 * eps * offset + 4 * tol * h) << what;
      EXPECT_GT(std::abs(v[0] - (-kGravity * h)), 0.1 * kGravity * h) << what << ": the row acts";
    }
}

// A violation e_0 of the tag, the sliders at rest and weightless: the row
// asks for J u = -erp e / dt, so each step removes the share erp of the
// error: e_n = e_0 (1 - erp)^n, in either direction, to rounding (double).
TEST(MimicJoints, AViolationShrinksByTheErrorReductionEachStep) {
  const Model model = sliders(1.0, 4.0, 1.5, -0.02);
  for (double e0 : {0.01, -0.03}) {
    StepOptions o = options(Precision::Double, SolverType::PGS);
    o.error_reduction = 0.25;
    Simulator sim(model, 1, o);
    sim.set_gravity(0, Eigen::Vector3d::Zero());
    sim.set_state(0, Eigen::Vector2d(0.2, 1.5 * 0.2 - 0.02 + e0), Eigen::Vector2d::Zero());
    for (int n = 1; n <= 20; ++n) {
      sim.step();
      const Eigen::VectorXd q = sim.q(0);
      const double e = q[1] - 1.5 * q[0] + 0.02;
      EXPECT_NEAR(e, e0 * std::pow(0.75, n), 1e-14) << "e0 " << e0 << ", step " << n;
    }
  }
}

// panda's second finger follows its first (mimic multiplier 1): from the
// ready pose, the arm and both fingers driven to targets of their own (the
// fingers' apart) for 1 s, then the first finger past its upper limit
// 0.04 m, which holds (the limits come after the mimic rows, as in PhysX).
// The fingers' own velocity limits are lifted: they would fight the mimic
// row while the drives part the fingers. Measured, how far apart the
// fingers get: PGS 3.7e-9 m in float (an ulp of 0.04) and 7e-18 in double;
// TGS 3.0e-7 in both, from the arm's velocity-limit rows, which the drives
// reach and which the fingers' row is coupled to (TGS sweeps once per
// substep: 5e-8 with 64 iterations; without those rows 3.7e-9 and 7e-18).
// With the stage forced off the drives part them (the check can fail).
TEST(MimicJoints, PandasFingersMoveTogetherAndTheirLimitsHold) {
  const Model model = load_shared_model("panda", false);
  const int f1 = model.dof_index("panda_finger_joint1"), f2 = model.dof_index("panda_finger_joint2");
  for (Precision precision : {Precision::Float, Precision::Double})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS})
      for (StageMode mode : {StageMode::Auto, StageMode::Off}) {
        const std::string what = std::string(precision_name(precision)) + " " + solver_name(solver) +
                                 (mode == StageMode::Off ? ", stage off" : "");
        StepOptions o = options(precision, solver);
        o.force(Stage::MimicJoints, mode);
        std::vector<DofSettings> dofs = default_dof_settings(model);
        for (DofSettings& d : dofs) d.drive_stiffness = 400, d.drive_damping = 40;
        dofs[f1].velocity_limit = dofs[f2].velocity_limit = Model::kInfinity;  // see the comment above
        Simulator sim(model, 4, o, dofs);
        EXPECT_EQ(sim.plan()[static_cast<int>(Stage::MimicJoints)].runs, mode == StageMode::Auto) << what;
        std::mt19937 rng(11);
        Eigen::VectorXd ready(model.nq);  // panda's ready pose, fingers closed
        ready << 0, -0.785, 0, -2.356, 0, 1.571, 0.785, 0, 0;
        for (int c = 0; c < sim.copies(); ++c) sim.set_state(c, ready, Eigen::VectorXd::Zero(model.nv));
        double worst = 0, highest = 0;
        for (int phase = 0; phase < 2; ++phase) {
          for (int c = 0; c < sim.copies(); ++c) {
            Eigen::VectorXd target = ready + 0.3 * random_vector(model.nq, rng);
            target[f1] = phase == 0 ? 0.01 + 0.005 * c : 0.08;  // then past the upper limit
            target[f2] = phase == 0 ? 0.035 - 0.005 * c : 0.0;  // against the first
            sim.set_drive_target(c, target, Eigen::VectorXd::Zero(model.nv));
          }
          for (int i = 0; i < 500; ++i) {
            sim.step();
            for (int c = 0; c < sim.copies(); ++c) {
              const Eigen::VectorXd q = sim.q(c);
              worst = std::max(worst, std::abs(q[f2] - q[f1]));
              highest = std::max(highest, q[f1]);
            }
          }
        }
        if (mode == StageMode::Off) {
          EXPECT_GT(worst, 0.01) << what << ": the drives part the fingers";
          continue;
        }
        std::cout << "[mimic] panda's fingers, " << what << ": apart by at most " << worst << " m\n";
        const double apart = solver == SolverType::TGS ? 1e-6 : precision == Precision::Float ? 2e-8 : 1e-15;
        EXPECT_LE(worst, apart) << what;
        EXPECT_LE(highest, 0.04 + (precision == Precision::Float ? 2e-8 : 1e-15)) << what;
        EXPECT_GT(highest, 0.0399) << what << ": the first finger reaches its limit";
        EXPECT_EQ(sim.fault_count(), 0) << what;
      }
}

// The SIMD lanes give the scalar path's bits: panda with its mimic row,
// hard limits, velocity limits and friction, random states and drives, 19
// copies (padding lanes in the last block).
TEST(MimicJoints, SimdLanesMatchTheScalarPath) {
  const Model model = load_shared_model("panda", false);
  const std::vector<DofSettings> dofs = limited_dofs(model, 0.5, 1.0);
  expect_simd_lanes_match_the_scalar_path(model, dofs, 19, 40u, 20);
}

// Tags added or edited in a Model by hand are checked as the step takes
// them, each named by its index (DOFs out of range even with the stage
// forced off, whose warning names them); several tags on one DOF are
// allowed.
TEST(MimicJoints, TagsTheStepCannotTakeAreRefusedByIndex) {
  auto expect_refused = [&](const Model& base, Mimic mimic, const std::string& piece, bool even_off) {
    Model model = base;
    model.mimics.push_back(mimic);
    const std::string index = "Model::mimics[" + std::to_string(model.mimics.size() - 1) + "]: ";
    EXPECT_THROW_WITH(Simulator(model, 1), std::invalid_argument, index + piece);
    StepOptions off;
    off.force(Stage::MimicJoints, StageMode::Off);
    if (even_off) {
      EXPECT_THROW_WITH(Simulator(model, 1, off), std::invalid_argument, index + piece);
    } else {
      EXPECT_NO_THROW(Simulator(model, 1, off).warnings()) << piece;
    }
  };
  const Model base = sliders(1.0, 1.0, 2.0, 0.0);
  expect_refused(base, {0, 2, 1.0, 0.0}, "dof 0 and leader_dof 2 must be DOFs of the model (of 2)", true);
  expect_refused(base, {-1, 0, 1.0, 0.0}, "dof -1 and leader_dof 0", true);
  expect_refused(base, {1, 1, 1.0, 0.0}, "follower_joint follows itself", false);
  expect_refused(base, {0, 1, 1e39, 0.0}, "multiplier and offset must be finite (in float", false);
  expect_refused(base, {0, 1, 1.0, std::nan("")}, "multiplier and offset must be finite", false);
  const Model anymal = load_shared_model("anymal_b", true);  // DOF 0 is the free root's
  const int knee = anymal.dof_index("LF_KFE");
  expect_refused(anymal, {knee, 0, 1.0, 0.0},
                 "dof " + std::to_string(knee) + " and leader_dof 0 must be DOFs of revolute or prismatic joints",
                 false);
  Model twice = base;
  twice.mimics.push_back({1, 0, 2.0, 0.0});  // the same tag again: consistent, redundant
  Simulator sim(twice, 1, options(Precision::Double, SolverType::PGS));
  sim.step(10);
  const Eigen::VectorXd q = sim.q(0);
  EXPECT_NEAR(q[1] - 2.0 * q[0], 0.0, 1e-12);
}

// A snapshot restores only into a simulator whose mimic rows couple the
// same DOFs (its warm start is theirs).
TEST(MimicJoints, ASnapshotRestoresOnlyWhereTheTagsCoupleTheSameDofs) {
  const Model model = load_shared_model("panda", false);
  Model other = model;
  other.mimics.front().leader_dof = 1;
  Simulator a(model, 1), b(model, 1), c(other, 1);
  a.step(3);
  EXPECT_NO_THROW(b.restore(0, a.snapshot(0)));
  EXPECT_THROW_WITH(c.restore(0, a.snapshot(0)), std::invalid_argument, "restore");
}

// A VecEnv takes no action for a mimic follower: panda has 8 action
// columns (the arm's 7, the first finger), and the second finger's
// position target follows the first's, so that both drives agree with the
// tag; both fingers reach the commanded opening. With the stage forced off
// each finger is its own column again. (Without gravity, so that the
// drives reach their targets.)
TEST(MimicJoints, AVecEnvActsOnTheLeaderAndTheFollowersTargetFollows) {
  Model model = load_shared_model("panda", false);
  model.gravity.setZero();
  const int f1 = model.dof_index("panda_finger_joint1"), f2 = model.dof_index("panda_finger_joint2");
  VecEnvOptions o;
  o.action_mode = ActionMode::PositionTarget;
  o.dofs = default_dof_settings(model);
  for (DofSettings& d : o.dofs) d.drive_stiffness = 400, d.drive_damping = 40;
  o.initial_q = Eigen::VectorXd::Zero(model.nq);
  o.initial_q << 0, -0.785, 0, -2.356, 0, 1.571, 0.785, 0, 0;
  o.drive_target_q = o.initial_q;
  o.drive_target_q[f1] = 0.02;  // the second finger's target follows: 0.02, not its own 0
  VecEnv env(model, 3, o);
  EXPECT_EQ(env.options().drive_target_q[f2], 0.02);
  ASSERT_EQ(env.action_size(), 8);
  EXPECT_EQ(env.action_names().back(), "panda_finger_joint1");
  env.reset();
  RowMatrix actions(3, 8);
  for (int c = 0; c < 3; ++c) actions.row(c) = env.position_action(o.initial_q);
  for (int c = 0; c < 3; ++c) actions(c, 7) = 0.01 * (c + 1);
  for (int i = 0; i < 500; ++i) env.step(actions);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(env.simulator().batch<float>().target_q.at(c, f2), env.simulator().batch<float>().target_q.at(c, f1));
    const Eigen::VectorXd q = env.simulator().q(c);
    EXPECT_NEAR(q[f1], 0.01 * (c + 1), 1e-4) << "copy " << c;
    EXPECT_NEAR(q[f2], q[f1], 2e-8) << "copy " << c;
  }
  o.step.force(Stage::MimicJoints, StageMode::Off);
  EXPECT_EQ(VecEnv(model, 1, o).action_size(), 9);
}

// Forced off, the plan and the warnings say the tags are not enforced;
// left to the plan, they are, and nothing is said.
TEST(MimicJoints, ThePlanSaysWhetherTheyAreEnforced) {
  const Model panda_model = load_shared_model("panda", false);
  const Simulator panda(panda_model, 1);
  EXPECT_TRUE(panda.plan()[static_cast<int>(Stage::MimicJoints)].runs);
  EXPECT_TRUE(panda.warnings().empty());
  EXPECT_NE(panda.describe_plan().find("  mimic joints: runs (1 mimic tags)"), std::string::npos)
      << panda.describe_plan();
  StepOptions off;
  off.force(Stage::MimicJoints, StageMode::Off);
  const Simulator unenforced(panda_model, 1, off);
  const std::string line =
      "mimic joints: not enforced, their stage forced off (1 mimic tag(s), such as panda_finger_joint2 following "
      "panda_finger_joint1; each DOF moves on its own)";
  EXPECT_EQ(unenforced.warnings(), std::vector<std::string>{line});
  EXPECT_NE(unenforced.describe_plan().find("  " + line + "\n"), std::string::npos) << unenforced.describe_plan();
}

}  // namespace
}  // namespace lockstep::test
