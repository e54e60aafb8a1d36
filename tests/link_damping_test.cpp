// Link damping (LinkSpec::linear_damping and angular_damping, PhysX's linear
// and angular damping of a link; docs/conventions.md, "Link damping"): the
// wrench -D v on each damped body, D the rigid inertia with mass c_lin m and
// rotational inertia c_ang I_c. Checked against a free body's closed-form
// decay under each integrator, against Jacobians on every model (the force)
// and against the exponential decay of kinetic energy that uniform damping
// gives any articulation, for ABA and RNEA being each other's inverse with
// it, for the SIMD lanes against the scalar path, and for its stage, its
// checks and its scene file key.
#include "batch/copy_dynamics.hpp"
#include "io/scene_file.hpp"
#include "kernels/aba.hpp"
#include "kernels/rnea.hpp"
#include "layout/batch_state.hpp"
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <iostream>

namespace lockstep::test {
namespace {

namespace fs = std::filesystem;

// `model` with damping on every body: linear c_lin + 0.5 b, angular c_ang + 0.25 b
// (b the body's index), so that no two bodies share a value.
Model damped(Model model, double linear, double angular) {
  for (int b = 0; b < model.nbody; ++b) {
    model.body_linear_damping[b] = linear + 0.5 * b;
    model.body_angular_damping[b] = angular + 0.25 * b;
  }
  return model;
}

// Uniform damping c on every body, linear and angular: D = c times the
// body's spatial inertia, so the generalized force is -c M v (M without
// armature).
Model uniformly_damped(Model model, double c) {
  std::fill(model.body_linear_damping.begin(), model.body_linear_damping.end(), c);
  std::fill(model.body_angular_damping.begin(), model.body_angular_damping.end(), c);
  return model;
}

// ---- the model

TEST(LinkDamping, TheBuilderKeepsEachBodysValuesAndChecksThem) {
  ArticulationSpec spec;
  spec.name = "arm";
  spec.links.push_back(massive_link("base", "", JointType::Fixed, Eigen::Vector3d::UnitZ(), 2.0));
  spec.links.push_back(massive_link("arm", "base", JointType::Revolute, Eigen::Vector3d::UnitY(), 1.0));
  spec.links.push_back(massive_link("glove", "arm", JointType::Fixed, Eigen::Vector3d::UnitZ(), 0.3));
  spec.links[1].linear_damping = spec.links[2].linear_damping = 0.5;
  spec.links[1].angular_damping = spec.links[2].angular_damping = 2.0;
  const Model m = build(spec);
  EXPECT_EQ(m.body_linear_damping, std::vector<double>{0.5});
  EXPECT_EQ(m.body_angular_damping, std::vector<double>{2.0});
  EXPECT_EQ(m.damped_bodies(), 1);
  EXPECT_EQ(load_shared_model("anymal_b", true).damped_bodies(), 0);  // none by default

  ModelBuilder builder;
  ArticulationSpec glove = spec;
  glove.links[2].angular_damping = 1.0;
  EXPECT_MODEL_ERROR(builder.add_articulation(glove), "link 'glove'", "damping linear 0.5, angular 1",
                     "fixed to link 'arm', which has damping linear 0.5, angular 2",
                     "damping is set per moving body");
  glove.links[2].inertial = InertialSpec{};  // a massless frame has nothing to damp
  EXPECT_EQ(build(glove).body_angular_damping, std::vector<double>{2.0});
  for (double bad : {-0.1, std::nan(""), Model::kInfinity}) {
    ArticulationSpec wrong = spec;
    wrong.links[1].linear_damping = bad;
    EXPECT_MODEL_ERROR(builder.add_articulation(wrong), "link 'arm'", "linear damping must be a finite number >= 0");
  }
}

// ---- the kernels

// ABA and RNEA of one copy in double on the scalar lane, with the step's
// link damping at weight w.
struct DampedKernels {
  explicit DampedKernels(const Model& model) : km(model), ws(km), state(model, 1, 1) {}
  BlockInputs<double> inputs(const Eigen::VectorXd& q, const Eigen::VectorXd& v, double w) {
    state.q.set(0, q);
    state.v.set(0, v);
    BlockInputs<double> in;
    in.q = state.q.block(0);
    in.v = state.v.block(0);
    in.inertia = state.inertia.block(0);
    in.gravity = state.gravity.block(0);
    in.link_damping = true;
    in.link_damping_weight = w;
    joint_transforms<double>(km, in.q, ws);
    world_transforms<double>(km, ws);
    return in;
  }
  Eigen::VectorXd forward(const Eigen::VectorXd& q, const Eigen::VectorXd& v, const Eigen::VectorXd& tau, double w) {
    BlockInputs<double> in = inputs(q, v, w);
    in.tau = tau.data();
    Eigen::VectorXd qacc(km.nv);
    aba<double>(km, in, ws, qacc.data());
    return qacc;
  }
  Eigen::VectorXd inverse(const Eigen::VectorXd& q, const Eigen::VectorXd& v, const Eigen::VectorXd& qacc, double w,
                          bool damping = true) {
    BlockInputs<double> in = inputs(q, v, w);
    in.link_damping = damping;
    in.qacc = qacc.data();
    Eigen::VectorXd tau(km.nv);
    rnea<double>(km, in, ws, tau.data());
    return tau;
  }
  KernelModel<double> km;
  Workspace<double> ws;
  BatchState<double> state;
};

class LinkDampingModels : public ::testing::TestWithParam<ModelCase> {};

// The damping force alone, taken explicitly (w = 0) at rest acceleration:
// RNEA's joint forces with it less those without it are J^T D J v
// (test::link_damping_matrix, from the bodies' Jacobians). Both sides sum the same products in another
// order: measured at most 2.1e-15 of the largest entry; asserted 1e-12.
TEST_P(LinkDampingModels, TheForceIsTheJacobiansTransposeTimesTheBodiesDamping) {
  const Model model = damped(load_model_case(GetParam()), 0.7, 1.3);
  DampedKernels k(model);
  std::mt19937 rng(21);
  double worst = 0;
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::VectorXd q = random_configuration(model, rng), v = random_vector(model.nv, rng, 2.0);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    const Eigen::VectorXd force = k.inverse(q, v, zero, 0.0) - k.inverse(q, v, zero, 0.0, false);
    const Eigen::VectorXd expected = link_damping_matrix(model, q) * v;
    worst = std::max(worst, (force - expected).cwiseAbs().maxCoeff() / std::max(1.0, expected.cwiseAbs().maxCoeff()));
  }
  std::cout << "[link damping] " << case_name(GetParam()) << ": J^T D J v within " << worst << "\n";
  EXPECT_LE(worst, 1e-12);
}

// ABA with the damping taken at the end of the step (w = 5 ms: its w D in
// the articulated inertias) and RNEA with it (the force at v + w a) are
// each other's inverse: RNEA(q, v, ABA(q, v, tau)) = tau. Measured at most
// 1.4e-13 of the largest torque (double_pendulum floating); asserted 1e-11.
TEST_P(LinkDampingModels, AbaAndRneaWithItAreEachOthersInverse) {
  const Model model = damped(load_model_case(GetParam()), 2.0, 3.0);
  DampedKernels k(model);
  std::mt19937 rng(22);
  double worst = 0;
  for (double w : {0.0, 0.005}) {
    const Eigen::VectorXd q = random_configuration(model, rng), v = random_vector(model.nv, rng, 2.0);
    const Eigen::VectorXd tau = random_vector(model.nv, rng, 10.0);
    const Eigen::VectorXd qacc = k.forward(q, v, tau, w);
    const Eigen::VectorXd back = k.inverse(q, v, qacc, w);
    worst = std::max(worst, (back - tau).cwiseAbs().maxCoeff() / tau.cwiseAbs().maxCoeff());
  }
  std::cout << "[link damping] " << case_name(GetParam()) << ": RNEA(ABA) within " << worst << "\n";
  EXPECT_LE(worst, 1e-11);
}

INSTANTIATE_TEST_SUITE_P(AllModels, LinkDampingModels, ::testing::ValuesIn(all_model_cases()),
                         [](const auto& info) { return case_name(info.param); });

// ---- the step

// A sphere (isotropic inertia, COM at its origin) with damping `c` both ways.
Model damped_sphere(double c) {
  Model model = single_body(ShapeType::Sphere, Eigen::Vector3d(0.1, 0, 0), 2.0);
  model.body_linear_damping[0] = model.body_angular_damping[0] = c;
  return model;
}

// One step's factor on a damped velocity, x = h c, for each integrator:
// backward Euler 1 / (1 + x) (both Eulers), Heun's 1 - x + x^2/2 for the
// trapezoid, RK4's 1 - x + x^2/2 - x^3/6 + x^4/24.
double decay_factor(Integrator integrator, double x) {
  switch (integrator) {
    case Integrator::Trapezoid: return 1 - x + x * x / 2;
    case Integrator::RK4: return 1 - x + x * x / 2 - x * x * x / 6 + x * x * x * x / 24;
    default: return 1 / (1 + x);
  }
}

// A free sphere without gravity, moving, or spinning about z: each step
// scales the velocity by the integrator's factor (decay_factor), to
// rounding (measured at most 4.3e-15 relative over 50 steps, from the
// factor's own rounding compounded; asserted 1e-13).
TEST(LinkDamping, AFreeBodysVelocitiesDecayByEachIntegratorsFactor) {
  const double c = 4.0, h = 0.01;
  const Model model = damped_sphere(c);
  Eigen::VectorXd moving(6), spinning(6);
  moving << 1.5, -0.5, 0.25, 0, 0, 0;
  spinning << 0, 0, 0, 0, 0, 3.0;
  for (Integrator integrator :
       {Integrator::SemiImplicitEuler, Integrator::ExplicitEuler, Integrator::Trapezoid, Integrator::RK4})
    for (const Eigen::VectorXd& v0 : {moving, spinning}) {
      StepOptions o;
      o.precision = Precision::Double;
      o.dt = h;
      o.integrator = integrator;
      Simulator sim(model, 1, o);
      sim.set_gravity(0, Eigen::Vector3d::Zero());
      sim.set_state(0, model.neutral_configuration(), v0);
      const double factor = decay_factor(integrator, h * c);
      double worst = 0;
      for (int i = 1; i <= 50; ++i) {
        sim.step();
        worst = std::max(worst, (sim.v(0) - std::pow(factor, i) * v0).norm() / (std::pow(factor, i) * v0.norm()));
      }
      std::cout << "[link damping] free sphere, " << integrator_name(integrator) << ": off the factor by " << worst
                << "\n";
      EXPECT_LE(worst, 1e-13) << integrator_name(integrator) << ", v0 " << v0.transpose();
    }
}

// A damped sphere falling from rest, turned so that its body axes are not
// the world's: backward Euler gives v1 = (v0 + h g) / (1 + h c) per step in
// world axes, which tends to the terminal velocity g / c (the implicit
// part's gravity shift, w [R^T g; 0], at work, in the body's axes).
TEST(LinkDamping, AFallingBodyReachesItsTerminalVelocity) {
  const double c = 2.0, h = 0.002;
  const Model model = damped_sphere(c);
  StepOptions o;
  o.precision = Precision::Double;
  o.dt = h;
  Simulator sim(model, 1, o);
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(1.0, Eigen::Vector3d(1, 2, 3).normalized()));
  sim.set_state(0, free_pose(Eigen::Vector3d(0, 0, 1), turn), Eigen::VectorXd::Zero(6));
  const Eigen::Matrix3d R = turn.toRotationMatrix();  // the sphere does not turn: nothing spins it
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  double worst = 0;
  for (int i = 0; i < 3000; ++i) {
    sim.step();
    v = (v + h * model.gravity) / (1 + h * c);
    worst = std::max(worst, (R * sim.v(0).head<3>() - v).norm());
  }
  EXPECT_LE(worst, 1e-12);
  // after 6 s, 4.9 exp(-12) = 3e-5 from it
  EXPECT_LT((R * sim.v(0).head<3>() - model.gravity / c).norm(), 1e-4);
}

// Uniform damping c on every body makes the generalized force -c M v, so
// without gravity or other forces the kinetic energy decays as exp(-2 c t)
// exactly (dT/dt = v^T (M a + 1/2 dM/dt v) = -2 c T): a whole-model check
// of the step. Over 1 s at h = 1 ms the discrete schemes follow it to their
// order: measured 1.0e-3 (semi-implicit Euler, first order) and 3.5e-14
// (RK4) of the exact ratio on ur5, 7.4e-4 and 2.2e-14 on the floating
// anymal_b; asserted 1e-2 and 1e-9.
TEST(LinkDamping, UniformDampingDecaysKineticEnergyExponentially) {
  const double c = 0.8;
  for (const auto& [name, floating] : {std::pair{"ur5", false}, std::pair{"anymal_b", true}}) {
    const Model model = uniformly_damped(load_shared_model(name, floating), c);
    ASSERT_TRUE(std::all_of(model.dof_armature.begin(), model.dof_armature.end(), [](double a) { return a == 0; }));
    std::vector<DofSettings> dofs(model.nv);  // no joint damping, friction or limits
    const CopyDynamics dyn(model);
    std::mt19937 rng(4);
    const Eigen::VectorXd q0 = random_configuration(model, rng), v0 = random_vector(model.nv, rng, 1.0);
    for (const auto& [integrator, tolerance] :
         {std::pair{Integrator::SemiImplicitEuler, 1e-2}, std::pair{Integrator::RK4, 1e-9}}) {
      StepOptions o;
      o.precision = Precision::Double;
      o.dt = 0.001;
      o.integrator = integrator;
      Simulator sim(model, 1, o, dofs);
      sim.set_gravity(0, Eigen::Vector3d::Zero());
      sim.set_state(0, q0, v0);
      sim.step(1000);
      const double ratio = dyn.kinetic_energy(sim.q(0), sim.v(0)) / dyn.kinetic_energy(q0, v0);
      const double error = std::abs(ratio / std::exp(-2 * c) - 1);
      std::cout << "[link damping] " << name << ", " << integrator_name(integrator) << ": T(1 s)/T(0) off exp(-2c) by "
                << error << "\n";
      EXPECT_LE(error, tolerance) << name << ", " << integrator_name(integrator);
    }
  }
}

// anymal_b standing on the ground under PD with damped links, 2 SIMD blocks
// plus a remainder against the scalar path: the same bits, float and double.
TEST(LinkDamping, SimdLanesMatchTheScalarPath) {
  const Model model = damped(load_shared_model("anymal_b", true), 0.5, 1.0);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  for (Precision precision : {Precision::Float, Precision::Double}) {
    StepOptions o;
    o.precision = precision;
    o.contacts.ground = true;
    const int copies = 19;
    std::vector<Simulator> sims;
    for (Lanes lanes : {Lanes::Simd, Lanes::Scalar}) {
      o.lanes = lanes;
      sims.emplace_back(model, copies, o, scene.dofs);
      std::mt19937 rng(9);
      for (int c = 0; c < copies; ++c) {
        sims.back().set_state(c, scene.q0, random_vector(model.nv, rng, 0.5));
        sims.back().set_drive_target(c, scene.q_target, Eigen::VectorXd::Zero(model.nv));
      }
      sims.back().step(40);
    }
    for (int c = 0; c < copies; ++c) EXPECT_TRUE(same_state(sims[0], c, sims[1], c)) << precision_name(precision) << " copy " << c;
  }
}

// The stage: skipped, the damped model steps as the undamped one, bit for
// bit; forced on without damping, as with it skipped.
TEST(LinkDamping, ItsStageCostsNothingWhereItDoesNothing) {
  const Model plain = load_shared_model("ur5", false);
  const Model with = damped(plain, 1.0, 1.0);
  std::mt19937 rng(12);
  const Eigen::VectorXd q0 = random_configuration(plain, rng), v0 = random_vector(plain.nv, rng, 1.0);
  auto run = [&](const Model& model, StageMode mode) {
    StepOptions o;
    o.force(Stage::LinkDamping, mode);
    Simulator sim(model, 1, o);
    sim.set_state(0, q0, v0);
    sim.step(50);
    return sim;
  };
  const Simulator reference = run(plain, StageMode::Auto);
  EXPECT_FALSE(reference.plan()[static_cast<int>(Stage::LinkDamping)].runs);
  EXPECT_TRUE(same_state(run(with, StageMode::Off), 0, reference, 0));
  EXPECT_TRUE(same_state(run(plain, StageMode::On), 0, reference, 0));
  const Simulator damped_run = run(with, StageMode::Auto);
  EXPECT_TRUE(damped_run.plan()[static_cast<int>(Stage::LinkDamping)].runs);
  EXPECT_NE(damped_run.describe_plan().find("link damping: runs (6 bodies with link damping)"), std::string::npos)
      << damped_run.describe_plan();
  EXPECT_LT(damped_run.v(0).norm(), reference.v(0).norm());
}

TEST(LinkDamping, TheSimulatorRefusesWhatItCannotStep) {
  Model sphere = damped_sphere(50.0);
  StepOptions o;
  o.dt = 0.05;  // h c = 2.5: past Heun's 2, within RK4's 2.78
  o.integrator = Integrator::Trapezoid;
  expect_invalid([&] { Simulator(sphere, 1, o); },
                 "link \"body\": linear damping 50 1/s is taken explicitly by the trapezoid, stable only for dt / "
                 "substeps below 0.04 s (got 0.05 s)");
  o.substeps = 2;
  EXPECT_NO_THROW(Simulator(sphere, 1, o));
  o.substeps = 1;
  o.integrator = Integrator::RK4;
  EXPECT_NO_THROW(Simulator(sphere, 1, o));
  o.integrator = Integrator::SemiImplicitEuler;
  o.conserve_linear_momentum = true;
  expect_invalid([&] { Simulator(sphere, 1, o); },
                 "link \"body\": linear damping: conserve_linear_momentum needs floating articulations without link "
                 "damping");
  o.conserve_linear_momentum = false;
  sphere.body_angular_damping[0] = 3e38;  // times the mass, 6e38: beyond float
  expect_invalid([&] { Simulator(sphere, 1, o); },
                 "link \"body\": angular damping must be >= 0 and, times the body's mass, finite (in float");
  o.precision = Precision::Double;
  EXPECT_NO_THROW(Simulator(sphere, 1, o));
  sphere.body_linear_damping[0] = -1;  // a Model edited past the builder's check
  expect_invalid([&] { Simulator(sphere, 1, o); }, "link \"body\": linear damping must be >= 0");
  // with its stage forced off, the damping is not taken, nor checked
  o.force(Stage::LinkDamping, StageMode::Off);
  EXPECT_NO_THROW(Simulator(sphere, 1, o));
}

// ---- scenes

class LinkDampingScene : public SceneFileTest {
 protected:
  std::string scene_text(const std::string& damping) {
    return "{\"model\": \"" + fs::absolute(shared_model_path("anymal_b")).string() +
           "\", \"floating_base\": true, \"link_damping\": " + damping + "}";
  }
};

// Every body's values, then one link's; the written scene reads back the same.
TEST_F(LinkDampingScene, EveryBodyThenNamedLinksAndTheSceneWritesThemBack) {
  const Scene s =
      load_scene(write(scene_text(R"({"angular": 0.5, "links": {"base": {"linear": 0.1}, "LF_SHANK": {"angular": 2}}})")));
  const Model& m = s.model;
  for (int b = 0; b < m.nbody; ++b) {
    const std::string& link = m.frame_name[m.body_frame[b]];
    EXPECT_EQ(m.body_linear_damping[b], link == "base" ? 0.1 : 0.0) << link;
    EXPECT_EQ(m.body_angular_damping[b], link == "LF_SHANK" ? 2.0 : 0.5) << link;
  }
  const Scene back = load_scene(write(scene_to_json(s)));
  EXPECT_EQ(back.model.body_linear_damping, m.body_linear_damping);
  EXPECT_EQ(back.model.body_angular_damping, m.body_angular_damping);
}

TEST_F(LinkDampingScene, BadEntriesAreRefusedByName) {
  const Model anymal = load_shared_model("anymal_b", true);
  std::string fused;  // a link fixed to another body's
  for (std::size_t f = 0; f < anymal.frame_name.size(); ++f)
    if (anymal.frame_body[f] >= 0 && anymal.body_frame[anymal.frame_body[f]] != static_cast<int>(f)) {
      fused = anymal.frame_name[f];
      break;
    }
  ASSERT_FALSE(fused.empty());
  EXPECT_THROW_WITH(load_scene(write(scene_text("{\"links\": {\"" + fused + "\": {\"linear\": 1}}}"))), SceneError,
                    "link_damping.links." + fused + ": link \"" + fused + "\" is fixed to link");
  EXPECT_THROW_WITH(load_scene(write(scene_text(R"({"linear": -1})"))), SceneError, "link_damping.linear");
  EXPECT_THROW_WITH(load_scene(write(scene_text(R"({"links": {"base": {"drag": 1}}})"))), SceneError,
                    "link_damping.links.base.drag: unknown key");
}

}  // namespace
}  // namespace lockstep::test
