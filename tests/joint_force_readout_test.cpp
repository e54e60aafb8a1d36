// Simulator::incoming_joint_forces: the force and torque each joint
// transmitted in the last step (StepOptions::record_motion), checked
// against the step's own applied torques, an analytic pendulum and a
// standing quadruped's statics; and how it behaves across resets,
// snapshots, lanes and substeps.
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

namespace lockstep::test {
namespace {

using Forces = Eigen::Matrix<double, 6, Eigen::Dynamic>;

// Each DOF's share of the joint forces f (one column per body, world axes)
// along its motion axes, with the bodies' poses at the start of the step: a
// revolute's torque and a prismatic's force about/along its body z, a
// Spherical joint's torque and a Free joint's force and torque in body axes.
Eigen::VectorXd along_joint_axes(const Model& model, const std::vector<Eigen::Isometry3d>& poses, const Forces& f) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(model.nv);
  for (int b = 0; b < model.nbody; ++b) {
    const Eigen::Matrix3d Rt = poses[b].linear().transpose();
    const Eigen::Vector3d force = Rt * f.col(b).head<3>(), torque = Rt * f.col(b).tail<3>();
    const int d = model.body_dof_offset[b];
    switch (model.body_joint[b]) {
      case JointType::Revolute: out[d] = torque.z(); break;
      case JointType::Prismatic: out[d] = force.z(); break;
      case JointType::Spherical: out.segment<3>(d) = torque; break;
      case JointType::Free: out.segment<6>(d) << force, torque; break;
      default: break;
    }
  }
  return out;
}

// The recorded acceleration of the copy's last step times its armature, in
// double: the rotor's share of the joint torque.
Eigen::VectorXd rotor_torque(const Simulator& sim, int copy) {
  // a vector, not an expression over the two temporaries it multiplies
  auto of = [&](const auto& b) -> Eigen::VectorXd {
    return b.armature.get(copy).cwiseProduct(b.motion_acceleration.get(copy));
  };
  return sim.options().precision == Precision::Float ? of(sim.batch<float>()) : of(sim.batch<double>());
}

struct Residual {
  double worst = 0;    // largest |along the axes + armature a - applied| over the DOFs that are not Free
  double largest = 0;  // largest |applied| seen
};

// Steps the copy `steps` times and compares, after each, the joint forces
// along the joints' axes (plus the rotor's share, armature x acceleration)
// with the applied torque the step reports (drive, passive, friction and
// limits): RaiSim's "joint torque = axis . joint torque" with the
// constraint rows included.
Residual step_and_compare(Simulator& sim, int steps) {
  const Model& model = sim.model();
  const CopyDynamics poses_of(model);
  Residual r;
  for (int i = 0; i < steps; ++i) {
    const Eigen::VectorXd q0 = sim.q(0);
    sim.step();
    const AppliedTorque t = sim.applied_torque(0);
    const Eigen::VectorXd applied = t.drive + t.passive + t.friction + t.limits;
    const Eigen::VectorXd along = along_joint_axes(model, poses_of.body_poses(q0), sim.incoming_joint_forces(0));
    const Eigen::VectorXd rotor = rotor_torque(sim, 0);
    for (int k = 0; k < model.nv; ++k) {
      if (model.body_joint[model.dof_body[k]] == JointType::Free) continue;
      r.worst = std::max(r.worst, std::abs(along[k] + rotor[k] - applied[k]));
      r.largest = std::max(r.largest, std::abs(applied[k]));
    }
  }
  return r;
}

// anymal_b (`scene`: floating, with the benchmark's stance drives) on the
// ground with record_motion, `copies` copies: copy c dropped from
// drop + c * spread above the stance, at rest or with the velocity v.
Simulator stance(const Model& model, const step_scene::Scene& scene, StepOptions o, int copies, double drop,
                 double spread = 0, const Eigen::VectorXd& v = {}) {
  o.contacts.ground = true;
  o.record_motion = true;
  Simulator sim(model, copies, o, scene.dofs);
  for (int c = 0; c < copies; ++c) {
    Eigen::VectorXd q = scene.q0;
    q[2] += drop + c * spread;
    sim.set_state(c, q, v.size() ? v : Eigen::VectorXd::Zero(model.nv));
    sim.set_drive_target(c, scene.q_target, Eigen::VectorXd::Zero(model.nv));
  }
  return sim;
}

// Tolerances of the identity, relative to the largest applied torque. The
// readout runs RNEA in double on the step's recorded motion. In double the
// two sides differ by round-off (ABA, the solver and RNEA): measured
// 5e-15 of the largest (anymal_b, ur5). In float the recorded acceleration
// (v1 - v0) / h carries v's rounding, ulp(|v|) / h = 6e-5 rad/s^2 per DOF
// at 1 rad/s and h = 2 ms, which the subtree's inertia turns into force,
// and the applied torques are float sums: measured 7e-7 (PGS) and 1.7e-6
// (TGS) of the largest on the landing quadruped, 1.5e-7 on ur5.
double identity_tolerance(Precision p) { return p == Precision::Double ? 1e-12 : 1e-5; }

// `model` (anymal_b) dropped 5 cm onto the ground under the stance drives:
// the landing's impacts, then standing, every row type a quadruped meets
// (contacts); the identity within identity_tolerance, `what` naming the run.
void expect_landing_identity(const Model& model, StepOptions o, const std::string& what) {
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  o.record_applied_torque = true;
  Simulator sim = stance(model, scene, o, 1, 0.05);
  const Residual r = step_and_compare(sim, 300);
  std::cout << "[joint forces] anymal_b landing, " << what << ": worst " << r.worst << " N m of " << r.largest << "\n";
  EXPECT_GT(r.largest, 10.0) << what;  // the legs carry the robot
  EXPECT_LE(r.worst, identity_tolerance(o.precision) * r.largest) << what;
}

// With either solver in either precision.
TEST(JointForces, AlongTheirAxesTheyAreTheAppliedTorqueOnALandingQuadruped) {
  const Model model = load_shared_model("anymal_b", true);
  for (SolverType solver : {SolverType::PGS, SolverType::TGS})
    for (Precision precision : {Precision::Float, Precision::Double}) {
      StepOptions o;
      o.precision = precision;
      o.solver = solver;
      expect_landing_identity(model, o, std::string(solver_name(solver)) + ", " + precision_name(precision));
    }
}

// Link damping on every body (its force at the end of the step, w D in
// the inertias: kernels/body_terms.hpp) is in the joint forces too, with
// the Free root's gyroscopic force implicit or not (the joints' balance
// leaves the root's unbalanced share out either way).
TEST(JointForces, AlongTheirAxesTheyAreTheAppliedTorqueWithLinkDamping) {
  Model model = load_shared_model("anymal_b", true);
  for (int b = 0; b < model.nbody; ++b) {
    model.body_linear_damping[b] = 0.5 + 0.1 * b;
    model.body_angular_damping[b] = 2.0 - 0.1 * b;
  }
  for (bool implicit : {true, false})
    for (Precision precision : {Precision::Float, Precision::Double}) {
      StepOptions o;
      o.precision = precision;
      o.implicit_gyroscopic = implicit;
      expect_landing_identity(model, o,
                              std::string("link damping, ") + (implicit ? "implicit" : "explicit") +
                                  " gyroscopic, " + precision_name(precision));
    }
}

// One copy of the fixed-base `model` (with `armature`, if given) driven
// toward `target` for `steps` steps: step_and_compare's residual, and the
// last step's applied torque.
struct DrivenRun {
  Residual residual;
  AppliedTorque last;
};
DrivenRun drive_and_compare(const Model& model, const std::vector<DofSettings>& dofs, Precision precision,
                            const Eigen::VectorXd& target, int steps, const Eigen::VectorXd& armature = {}) {
  StepOptions o;
  o.precision = precision;
  o.record_applied_torque = true;
  o.record_motion = true;
  Simulator sim(model, 1, o, dofs);
  if (armature.size()) sim.set_armature(0, armature);
  sim.set_drive_target(0, target, Eigen::VectorXd::Zero(model.nv));
  const Residual r = step_and_compare(sim, steps);
  return {r, sim.applied_torque(0)};
}

// ur5 with drives past its hard limits, velocity limits, Coulomb friction,
// damping and armature: the joint rows' impulses are in the joint forces.
TEST(JointForces, AlongTheirAxesTheyAreTheAppliedTorqueWithEveryJointRow) {
  const Model model = load_shared_model("ur5", false);
  std::vector<DofSettings> dofs = limited_dofs(model, 0.4, 1.5);
  Eigen::VectorXd armature(model.nv);
  for (int k = 0; k < model.nv; ++k) {
    dofs[k].drive_stiffness = 400;
    dofs[k].drive_damping = 20;
    armature[k] = 0.05 * (k + 1);
  }
  Eigen::VectorXd target = Eigen::VectorXd::Constant(model.nq, 1.0);  // beyond the limits at 0.4
  target[1] = -1.0;
  for (Precision precision : {Precision::Float, Precision::Double}) {
    const auto [r, last] = drive_and_compare(model, dofs, precision, target, 500, armature);
    EXPECT_GT(last.limits.cwiseAbs().maxCoeff(), 1.0) << "the limits hold the drives";
    std::cout << "[joint forces] ur5 on its limits, " << precision_name(precision) << ": worst " << r.worst
              << " N m of " << r.largest << "\n";
    EXPECT_LE(r.worst, identity_tolerance(precision) * r.largest) << precision_name(precision);
  }
}

// panda's fingers driven apart against their mimic row: its impulse acts
// on both fingers (J^T lambda, with the limits in applied_torque) and is in
// their joint forces.
TEST(JointForces, AlongTheirAxesTheyAreTheAppliedTorqueWithAMimicJoint) {
  const Model model = load_shared_model("panda", false);
  const int f1 = model.dof_index("panda_finger_joint1"), f2 = model.dof_index("panda_finger_joint2");
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 200, d.drive_damping = 10;
  Eigen::VectorXd target = Eigen::VectorXd::Zero(model.nq);
  target[f1] = 0.01;
  target[f2] = 0.03;
  for (Precision precision : {Precision::Float, Precision::Double}) {
    const auto [r, last] = drive_and_compare(model, dofs, precision, target, 300);
    EXPECT_GT(std::abs(last.limits[f1]), 0.5) << "the mimic row holds the drives apart";
    EXPECT_NEAR(last.limits[f2], -last.limits[f1], 1e-6 * std::abs(last.limits[f1])) << "J = e_2 - e_1";
    std::cout << "[joint forces] panda's mimic fingers, " << precision_name(precision) << ": worst " << r.worst
              << " N m of " << r.largest << "\n";
    EXPECT_LE(r.worst, identity_tolerance(precision) * r.largest) << precision_name(precision);
  }
}

// Spherical joints (test::spherical_tree) under drives and damping.
TEST(JointForces, AlongTheirAxesTheyAreTheAppliedTorqueOnSphericalJoints) {
  const Model model = spherical_tree(false);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 30, d.drive_damping = 2, d.damping = 0.1;
  StepOptions o;
  o.precision = Precision::Double;
  o.record_applied_torque = true;
  o.record_motion = true;
  Simulator sim(model, 1, o, dofs);
  std::mt19937 rng(5);
  sim.set_drive_target(0, random_configuration(model, rng), Eigen::VectorXd::Zero(model.nv));
  const Residual r = step_and_compare(sim, 200);
  EXPECT_GT(r.largest, 0.1);
  EXPECT_LE(r.worst, identity_tolerance(Precision::Double) * r.largest);
}

// A swinging rod on a revolute joint, one step: the pivot's force is
// m (a_com - g), a_com = alpha x r - w^2 r, alpha = (r x m g) . y / I_pivot
// from the rod's statics alone; no torque along the free axis.
TEST(JointForces, ThePivotOfASwingingRodCarriesItsCentripetalLoad) {
  const double m = 2.0, l = 0.5, theta = 0.7, w = 3.0;
  const Model model = rod_chain({m}, l);
  for (Precision precision : {Precision::Float, Precision::Double}) {
    StepOptions o;
    o.precision = precision;
    o.dt = 0.01;
    o.record_motion = true;
    Simulator sim(model, 1, o);
    sim.set_state(0, Eigen::VectorXd::Constant(1, theta), Eigen::VectorXd::Constant(1, w));
    sim.step();
    const Eigen::Vector3d y = Eigen::Vector3d::UnitY(), g = model.gravity;
    const Eigen::Vector3d r = Eigen::AngleAxisd(theta, y) * Eigen::Vector3d(0, 0, -0.5 * l);
    const double alpha = r.cross(m * g).dot(y) / (m * l * l / 3.0);
    const Eigen::Vector3d a_com = alpha * y.cross(r) - w * w * r;
    const Eigen::Vector3d expected = m * (a_com - g);
    const Forces f = sim.incoming_joint_forces(0);
    // float: the recorded alpha carries ulp(w) / h = 2.4e-5 rad/s^2 of 8.8
    const double tolerance = precision == Precision::Double ? 1e-10 : 1e-5;
    EXPECT_LE((f.col(0).head<3>() - expected).norm(), tolerance * expected.norm()) << precision_name(precision);
    EXPECT_LE(std::abs(f.col(0).tail<3>().dot(y)), tolerance * expected.norm() * l) << precision_name(precision);
  }
}

// A free box spinning about its intermediate axis and pushed along its own
// x by a feedforward force on its Free joint: the joint transmits exactly
// that force (the world holds nothing), once the implicit gyroscopic
// force, which changes the step's equations of the Free body, is off.
// With it on, the joint also carries what it changed: O(h |w| |a|).
TEST(JointForces, AFreeJointTransmitsItsFeedforwardForceOnly) {
  const Model model = single_body(ShapeType::Box, Eigen::Vector3d(0.1, 0.2, 0.3), 1.0);
  Eigen::VectorXd v(6), tau = Eigen::VectorXd::Zero(6);
  v << 1.0, 0, 0, 0.05, 5, 0.05;
  tau[0] = 2.0;
  for (bool implicit : {false, true}) {
    StepOptions o;
    o.precision = Precision::Double;
    o.dt = 0.005;
    o.implicit_gyroscopic = implicit;
    o.record_motion = true;
    Simulator sim(model, 1, o);
    sim.set_gravity(0, Eigen::Vector3d::Zero());
    sim.set_state(0, model.neutral_configuration(), v);
    sim.set_torque(0, tau);
    const CopyDynamics poses_of(model);
    double worst = 0;
    for (int i = 0; i < 200; ++i) {
      const Eigen::VectorXd q0 = sim.q(0);
      sim.step();
      const Eigen::VectorXd along = along_joint_axes(model, poses_of.body_poses(q0), sim.incoming_joint_forces(0));
      worst = std::max(worst, (along - tau).norm());
    }
    std::cout << "[joint forces] spinning box, implicit gyroscopic " << implicit << ": worst " << worst << "\n";
    if (implicit) EXPECT_GT(worst, 1e-3);  // 0.06 N m here
    else EXPECT_LE(worst, 1e-12);
  }
}

// A link's acceleration: a free box in free fall reads g at its COM (its
// link origin) however it spins; the second rod of a swinging chain has its
// origin at the first rod's end, r from the pivot: alpha x r - w^2 r, with
// alpha the step's acceleration of the first joint, and the chain's
// angular acceleration about y.
TEST(LinkAccelerations, AFallingBoxReadsGravityAndARodsEndMovesOnItsCircle) {
  StepOptions o;
  o.precision = Precision::Double;
  o.record_motion = true;
  const Model box = single_body(ShapeType::Box, Eigen::Vector3d(0.1, 0.2, 0.3), 1.0);
  Simulator fall(box, 1, o);
  Eigen::VectorXd v(6);
  v << 0.3, -0.2, 0.1, 0.05, 5, 0.05;
  fall.set_state(0, box.neutral_configuration(), v);
  EXPECT_TRUE(fall.link_accelerations(0).isZero(0));  // no step yet
  for (int i = 0; i < 50; ++i) {
    fall.step();
    const Eigen::Vector3d a = fall.link_accelerations(0).col(0).head<3>();
    ASSERT_LE((a - box.gravity).norm(), 1e-12) << "step " << i << ": " << a.transpose();
  }

  const double theta = 0.7, w = 3.0, l = 0.5;
  const Model chain = rod_chain({2.0, 1.0}, l);
  Simulator swing(chain, 1, o);
  const Eigen::VectorXd q0 = Eigen::Vector2d(theta, -0.4), v0 = Eigen::Vector2d(w, 1.0);
  swing.set_state(0, q0, v0);
  swing.step();
  const double alpha = CopyDynamics(chain).forward_dynamics(q0, v0, Eigen::Vector2d::Zero())[0];
  const Eigen::Vector3d y = Eigen::Vector3d::UnitY();
  const Eigen::Vector3d r = Eigen::AngleAxisd(theta, y) * Eigen::Vector3d(0, 0, -l);
  const Eigen::Vector3d expected = alpha * y.cross(r) - w * w * r;
  const Forces acc = swing.link_accelerations(0);
  const int end = chain.frame_index("link1");
  EXPECT_LE((acc.col(end).head<3>() - expected).norm(), 1e-10 * expected.norm()) << acc.col(end).transpose();
  EXPECT_NEAR(acc.col(chain.frame_index("link0"))[4], alpha, 1e-10 * std::abs(alpha));

  Simulator plain(chain, 1);
  EXPECT_THROW(plain.link_accelerations(0), std::logic_error);
}

// With conserve_linear_momentum the step corrects the base's velocity after
// its solve: the links' accelerations hold the correction (the base
// origin's equals the rate of its world velocity over the step), the joint
// forces do not (their identity with the applied torques still holds). The
// correction was left out of the motion: 0.57 m/s^2 off of 21.
TEST(LinkAccelerations, HoldTheMomentumProjectionsCorrection) {
  const Model model = load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  StepOptions o;
  o.precision = Precision::Double;
  o.conserve_linear_momentum = true;
  o.record_applied_torque = true;
  Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
  v.segment<3>(3) << 0.5, -1.0, 2.0;  // the base spinning
  Simulator sim = stance(model, scene, o, 1, 0.05, 0, v);
  const CopyDynamics dyn(model);
  double worst = 0, largest = 0;
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d v0 = dyn.frame_velocities(sim.q(0), sim.v(0)).col(0).head<3>();
    sim.step();
    const Eigen::Vector3d rate = (dyn.frame_velocities(sim.q(0), sim.v(0)).col(0).head<3>() - v0) / o.dt;
    worst = std::max(worst, (sim.link_accelerations(0).col(0).head<3>() - rate).norm());
    largest = std::max(largest, rate.norm());
  }
  EXPECT_GT(largest, 5.0);  // the landing
  EXPECT_LE(worst, 1e-9 * largest);
  sim.reset(0);
  const Residual r = step_and_compare(sim, 100);
  EXPECT_LE(r.worst, identity_tolerance(Precision::Double) * r.largest);
}

// anymal_b standing still: its hips hold up the base (their forces on the
// legs sum to the base's weight), and the floating base's Free joint
// transmits nothing.
TEST(JointForces, AStandingQuadrupedsHipsCarryItsBase) {
  const Model model = load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  StepOptions o;
  o.precision = Precision::Double;
  Simulator sim = stance(model, scene, o, 1, 0.0);
  sim.step(1000);
  ASSERT_LT(sim.v(0).cwiseAbs().maxCoeff(), 1e-3) << "it stands still";
  const Forces f = sim.incoming_joint_forces(0);
  Eigen::Vector3d hips = Eigen::Vector3d::Zero();
  int legs = 0;
  for (int b = 0; b < model.nbody; ++b)
    if (model.body_parent[b] == 0) hips += f.col(b).head<3>(), ++legs;
  ASSERT_EQ(legs, 4);
  const Eigen::Vector3d weight = model.body_mass[0] * model.gravity;
  // at rest to |qd| < 1e-3: the base's m a is below 1e-3 of its weight
  EXPECT_LE((hips - weight).norm(), 1e-3 * weight.norm()) << hips.transpose() << " vs " << weight.transpose();
  EXPECT_LE(f.col(0).norm(), 1e-3 * weight.norm());
}

// Before any step, after a reset, a set_state or a reset_on_fault restart
// there is no step to report: zero. A snapshot carries the report.
TEST(JointForces, ZeroWithoutAStepAndCarriedBySnapshots) {
  const Model model = rod_chain({1.0, 0.5}, 0.3);
  StepOptions o;
  o.record_motion = true;
  o.reset_on_fault = true;
  Simulator sim(model, 2, o);
  EXPECT_TRUE(sim.incoming_joint_forces(0).isZero(0));
  sim.step();
  const Forces after_step = sim.incoming_joint_forces(0);
  EXPECT_GT(after_step.norm(), 1.0);  // the rods' weight
  const CopySnapshot snap = sim.snapshot(0);
  sim.reset(0);
  EXPECT_TRUE(sim.incoming_joint_forces(0).isZero(0));
  sim.restore(0, snap);
  EXPECT_EQ(sim.incoming_joint_forces(0), after_step);
  sim.set_state(0, sim.q(0), sim.v(0));
  EXPECT_TRUE(sim.incoming_joint_forces(0).isZero(0));
  // a faulted copy restarts from its initial state: no step to report
  sim.step();
  sim.set_torque(1, Eigen::VectorXd::Constant(model.nv, std::nan("")));
  sim.step();
  EXPECT_EQ(sim.fault(1), Fault::NonFiniteTorque);
  EXPECT_TRUE(sim.incoming_joint_forces(1).isZero(0));
  EXPECT_GT(sim.incoming_joint_forces(0).norm(), 1.0);

  StepOptions without;
  Simulator plain(model, 1, without);
  EXPECT_THROW(plain.incoming_joint_forces(0), std::logic_error);
  EXPECT_THROW(plain.restore(0, snap), std::invalid_argument);  // its snapshot holds a motion
}

// The bulk readouts give every copy's per-copy readout, bit for bit (the
// SIMD lanes compute what the scalar reference does), zeros for a copy
// reset since its step, and refuse an output of the wrong shape.
TEST(JointForces, TheBulkReadoutsAreThePerCopyOnes) {
  const Model model = load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  const int copies = 19;
  Simulator sim = stance(model, scene, {}, copies, 0.0, 0.002);  // copies in different phases of their landing
  sim.step(40);
  sim.reset(5);
  const int frames = static_cast<int>(model.frame_name.size());
  RowMatrix forces(copies, 6 * model.nbody), accelerations(copies, 6 * frames);
  sim.all_incoming_joint_forces(forces);
  sim.all_link_accelerations(accelerations);
  for (int c = 0; c < copies; ++c) {
    const Forces f = sim.incoming_joint_forces(c), a = sim.link_accelerations(c);
    EXPECT_TRUE(same_bits(forces.row(c).transpose(), Eigen::Map<const Eigen::VectorXd>(f.data(), f.size())))
        << "copy " << c;
    EXPECT_TRUE(same_bits(accelerations.row(c).transpose(), Eigen::Map<const Eigen::VectorXd>(a.data(), a.size())))
        << "copy " << c;
  }
  EXPECT_TRUE(forces.row(5).isZero(0));
  EXPECT_GT(forces.row(0).norm(), 10.0);
  RowMatrix wrong(copies, 6);
  EXPECT_THROW(sim.all_incoming_joint_forces(wrong), std::invalid_argument);
  EXPECT_THROW(sim.all_link_accelerations(wrong), std::invalid_argument);
}

// SIMD lanes record what the scalar reference records, bit for bit; a step
// of two pipeline runs reports its last run, as two steps of half the dt
// report their second.
TEST(JointForces, TheSameBitsInEveryLaneAndForTheLastPipelineRun) {
  const Model model = load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  auto run = [&](Lanes lanes, double dt, int substeps, int steps) {
    StepOptions o;
    o.lanes = lanes;
    o.dt = dt;
    o.substeps = substeps;
    Simulator sim = stance(model, scene, o, 19, 0.02);
    sim.step(steps);
    std::vector<Forces> out;
    for (int c = 0; c < sim.copies(); ++c) out.push_back(sim.incoming_joint_forces(c));
    return out;
  };
  const std::vector<Forces> simd = run(Lanes::Simd, 0.002, 1, 60), scalar = run(Lanes::Scalar, 0.002, 1, 60);
  const std::vector<Forces> halves = run(Lanes::Simd, 0.001, 1, 120), runs = run(Lanes::Simd, 0.002, 2, 60);
  for (int c = 0; c < 19; ++c) {
    EXPECT_TRUE(same_bits(Eigen::Map<const Eigen::VectorXd>(simd[c].data(), simd[c].size()),
                          Eigen::Map<const Eigen::VectorXd>(scalar[c].data(), scalar[c].size())))
        << "copy " << c;
    EXPECT_TRUE(same_bits(Eigen::Map<const Eigen::VectorXd>(halves[c].data(), halves[c].size()),
                          Eigen::Map<const Eigen::VectorXd>(runs[c].data(), runs[c].size())))
        << "copy " << c;
  }
  EXPECT_GT(simd[0].norm(), 10.0);
}

}  // namespace
}  // namespace lockstep::test
