// The integrators' measured order of convergence and energy error on a
// double pendulum, against a fine RK4 reference. docs/stability.md has the
// table of the numbers this test prints.
#include "tests/sim_support.hpp"

#include <cmath>
#include <iostream>

namespace lockstep {
namespace {

struct PendulumRun {
  Eigen::VectorXd q, v;
  double max_energy_error = 0;  // max over the steps of |E - E0| [J]
};

// Two 1 kg, 1 m rods on revolute joints about y, fixed base, gravity, no
// damping, no limits (the limit stages forced off, as RK4 requires), from
// q = (1, -0.5) rad, v = (0.5, 1) rad/s, integrated to T = 1 s in double on
// the scalar lane.
PendulumRun run_pendulum(Integrator integrator, double dt, SolverType solver = SolverType::PGS,
                         const std::vector<DofSettings>& dofs = {}) {
  static const Model model = test::rod_chain({1.0, 1.0}, 1.0);
  const CopyDynamics dyn(model, Precision::Double);
  StepOptions o;
  o.dt = dt;
  o.precision = Precision::Double;
  o.lanes = Lanes::Scalar;
  o.integrator = integrator;
  o.solver = solver;
  o.force(Stage::HardLimits, StageMode::Off).force(Stage::VelocityLimits, StageMode::Off);
  Simulator sim(model, 1, o, dofs.empty() ? default_dof_settings(model) : dofs);
  Eigen::VectorXd q0(2), v0(2);
  q0 << 1.0, -0.5;
  v0 << 0.5, 1.0;
  sim.set_state(0, q0, v0);
  const double e0 = dyn.kinetic_energy(q0, v0) + dyn.potential_energy(q0);
  PendulumRun run;
  const int steps = static_cast<int>(std::lround(1.0 / dt));
  for (int i = 0; i < steps; ++i) {
    sim.step();
    const Eigen::VectorXd q = sim.q(0), v = sim.v(0);
    run.max_energy_error = std::max(run.max_energy_error, std::abs(dyn.kinetic_energy(q, v) + dyn.potential_energy(q) - e0));
  }
  EXPECT_EQ(sim.fault(0), Fault::None);
  run.q = sim.q(0);
  run.v = sim.v(0);
  return run;
}

// Least-squares slope of log y against log x.
double log_log_slope(const std::vector<double>& x, const std::vector<double>& y) {
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < x.size(); ++i) mx += std::log(x[i]), my += std::log(y[i]);
  mx /= x.size(), my /= y.size();
  double sxy = 0, sxx = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double dx = std::log(x[i]) - mx;
    sxy += dx * (std::log(y[i]) - my);
    sxx += dx * dx;
  }
  return sxy / sxx;
}

// The global error at T of (q, v), Euclidean, against RK4 at dt = 2.5e-5
// (its own error ~1e-14: two references at 5e-5 and 2.5e-5 differ by
// 5e-14, far below the smallest error on the ladder, 5e-12), over the
// ladder dt = 0.02 / 2^j, j = 0..6 (dt omega <= 0.1 for the pendulum's
// ~4 rad/s). Orders are log-log least-squares slopes, within +-0.3 of:
//
// - semi-implicit Euler, v1 = v0 + dt a(q0, v0), q1 = q0 + dt v1: order 1.
// - Trapezoid: the explicit trapezoidal rule (Heun) for the velocity,
//   v1 = v0 + dt (a(q0, v0) + a(q0 + dt v0, v0 + dt a0)) / 2, positions by
//   the average velocity q1 = q0 + dt (v0 + v1) / 2 (RaiSim's position
//   update): local error O(dt^3) in both, order 2.
// - RK4: order 4 (about 3.85 measured: the coarse end of the ladder is not
//   yet asymptotic; successive ratios rise to 16).
// - Explicit Euler, the same velocity as semi-implicit Euler, positions
//   q1 = q0 + dt v0: order 1.
//
// Energy error (max |E - E0| over the run) at the same dt follows the
// orders: RK4 O(dt^4) < trapezoid O(dt^2) < semi-implicit Euler O(dt), the
// issue's ordering, asserted at every dt of the ladder. Explicit Euler's
// positions lag the velocities they are moved by: its energy error exceeds
// semi-implicit Euler's at every dt (measured 3.7 to 4.0 times; its state
// error 5.4 to 6.8 times), asserted too.
TEST(IntegratorOrder, MeasuredOrdersAndEnergyErrorsOnADoublePendulum) {
  const PendulumRun reference = run_pendulum(Integrator::RK4, 2.5e-5);
  const Integrator integrators[4] = {Integrator::SemiImplicitEuler, Integrator::Trapezoid, Integrator::RK4,
                                     Integrator::ExplicitEuler};
  const double theory[4] = {1.0, 2.0, 4.0, 1.0};
  std::vector<double> dts;
  for (int j = 0; j <= 6; ++j) dts.push_back(0.02 / (1 << j));
  std::vector<double> state_error[4], energy_error[4];
  for (int m = 0; m < 4; ++m)
    for (double dt : dts) {
      const PendulumRun run = run_pendulum(integrators[m], dt);
      state_error[m].push_back(std::hypot((run.q - reference.q).norm(), (run.v - reference.v).norm()));
      energy_error[m].push_back(run.max_energy_error);
    }
  for (int m = 0; m < 4; ++m) {
    const std::string name = integrator_name(integrators[m]);
    const double order = log_log_slope(dts, state_error[m]);
    const double energy_order = log_log_slope(dts, energy_error[m]);
    EXPECT_NEAR(order, theory[m], 0.3) << name;
    EXPECT_NEAR(energy_order, theory[m], 0.3) << name << " energy error";
    std::cout << "[ measured ] " << name << ": order " << order << ", energy-error order " << energy_order << "\n";
    for (std::size_t j = 0; j < dts.size(); ++j)
      std::cout << "[ measured ]   dt " << dts[j] << "  state error " << state_error[m][j] << "  max |E - E0| "
                << energy_error[m][j] << " J\n";
    ::testing::Test::RecordProperty(name + " order", std::to_string(order));
  }
  for (std::size_t j = 0; j < dts.size(); ++j) {
    EXPECT_LT(energy_error[2][j], energy_error[1][j]) << "dt " << dts[j];
    EXPECT_LT(energy_error[1][j], energy_error[0][j]) << "dt " << dts[j];
    EXPECT_LT(energy_error[0][j], energy_error[3][j]) << "dt " << dts[j];
  }
}

// The same orders with every joint effect the integrators treat implicitly
// acting: a PD drive on the shoulder (kp 30, kd 2, towards the hanging
// pose), a spring on the elbow (12 N m/rad about -0.2 rad) and
// damping on both (0.3 N m s). Their implicit part once made the trapezoid
// and RK4 first order: each stage took the backward-Euler acceleration
// (M + h kd + h^2 kp)^-1 f(q + h v), O(h) off the stage's own (measured
// then: orders 0.95 and 0.90, errors at dt = 5 ms 0.28 and 0.27 against
// semi-implicit Euler's 0.31). Now the trapezoid takes them by the implicit
// trapezoidal rule (weight h/2, once at the start) and RK4 explicitly at
// each stage. Measured: orders 0.88, 2.00 and 3.94, errors at 5 ms 0.31,
// 3.4e-3 and 2.9e-6. Asserted: each within 0.3 of 1, 2 and 4 over the
// ladder of the test above (RK4's from dt = 0.02 to 0.00125, where its
// error stays well above the reference's).
TEST(IntegratorOrder, JointEffectsKeepTheOrders) {
  const Model model = test::rod_chain({1.0, 1.0}, 1.0);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  dofs[0].drive_stiffness = 30, dofs[0].drive_damping = 2;
  dofs[1].spring_stiffness = 12, dofs[1].spring_rest = -0.2;
  for (DofSettings& d : dofs) d.damping = 0.3;
  const PendulumRun reference = run_pendulum(Integrator::RK4, 2.5e-5, SolverType::PGS, dofs);
  const Integrator integrators[3] = {Integrator::SemiImplicitEuler, Integrator::Trapezoid, Integrator::RK4};
  const double theory[3] = {1.0, 2.0, 4.0};
  for (int m = 0; m < 3; ++m) {
    std::vector<double> dts, errors;
    for (int j = 0; j <= (m == 2 ? 4 : 6); ++j) {
      const double dt = 0.02 / (1 << j);
      const PendulumRun run = run_pendulum(integrators[m], dt, SolverType::PGS, dofs);
      dts.push_back(dt);
      errors.push_back(std::hypot((run.q - reference.q).norm(), (run.v - reference.v).norm()));
    }
    const std::string name = integrator_name(integrators[m]);
    const double order = log_log_slope(dts, errors);
    std::cout << "[ measured ] " << name << " with joint effects: order " << order << ", error at dt 0.005 "
              << errors[2] << "\n";
    EXPECT_NEAR(order, theory[m], 0.3) << name;
  }
}

// RK4 on the quaternion joints: a free box tumbling about all three axes
// (half sizes 0.1, 0.2, 0.3 m, 1 kg, w0 = (1, 3, 0.7) rad/s and v0 = (0.3,
// 0.1, 0.5) m/s in its body frame, under gravity) and the spherical tree
// (fixed base, gravity, from a turn of 0.5 rad on each ball), to T = 1 s in
// double on the scalar lane, against RK4 at dt = 2.5e-5. The stages' turns
// add up in the rotation vector from q0 with the slope J_r(u)^-1 w
// (turn_rate_at_start, RKMK). Adding the stages' body-frame w as if they
// were that slope made RK4 second order wherever w turns: measured then
// orders 2.00 (box) and 2.00 (tree), errors at dt = 0.005 4.7e-5 and
// 1.4e-5. Measured now: orders 4.00 and 4.02, errors at dt = 0.005 2.0e-8
// and 9.0e-8. Asserted: within 0.3 of 4 over dt = 0.02 ... 0.00125 (the
// smallest error, 8e-11, far above the reference's).
TEST(IntegratorOrder, Rk4KeepsItsOrderOnQuaternionJoints) {
  struct Case {
    const char* name;
    Model model;
    Eigen::VectorXd q0, v0;
  };
  std::vector<Case> cases;
  {
    Case box{"free box", test::free_box(Eigen::Vector3d(0.1, 0.2, 0.3), 1.0), {}, {}};
    box.q0 = box.model.neutral_configuration();
    box.v0.resize(6);
    box.v0 << 0.3, 0.1, 0.5, 1.0, 3.0, 0.7;
    cases.push_back(box);
  }
  {
    Case tree{"spherical tree", test::spherical_tree(false), {}, {}};
    tree.q0 = tree.model.neutral_configuration();
    for (int b = 0; b < tree.model.nbody; ++b)
      if (tree.model.body_joint[b] == JointType::Spherical) {
        const Eigen::Quaterniond turn(Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 2, 3).normalized()));
        tree.q0.segment<4>(tree.model.body_q_offset[b]) << turn.w(), turn.x(), turn.y(), turn.z();
      }
    tree.v0 = Eigen::VectorXd::Constant(tree.model.nv, 0.5);
    cases.push_back(tree);
  }
  for (const Case& c : cases) {
    auto run = [&](double dt) {
      StepOptions o;
      o.dt = dt;
      o.precision = Precision::Double;
      o.lanes = Lanes::Scalar;
      o.integrator = Integrator::RK4;
      o.force(Stage::HardLimits, StageMode::Off).force(Stage::VelocityLimits, StageMode::Off);
      Simulator sim(c.model, 1, o);
      sim.set_state(0, c.q0, c.v0);
      sim.step(static_cast<int>(std::lround(1.0 / dt)));
      EXPECT_EQ(sim.fault(0), Fault::None) << c.name;
      Eigen::VectorXd x(c.model.nq + c.model.nv);
      x << sim.q(0), sim.v(0);
      return x;
    };
    const Eigen::VectorXd reference = run(2.5e-5);
    std::vector<double> dts, errors;
    for (int j = 0; j <= 4; ++j) {
      dts.push_back(0.02 / (1 << j));
      errors.push_back((run(dts.back()) - reference).norm());
      std::cout << "[ measured ] RK4 " << c.name << " dt " << dts.back() << "  state error " << errors.back() << "\n";
    }
    const double order = log_log_slope(dts, errors);
    std::cout << "[ measured ] RK4 " << c.name << ": order " << order << "\n";
    EXPECT_NEAR(order, 4.0, 0.3) << c.name;
  }
}

// The solver does not change how a copy without acting rows integrates: TGS
// moves it by the integrator's velocity, as PGS does (the trapezoid's
// (v0 + v1)/2 too, not TGS's displacement h v1). Not to the bit: PGS adds
// fma(h, v, q), TGS q + (h v) rounded first, about 1e-16 per step, 1e-13
// over the 200 steps of chaotic motion; the trapezoid moved by h v1 instead
// would be off by h^2 a / 2 per step: 0.07 rad in q at the end.
TEST(IntegratorOrder, TgsIntegratesACopyWithoutRowsAsPgsDoes) {
  for (Integrator integrator : {Integrator::SemiImplicitEuler, Integrator::Trapezoid}) {
    const PendulumRun pgs = run_pendulum(integrator, 0.005, SolverType::PGS);
    const PendulumRun tgs = run_pendulum(integrator, 0.005, SolverType::TGS);
    std::cout << "[ measured ] " << integrator_name(integrator) << ": TGS - PGS at 1 s, q "
              << (tgs.q - pgs.q).cwiseAbs().maxCoeff() << ", v " << (tgs.v - pgs.v).cwiseAbs().maxCoeff() << "\n";
    for (int i = 0; i < 2; ++i) {
      EXPECT_NEAR(tgs.q[i], pgs.q[i], 1e-10) << integrator_name(integrator) << " q " << i;
      EXPECT_NEAR(tgs.v[i], pgs.v[i], 1e-10) << integrator_name(integrator) << " v " << i;
    }
  }
}

// Explicit Euler moves a copy whose rows rest by v0, and whether a row
// acts is decided at q0 + h u*: the spinner at 0.29 rad moving at 10 rad/s
// into its limit at 0.3, while a torque of -600 N m turns u* to -2 rad/s,
// passes the limit in that step by at most h |v0| = 0.02 rad. From the next
// step its limit row acts: let go at rest past the limit, the row gives it
// the speed that removes error_reduction (0.2) of the violation, and the
// joint keeps that speed (the one-sided row lets it go) back inside its
// range (measured: 0.01 rad past, then 0.008, 0.006, ..., 0 after 5 steps,
// and on inside).
TEST(IntegratorOrder, ExplicitEulerCorrectsALimitItPassedByHV0) {
  const Model model = test::spinner(0.1, -1.0, 0.3);
  StepOptions o;
  o.precision = Precision::Double;
  o.integrator = Integrator::ExplicitEuler;
  Simulator sim(model, 1, o);
  sim.set_state(0, Eigen::VectorXd::Constant(1, 0.29), Eigen::VectorXd::Constant(1, 10.0));
  sim.set_torque(0, Eigen::VectorXd::Constant(1, -600.0));
  sim.step();
  const double passed = sim.q(0)[0] - 0.3;
  EXPECT_GT(passed, 0.0) << "the step moved by v0 past the limit";
  EXPECT_LE(passed, o.dt * 10.0 + 1e-12);
  sim.set_torque(0, Eigen::VectorXd::Zero(1));
  sim.set_state(0, sim.q(0), Eigen::VectorXd::Zero(1));
  sim.step();
  EXPECT_NEAR(sim.q(0)[0] - 0.3, (1 - o.error_reduction) * passed, 1e-12);
  double violation = sim.q(0)[0] - 0.3;
  for (int i = 0; i < 30; ++i) {
    sim.step();
    const double now = sim.q(0)[0] - 0.3;
    EXPECT_LE(now, violation) << "step " << i;
    violation = now;
  }
  EXPECT_LE(violation, 0.0) << "back inside its range";
}

}  // namespace
}  // namespace lockstep
