// The simulation step's physics on small models with known answers, the
// per-source applied torque against the equation of motion, the stage plan,
// and the errors for bad options.
#include "batch/vec_env.hpp"
#include "tests/contact_support.hpp"

#include <cmath>
#include <functional>

namespace lockstep {
namespace {

using test::free_box;
using test::spinner;

StepOptions double_options(double dt) {
  StepOptions o;
  o.dt = dt;
  o.precision = Precision::Double;
  return o;
}

// Semi-implicit Euler from rest under gravity g: v_n = -g n dt and
// z_n = -g dt^2 n (n + 1) / 2, exactly up to rounding.
// Models whose mass matrix is singular are refused by name: their steps
// gave NaN. A massless floating root turning with its only child (the child
// on a revolute adds no inertia the root's rotation lacks), and a point mass
// on its revolute's axis.
TEST(Simulator, RefusesAModelWhoseMassMatrixIsSingular) {
  ArticulationSpec floating;
  floating.name = "floating";
  floating.floating_base = true;
  floating.links.push_back(test::joint_link("root", "", JointType::Fixed, Eigen::Vector3d::UnitZ(), {}));
  floating.links.push_back(test::massive_link("arm", "root", JointType::Revolute, Eigen::Vector3d::UnitZ(), 1.0));
  ArticulationSpec pointed;
  pointed.name = "pointed";
  pointed.links.push_back(test::joint_link("base", "", JointType::Fixed, Eigen::Vector3d::UnitZ(), {}));
  LinkSpec point = test::joint_link("point", "base", JointType::Revolute, Eigen::Vector3d::UnitZ(), {});
  point.inertial.mass = 1.0;  // at the joint's origin, no rotational inertia
  pointed.links.push_back(point);
  for (const auto& [spec, dof] : {std::pair{floating, "arm_joint"}, std::pair{pointed, "point_joint"}}) {
    const Model model = test::build(spec);
    EXPECT_THROW(
        {
          try {
            Simulator sim(model, 1);
          } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find(std::string("(") + dof + ") moves no inertia"), std::string::npos)
                << e.what();
            throw;
          }
        },
        std::invalid_argument);
  }
  // with a massive root the same arm is fine
  floating.links[0].inertial = floating.links[1].inertial;
  const Model massive = test::build(floating);
  EXPECT_NO_THROW(Simulator(massive, 1));
}

TEST(Simulator, FreeFallFollowsSemiImplicitEuler) {
  const Model model = free_box(Eigen::Vector3d(0.1, 0.2, 0.3), 2.0);
  for (Precision precision : {Precision::Float, Precision::Double}) {
    StepOptions o = double_options(0.01);
    o.precision = precision;
    Simulator sim(model, 3, o);
    const int n = 100;
    sim.step(n);
    const double tol = precision == Precision::Float ? 1e-4 : 1e-12;  // float: 100 sums of 0.0981, ~ 100 * 6e-8 relative
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(sim.v(c)[2], -9.81 * n * 0.01, tol * 10) << precision_name(precision);
      EXPECT_NEAR(sim.q(c)[2], -9.81 * 0.01 * 0.01 * n * (n + 1) / 2.0, tol * 10) << precision_name(precision);
      EXPECT_EQ(sim.fault(c), Fault::None);
    }
  }
}

// An implicit PD drive on a 1-DOF spinner settles on its target, and its
// steady state is the target exactly (no gravity torque on the axis).
TEST(Simulator, ImplicitDriveSettlesOnTarget) {
  const double inertia = 0.01, kp = 100.0;
  const Model model = spinner(inertia);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = kp;
  dofs[0].drive_damping = 2.0 * std::sqrt(kp * (inertia + 0.0));
  Simulator sim(model, 1, double_options(0.01), dofs);
  sim.set_drive_target(0, Eigen::VectorXd::Constant(1, 0.5), Eigen::VectorXd::Zero(1));
  sim.step(200);  // 2 s, 20 time constants sqrt(I / kp)
  EXPECT_NEAR(sim.q(0)[0], 0.5, 1e-6);
  EXPECT_NEAR(sim.v(0)[0], 0.0, 1e-5);
}

// The drive's effort limit clamps feedforward + PD: a drive far from its
// target accelerates the spinner by max_force / I in the first step (the
// implicit part acts on top, so measure with kd = 0 and kp small).
TEST(Simulator, EffortLimitClampsTheCommand) {
  const double inertia = 0.5;
  const Model model = spinner(inertia);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = 1e-3;
  dofs[0].max_force = 2.0;
  StepOptions o = double_options(0.001);
  o.record_applied_torque = true;
  Simulator sim(model, 1, o, dofs);
  sim.set_drive_target(0, Eigen::VectorXd::Constant(1, 1e6), Eigen::VectorXd::Zero(1));
  sim.step();
  // dv = dt * max_force / (I + dt^2 kp)
  EXPECT_NEAR(sim.v(0)[0], 0.001 * 2.0 / (inertia + 1e-9), 1e-12);
  EXPECT_NEAR(sim.applied_torque(0).drive[0], 2.0, 1e-8);
}

// Coulomb friction stronger than the applied torque holds the joint still;
// weaker, it takes away exactly its bound.
TEST(Simulator, CoulombFrictionHoldsOrSlows) {
  const double inertia = 0.2, dt = 0.01;
  const Model model = spinner(inertia);
  for (double friction : {2.0, 0.5}) {
    std::vector<DofSettings> dofs = default_dof_settings(model);
    dofs[0].friction = friction;
    StepOptions o = double_options(dt);
    o.record_applied_torque = true;
    Simulator sim(model, 1, o, dofs);
    sim.set_torque(0, Eigen::VectorXd::Constant(1, 1.0));
    sim.step(10);
    const double expected_v = friction > 1.0 ? 0.0 : 10 * dt * (1.0 - friction) / inertia;
    EXPECT_NEAR(sim.v(0)[0], expected_v, 1e-12) << "friction " << friction;
    EXPECT_NEAR(sim.applied_torque(0).friction[0], friction > 1.0 ? -1.0 : -friction, 1e-9);
  }
}

// A joint driven at speed into its hard limit stops on it within the step of
// impact (speculative row) and does not bounce back.
TEST(Simulator, HardLimitStopsAtImpactWithoutBounce) {
  const Model model = spinner(0.1, -1.0, 0.3);
  for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
    StepOptions o = double_options(0.01);
    o.solver = solver;
    Simulator sim(model, 1, o);
    sim.set_state(0, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, 10.0));
    sim.set_torque(0, Eigen::VectorXd::Constant(1, 5.0));
    for (int i = 0; i < 50; ++i) {
      sim.step();
      EXPECT_LE(sim.q(0)[0], 0.3 + 1e-9) << solver_name(solver) << " step " << i;
      if (sim.q(0)[0] > 0.3 - 1e-9) {
        EXPECT_GE(sim.v(0)[0], -1e-9) << "bounce at step " << i;
      }
    }
    EXPECT_NEAR(sim.q(0)[0], 0.3, 1e-6);
  }
}

// A velocity limit bounds |v| under a large torque.
TEST(Simulator, VelocityLimitBoundsSpeed) {
  const Model model = spinner(0.1);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].velocity_limit = 2.0;
  Simulator sim(model, 1, double_options(0.01), dofs);
  sim.set_torque(0, Eigen::VectorXd::Constant(1, -50.0));
  sim.step(20);
  EXPECT_NEAR(sim.v(0)[0], -2.0, 1e-9);
}

// The velocity limit holds both ways, also when another row (here a
// position limit on the first joint) drives the joint against its free
// motion: the band row -v_max <= v <= v_max.
TEST(Simulator, VelocityLimitHoldsWhenAnotherRowReversesTheJoint) {
  const Model model = test::rod_chain({1.0, 1.0}, 1.0);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].upper = 0.1;
  dofs[1].velocity_limit = 1.0;
  for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
    StepOptions o = double_options(0.002);
    o.solver = solver;
    o.iterations = 64;
    Simulator sim(model, 1, o, dofs);
    sim.set_gravity(0, Eigen::Vector3d::Zero());
    sim.set_state(0, Eigen::VectorXd::Zero(2), Eigen::Vector2d(5.0, -0.05));
    for (int i = 0; i < 20; ++i) {
      sim.step();
      EXPECT_LE(std::abs(sim.v(0)[1]), 1.0 + 1e-6) << solver_name(solver) << " step " << i;
    }
  }
}

// A joint past its hard limit goes back at the limit's correction speed
// (erp times the violation per step), which is faster than its velocity
// limit here: the velocity limit gives way to the position limit, as in
// RaiSim's step. Without that the two rows asked for opposite speeds and
// the solve ended at whichever row it swept last (v = -v_max). On the
// limit, a rounding error past it, the velocity limit still bounds a
// torque pulling the joint back in.
TEST(Simulator, VelocityLimitGivesWayToAPositionLimitThatCorrects) {
  const Model model = spinner(0.1, -0.5, 0.5);
  for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
    StepOptions o = double_options(0.01);
    o.solver = solver;
    std::vector<DofSettings> limited = default_dof_settings(model), free = limited;
    limited[0].velocity_limit = 0.05;
    Simulator with(model, 1, o, limited), without(model, 1, o, free);
    for (Simulator* sim : {&with, &without}) {
      sim->set_gravity(0, Eigen::Vector3d::Zero());
      sim->set_state(0, Eigen::VectorXd::Constant(1, 0.8), Eigen::VectorXd::Zero(1));
      sim->step();
    }
    // PGS: back at error_reduction * 0.3 / dt; TGS eases its target as the
    // substeps close the violation, but is still far above v_max
    if (solver == SolverType::PGS) EXPECT_NEAR(without.v(0)[0], -o.error_reduction * 0.3 / o.dt, 1e-9);
    EXPECT_LT(without.v(0)[0], -1.0) << solver_name(solver);
    EXPECT_NEAR(with.v(0)[0], without.v(0)[0], 1e-12) << solver_name(solver);
    with.set_state(0, Eigen::VectorXd::Constant(1, 0.5 + 1e-12), Eigen::VectorXd::Zero(1));
    with.set_torque(0, Eigen::VectorXd::Constant(1, -50.0));
    with.step();
    EXPECT_NEAR(with.v(0)[0], -0.05, 1e-9) << solver_name(solver);
  }
}

// A joint fast enough to cross a narrow range in one step meets the limit
// it heads for, not the one its position is nearer to.
TEST(Simulator, FastJointStopsAtTheFarLimitOfANarrowRange) {
  const Model model = spinner(0.1, -0.05, 0.05);
  for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
    StepOptions o = double_options(0.002);
    o.solver = solver;
    Simulator sim(model, 1, o);
    sim.set_state(0, Eigen::VectorXd::Constant(1, 0.04), Eigen::VectorXd::Constant(1, -100.0));
    sim.step();  // closes the 0.09 rad gap exactly: v = -0.09 / dt
    EXPECT_NEAR(sim.q(0)[0], -0.05, 1e-9) << solver_name(solver);
    sim.step();  // then rests on the limit
    EXPECT_NEAR(sim.q(0)[0], -0.05, 1e-9) << solver_name(solver);
    EXPECT_NEAR(sim.v(0)[0], 0.0, 1e-9) << solver_name(solver);
  }
}

// A spring-damper limit lets the joint in past the limit and pushes back:
// at rest against a constant torque tau the overshoot is tau / k.
TEST(Simulator, SoftLimitSettlesAtForceBalance) {
  const Model model = spinner(0.1, -1.0, 0.3);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].limit_stiffness = 1000.0;
  dofs[0].limit_damping = 20.0;
  Simulator sim(model, 1, double_options(0.002), dofs);
  sim.set_torque(0, Eigen::VectorXd::Constant(1, 5.0));
  sim.step(2000);
  EXPECT_NEAR(sim.q(0)[0], 0.3 + 5.0 / 1000.0, 1e-6);
}

// RaiSim's torque over the step, summed over its sources, is the equation of
// motion of the step: M(q0) (v1 - v0) / dt + h(q0, v0) = drive + passive +
// friction + limits. Checked on anymal_b with drives, damping, springs,
// friction and limits all active, in double.
TEST(Simulator, AppliedTorqueBalancesTheEquationOfMotion) {
  const Model model = test::load_shared_model("anymal_b", false);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 0; k < model.nv; ++k) {
    dofs[k].drive_stiffness = 50.0;
    dofs[k].drive_damping = 2.0;
    dofs[k].damping = 0.3;
    dofs[k].spring_stiffness = 5.0;
    dofs[k].spring_rest = 0.1;
    dofs[k].friction = 0.4;
    dofs[k].lower = -0.2;  // joints start at 0 moving fast: limits engage
    dofs[k].upper = 0.2;
  }
  StepOptions o = double_options(0.005);
  o.record_applied_torque = true;
  Simulator sim(model, 1, o, dofs);
  std::mt19937 rng(3);
  const Eigen::VectorXd q0 = Eigen::VectorXd::Zero(model.nq);
  const Eigen::VectorXd v0 = test::random_vector(model.nv, rng, 40.0);
  sim.set_state(0, q0, v0);
  sim.set_drive_target(0, Eigen::VectorXd::Constant(model.nq, 0.3), Eigen::VectorXd::Zero(model.nv));
  sim.step();
  const CopyDynamics dyn(model, Precision::Double);
  const Eigen::VectorXd lhs = dyn.mass_matrix(q0) * (sim.v(0) - v0) / o.dt + dyn.bias_force(q0, v0);
  const AppliedTorque t = sim.applied_torque(0);
  EXPECT_GT(t.limits.cwiseAbs().maxCoeff(), 1.0);  // the limits did act
  EXPECT_GT(t.friction.cwiseAbs().maxCoeff(), 0.1);
  const Eigen::VectorXd rhs = t.drive + t.passive + t.friction + t.limits;
  EXPECT_LT((lhs - rhs).cwiseAbs().maxCoeff(), 1e-8 * (1.0 + rhs.cwiseAbs().maxCoeff())) << "lhs " << lhs.transpose()
                                                                                          << "\nrhs " << rhs.transpose();
}

// applied_torque() is the last step's: a reset leaves no step behind it
// (it once kept the ended episode's torque, which VecEnv then observed as
// the new episode's first), and a snapshot carries it, so that a restored
// copy reports what its source does.
TEST(Simulator, ResetClearsAndSnapshotsCarryTheAppliedTorque) {
  const Model model = test::rod_chain({1.0, 1.0}, 1.0);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = 40.0;
  dofs[1].friction = 0.5;
  StepOptions o = double_options(0.01);
  o.record_applied_torque = true;
  Simulator sim(model, 2, o, dofs);
  sim.set_torque(0, Eigen::Vector2d(1.0, -2.0));
  sim.set_drive_target(0, Eigen::Vector2d(0.5, 0.0), Eigen::Vector2d::Zero());
  sim.step(3);
  const AppliedTorque before = sim.applied_torque(0);
  ASSERT_GT(before.drive.cwiseAbs().maxCoeff(), 1.0);
  sim.restore(1, sim.snapshot(0));
  const AppliedTorque restored = sim.applied_torque(1);
  for (const auto& [a, b] : {std::pair{before.drive, restored.drive}, {before.passive, restored.passive},
                             {before.friction, restored.friction}, {before.limits, restored.limits}})
    EXPECT_EQ(a, b);
  sim.reset(0);
  const AppliedTorque after = sim.applied_torque(0);
  for (const Eigen::VectorXd* t : {&after.drive, &after.passive, &after.friction, &after.limits})
    EXPECT_EQ(*t, Eigen::VectorXd::Zero(model.nv));
  Simulator unrecorded(model, 1, double_options(0.01), dofs);
  EXPECT_THROW(unrecorded.restore(0, sim.snapshot(1)), std::invalid_argument);
  EXPECT_EQ(unrecorded.snapshot(0).applied_torque.size(), 0);
}

// On a spinner (constant inertia, no bias force on its axis) the torque
// that acted over the step is I (v1 - v0) / dt with every integrator: the
// report must be the drive and passive forces the step used, averaged as
// the integrator averaged them (the trapezoid's are taken once with weight
// h/2, RK4's at four stages by its weights), and with substeps their mean
// over the step. The report once took the trapezoid's and RK4's last stage
// instead (0.125 and 0.081 N m off here), and the last substep's.
// Asserted to 1e-12 of the torque (double rounding of a few terms).
TEST(Simulator, AppliedTorqueIsWhatActedWithEveryIntegrator) {
  const Model model = spinner(2.0);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = 10.0, dofs[0].drive_damping = 1.0;
  dofs[0].damping = 0.5;
  dofs[0].spring_stiffness = 3.0, dofs[0].spring_rest = 0.1;
  for (Integrator integrator :
       {Integrator::SemiImplicitEuler, Integrator::Trapezoid, Integrator::RK4, Integrator::ExplicitEuler})
    for (int substeps : {1, 3}) {
      StepOptions o = double_options(0.05);
      o.integrator = integrator;
      o.substeps = substeps;
      o.record_applied_torque = true;
      Simulator sim(model, 1, o, dofs);
      sim.set_state(0, Eigen::VectorXd::Constant(1, 0.4), Eigen::VectorXd::Constant(1, 1.0));
      sim.set_drive_target(0, Eigen::VectorXd::Constant(1, -0.2), Eigen::VectorXd::Constant(1, 0.5));
      sim.set_torque(0, Eigen::VectorXd::Constant(1, 0.7));
      sim.step();
      const double acted = 2.0 * (sim.v(0)[0] - 1.0) / o.dt;
      const AppliedTorque t = sim.applied_torque(0);
      EXPECT_NEAR(t.drive[0] + t.passive[0], acted, 1e-12 * std::abs(acted))
          << integrator_name(integrator) << ", " << substeps << " substeps";
      EXPECT_LT(t.passive[0], 0) << "damping and the spring oppose the motion";
    }
}

// Joint damping on a floating base acts on its body-frame twist, implicitly
// like any damping: without gravity, a box moving along x keeps v / (1 +
// h c / m), and one spinning about its z axis (a principal axis: no
// gyroscopic turn) w / (1 + h c / I_zz), after one semi-implicit Euler
// step. The damping was once accepted, named in the plan, and ignored.
TEST(Simulator, DampingOnAFloatingBaseSlowsItsTwist) {
  const Model box = test::free_box(Eigen::Vector3d(0.1, 0.2, 0.3), 1.0);
  const double izz = 1.0 * (0.2 * 0.2 + 0.4 * 0.4) / 12.0;  // m ((2 hx)^2 + (2 hy)^2) / 12
  std::vector<DofSettings> dofs = default_dof_settings(box);
  for (DofSettings& d : dofs) d.damping = 2.0;
  StepOptions o = double_options(0.01);
  Simulator sim(box, 2, o, dofs);
  for (int copy : {0, 1}) {
    sim.set_gravity(copy, Eigen::Vector3d::Zero());
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(6);
    v0[copy == 0 ? 0 : 5] = 1.0;  // along x, or about z
    sim.set_state(copy, box.neutral_configuration(), v0);
  }
  sim.step();
  EXPECT_NEAR(sim.v(0)[0], 1.0 / (1.0 + o.dt * 2.0 / 1.0), 1e-12);
  EXPECT_NEAR(sim.v(1)[5], 1.0 / (1.0 + o.dt * 2.0 / izz), 1e-12);
  EXPECT_NE(sim.describe_plan().find("damping: runs (6 DOFs with damping)"), std::string::npos);
}

// energy() counts the rotor inertia the step integrates: a 1 kg, 1 m rod
// pendulum with a copy's own armature of 1 kg m^2, RK4 at dt = 1 ms for
// 3 s from 1 rad, keeps its energy to RK4's error (measured 6e-14 J); it
// once left out 1/2 a v^2 and swung by 1.69 J.
TEST(Simulator, EnergyCountsTheCopysArmature) {
  const Model rod = test::rod_chain({1.0}, 1.0);
  StepOptions o = double_options(1e-3);
  o.integrator = Integrator::RK4;
  o.force(Stage::HardLimits, StageMode::Off).force(Stage::VelocityLimits, StageMode::Off);
  Simulator sim(rod, 2, o);
  sim.set_armature(1, Eigen::VectorXd::Constant(1, 1.0));
  for (int copy : {0, 1}) sim.set_state(copy, Eigen::VectorXd::Constant(1, 1.0), Eigen::VectorXd::Zero(1));
  const double e0 = sim.energy(1);
  double spread = 0;
  for (int i = 0; i < 3000; ++i) {
    sim.step();
    spread = std::max(spread, std::abs(sim.energy(1) - e0));
  }
  std::cout << "[ measured ] energy spread with armature over 3 s: " << spread << " J\n";
  EXPECT_GT(std::abs(sim.q(1)[0] - sim.q(0)[0]), 0.1) << "the armature slows the swing";
  EXPECT_LT(spread, 1e-9);
}

// With their stages forced off the step takes the model's inertias and
// the scene's armature, and so does energy(): two spinners turning alike
// have one energy whatever a copy was given.
TEST(Simulator, EnergyTakesWhatTheStepTakesWithStagesForcedOff) {
  const Model model = spinner(0.1);
  StepOptions o;
  o.force(Stage::PerCopyInertia, StageMode::Off).force(Stage::PerCopyJointParameters, StageMode::Off);
  Simulator sim(model, 2, o);
  sim.set_body_inertia(1, 0, 5.0, Eigen::Vector3d::Zero(), 2.0 * Eigen::Matrix3d::Identity());
  sim.set_armature(1, Eigen::VectorXd::Constant(1, 1.0));
  for (int c : {0, 1}) sim.set_state(c, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, 4.0));
  sim.step(5);
  EXPECT_EQ(sim.v(0), sim.v(1));
  EXPECT_EQ(sim.energy(0), sim.energy(1));
  EXPECT_NEAR(sim.energy(0), 0.5 * 0.1 * 16.0, 1e-6);
}

// Per-copy inputs the constructor's checks would refuse are refused by the
// setters and by restore too: Coulomb friction on a floating base, and
// with the momentum projection damping or armature on one.
TEST(Simulator, SettersAndRestoreRefuseWhatTheConstructorRefuses) {
  const Model box = free_box(Eigen::Vector3d::Constant(0.1), 1.0);
  Simulator plain(box, 1);
  EXPECT_THROW_WITH(plain.set_joint_friction(0, Eigen::VectorXd::Constant(6, 0.5)), std::invalid_argument,
                    "set_joint_friction: DOF 0");
  plain.set_joint_damping(0, Eigen::VectorXd::Constant(6, 5.0));
  StepOptions keep;
  keep.conserve_linear_momentum = true;
  Simulator projected(box, 1, keep);
  EXPECT_THROW_WITH(projected.restore(0, plain.snapshot(0)), std::invalid_argument,
                    "restore: the snapshot's joint damping: DOF 0");
  EXPECT_EQ(projected.v(0), Eigen::VectorXd::Zero(6)) << "nothing restored";
}

// A copy's readout does not move when another copy's inertia is set: the
// model's inertias, which the step takes while no copy has its own, are
// those it holds (rounded to float), as they are once the stage runs.
TEST(Simulator, AnotherCopysInertiaLeavesACopysJointForcesAlone) {
  const Model model = test::load_shared_model("ur5", false);
  StepOptions o;
  o.record_motion = true;
  Simulator sim(model, 2, o);
  sim.step();
  const Eigen::Matrix<double, 6, Eigen::Dynamic> before = sim.incoming_joint_forces(0);
  sim.set_body_inertia(1, 2, 2.0 * model.body_mass[2], model.body_com[2], model.body_inertia[2]);
  EXPECT_EQ(sim.incoming_joint_forces(0), before);
}

// An Acceleration drive's gains are in 1/s^2 and 1/s: the response of a
// single joint does not depend on its inertia (PhysX eACCELERATION).
TEST(Simulator, AccelerationDriveIgnoresInertia) {
  std::vector<Eigen::VectorXd> trajectories;
  for (double inertia : {0.01, 10.0}) {
    const Model model = spinner(inertia);
    std::vector<DofSettings> dofs = default_dof_settings(model);
    dofs[0].drive_type = DriveType::Acceleration;
    dofs[0].drive_stiffness = 400.0;
    dofs[0].drive_damping = 40.0;
    Simulator sim(model, 1, double_options(0.005), dofs);
    sim.set_drive_target(0, Eigen::VectorXd::Constant(1, 1.0), Eigen::VectorXd::Zero(1));
    Eigen::VectorXd q(20);
    for (int i = 0; i < 20; ++i) sim.step(), q[i] = sim.q(0)[0];
    trajectories.push_back(q);
  }
  EXPECT_GT(trajectories[0][19], 0.5);
  // Same arithmetic up to the order of a product with I: a few ulps.
  EXPECT_LT((trajectories[0] - trajectories[1]).cwiseAbs().maxCoeff(), 1e-13);
}

// A drive on a spherical joint turns it to the target orientation: RaiSim's
// error is the rotation vector of q^-1 q_target.
TEST(Simulator, SphericalDriveReachesTargetOrientation) {
  const Model model = test::ball_joint();
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 20.0, d.drive_damping = 2.0;
  Simulator sim(model, 1, double_options(0.005), dofs);
  const Eigen::Quaterniond target(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, 2, 3).normalized()));
  sim.set_drive_target(0, Eigen::Vector4d(target.w(), target.x(), target.y(), target.z()), Eigen::VectorXd::Zero(3));
  sim.step(1000);
  const Eigen::VectorXd q = sim.q(0);
  const Eigen::Quaterniond reached(q[0], q[1], q[2], q[3]);
  EXPECT_LT(reached.angularDistance(target), 1e-6);
}

// A spherical drive's target quaternion is taken at unit length: three
// times a small rotation's quaternion acts as that rotation (it once tripled
// the drive's pull below 0.01 rad, where the rotation vector is taken by
// its series), and a zero quaternion is refused by name.
TEST(Simulator, SphericalDriveTargetIsTakenAtUnitLength) {
  const Model model = test::ball_joint();
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 100.0;
  for (Precision precision : {Precision::Double, Precision::Float})
    for (double angle : {5e-5, 5e-3, 0.5}) {
      StepOptions o = double_options(0.01);
      o.precision = precision;
      Eigen::VectorXd v1[2];
      for (double scale : {1.0, 3.0}) {
        Simulator sim(model, 1, o, dofs);
        const Eigen::Vector4d target(std::cos(angle / 2), std::sin(angle / 2), 0, 0);
        sim.set_drive_target(0, scale * target, Eigen::VectorXd::Zero(3));
        sim.step();
        v1[scale == 1.0 ? 0 : 1] = sim.v(0);
      }
      EXPECT_GT(v1[0][0], 0) << "turns towards the target";
      EXPECT_NEAR(v1[1][0], v1[0][0], 1e-6 * v1[0][0]) << precision_name(precision) << ", angle " << angle;
    }
  Simulator sim(model, 1, double_options(0.01), dofs);
  try {
    sim.set_drive_target(0, Eigen::Vector4d::Zero(), Eigen::VectorXd::Zero(3));
    ADD_FAILURE() << "a zero target quaternion was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("set_drive_target q_target: the quaternion of joint " + model.joint_name[0] +
                                         " is zero"),
              std::string::npos)
        << e.what();
  }
}

// A spinner's Stribeck friction: Coulomb 1, peak 1.5 below the fall-off
// velocity 0.01, Stribeck velocity 0.1.
std::vector<DofSettings> stribeck_dofs(const Model& spinner) {
  std::vector<DofSettings> dofs = default_dof_settings(spinner);
  dofs[0].friction = 1.0;
  dofs[0].friction_model = FrictionModel::Stribeck;
  dofs[0].stiction_extra = 0.5;
  dofs[0].falloff_velocity = 0.01;
  dofs[0].stribeck_velocity = 0.1;
  return dofs;
}

// The Stribeck force: a linear ramp to the static peak below the fall-off
// velocity, the Coulomb force plus a Gaussian fall-off of the extra above.
// It is taken implicitly as the damper of its secant c = |F(v0)| / |v0|
// (the ramp's slope, peak / falloff = 150 N m s, below the fall-off): the
// step ends at v1 = v0 / (1 + h c / I) with the force -c v1.
TEST(Simulator, StribeckFrictionFollowsItsCurve) {
  const Model model = spinner(0.1);
  const std::vector<DofSettings> dofs = stribeck_dofs(model);
  StepOptions o = double_options(0.001);
  o.record_applied_torque = true;
  Simulator sim(model, 1, o, dofs);
  EXPECT_TRUE(sim.plan()[static_cast<int>(Stage::StribeckFriction)].runs);
  EXPECT_FALSE(sim.plan()[static_cast<int>(Stage::CoulombFriction)].runs);
  for (double v : {0.005, -0.005, 0.05, 1.0}) {
    sim.set_state(0, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, v));
    sim.step();
    const double speed = std::abs(v);
    const double magnitude = speed < 0.01 ? 150.0 * speed : 1.0 + 0.5 * std::exp(-std::pow((speed - 0.01) / 0.1, 2));
    const double c = magnitude / speed;
    const double v1 = v / (1.0 + o.dt * c / 0.1);
    EXPECT_NEAR(sim.v(0)[0], v1, 1e-15) << "v = " << v;
    EXPECT_NEAR(sim.applied_torque(0).passive[0], -c * v1, 1e-12) << "v = " << v;
  }
}

// A light joint coasting above the fall-off velocity slows to rest and
// never turns: the friction's secant damper is implicit. Explicit, F(v0)
// reversed it within a step (h |F| / I = 2 rad/s on I = 0.001 kg m^2 at
// dt = 2 ms), and the next step's force pushed it back: v swung between
// -0.8 and +1.2 rad/s for good, from 0.05.
TEST(Simulator, StribeckFrictionSlowsALightJointWithoutTurningIt) {
  const Model model = spinner(0.001);
  Simulator sim(model, 1, double_options(0.002), stribeck_dofs(model));
  sim.set_state(0, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, 0.05));
  double last = 0.05;
  for (int i = 0; i < 200; ++i) {
    sim.step();
    const double v = sim.v(0)[0];
    ASSERT_GE(v, 0.0) << "step " << i << ": turned";
    ASSERT_LE(v, last) << "step " << i << ": sped up";
    last = v;
  }
  EXPECT_LT(last, 1e-6);
}

// A light joint pushed below its Stribeck friction creeps at the ramp's
// speed, torque * falloff / peak = 0.5 * 0.01 / 1.5 = 3.33e-3 rad/s. With
// the ramp explicit, h peak / (falloff I) = 30 on this 0.01 kg m^2 link at
// dt = 2 ms, far past 2: it chattered between -0.19 and +0.38 rad/s and
// moved 28 times as far in 2 s.
TEST(Simulator, StribeckFrictionHoldsALightJointAtItsCreep) {
  const Model model = spinner(0.01);
  const std::vector<DofSettings> dofs = stribeck_dofs(model);
  Simulator sim(model, 1, double_options(0.002), dofs);
  sim.set_torque(0, Eigen::VectorXd::Constant(1, 0.5));
  const double creep = 0.5 * 0.01 / 1.5;
  double fastest = 0;
  for (int i = 0; i < 1000; ++i) sim.step(), fastest = std::max(fastest, std::abs(sim.v(0)[0]));
  EXPECT_NEAR(sim.v(0)[0], creep, 1e-9);
  EXPECT_LE(fastest, creep * (1 + 1e-9)) << "no chatter: it approaches its creep from below";
  EXPECT_NEAR(sim.q(0)[0], 2.0 * creep, 1e-4);
}

// A snapshot belongs to its scene: restored into a simulator of another
// model whose arrays have the same sizes (one revolute link each, other
// names), it is refused; into one built alike, in the other precision and
// with more copies, it is taken; a snapshot put together by hand
// (scene_key 0) is not checked.
// restore refuses what the setters refuse, naming it: a contact slot that
// holds no candidate of the scene (the next contacts() indexed the pairs
// with it and crashed), a slot used after an empty one, a negative mass or
// drive stiffness, a fault code that is no Fault. The copy keeps its state.
TEST(Simulator, RestoreRefusesValuesTheSettersRefuse) {
  const Model ball = test::single_body(ShapeType::Box, Eigen::Vector3d::Constant(0.1), 1.0);
  StepOptions o = double_options(0.002);
  o.contacts.ground = true;
  Simulator sim(ball, 2, o);
  Eigen::VectorXd q = ball.neutral_configuration();
  q[2] = 0.1;
  sim.set_state(0, q, Eigen::VectorXd::Zero(6));
  sim.set_body_inertia(0, 0, 7.25, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * 0.05);
  sim.step(5);
  ASSERT_GE(sim.contacts(0).size(), 2u);
  const CopySnapshot good = sim.snapshot(0);
  auto index_of = [](const Eigen::VectorXd& x, double value) {
    for (Eigen::Index i = 0; i < x.size(); ++i)
      if (x[i] == value) return i;
    return Eigen::Index(-1);
  };
  const CopySnapshot untouched = sim.snapshot(1);
  auto expect_refused = [&](const CopySnapshot& bad, const std::string& message) {
    try {
      sim.restore(1, bad);
      ADD_FAILURE() << "restored: " << message;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
    const CopySnapshot after = sim.snapshot(1);
    EXPECT_TRUE(after.parameters == untouched.parameters && after.contact_id == untouched.contact_id &&
                after.q == untouched.q)
        << message << ": the copy changed";
  };
  CopySnapshot bad = good;
  bad.contact_id[0] = 1e6;
  expect_refused(bad, "restore: the snapshot's contact slot 0 holds 1e+06, not a candidate of this scene's 8");
  bad = good;
  bad.contact_id[0] = -1;
  expect_refused(bad, "restore: the snapshot's contact slot 1 holds");
  bad = good;
  const Eigen::Index mass = index_of(good.parameters, 7.25);
  ASSERT_GE(mass, 0);
  bad.parameters[mass] = -1;
  expect_refused(bad, "restore: the snapshot: body 0 (body): mass must be finite and >= 0");
  Simulator faulted(ball, 1, o);
  const CopySnapshot before = faulted.snapshot(0);
  faulted.set_gravity(0, Eigen::Vector3d::Constant(std::nan("")));
  faulted.step();
  ASSERT_EQ(faulted.fault(0), Fault::NonFiniteGravity);
  CopySnapshot wrong_fault = faulted.snapshot(0);
  Eigen::Index code = -1;
  for (Eigen::Index i = 0; i < before.parameters.size() && code < 0; ++i)
    if (before.parameters[i] == 0 && wrong_fault.parameters[i] == static_cast<double>(Fault::NonFiniteGravity)) code = i;
  ASSERT_GE(code, 0);
  wrong_fault.parameters[code] = 253;
  try {
    faulted.restore(0, wrong_fault);
    ADD_FAILURE() << "a fault code of 253 was restored";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("restore: the snapshot's fault code 253 is none of Fault's values"),
              std::string::npos)
        << e.what();
  }
  sim.restore(1, good);  // the good one still goes in
  EXPECT_EQ(sim.contacts(1).size(), sim.contacts(0).size());
}

TEST(Simulator, RestoreRefusesASnapshotOfAnotherScene) {
  const Model wheel = spinner(0.1);
  const Model arm =
      test::build(test::one_link_spec("elbow", "forearm", JointType::Revolute, Eigen::Vector3d::Constant(0.1)));
  Simulator a(wheel, 2, double_options(0.01));
  a.set_state(0, Eigen::VectorXd::Constant(1, 0.3), Eigen::VectorXd::Constant(1, 2.0));
  a.step();
  const CopySnapshot snapshot = a.snapshot(0);
  Simulator other(arm, 2, double_options(0.01));
  ASSERT_NE(other.scene_key(), a.scene_key());
  try {
    other.restore(1, snapshot);
    ADD_FAILURE() << "a snapshot of another scene was restored";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("restore: the snapshot was taken from another scene"), std::string::npos)
        << e.what();
  }
  StepOptions float_options = double_options(0.01);
  float_options.precision = Precision::Float;
  Simulator alike(wheel, 5, float_options);
  EXPECT_EQ(alike.scene_key(), a.scene_key());
  alike.restore(4, snapshot);
  EXPECT_EQ(alike.q(4)[0], static_cast<double>(static_cast<float>(snapshot.q[0])));
  CopySnapshot by_hand = snapshot;
  by_hand.scene_key = 0;
  other.restore(1, by_hand);
  EXPECT_EQ(other.q(1)[0], snapshot.q[0]);
}

// Of one model, a scene whose joint row is a position limit and one whose
// row is a velocity limit keep warm starts of the same size that mean
// different things: their keys differ, and restore refuses the other's.
TEST(Simulator, RestoreRefusesASnapshotWithOtherJointRows) {
  const Model wheel = spinner(0.1);
  std::vector<DofSettings> limited = default_dof_settings(wheel), fast = limited;
  limited[0].lower = -1.0, limited[0].upper = 1.0;
  fast[0].velocity_limit = 5.0;
  Simulator a(wheel, 1, double_options(0.01), limited), b(wheel, 1, double_options(0.01), fast);
  ASSERT_EQ(a.row_count(), 1);
  ASSERT_EQ(b.row_count(), 1);
  EXPECT_NE(a.scene_key(), b.scene_key());
  EXPECT_THROW(b.restore(0, a.snapshot(0)), std::invalid_argument);
  EXPECT_NO_THROW(a.restore(0, a.snapshot(0)));
}

// URDF effort, velocity, damping and friction are the defaults.
TEST(Simulator, UrdfValuesAreTheDefaults) {
  const Model model = test::load_shared_model("anymal_b", true);
  const std::vector<DofSettings> dofs = default_dof_settings(model);
  const int haa = model.dof_index("LF_HAA");
  EXPECT_EQ(dofs[haa].max_force, 80.0);
  EXPECT_EQ(dofs[haa].velocity_limit, 15.0);
  EXPECT_EQ(dofs[haa].lower, -9.42);
  EXPECT_EQ(dofs[0].max_force, Model::kInfinity);  // the base
  const Model ur5 = test::load_shared_model("ur5", false);
  const std::vector<DofSettings> ur5_dofs = default_dof_settings(ur5);
  for (int k = 0; k < ur5.nv; ++k) {
    EXPECT_EQ(ur5_dofs[k].damping, ur5.dof_damping[k]);
    EXPECT_EQ(ur5_dofs[k].friction, ur5.dof_friction[k]);
    EXPECT_EQ(ur5_dofs[k].max_force, ur5.dof_effort_limit[k]);
  }
  // ur5's URDF writes zero damping and friction: the written values, from a
  // hand whose <dynamics> are not zero (joint_0.0: damping 3, friction 10)
  const Model hand = test::load_shared_model("allegro_right_hand", false);
  const DofSettings first = default_dof_settings(hand)[hand.dof_index("joint_0.0")];
  EXPECT_EQ(first.damping, 3.0);
  EXPECT_EQ(first.friction, 10.0);
  EXPECT_EQ(first.max_force, 15.0);
  EXPECT_EQ(first.velocity_limit, 7.0);
  EXPECT_EQ(first.upper, 0.47);
}

// substeps = n runs the pipeline n times with dt / n: the same bits as n
// steps of dt / n (drives, limits and friction engaged).
TEST(Simulator, SubstepsEqualShorterSteps) {
  const Model model = test::load_shared_model("ur5", false);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 100.0, d.drive_damping = 3.0, d.friction = 0.5, d.lower = -0.3, d.upper = 0.3;
  StepOptions coarse = double_options(0.008);
  coarse.substeps = 4;
  StepOptions fine = double_options(0.002);
  Simulator a(model, 3, coarse, dofs), b(model, 3, fine, dofs);
  std::mt19937 rng(5);
  for (int c = 0; c < 3; ++c) {
    const Eigen::VectorXd v = test::random_vector(model.nv, rng, 5.0);
    const Eigen::VectorXd target = test::random_vector(model.nq, rng, 1.0);
    for (Simulator* sim : {&a, &b}) {
      sim->set_state(c, Eigen::VectorXd::Zero(model.nq), v);
      sim->set_drive_target(c, target, Eigen::VectorXd::Zero(model.nv));
    }
  }
  a.step(5);
  b.step(20);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(a.q(c), b.q(c)) << "copy " << c;
    EXPECT_EQ(a.v(c), b.v(c)) << "copy " << c;
  }
  EXPECT_GT((a.q(0) - Eigen::VectorXd::Zero(model.nq)).cwiseAbs().maxCoeff(), 0.1);
}

TEST(Simulator, PlanSaysWhichStagesRunAndWhy) {
  const Model model = test::load_shared_model("anymal_b", true);
  Simulator sim(model, 4);
  const auto& plan = sim.plan();
  ASSERT_EQ(plan.size(), static_cast<std::size_t>(kStageCount));
  EXPECT_FALSE(plan[static_cast<int>(Stage::Drives)].runs);
  EXPECT_TRUE(plan[static_cast<int>(Stage::HardLimits)].runs);
  EXPECT_EQ(plan[static_cast<int>(Stage::HardLimits)].reason, "12 DOFs with hard position limits");
  EXPECT_EQ(sim.row_count(), 24);  // 12 position + 12 velocity limit rows
  EXPECT_NE(sim.describe_plan().find("drives: skipped (no DOFs with drive gains)"), std::string::npos)
      << sim.describe_plan();
  StepOptions off;
  off.force(Stage::HardLimits, StageMode::Off).force(Stage::VelocityLimits, StageMode::Off);
  Simulator bare(model, 4, off);
  EXPECT_EQ(bare.row_count(), 0);
  EXPECT_NE(bare.describe_plan().find("hard limits: skipped (forced off (12 DOFs"), std::string::npos);
}

// Mimic tags are kept in the model but not enforced by the step yet; the
// plan says so, naming one, rather than letting a gripper's fingers part
// silently. anymal_b has none; talos_reduced's are all on fixed joints,
// which the loader drops with a warning.
TEST(Simulator, ModelsWithoutMimicTagsSayNothingOfThem) {
  for (const char* name : {"anymal_b", "talos_reduced"}) {
    const Model model = test::load_shared_model(name, true);
    const Simulator sim(model, 1);
    EXPECT_TRUE(sim.warnings().empty()) << name;
    EXPECT_NE(sim.describe_plan().find("mimic joints: skipped (no mimic tags)"), std::string::npos) << name;
  }
}

TEST(Simulator, BadOptionsAreRejectedByName) {
  const Model model = spinner(0.1, -1.0, 1.0);
  auto expect_error_for = [&](const Model& m, const StepOptions& o, std::vector<DofSettings> dofs,
                              const std::string& piece) {
    try {
      Simulator sim(m, 1, o, std::move(dofs));
      ADD_FAILURE() << "no error for " << piece;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(piece), std::string::npos) << e.what();
    }
  };
  auto expect_error = [&](const StepOptions& o, std::vector<DofSettings> dofs, const std::string& piece) {
    expect_error_for(model, o, std::move(dofs), piece);
  };
  StepOptions o;
  o.dt = 0.0;
  expect_error(o, {}, "StepOptions::dt");
  o = StepOptions();
  o.integrator = Integrator::RK4;
  expect_error(o, {}, "RK4");
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_damping = -1.0;
  expect_error(StepOptions(), dofs, "DOF 0 (wheel_joint): drive_damping");
  // the value as the shortest text that reads back as it (std::to_string
  // once printed -1e-9 as -0.000000)
  dofs[0].drive_damping = -1e-9;
  expect_error(StepOptions(), dofs, "drive_damping must be finite (in float, within 3.4e38) and >= 0, got -1e-09");
  expect_error(StepOptions(), std::vector<DofSettings>(3), "3 DOF settings");
  for (const double nan_limit : {0, 1}) {  // a NaN limit is no limit: refused, not ignored
    dofs = default_dof_settings(model);
    (nan_limit == 0 ? dofs[0].lower : dofs[0].upper) = std::nan("");
    expect_error(StepOptions(), dofs, "DOF 0 (wheel_joint): lower and upper limits must be numbers");
  }
  // joint friction: Coulomb on spherical joints, Stribeck on 1-DOF joints only
  const Model ball = test::ball_joint();
  std::vector<DofSettings> ball_dofs = default_dof_settings(ball);
  ball_dofs[1].friction = 0.5;
  EXPECT_NO_THROW(Simulator(ball, 1, StepOptions(), ball_dofs));
  ball_dofs[1].friction_model = FrictionModel::Stribeck;
  expect_error_for(ball, StepOptions(), ball_dofs,
                   "DOF 1 (arm_joint[1]): Stribeck friction acts on revolute and prismatic joints");
  const Model box = free_box(Eigen::Vector3d::Constant(0.1), 1.0);
  std::vector<DofSettings> box_dofs = default_dof_settings(box);
  box_dofs[2].drive_stiffness = 1.0;
  expect_error_for(box, StepOptions(), box_dofs, "floating base takes no drive");
  box_dofs = default_dof_settings(box);
  box_dofs[0].friction = 1.0;
  expect_error_for(box, StepOptions(), box_dofs, "friction acts on revolute, prismatic and spherical joints only");
  // a spherical joint's limits bound its rotation vector, which jumps to
  // the other side where |r| reaches pi: all three DOFs limited on both
  // sides, within |r| < pi (with one DOF limited, a spin about another
  // carried |r| through pi, and the limit pushed the joint by the jump:
  // energy 0.24 -> 1.07 J)
  ball_dofs = default_dof_settings(ball);
  ball_dofs[2].lower = -0.1, ball_dofs[2].upper = 0.1;
  expect_error_for(ball, StepOptions(), ball_dofs,
                   "DOFs 0-2 (spherical joint arm_joint): limits on a spherical joint need all three DOFs limited on "
                   "both sides");
  for (DofSettings& d : ball_dofs) d.lower = -2.0, d.upper = 2.0;
  expect_error_for(ball, StepOptions(), ball_dofs,
                   "DOFs 0-2 (spherical joint arm_joint): the limits' box reaches |r| = 3.4641016151377544; it must "
                   "stay within pi");
  box_dofs = default_dof_settings(box);
  box_dofs[3].upper = 1.0;
  expect_error_for(box, StepOptions(), box_dofs, "a floating base takes no position limits (got -inf to 1)");
  // integers cast to an enum, and limits that leave no range: refused (they
  // were read as a Force drive, Coulomb friction, or no limit at all)
  dofs = default_dof_settings(model);
  dofs[0].drive_type = static_cast<DriveType>(7);
  expect_error(StepOptions(), dofs, "DOF 0 (wheel_joint): drive_type holds 7, which is none of its values");
  dofs = default_dof_settings(model);
  dofs[0].friction_model = static_cast<FrictionModel>(7);
  expect_error(StepOptions(), dofs, "friction_model holds 7");
  o = StepOptions();
  o.integrator = static_cast<Integrator>(9);
  expect_error(o, {}, "StepOptions::integrator holds 9");
  o = StepOptions();
  o.stages[2] = static_cast<StageMode>(9);
  expect_error(o, {}, "StepOptions::stages[2] holds 9");
  dofs = default_dof_settings(model);
  dofs[0].lower = dofs[0].upper = Model::kInfinity;
  expect_error(StepOptions(), dofs,
               "DOF 0 (wheel_joint): a lower limit of +inf or an upper one of -inf leaves no range");
  // in float, a double beyond float's range would be stored as inf
  o = StepOptions();
  o.precision = Precision::Float;
  dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = 1e39;
  expect_error_for(model, o, dofs, "drive_stiffness must be finite (in float, within 3.4e38)");
  o.dt = 1e-46;  // 0 in float
  expect_error_for(model, o, {}, "StepOptions::dt must be positive");
  o.precision = Precision::Double;
  EXPECT_NO_THROW(Simulator(model, 1, o, dofs));
  Simulator sim(model, 2);
  sim.set_state(0, Eigen::VectorXd::Constant(1, 0.25), Eigen::VectorXd::Constant(1, 1.0));
  try {
    sim.step(-1);
    ADD_FAILURE() << "no error for step(-1)";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("Simulator::step: the number of steps must be >= 0, got -1"),
              std::string::npos)
        << e.what();
  }
  sim.step(0);
  EXPECT_EQ(sim.time(), 0.0) << "step(0) and a refused step(-1) take no step";
  EXPECT_EQ(sim.q(0)[0], 0.25);
  EXPECT_EQ(sim.v(0)[0], 1.0);
  EXPECT_THROW(sim.set_state(2, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Zero(1)), std::out_of_range);
  EXPECT_THROW(sim.set_torque(0, Eigen::VectorXd::Zero(3)), std::invalid_argument);
  EXPECT_THROW(sim.batch<double>(), std::logic_error);
}

// In float, the setters refuse doubles beyond float's range: stored, they
// became inf, and set_state's inf velocity, the copy's initial state too,
// faulted it at every step even with reset_on_fault.
TEST(Simulator, FloatSettersRefuseValuesBeyondFloatsRange) {
  const Model model = spinner(0.1, -1.0, 1.0);
  StepOptions o;
  o.precision = Precision::Float;
  Simulator sim(model, 1, o);
  const Eigen::VectorXd big = Eigen::VectorXd::Constant(1, 1e39), zero = Eigen::VectorXd::Zero(1);
  EXPECT_THROW_WITH(sim.set_state(0, zero, big), std::invalid_argument,
                    "set_state v: entry 0 is not finite (in float, within 3.4e38)");
  EXPECT_THROW_WITH(sim.set_drive_gains(0, big, zero), std::invalid_argument,
                    "needs finite (in float, within 3.4e38) gains");
  EXPECT_THROW_WITH(sim.set_joint_damping(0, big), std::invalid_argument, "finite (in float, within 3.4e38) value");
  EXPECT_THROW_WITH(sim.set_body_inertia(0, 0, 1e39, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity()),
                    std::invalid_argument, "mass must be finite (in float, within 3.4e38)");
  sim.set_state(0, zero, Eigen::VectorXd::Constant(1, 3e38));  // within range: kept
  EXPECT_EQ(sim.v(0)[0], static_cast<double>(3e38f));
}

// A Free joint takes no drive, and its entries of the drive target are not
// read: a NaN there once faulted the copy all the same.
TEST(Simulator, AFloatingBasesUnreadTargetDoesNotFault) {
  const Model model = test::load_shared_model("anymal_b", true);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 6; k < model.nv; ++k) dofs[k].drive_stiffness = 10.0;
  StepOptions o;
  o.precision = Precision::Double;
  Simulator sim(model, 2, o, dofs);
  Eigen::VectorXd target = model.neutral_configuration();
  sim.set_drive_target(0, target, Eigen::VectorXd::Zero(model.nv));
  target[0] = std::nan("");  // the base's x
  Eigen::VectorXd v_target = Eigen::VectorXd::Zero(model.nv);
  v_target[0] = std::nan("");
  sim.set_drive_target(1, target, v_target);
  sim.step(3);
  EXPECT_EQ(sim.fault(1), Fault::None);
  EXPECT_EQ(sim.q(1), sim.q(0));
  EXPECT_EQ(sim.v(1), sim.v(0));
  target[7] = std::nan("");  // a leg's: read, and it faults
  sim.set_drive_target(1, target, Eigen::VectorXd::Zero(model.nv));
  sim.step();
  EXPECT_EQ(sim.fault(1), Fault::NonFiniteTarget);
}

// The plan's reasons count the scene's DOFs and say what else turned a
// stage on: per-copy gains or damping, or set_link_wrench (it once counted
// every DOF as having gains once one copy had some, and "1 calls").
TEST(Simulator, PlanNamesPerCopySettersAsTheReason) {
  const Model model = test::load_shared_model("anymal_b", true);
  Simulator sim(model, 4);
  Eigen::VectorXd kp = Eigen::VectorXd::Zero(model.nv), damping = Eigen::VectorXd::Zero(model.nv);
  kp[7] = 10.0;
  damping[9] = 0.5;
  sim.set_drive_gains(2, kp, Eigen::VectorXd::Zero(model.nv));
  sim.set_joint_damping(1, damping);
  sim.set_link_wrench(0, 0, Eigen::Matrix<double, 6, 1>::Zero());
  const std::string plan = sim.describe_plan();
  for (const char* line : {"  drives: runs (no DOFs with drive gains, and copies given gains by set_drive_gains)\n",
                           "  damping: runs (no DOFs with damping, and copies given damping by set_joint_damping)\n",
                           "  external wrenches: runs (set_link_wrench called)\n"})
    EXPECT_NE(plan.find(line), std::string::npos) << line << plan;
}

// The per-copy setters name what is wrong and leave the copy as it was.
// A rotational inertia is accepted down to an eigenvalue of -1e-12 of its
// largest diagonal entry (round-off), including singular ones (a thin rod,
// a point mass) and ones whose off-diagonal entries outweigh the diagonal.
// Code compiled with other SIMD widths than the library (another -march)
// is refused at construction, before anything is built.
// A Simulator moved from is refused by name, where its calls dereferenced
// a null engine (copies(), q(), step() crashed); assigned anew, it works.
TEST(Simulator, AMovedFromSimulatorIsRefusedUntilAssigned) {
  const Model model = spinner(0.1);
  Simulator a(model, 3, double_options(0.01));
  Simulator b(std::move(a));
  EXPECT_EQ(b.copies(), 3);
  for (const std::function<void()>& use : std::vector<std::function<void()>>{
           [&] { (void)a.copies(); }, [&] { (void)a.q(0); }, [&] { a.step(); }, [&] { (void)a.energy(0); }})
    try {
      use();
      ADD_FAILURE() << "a moved-from simulator was used";
    } catch (const std::logic_error& e) {
      EXPECT_NE(std::string(e.what()).find("Simulator: used after it was moved from"), std::string::npos) << e.what();
    }
  a = Simulator(model, 2, double_options(0.01));
  a.step();
  EXPECT_EQ(a.copies(), 2);
}

// A model's values beyond float's range (the model loads in double) are
// refused by a float simulator, naming the body, where every copy faulted
// NonFiniteState at its first step; a double simulator takes them.
TEST(Simulator, AFloatSimulatorRefusesModelValuesBeyondFloatsRange) {
  ArticulationSpec spec = test::one_link_spec("heavy", "mass", JointType::Revolute, Eigen::Vector3d::Constant(1e39));
  spec.links[1].inertial.mass = 1e39;
  const Model model = test::build(spec);
  StepOptions o;
  o.precision = Precision::Float;
  try {
    Simulator sim(model, 2, o);
    ADD_FAILURE() << "a mass of 1e39 was taken in float";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("body 0 (mass): its mass, centre of mass, inertia and joint placement must be "
                                         "finite (in float, within 3.4e38)"),
              std::string::npos)
        << e.what();
  }
  o.precision = Precision::Double;
  Simulator sim(model, 2, o);
  sim.step();
  EXPECT_EQ(sim.fault(0), Fault::None);
}

TEST(Simulator, CodeCompiledForOtherLanesIsRefused) {
  const Model model = test::rod_chain({1.0}, 0.5);
  const HeaderBuild own;
  EXPECT_NO_THROW(Simulator(model, 4, {}, {}, own));
  for (const HeaderBuild other :
       {HeaderBuild{own.float_lanes * 2, own.double_lanes * 2}, HeaderBuild{own.float_lanes, own.double_lanes + 1}}) {
    EXPECT_THROW_WITH(Simulator(model, 4, {}, {}, other), std::logic_error,
                      "compiled for SIMD lanes of " + std::to_string(other.float_lanes) + " float / " +
                          std::to_string(other.double_lanes) + " double, but the library is lockstep ");
    VecEnvOptions options;
    options.dofs = default_dof_settings(model);
    EXPECT_THROW_WITH(VecEnv(model, 4, options, other), std::logic_error, "with the library's flags");
  }
}

TEST(Simulator, BadPerCopyInputsAreRejectedByNameAndChangeNothing) {
  const Model model = free_box(Eigen::Vector3d(0.1, 0.2, 0.3), 2.0);
  Simulator sim(model, 2, double_options(0.01));
  auto expect_error = [](auto&& call, const std::string& piece) {
    try {
      call();
      ADD_FAILURE() << "no error for " << piece;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(piece), std::string::npos) << e.what();
    }
  };
  const Eigen::Vector3d com = model.body_com[0];
  auto set_inertia = [&](const Eigen::Matrix3d& inertia) { sim.set_body_inertia(1, 0, 2.0, com, inertia); };
  const Eigen::Matrix3d rotation = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Matrix3d rod = rotation * Eigen::Vector3d(0, 1, 1).asDiagonal() * rotation.transpose();
  Eigen::Matrix3d coupled;  // eigenvalues 0, 2 and 1: the off-diagonal entry equals the diagonal
  coupled << 1, 1, 0, 1, 1, 0, 0, 0, 1;
  for (const Eigen::Matrix3d& good :
       {Eigen::Matrix3d(Eigen::Matrix3d::Zero()), rod, coupled,
        Eigen::Matrix3d(rotation * Eigen::Vector3d(-1e-13, 1, 1).asDiagonal() * rotation.transpose())})
    EXPECT_NO_THROW(set_inertia(good)) << good;
  const Eigen::VectorXd parameters = sim.batch<double>().state.inertia.get(1);
  Eigen::Matrix3d indefinite = coupled;
  indefinite(0, 1) = indefinite(1, 0) = 1.001;  // eigenvalue -1e-3
  Eigen::Matrix3d asymmetric = Eigen::Matrix3d::Identity();
  asymmetric(0, 2) = 1e-3;
  for (const Eigen::Matrix3d& bad :
       {indefinite, asymmetric,
        Eigen::Matrix3d(rotation * Eigen::Vector3d(-1e-9, 1, 1).asDiagonal() * rotation.transpose())})
    expect_error([&] { set_inertia(bad); },
                 "set_body_inertia: body 0 (box): the rotational inertia must be symmetric "
                 "positive semidefinite");
  expect_error([&] { sim.set_body_inertia(1, 0, -1.0, com, rod); }, "body 0 (box): mass must be finite");
  EXPECT_EQ(sim.batch<double>().state.inertia.get(1), parameters) << "a rejected inertia was written";

  const Eigen::VectorXd q = sim.q(1);
  Eigen::VectorXd bad_q = q;
  bad_q[4] = std::nan("");
  expect_error([&] { sim.set_state(1, bad_q, Eigen::VectorXd::Zero(6)); }, "set_state q: entry 4 is not finite");
  expect_error([&] { sim.set_state(1, Eigen::VectorXd::Zero(7), Eigen::VectorXd::Zero(6)); },
               "set_state q: the quaternion of joint");
  EXPECT_EQ(sim.q(1), q) << "a rejected state was written";
  Eigen::VectorXd damping = Eigen::VectorXd::Zero(6);
  damping[2] = -1.0;
  expect_error([&] { sim.set_joint_damping(1, damping); }, "set_joint_damping: DOF 2 (");
}

}  // namespace
}  // namespace lockstep
