// What a simulation step does: the time step and its knobs (StepOptions), the
// per-DOF joint effects (DofSettings: drive, damping, spring, friction,
// limits), and the stages of the pipeline that a scene switches on.
#pragma once

#include "batch/actuators.hpp"
#include "batch/contact_settings.hpp"
#include "batch/precision.hpp"
#include "layout/model.hpp"

#include <array>
#include <string>
#include <vector>

namespace lockstep {

enum class SolverType { PGS, TGS };
// How positions and velocities advance (docs/stability.md, section 7):
// semi-implicit Euler moves the positions by the new velocity, explicit
// Euler by the old one (RaiSim's EXPLICIT_EULER: the same forces, the
// position update one step behind), the trapezoid by their mean, RK4 by
// its four stages.
enum class Integrator { SemiImplicitEuler, Trapezoid, RK4, ExplicitEuler };
// The two Eulers share their velocity: v1 = v0 + h a from one ABA at
// (q0, v0), the joint effects by backward Euler (w = h); they differ only
// in the velocity their positions move by.
inline bool euler_velocity(Integrator integrator) {
  return integrator == Integrator::SemiImplicitEuler || integrator == Integrator::ExplicitEuler;
}
// The weight w with which the step takes link damping, -D (v + w a)
// (kernels/body_terms.hpp): backward Euler (w = h) with the Eulers, like
// the joint effects; explicit (w = 0) with the trapezoid and RK4, which
// take it at each of their evaluations and keep their order, stable while
// h c stays below their bounds (the Simulator checks it).
inline double link_damping_weight(Integrator integrator, double h) { return euler_velocity(integrator) ? h : 0.0; }
// Scalar runs the reference path, one copy per block; Simd one copy per lane.
enum class Lanes { Simd, Scalar };

const char* solver_name(SolverType solver);
const char* integrator_name(Integrator integrator);

// PhysX's drive types: a Force drive outputs stiffness * error + damping *
// velocity error as a force; an Acceleration drive outputs it as a joint
// acceleration (gains in 1/s^2 and 1/s), i.e. scaled by the joint's
// articulated inertia, so one DOF's response does not depend on the links'
// masses (docs/conventions.md: chains, Spherical joints).
enum class DriveType { Force, Acceleration };

// Coulomb: a solver row that stops the joint if the friction force can, the
// force a constant bound (RaiSim's model; PhysX scales its bound by the
// joint's load, which is not modelled). Stribeck: a smooth explicit force (the articulated-actors
// reference): peak static force coulomb + stiction_extra reached linearly at
// falloff_velocity, falling to coulomb with a Gaussian of width
// stribeck_velocity.
enum class FrictionModel { Coulomb, Stribeck };

// Per-DOF joint effects. default_dof_settings(model) fills them from the
// model (URDF effort, velocity, limits, damping, friction, springs); everything
// else defaults to off. A Free joint's DOFs take no drive, spring or limit.
struct DofSettings {
  // drive: tau = clamp(tau_ff + kp (q_target - q) + kd (v_target - v), -max_force, max_force)
  double drive_stiffness = 0.0;  // kp [N m/rad or N/m; 1/s^2 for Acceleration]
  double drive_damping = 0.0;    // kd [N m s/rad or N s/m; 1/s for Acceleration]
  DriveType drive_type = DriveType::Force;
  double max_force = Model::kInfinity;  // the effort limit; clamps feedforward + PD together
  // passive, never clamped
  double damping = 0.0;           // viscous [N m s/rad], implicit
  double spring_stiffness = 0.0;  // [N m/rad], implicit
  double spring_rest = 0.0;       // rest position [rad or m]
  // (armature, the rotor inertia, is the model's: JointSpec::armature)
  // friction
  double friction = 0.0;  // Coulomb force [N m or N]
  FrictionModel friction_model = FrictionModel::Coulomb;
  double stiction_extra = 0.0;       // Stribeck only [N m]
  double falloff_velocity = 1e-3;    // Stribeck only [rad/s]
  double stribeck_velocity = 0.0;    // Stribeck only [rad/s]; 0: no Stribeck fall-off
  // limits: hard (a one-sided solver row) when limit_stiffness is 0, else a
  // spring-damper acting beyond the range, integrated implicitly. A
  // spherical joint's limits bound the components of its rotation vector
  // log(q) (its DOF k's limits bound component k; all three DOFs limited
  // on both sides, the box within |r| < pi)
  double lower = -Model::kInfinity;
  double upper = Model::kInfinity;
  double limit_stiffness = 0.0;
  double limit_damping = 0.0;
  double velocity_limit = Model::kInfinity;  // |v| bound, a solver row
};

std::vector<DofSettings> default_dof_settings(const Model& model);

// The per-DOF parameters every copy starts with: the scene's drive gains,
// damping and Coulomb friction (zero on DOFs with another friction model)
// and the model's armature. With Stage::PerCopyJointParameters skipped,
// every copy steps with these.
struct JointParameters {
  Eigen::VectorXd drive_stiffness, drive_damping, damping, armature, friction;  // (nv) each
};
JointParameters scene_joint_parameters(const Model& model, const std::vector<DofSettings>& dofs);

// The pipeline's stages; each runs when the scene needs it (Auto) or when
// forced On; Off skips it even if the scene has the feature.
enum class Stage : int {
  Drives,                  // PD drives (explicit command + implicit diagonal)
  Damping,                 // joint damping, implicit
  Springs,                 // joint springs, implicit
  SoftLimits,              // spring-damper limits, implicit
  StribeckFriction,        // smooth friction force, explicit
  ExternalWrenches,        // link wrenches through J^T
  LinkDamping,             // links' linear and angular damping (LinkSpec), implicit with the Eulers
  PerCopyInertia,          // each copy's own inertial parameters; skipped, all share the model's
  PerCopyJointParameters,  // each copy's own drive gains, damping, armature, joint friction; skipped, the scene's
  MimicJoints,             // solver rows: URDF mimic tags as equalities q_f = m q_l + c
  FixedTendons,            // solver rows: fixed tendons' springs and length limits
  HardLimits,              // solver rows: one-sided position limits
  VelocityLimits,          // solver rows: |v| bounds
  CoulombFriction,         // solver rows: boxed friction impulses
  Contacts,                // collision detection and contact rows
  Count
};
inline constexpr int kStageCount = static_cast<int>(Stage::Count);
enum class StageMode { Auto, On, Off };
const char* stage_name(Stage stage);

struct StepOptions {
  double dt = 0.002;   // seconds per step()
  int substeps = 1;    // pipeline runs per step(), each of dt / substeps
  SolverType solver = SolverType::PGS;
  int iterations = 16;  // PGS sweeps, or TGS position iterations (each a solver substep)
  Integrator integrator = Integrator::SemiImplicitEuler;
  Precision precision = Precision::Float;
  Lanes lanes = Lanes::Simd;
  // Share of a limit violation removed per step (Baumgarte); rows that are
  // not violated are speculative: they let the joint reach the limit exactly.
  double error_reduction = 0.2;
  double warm_start = 1.0;  // factor on last step's impulses as the solver's start
  // A Free body's gyroscopic (velocity-product) force taken at the middle
  // of the step, linearised (implicit midpoint): a body spinning about its
  // major or intermediate axis keeps its energy instead of blowing up as
  // with the explicit force. Not with RK4.
  bool implicit_gyroscopic = true;
  // Each floating articulation (Free root) leaves the step with exactly its
  // momentum before it plus the impulse of gravity, link wrenches, the
  // base's feedforward force and the solver's rows (contacts included): its
  // base's linear velocity is corrected by the O(h^2) per step that
  // semi-implicit Euler otherwise lets the momentum drift. Semi-implicit
  // Euler only; the floating bases may have no damping or armature. Costs
  // two kinematics passes per step (docs/stability.md).
  bool conserve_linear_momentum = false;
  bool reset_on_fault = false;  // put a faulted copy back to its initial state
  bool record_applied_torque = false;  // keep RaiSim's per-source torque of the last step
  // Keep the last step's motion for Simulator::incoming_joint_forces and
  // link_accelerations (RaiSim's setComputeInverseDynamics): nq + 3 nv + 1
  // values per copy written per step; the readouts are found when read.
  bool record_motion = false;
  ContactSettings contacts;  // ground, static boxes, filters, contact parameters
  // Motors behind gearboxes with their operating regions (batch/actuators.hpp);
  // each copy commands them through Simulator::set_actuator_torques.
  std::vector<Actuator> actuators;
  std::array<StageMode, kStageCount> stages{};  // all Auto

  StepOptions& force(Stage stage, StageMode mode) {
    stages[static_cast<int>(stage)] = mode;
    return *this;
  }
};

// Whether a stage runs in a scene, and why.
struct StageDecision {
  Stage stage;
  bool runs = false;
  std::string reason;
};

// Reason a copy was flagged. Sticky until the copy is reset or cleared.
enum class Fault : unsigned char {
  None = 0,
  NonFiniteTorque,  // feedforward joint torque or actuator command
  NonFiniteTarget,  // drive target position or velocity
  NonFiniteWrench,  // external link wrench
  NonFiniteGravity,
  NonFiniteState,   // q or v after the step
};
const char* fault_name(Fault fault);

}  // namespace lockstep
