// Fixed tendons (Stage::FixedTendons, PhysX's fixed tendon): a length l =
// sum_i c_i q_i with an implicit spring-damper towards rest_length + offset
// and length limits, hard or springy. Checked against a joint spring (a
// tendon on one joint is one), the steady stretch of a stiff coupling of
// two sliders pushed as one body, limits that hold exactly or by the
// spring's deflection, the SIMD lanes against the scalar path, and the
// checks of the tendons a caller adds.
#include "tests/sim_support.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace lockstep::test {
namespace {

constexpr double kFloatEps = std::numeric_limits<float>::epsilon();

// Sliders along world z on a fixed base, masses `masses`, no gravity.
Model sliders(const std::vector<double>& masses) {
  ArticulationSpec spec;
  spec.name = "sliders";
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  for (std::size_t i = 0; i < masses.size(); ++i) {
    LinkSpec link = joint_link("slider" + std::to_string(i), "base", JointType::Prismatic, Eigen::Vector3d::UnitZ(),
                               Eigen::Vector3d::Zero());
    link.inertial.mass = masses[i];
    link.inertial.inertia = masses[i] * Eigen::Matrix3d::Identity();
    spec.links.push_back(link);
  }
  Model model = build(spec);
  model.gravity.setZero();
  return model;
}

FixedTendon tendon(std::vector<TendonJoint> joints) {
  FixedTendon t;
  t.name = "tendon";
  t.joints = std::move(joints);
  return t;
}

StepOptions options(Precision precision, SolverType solver, double dt) {
  StepOptions o;
  o.dt = dt;
  o.precision = precision;
  o.solver = solver;
  return o;
}

std::string what(Precision precision, SolverType solver) {
  return std::string(precision_name(precision)) + " " + solver_name(solver);
}

// A tendon on one joint with coefficient c, stiffness k, damping d and
// rest length plus offset l0 is the joint's spring of stiffness c^2 k,
// damping c^2 d and rest position l0 / c: the step takes both by backward
// Euler (docs/conventions.md), the joint's in Mt's diagonal and the
// tendon's as a compliant row, so the two pendulums (under gravity, 2 s)
// agree to rounding, and the tendon's torque is reported with the passive
// ones. Tolerances: the two paths round differently (a row through Mt^-1
// against a diagonal inside ABA), a few ulps per step, carried by a
// pendulum that swings through 0.95 rad: measured at most 1.5e-7 rad and
// 2.9e-6 rad/s (float), 1.3e-16 rad and 2.7e-15 rad/s (double); bounds
// 1e-6 and 1e-13 on the angle, 50 times those on the rate.
TEST(FixedTendons, ATendonOnOneJointIsThatJointsSpring) {
  const Model plain = rod_chain({1.5}, 0.8);
  const double c = -2.0, k = 30.0, d = 0.4, rest = 0.3, offset = -0.1;
  Model tendoned = plain;
  FixedTendon t = tendon({{0, c}});
  t.stiffness = k, t.damping = d, t.rest_length = rest, t.offset = offset;
  tendoned.fixed_tendons.push_back(t);
  std::vector<DofSettings> spring = default_dof_settings(plain);
  spring[0].spring_stiffness = c * c * k;
  spring[0].damping = c * c * d;
  spring[0].spring_rest = (rest + offset) / c;
  for (Precision precision : {Precision::Float, Precision::Double})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      StepOptions o = options(precision, solver, 0.004);
      o.record_applied_torque = true;
      Simulator a(tendoned, 1, o), b(plain, 1, o, spring);
      ASSERT_TRUE(a.plan()[static_cast<int>(Stage::FixedTendons)].runs);
      ASSERT_EQ(a.row_count(), 1);
      for (Simulator* sim : {&a, &b}) sim->set_state(0, Eigen::VectorXd::Constant(1, 0.5), Eigen::VectorXd::Zero(1));
      const double tol = precision == Precision::Float ? 1e-6 : 1e-13;
      double swing = 0;
      for (int n = 0; n < 500; ++n) {
        a.step();
        b.step();
        ASSERT_NEAR(a.q(0)[0], b.q(0)[0], tol) << what(precision, solver) << ", step " << n;
        ASSERT_NEAR(a.v(0)[0], b.v(0)[0], 50 * tol) << what(precision, solver) << ", step " << n;
        const double passive = b.applied_torque(0).passive[0];
        ASSERT_NEAR(a.applied_torque(0).passive[0], passive, 50 * tol * (1 + std::abs(passive)))
            << what(precision, solver) << ", step " << n;
        swing = std::max(swing, std::abs(a.q(0)[0] - 0.5));
      }
      EXPECT_GT(swing, 0.3) << what(precision, solver) << ": the pendulum swings";
    }
}

// Two sliders tied by l = q_0 - q_1 (PhysX's mirrored joints), slider 0
// pushed by F, no gravity: together they accelerate at a = F / (m_0 +
// m_1), so the tendon pulls slider 1 with m_1 a, stretched by
// l = m_1 F / (k (m_0 + m_1)) once its damping has settled the stretch.
// From a soft tendon to one a million times stiffer, at dt = 1/60 (the
// stiff one's period 0.4 ms, far below the step): the stretch matches to
// 1 % and nothing diverges, where the same stiffness as an explicit force
// would (its k h^2 / m is 5.6e4 > 4 for the 0.5 kg slider). Measured: 4e-14
// to 8e-8 of the stretch in double. In float the slider has moved 15 m,
// whose ulp (1e-6 m) is above the stiffer tendons' stretch (6e-5 m down to
// 6e-9 m): there the bound adds q's rounding, 4 float eps q_0 (measured
// 3.5e-7 m at most).
TEST(FixedTendons, AStiffTendonMovesTwoSlidersAsOneBody) {
  const double m0 = 2.0, m1 = 0.5, F = 3.0, dt = 1.0 / 60.0;
  for (double k : {1e2, 1e4, 1e6, 1e8}) {
    Model model = sliders({m0, m1});
    FixedTendon t = tendon({{0, 1.0}, {1, -1.0}});
    t.stiffness = k;
    t.damping = 2.0 * std::sqrt(k * m1);
    model.fixed_tendons.push_back(t);
    for (Precision precision : {Precision::Float, Precision::Double})
      for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
        const std::string at = what(precision, solver) + ", k " + std::to_string(k);
        Simulator sim(model, 1, options(precision, solver, dt));
        sim.set_torque(0, Eigen::Vector2d(F, 0.0));
        sim.step(300);  // 5 s
        const Eigen::VectorXd q = sim.q(0), v = sim.v(0);
        const double stretch = m1 * F / (k * (m0 + m1)), a = F / (m0 + m1), t_end = 300 * dt;
        const double rounding = precision == Precision::Float ? 4 * kFloatEps * q[0] : 0.0;
        EXPECT_NEAR(q[0] - q[1], stretch, 0.01 * stretch + rounding) << at;
        EXPECT_NEAR(v[1], a * t_end, 0.01 * a * t_end) << at;
        EXPECT_EQ(sim.fault_count(), 0) << at;
      }
  }
}

// Hard length limits hold: sliders with l = q_0 + 2 q_1 <= 0.1, both pushed
// up, with joint damping so that they settle. At rest on the limit, l =
// 0.1 to rounding; on the way, speculative (the row may close the gap
// exactly), never past it by more than rounding: measured 1.5e-8 (float)
// and 2.8e-17 (double) past it at most, bounds 1e-7 and 1e-15. Pushed by
// F (1, 2) along the tendon's J, a springy limit of stiffness k_l gives way
// by F / k_l (measured to 1e-8 in float, exactly in double).
TEST(FixedTendons, LengthLimitsHoldHardOrGiveWayAsSprings) {
  const double upper = 0.1, F = 2.0, k_limit = 400.0;
  for (const bool hard : {true, false}) {
    Model model = sliders({1.0, 3.0});
    FixedTendon t = tendon({{0, 1.0}, {1, 2.0}});
    t.upper_limit = upper;
    t.lower_limit = -1.0;
    if (!hard) t.limit_stiffness = k_limit;
    model.fixed_tendons.push_back(t);
    std::vector<DofSettings> dofs = default_dof_settings(model);
    for (DofSettings& d : dofs) d.damping = 8.0;
    for (Precision precision : {Precision::Float, Precision::Double})
      for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
        const std::string at = what(precision, solver) + (hard ? ", hard" : ", spring");
        Simulator sim(model, 1, options(precision, solver, 0.005), dofs);
        sim.set_torque(0, Eigen::Vector2d(F, 2.0 * F));
        const double eps = precision == Precision::Float ? 1e-7 : 1e-15;
        double highest = -1;
        for (int n = 0; n < 2000; ++n) {
          sim.step();
          const Eigen::VectorXd q = sim.q(0);
          highest = std::max(highest, q[0] + 2.0 * q[1]);
        }
        const Eigen::VectorXd q = sim.q(0);
        if (hard) {
          EXPECT_LE(highest, upper + eps) << at;
          EXPECT_NEAR(q[0] + 2.0 * q[1], upper, eps) << at;
        } else {
          EXPECT_NEAR(q[0] + 2.0 * q[1], upper + F / k_limit, 1e-4 * F / k_limit + eps) << at;
        }
        EXPECT_LT(sim.v(0).norm(), 1e-6) << at << ": at rest";
      }
  }
}

// The SIMD lanes give the scalar path's bits: anymal_b with a spring
// tendon tying its front knees and a limited one over three hind joints,
// beside hard limits, velocity limits and friction, random states and
// drives, 19 copies (padding lanes in the last block).
TEST(FixedTendons, SimdLanesMatchTheScalarPath) {
  Model model = load_shared_model("anymal_b", true);
  FixedTendon knees = tendon({{model.dof_index("LF_KFE"), 1.0}, {model.dof_index("RF_KFE"), 1.0}});
  knees.stiffness = 200.0, knees.damping = 2.0, knees.rest_length = -0.2;
  FixedTendon hind = tendon({{model.dof_index("LH_HFE"), 0.5},
                             {model.dof_index("LH_KFE"), -1.0},
                             {model.dof_index("RH_KFE"), 0.25}});
  hind.name = "hind", hind.lower_limit = -0.1, hind.upper_limit = 0.1;
  model.fixed_tendons = {knees, hind};
  const std::vector<DofSettings> dofs = limited_dofs(model, 0.5, 1.0);
  expect_simd_lanes_match_the_scalar_path(model, dofs, 19, 70u, 20);
}

// A tendon is a solver row: RK4 refuses it, the plan says whether it runs,
// and forced off the warnings say that it is not enforced.
TEST(FixedTendons, ThePlanSaysWhetherTheyAreEnforced) {
  Model model = sliders({1.0, 1.0});
  FixedTendon t = tendon({{0, 1.0}, {1, 1.0}});
  t.stiffness = 10.0;
  model.fixed_tendons.push_back(t);
  const Simulator on(model, 1);
  EXPECT_TRUE(on.plan()[static_cast<int>(Stage::FixedTendons)].runs);
  EXPECT_NE(on.describe_plan().find("fixed tendons: runs (1 fixed tendons with a spring or limits)"),
            std::string::npos)
      << on.describe_plan();
  StepOptions off;
  off.force(Stage::FixedTendons, StageMode::Off);
  const Simulator skipped(model, 1, off);
  EXPECT_EQ(skipped.row_count(), 0);
  const std::vector<std::string> warnings = skipped.warnings();
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("fixed tendons: not enforced"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("'tendon'"), std::string::npos) << warnings[0];
  StepOptions rk4;
  rk4.integrator = Integrator::RK4;
  EXPECT_THROW_WITH(Simulator(model, 1, rk4), std::invalid_argument, "fixed tendons (1 fixed tendons with a spring");
  // a tendon without a spring or limits has no rows: nothing runs, RK4
  // takes it, and nothing is said of it
  Model idle = model;
  idle.fixed_tendons[0].stiffness = 0.0;
  const Simulator quiet(idle, 1, rk4);
  EXPECT_FALSE(quiet.plan()[static_cast<int>(Stage::FixedTendons)].runs);
  EXPECT_TRUE(quiet.warnings().empty());
}

// Tendons added to a Model by hand are checked, each named by its index
// and name, whether the stage runs or not.
TEST(FixedTendons, TendonsTheStepCannotTakeAreRefusedByIndexAndName) {
  const Model base = sliders({1.0, 1.0});
  auto expect_refused = [&](const Model& from, FixedTendon t, const std::string& piece) {
    Model model = from;
    model.fixed_tendons.push_back(t);
    const std::string index = "Model::fixed_tendons[0] ('tendon'): ";
    EXPECT_THROW_WITH(Simulator(model, 1), std::invalid_argument, index + piece);
    StepOptions off;
    off.force(Stage::FixedTendons, StageMode::Off);
    EXPECT_THROW_WITH(Simulator(model, 1, off), std::invalid_argument, index + piece);
  };
  expect_refused(base, tendon({}), "has no joints");
  // names: scene files write them and read them back, errors quote them
  Model named = base;
  named.fixed_tendons = {tendon({{0, 1.0}}), tendon({{1, 1.0}})};
  EXPECT_THROW_WITH(Simulator(named, 1), std::invalid_argument,
                    "Model::fixed_tendons[1] ('tendon'): its name is also fixed_tendons[0]'s");
  named.fixed_tendons[1].name.clear();
  EXPECT_THROW_WITH(Simulator(named, 1), std::invalid_argument, "Model::fixed_tendons[1] (''): has no name");
  expect_refused(base, tendon({{0, 1.0}, {2, 1.0}}), "joints[1]: dof 2 must be a DOF of the model (of 2)");
  expect_refused(base, tendon({{0, 1.0}, {1, 0.0}}),
                 "joints[1]: coefficient must be nonzero, a normal number and finite");
  expect_refused(base, tendon({{0, 1e39}}),
                 "joints[0]: coefficient must be nonzero, a normal number and finite (in float");
  expect_refused(base, tendon({{0, 1e-46}}), "joints[0]: coefficient must be nonzero, a normal number");  // 0 in float
  expect_refused(base, tendon({{1, 1.0}, {0, 1.0}, {1, 2.0}}),
                 "joints[2]: slider1_joint appears twice (also joints[0])");
  FixedTendon negative = tendon({{0, 1.0}});
  negative.damping = -1.0;
  expect_refused(base, negative, "damping must be non-negative");
  FixedTendon reversed = tendon({{0, 1.0}});
  reversed.lower_limit = 0.2, reversed.upper_limit = 0.1;
  expect_refused(base, reversed, "lower_limit and upper_limit must be ordered");
  FixedTendon upside = tendon({{0, 1.0}});
  upside.lower_limit = std::numeric_limits<double>::infinity();
  expect_refused(base, upside, "lower_limit and upper_limit must be ordered");
  // a units mistake: 1e-40 N/m gives an infinite compliance 1 / (h (k h + c))
  // in float (h 2 ms); the same gains are refused for a contact
  FixedTendon faint = tendon({{0, 1.0}});
  faint.stiffness = 1e-40;
  expect_refused(base, faint, "stiffness 1e-40, damping 0 and limit_stiffness 0 must each be 0 or large enough");
  FixedTendon faint_limit = tendon({{0, 1.0}});
  faint_limit.upper_limit = 0.1, faint_limit.limit_stiffness = 1e-40;
  expect_refused(base, faint_limit, "stiffness 0, damping 0 and limit_stiffness 1e-40 must each be 0 or large enough");
  EXPECT_NO_THROW(Simulator(base, 1, options(Precision::Double, SolverType::PGS, 0.002)));
  StepOptions faint_contacts;
  faint_contacts.contacts.stiffness = 1e-40;
  EXPECT_THROW_WITH(Simulator(base, 1, faint_contacts), std::invalid_argument,
                    "ContactSettings::stiffness 1e-40 N/m and damping 0 N s/m are too small for float");
  faint_contacts.precision = Precision::Double;
  EXPECT_NO_THROW(Simulator(base, 1, faint_contacts));
  FixedTendon nan_rest = tendon({{0, 1.0}});
  nan_rest.rest_length = std::nan("");
  expect_refused(base, nan_rest, "rest_length and offset must be finite");
  const Model anymal = load_shared_model("anymal_b", true);  // DOF 0 is the free root's
  expect_refused(anymal, tendon({{0, 1.0}}), "joints[0]: " + anymal.dof_name[0] + " is a DOF of a free joint");
}

// A snapshot restores only into a simulator whose tendon rows act on the
// same DOFs, split the same way into rows (its warm start is theirs).
TEST(FixedTendons, ASnapshotRestoresOnlyWhereTheTendonsSpanTheSameDofs) {
  Model model = sliders({1.0, 1.0, 1.0});
  FixedTendon t = tendon({{0, 1.0}, {1, 1.0}});
  t.stiffness = 10.0;
  model.fixed_tendons.push_back(t);
  Model other = model;
  other.fixed_tendons[0].joints[1].dof = 2;
  Simulator a(model, 1), b(model, 1), c(other, 1);
  a.set_state(0, Eigen::Vector3d(0.1, 0.2, 0.0), Eigen::Vector3d::Zero());
  a.step(3);
  EXPECT_NO_THROW(b.restore(0, a.snapshot(0)));
  EXPECT_THROW_WITH(c.restore(0, a.snapshot(0)), std::invalid_argument, "restore");
  // the same DOFs split otherwise: {0, 1} and {2} against {0} and {1, 2}
  Model split = model, resplit = model;
  split.fixed_tendons.push_back(tendon({{2, 1.0}}));
  split.fixed_tendons[1].name = "second";
  split.fixed_tendons[1].stiffness = 10.0;
  resplit.fixed_tendons = split.fixed_tendons;
  resplit.fixed_tendons[0].joints = {{0, 1.0}};
  resplit.fixed_tendons[1].joints = {{1, 1.0}, {2, 1.0}};
  Simulator d(split, 1), e(resplit, 1);
  d.step(3);
  EXPECT_THROW_WITH(e.restore(0, d.snapshot(0)), std::invalid_argument, "restore");
}

}  // namespace
}  // namespace lockstep::test
