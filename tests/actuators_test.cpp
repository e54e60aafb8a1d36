// Actuators (batch/actuators.hpp): motors behind gearboxes whose torque the
// motor operating region bounds by speed, added to the joints after the
// effort clamp (RaiSim's "Joint torque of a simulation step", step 2).
#include "batch/vec_env.hpp"
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <set>

namespace lockstep::test {
namespace {

// G 10, K_t 0.1 N m/A, 24 V, 1 ohm, K_v 10 rad/(s V): stall 2.4 N m, back-EMF
// damping 0.01 N m s/rad, peak 1.5 N m (at the motor).
Actuator motor(int dof, const std::string& name = "motor") {
  Actuator a;
  a.name = name;
  a.dof = dof;
  a.gear = 10;
  a.torque_constant = 0.1;
  a.bus_voltage = 24;
  a.resistance = 1;
  a.velocity_constant = 10;
  a.peak_torque = 1.5;
  return a;
}

// The operating region written out case by case, apart from the kernel's
// two clamps: the peak torque, and the voltage lines, which win where the
// two leave no common torque.
double expected_motor_torque(const Actuator& a, double command, double omega) {
  const double wanted = command / a.gear;
  if (!a.enforce_operating_region) return wanted;
  const double top = a.stall_torque() - a.back_emf_damping() * omega;
  const double bottom = -a.stall_torque() - a.back_emf_damping() * omega;
  if (top < -a.peak_torque) return top;        // overspeed forwards: the least braking the voltage allows
  if (bottom > a.peak_torque) return bottom;   // overspeed backwards
  const double low = std::max(bottom, -a.peak_torque), high = std::min(top, a.peak_torque);
  return std::clamp(wanted, low, high);
}

StepOptions actuated(Precision precision, std::vector<Actuator> actuators) {
  StepOptions o;
  o.precision = precision;
  o.record_applied_torque = true;
  o.actuators = std::move(actuators);
  return o;
}

// One joint of inertia 0.1 kg m^2 turning freely about z (no gravity torque):
// over a step the motor's torque is all that moves it, so
// v1 = v0 + h G tau_m / I.
TEST(Actuators, TorqueFollowsTheMotorOperatingRegion) {
  const Model model = spinner(0.1);
  for (bool enforce : {true, false}) {
    Actuator a = motor(0);
    a.enforce_operating_region = enforce;
    Simulator sim(model, 1, actuated(Precision::Double, {a}));
    // speeds inside the region, on either voltage line, and past where the
    // lines leave nothing within the peak ((2.4 + 1.5) / 0.01 = 390 rad/s at the motor)
    for (double v0 : {0.0, 10.0, -10.0, 22.0, 50.0, -50.0})
      for (double command : {5.0, 30.0, -30.0, 0.0}) {
        sim.set_state(0, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, v0));
        sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, command));
        sim.step();
        const ActuatorState state = sim.actuator_states(0)[0];
        const double omega = a.gear * v0, tau = expected_motor_torque(a, command, omega);
        const std::string at = "enforced " + std::to_string(enforce) + ", v0 " + std::to_string(v0) + ", command " +
                               std::to_string(command);
        EXPECT_EQ(state.command, command) << at;
        EXPECT_EQ(state.motor_speed, omega) << at;
        EXPECT_NEAR(state.motor_torque, tau, 1e-15) << at;
        EXPECT_EQ(state.clipped, tau != command / a.gear) << at;
        EXPECT_NEAR(sim.applied_torque(0).actuators[0], a.gear * tau, 1e-14) << at;
        EXPECT_NEAR(sim.v(0)[0], v0 + 0.002 * a.gear * tau / 0.1, 1e-12) << at;
      }
  }
}

// The coupled joint gets r tau_m, and its speed joins the motor's.
TEST(Actuators, CouplingsDriveFurtherJoints) {
  const Model model = rod_chain({1.0, 0.5}, 0.4);
  Actuator a = motor(0);
  a.couplings = {{1, -0.5}};
  a.peak_torque = Model::kInfinity;
  Simulator sim(model, 1, actuated(Precision::Double, {a}));
  sim.set_gravity(0, Eigen::Vector3d::Zero());
  const Eigen::Vector2d v0(1.0, 2.0);
  sim.set_state(0, Eigen::Vector2d(0.3, -0.2), v0);
  sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, 30.0));
  sim.step();
  const ActuatorState state = sim.actuator_states(0)[0];
  const double omega = 10 * 1.0 - 0.5 * 2.0;
  EXPECT_EQ(state.motor_speed, omega);
  const double tau = expected_motor_torque(a, 30.0, omega);  // 2.4 - 0.09: on the voltage line
  EXPECT_NEAR(state.motor_torque, tau, 1e-15);
  EXPECT_TRUE(state.clipped);
  const Eigen::VectorXd applied = sim.applied_torque(0).actuators;
  EXPECT_NEAR(applied[0], 10 * tau, 1e-14);
  EXPECT_NEAR(applied[1], -0.5 * tau, 1e-15);
}

// RaiSim: the effort limit clamps feedforward + PD, not the actuators; with
// every integrator (the motor's torque stays inside its region at the
// speeds of every stage, so each evaluation gives the same).
TEST(Actuators, TheEffortLimitClipsTheFeedforwardNotTheActuator) {
  const Model model = spinner(0.1);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].max_force = 1.0;
  for (Integrator integrator :
       {Integrator::SemiImplicitEuler, Integrator::Trapezoid, Integrator::RK4, Integrator::ExplicitEuler}) {
    StepOptions o = actuated(Precision::Double, {motor(0)});
    o.integrator = integrator;
    Simulator sim(model, 1, o, dofs);
    sim.set_torque(0, Eigen::VectorXd::Constant(1, 5.0));
    sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, 12.0));  // 1.2 N m at the motor: inside its region
    sim.step();
    const AppliedTorque applied = sim.applied_torque(0);
    const std::string name = integrator_name(integrator);
    EXPECT_NEAR(applied.drive[0], 1.0, 1e-15) << name;
    EXPECT_NEAR(applied.actuators[0], 12.0, 1e-14) << name;
    EXPECT_FALSE(sim.actuator_states(0)[0].clipped) << name;
    EXPECT_NEAR(sim.v(0)[0], 0.002 * 13.0 / 0.1, 1e-12) << name;
  }
}

// anymal_b with a motor on every leg joint (the knees coupled to their
// hips), each copy commanding its own torques: the SIMD lanes reproduce the
// scalar reference bit for bit, motor states included.
TEST(Actuators, LanesMatchTheScalarReference) {
  const Model model = load_shared_model("anymal_b", true);
  std::vector<Actuator> actuators;
  for (int k = 6; k < model.nv; ++k) {
    Actuator a = motor(k, model.dof_name[k] + "_motor");
    a.gear = 20;
    if ((k - 6) % 3 == 2) a.couplings = {{k - 2, 0.25}};
    actuators.push_back(a);
  }
  const int copies = 37;
  for (Precision precision : {Precision::Float, Precision::Double}) {
    StepOptions o = actuated(precision, actuators);
    Simulator simd(model, copies, o);
    o.lanes = Lanes::Scalar;
    Simulator scalar(model, copies, o);
    std::mt19937 rng(3);
    const Eigen::VectorXd stand = stance(model);
    for (int c = 0; c < copies; ++c) {
      const Eigen::VectorXd v = random_vector(model.nv, rng, 1.0), command = random_vector(12, rng, 40.0);
      for (Simulator* sim : {&simd, &scalar}) {
        sim->set_state(c, stand, v);
        sim->set_actuator_torques(c, command);
      }
    }
    simd.step(20);
    scalar.step(20);
    int clipped = 0;
    for (int c = 0; c < copies; ++c) {
      ASSERT_TRUE(same_state(simd, c, scalar, c)) << precision_name(precision) << " copy " << c;
      const std::vector<ActuatorState> a = simd.actuator_states(c), b = scalar.actuator_states(c);
      for (std::size_t m = 0; m < a.size(); ++m) {
        EXPECT_EQ(a[m].motor_speed, b[m].motor_speed);
        EXPECT_EQ(a[m].motor_torque, b[m].motor_torque);
        clipped += a[m].clipped;
      }
      EXPECT_TRUE(same_bits(simd.applied_torque(c).actuators, scalar.applied_torque(c).actuators));
    }
    EXPECT_GT(clipped, 0) << "no motor reached its region's edge: the test would not see the clamps";
  }
}

// With RK4 the motor is evaluated at each stage (its state is the last
// stage's), and the applied torque is the stages' average by RK4's weights.
TEST(Actuators, Rk4EvaluatesTheMotorAtEveryStage) {
  const Model model = spinner(0.1);
  StepOptions o = actuated(Precision::Double, {motor(0)});
  o.integrator = Integrator::RK4;
  Simulator sim(model, 1, o);
  const double v0 = 15.0, h = 0.002, command = 30.0;  // on the voltage line: tau_m = 2.4 - 0.1 v
  sim.set_state(0, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, v0));
  sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, command));
  sim.step();
  // dv/dt = G (2.4 - 0.01 G v) / I = 240 - 10 v: RK4's stages of that linear ODE
  auto f = [](double v) { return 240.0 - 10.0 * v; };
  const double k1 = f(v0), k2 = f(v0 + 0.5 * h * k1), k3 = f(v0 + 0.5 * h * k2), k4 = f(v0 + h * k3);
  EXPECT_NEAR(sim.v(0)[0], v0 + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), 1e-12);
  EXPECT_NEAR(sim.applied_torque(0).actuators[0], 0.1 * (k1 + 2 * k2 + 2 * k3 + k4) / 6, 1e-10);
  EXPECT_NEAR(sim.actuator_states(0)[0].motor_speed, 10 * (v0 + h * k3), 1e-12);
}

TEST(Actuators, SnapshotsCarryCommandsAndStatesAndResetsClearTheStates) {
  const Model model = spinner(0.1);
  const StepOptions o = actuated(Precision::Float, {motor(0), motor(0, "second")});
  Simulator sim(model, 2, o), other(model, 1, o);
  sim.set_actuator_torques(1, Eigen::Vector2d(30.0, -4.0));
  sim.step(3);
  other.restore(0, sim.snapshot(1));
  EXPECT_EQ(other.actuator_torques(0), sim.actuator_torques(1));
  for (std::size_t m = 0; m < 2; ++m)
    EXPECT_EQ(other.actuator_states(0)[m].motor_torque, sim.actuator_states(1)[m].motor_torque);
  sim.step();
  other.step();
  EXPECT_TRUE(same_state(sim, 1, other, 0));
  sim.reset(1);
  EXPECT_EQ(sim.actuator_states(1)[0].motor_torque, 0.0);
  EXPECT_EQ(sim.actuator_states(1)[0].motor_speed, 0.0);
  EXPECT_EQ(sim.actuator_torques(1), Eigen::Vector2d(30.0, -4.0)) << "a command persists, as set_torque's does";
}

// A copy's strength scales what reaches the joints, not the motor's own
// torque (its operating region is the same motor's).
TEST(Actuators, StrengthScalesWhatReachesTheJoints) {
  const Model model = spinner(0.1);
  Simulator sim(model, 2, actuated(Precision::Double, {motor(0)}));
  EXPECT_EQ(sim.actuator_strength(1), Eigen::VectorXd::Ones(1));
  sim.set_actuator_strength(1, Eigen::VectorXd::Constant(1, 0.8));
  for (int c = 0; c < 2; ++c) sim.set_actuator_torques(c, Eigen::VectorXd::Constant(1, 30.0));  // clipped at the peak
  sim.step();
  EXPECT_EQ(sim.actuator_states(1)[0].motor_torque, 1.5);
  EXPECT_NEAR(sim.applied_torque(0).actuators[0], 15.0, 1e-14);
  EXPECT_NEAR(sim.applied_torque(1).actuators[0], 0.8 * 15.0, 1e-14);
  EXPECT_NEAR(sim.v(1)[0], 0.002 * 12.0 / 0.1, 1e-12);
  EXPECT_THROW_WITH(sim.set_actuator_strength(0, Eigen::VectorXd::Constant(1, 0.0)), std::invalid_argument,
                    "set_actuator_strength: actuator 0 (motor): the strength must be finite and > 0, got 0");
  EXPECT_THROW_WITH(sim.set_actuator_strength(0, Eigen::VectorXd::Ones(2)), std::invalid_argument,
                    "set_actuator_strength: expects 1 values (one per actuator), got 2");
}

// VecEnv draws each copy's strength per actuator at every reset from
// actuator_strength_scale, as it draws the other parameters.
TEST(Actuators, VecEnvDrawsTheStrengthsAtReset) {
  const Model model = spinner(0.1);
  VecEnvOptions o;
  o.step = actuated(Precision::Float, {motor(0, "a"), motor(0, "b")});
  o.randomization.actuator_strength_scale = {0.8, 1.2};
  o.seed = 11;
  VecEnv env(model, 20, o);
  env.reset();
  std::set<double> seen;
  for (int c = 0; c < 20; ++c) {
    const Eigen::VectorXd s = env.simulator().actuator_strength(c);
    for (int a = 0; a < 2; ++a) {
      EXPECT_GE(s[a], 0.8f);
      EXPECT_LE(s[a], 1.2f);
      EXPECT_EQ(s[a], static_cast<float>(draw(o.randomization, &Randomization::actuator_strength_scale, o.seed, c, 0, a)));
      seen.insert(s[a]);
    }
  }
  EXPECT_EQ(seen.size(), 40u) << "every copy and actuator draws its own";
}

// A state is the last evaluation's: its command is the one that
// evaluation took, and a copy that has not stepped since its reset has a
// zero state, not a clipped one.
TEST(Actuators, AStateDescribesTheEvaluationThatMadeIt) {
  const Model model = spinner(0.1);
  Simulator sim(model, 1, actuated(Precision::Double, {motor(0)}));
  sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, 5.0));
  EXPECT_FALSE(sim.actuator_states(0)[0].clipped) << "before the first step";
  sim.step();
  sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, 8.0));
  const ActuatorState state = sim.actuator_states(0)[0];
  EXPECT_EQ(state.command, 5.0);
  EXPECT_EQ(state.motor_torque, 0.5);
  EXPECT_FALSE(state.clipped);
  sim.reset(0);
  EXPECT_FALSE(sim.actuator_states(0)[0].clipped) << "after a reset";
  EXPECT_EQ(sim.actuator_states(0)[0].command, 0.0);
}

// A restart after a fault leaves no step behind it either.
TEST(Actuators, AResetOnFaultRestartClearsTheStates) {
  const Model model = spinner(0.1);
  StepOptions o = actuated(Precision::Float, {motor(0)});
  o.reset_on_fault = true;
  Simulator sim(model, 2, o);
  sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, 5.0));
  sim.set_actuator_torques(1, Eigen::VectorXd::Constant(1, 5.0));
  sim.step();
  sim.set_torque(1, Eigen::VectorXd::Constant(1, std::nan("")));
  sim.step();
  EXPECT_EQ(sim.fault(1), Fault::NonFiniteTorque);
  EXPECT_EQ(sim.actuator_states(1)[0].motor_torque, 0.0);
  EXPECT_EQ(sim.actuator_states(0)[0].motor_torque, 0.5f);
}

// A snapshot's commands drive what its actuators drove: another set of
// actuators is another scene.
TEST(Actuators, ASnapshotRestoresOnlyWhereTheActuatorsAreTheSame) {
  const Model model = rod_chain({1.0, 0.5}, 0.4);
  Simulator a(model, 1, actuated(Precision::Float, {motor(0)}));
  Simulator b(model, 1, actuated(Precision::Float, {motor(1)}));
  EXPECT_THROW_WITH(b.restore(0, a.snapshot(0)), std::invalid_argument, "its actuators differ");
  Simulator two(model, 1, actuated(Precision::Float, {motor(0), motor(1, "other")}));
  EXPECT_THROW_WITH(two.restore(0, a.snapshot(0)), std::invalid_argument, "its actuators differ");
}

TEST(Actuators, ANonFiniteCommandFaultsOnlyItsCopy) {
  const Model model = spinner(0.1);
  Simulator sim(model, 3, actuated(Precision::Float, {motor(0)}));
  sim.set_actuator_torques(1, Eigen::VectorXd::Constant(1, std::nan("")));
  sim.set_actuator_torques(2, Eigen::VectorXd::Constant(1, 3.0));
  sim.step();
  EXPECT_EQ(sim.fault(0), Fault::None);
  EXPECT_EQ(sim.fault(1), Fault::NonFiniteTorque);
  EXPECT_EQ(sim.fault(2), Fault::None);
  EXPECT_GT(sim.v(2)[0], 0.0);
}

TEST(Actuators, DescribePlanCountsThem) {
  Actuator free = motor(0, "free");
  free.enforce_operating_region = false;
  const Model model = spinner(0.1);
  const Simulator sim(model, 1, actuated(Precision::Float, {motor(0), free}));
  EXPECT_NE(sim.describe_plan().find("actuators: 2 (1 within their motors' operating regions)"), std::string::npos)
      << sim.describe_plan();
}

// The back-EMF braking is explicit, as RaiSim takes it: on a voltage line a
// motor damps its joint at the rate G^2 b / I, and the step multiplies the
// velocity's distance from the line's speed by 1 - h G^2 b / I. A shank of
// 0.02 kg m^2 behind an ANYdrive-like motor (G 50, K_t 0.1, 48 V, 0.5 ohm,
// K_v 10: G^2 b = 50 N m s) at dt 2 ms has h G^2 b / I = 5: saturated, its
// velocity grows fourfold per step, alternating in sign, and the warnings
// name it; with G 20 (h G^2 b / I = 0.8) it settles on the line's speed,
// tau_stall / (b G) = 23 rad/s (v = omega / G), and nothing is said.
TEST(Actuators, BrakingTooFastForTheStepIsWarnedOf) {
  const Model model = spinner(0.02);
  for (const double gear : {50.0, 20.0}) {
    Actuator a = motor(0, "knee");
    a.gear = gear, a.torque_constant = 0.1, a.bus_voltage = 48, a.resistance = 0.5, a.velocity_constant = 10;
    a.peak_torque = Model::kInfinity;
    StepOptions o = actuated(Precision::Double, {a});
    o.dt = 0.002;
    Simulator sim(model, 1, o);
    sim.set_actuator_torques(0, Eigen::VectorXd::Constant(1, 1e3));  // saturated: on the voltage line
    sim.step(100);
    const double v = sim.v(0)[0], line = a.stall_torque() / (a.back_emf_damping() * gear);
    const std::vector<std::string> warnings = sim.warnings();
    if (gear == 50.0) {
      EXPECT_GT(std::abs(v), 1e6 * line) << "diverges";
      ASSERT_EQ(warnings.size(), 1u);
      EXPECT_NE(warnings[0].find("fast actuators: 1 actuator(s) brake on their voltage lines faster than the step"),
                std::string::npos)
          << warnings[0];
      EXPECT_NE(warnings[0].find("(h b g^T Mt^-1 g 5 at 'knee', diverging above 2"), std::string::npos) << warnings[0];
    } else {
      EXPECT_NEAR(v, line, 1e-9 * line);
      EXPECT_TRUE(warnings.empty()) << warnings.front();
    }
  }
}

// Each bad actuator is refused with its index, name and field.
TEST(Actuators, BadActuatorsAreRefusedByName) {
  const Model anymal = load_shared_model("anymal_b", true);
  struct Bad {
    std::function<void(Actuator&)> change;
    std::string message;
  };
  const Bad cases[] = {
      {[](Actuator& a) { a.dof = 18; }, "actuator 0 (motor): DOF 18 outside [0, 18)"},
      {[](Actuator& a) { a.dof = 2; }, "actuator 0 (motor): DOF 2 (anymal_root[2]) is a floating base's"},
      {[](Actuator& a) { a.gear = 0; }, "actuator 0 (motor): gear must be finite (in float, within 3.4e38) and > 0 (a normal number), got 0"},
      {[](Actuator& a) { a.gear = -1e-9; }, "gear must be finite (in float, within 3.4e38) and > 0 (a normal number), got -1e-09"},
      {[](Actuator& a) { a.gear = 1e-50; },  // zero in float: the command would be divided by it
       "gear must be finite (in float, within 3.4e38) and > 0 (a normal number), got 1e-50"},
      {[](Actuator& a) { a.peak_torque = 1e-50; }, "peak_torque must be > 0 (a normal number)"},
      {[](Actuator& a) { a.gear = 1e39; },
       "gear must be finite (in float, within 3.4e38) and > 0 (a normal number), got 1e+39"},
      {[](Actuator& a) { a.torque_constant = 1e30, a.resistance = 1e-10; },
       "the stall torque K_t V_bus / R must be finite (in float, within 3.4e38) and > 0"},
      {[](Actuator& a) { a.velocity_constant = 1e-20, a.resistance = 1e-20; },
       "the back-EMF damping K_t / (R K_v) must be finite (in float, within 3.4e38) and > 0 (a normal number), "
       "got 1.0000000000000001e+39"},
      {[](Actuator& a) { a.resistance = -1; }, "resistance must be finite (in float, within 3.4e38) and > 0"},
      {[](Actuator& a) { a.velocity_constant = Model::kInfinity; }, "velocity_constant must be finite (in float, within 3.4e38) and > 0"},
      {[](Actuator& a) { a.peak_torque = 0; }, "peak_torque must be > 0 (a normal number) and finite (in float, within 3.4e38) (+inf for none)"},
      {[](Actuator& a) { a.couplings = {{7, 1.0}}; }, "coupled DOF 7 is the driven DOF"},
      {[](Actuator& a) { a.couplings = {{8, 1.0}, {8, 2.0}}; }, "coupled DOF 8 given twice"},
      {[](Actuator& a) { a.couplings = {{8, std::nan("")}}; }, "the ratio of coupled DOF 8 must be finite (in float, within 3.4e38)"},
      {[](Actuator& a) { a.couplings = {{0, 1.0}}; }, "coupled DOF 0 (anymal_root[0]) is a floating base's"},
      {[](Actuator& a) { a.name = ""; }, "actuator 0: has no name"},
  };
  for (const Bad& bad : cases) {
    Actuator a = motor(7);
    bad.change(a);
    EXPECT_THROW_WITH(Simulator(anymal, 1, actuated(Precision::Float, {a})), std::invalid_argument, bad.message);
  }
  EXPECT_THROW_WITH(Simulator(anymal, 1, actuated(Precision::Float, {motor(7), motor(8)})), std::invalid_argument,
                    "actuator 1 (motor): the name is another actuator's");
  Simulator sim(anymal, 1, actuated(Precision::Float, {motor(7)}));
  EXPECT_THROW_WITH(sim.set_actuator_torques(0, Eigen::Vector2d(1, 2)), std::invalid_argument,
                    "set_actuator_torques: expects 1 values (one per actuator), got 2");
}

// ---- VecEnv

TEST(Actuators, VecEnvActsThroughTheActuators) {
  const Model model = spinner(0.1);
  VecEnvOptions o;
  o.step = actuated(Precision::Double, {motor(0, "a"), motor(0, "b")});
  o.action_mode = ActionMode::ActuatorTorque;
  VecEnv env(model, 3, o);
  EXPECT_EQ(env.action_size(), 2);
  EXPECT_EQ(env.action_names(), (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(env.action_dofs(), (std::vector<int>{0, 0}));
  env.reset();
  RowMatrix actions(3, 2);
  actions << 5, 1, 30, 0, -2, -3;
  env.step(actions);
  for (int c = 0; c < 3; ++c) {
    // both within the region at rest but for copy 1's 30 (3 N m at the motor: the peak)
    const double expected = c == 1 ? 15.0 : actions(c, 0) + actions(c, 1);
    EXPECT_NEAR(env.observations().applied_torque(c, 0), expected, 1e-12) << "copy " << c;
  }
  // the motors observed: speed and torque per actuator, in their order
  ASSERT_EQ(env.observations().motor_torque.cols(), 2);
  EXPECT_EQ(env.observations().motor_torque(1, 0), 1.5);
  EXPECT_EQ(env.observations().motor_torque(0, 1), 0.1);
  EXPECT_EQ(env.observations().motor_speed(0, 0), 0.0);
  env.step(actions);
  EXPECT_NEAR(env.observations().motor_speed(1, 0), 10 * 0.002 * 15.0 / 0.1, 1e-13);  // G v after one step
  EXPECT_THROW_WITH(env.position_action(model.neutral_configuration()), std::logic_error,
                    "the actions are actuator torques");
  o.step.actuators.clear();
  EXPECT_THROW_WITH(VecEnv(model, 1, o), std::invalid_argument, "actuator_torque actions need actuators");
}

}  // namespace
}  // namespace lockstep::test
