// The simulator: a Model, N copies of its state and inputs, and the step
// pipeline that advances them all by dt, in parallel over blocks of lanes,
// bit for bit the same whatever the thread count, batch size or position of
// a copy in the batch.
//
//   lockstep::Simulator sim(model, 4096, options, dofs);  // dofs: the drive gains of every copy
//   sim.set_drive_gains(copy, kp, kd);                     // one copy's own gains
//   sim.set_drive_target(copy, q_target, v_target);
//   sim.step();
//
// Per-copy accessors take and return double Eigen vectors in low-level order
// (q: nq, v and torques: nv). For throughput, batch<T>() exposes the
// structure-of-arrays storage directly (T = the chosen precision).
#pragma once

#include <cstdint>

#include "batch/build_info.hpp"
#include "batch/contact_pairs.hpp"
#include "batch/step_options.hpp"
#include "batch/stiff_drives.hpp"
#include "layout/batch_state.hpp"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace lockstep {

struct StepPlan;

// A row per copy (VecEnv's buffers, the simulator's bulk readouts).
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Everything kept per copy, structure-of-arrays, in precision T. The state
// and the inputs a user writes between steps, the per-copy parameters, the
// solver's warm start and the fault flags.
template <class T>
struct StepBatch {
  StepBatch(const Model& model, int copies, int width, int rows);

  int copies() const { return state.copies(); }

  // q, v, tau (feedforward), wrench, inertia, gravity; qacc = last (v1 - v0) / h.
  // Wrenches written here act only with Stage::ExternalWrenches on (forced,
  // or after a set_link_wrench call); inertias only with
  // Stage::PerCopyInertia on (forced, or while set_body_inertia or a
  // restore has given some copy inertias other than the model's).
  BatchState<T> state;
  BatchArray<T> target_q;  // (nq) drive target position (quaternions for Spherical joints)
  BatchArray<T> target_v;  // (nv) drive target velocity
  // The per-DOF parameters below start as the scene's in every copy
  // (scene_joint_parameters). A copy's own values act only with
  // Stage::PerCopyJointParameters on: after a Simulator setter (or a
  // restore) gave some copy values other than the scene's, or forced On.
  // Written here directly, they need the stage forced On.
  // (nv) per-copy kp and kd. Writing them here does not switch the drive
  // stage on either: use Simulator::set_drive_gains, or force Stage::Drives On.
  BatchArray<T> drive_stiffness;
  BatchArray<T> drive_damping;
  // (nv) per-copy joint damping and armature, from DofSettings::damping and
  // the model's armature. Damping acts only with Stage::Damping on (a DOF
  // with damping, Simulator::set_joint_damping, or forced On).
  BatchArray<T> joint_damping;
  BatchArray<T> armature;
  // (nv) per-copy Coulomb friction force of the DOFs that have friction
  // rows (DofSettings::friction > 0 with the Coulomb model, or
  // Stage::CoulombFriction forced On), from DofSettings::friction.
  BatchArray<T> joint_friction;
  // (rows) the solver's impulses of the last step, each along its row's J
  // with the sign sigma left out (DOF axes: a limit row's impulse is
  // negative at its upper limit): the warm start, and what applied_torque
  // reports
  BatchArray<T> impulse;
  BatchArray<T> initial_q; // (nq) what a reset restores
  BatchArray<T> initial_v; // (nv)
  BatchArray<T> fault;     // (1) Fault code, sticky
  // RaiSim's torque over the last step by source (nv each), when
  // StepOptions::record_applied_torque: drive (feedforward + PD, with its
  // implicit part), passive (damping, springs, soft limits, Stribeck
  // friction, with their implicit parts), Coulomb friction impulse / dt,
  // limit impulses / dt; with substeps, the mean over the step's pipeline
  // runs. Empty otherwise.
  BatchArray<T> applied_drive, applied_passive, applied_friction, applied_limits;
  // (nv) the actuators' joint torques over the last step, with
  // record_applied_torque (explicit, so without an implicit part). Empty otherwise.
  BatchArray<T> applied_actuation;
  // Per actuator (StepOptions::actuators): the torque each copy commands
  // (tau_a at the driven joint; kept until changed, like `tau`), and the
  // last step's last evaluation of the motor: the command it took, the
  // motor's speed and torque (3 per actuator; zero after a reset, or a
  // reset_on_fault restart).
  BatchArray<T> actuator_command, actuator_state;
  // Per actuator, each copy's strength: the share of the motor's torque that
  // reaches the joints (1 unless set_actuator_strength or randomisation).
  BatchArray<T> actuator_strength;
  // With StepOptions::record_motion, the motion of the last step's last
  // pipeline run, from which Simulator::incoming_joint_forces and
  // link_accelerations find theirs: the run's start state (nq, nv); its
  // acceleration (nv: (v1 - v0) / h, a Free joint's linear part the spatial
  // acceleration, the frame's turn rate w0 x v0 taken out); of that, the
  // Free joints' share that the step's forces do not balance (nv, zero on
  // the other DOFs): the implicit gyroscopic force's and the momentum
  // projection's correction, which RNEA's balance leaves out; and
  // 1 where a run was recorded since the copy's last reset or set_state,
  // else 0. Empty otherwise.
  BatchArray<T> motion_q, motion_v, motion_acceleration, motion_unbalanced, motion_recorded;
  // Contacts (empty without them): the ground plane n . x = d as (n, d) and
  // its friction; per contact slot the point's candidate number (-1: none,
  // and the slot's other entries are then unspecified; a copy's contacts
  // fill its slots from the first, so none follows an empty one), the solver's
  // impulses (normal, t1, t2[, torsion]; also the next step's warm start),
  // point, normal and separation at the start of the step; the contacts
  // kept, those dropped beyond capacity, and the steps that dropped some
  // since the last reset.
  BatchArray<T> ground, ground_friction;
  BatchArray<T> contact_id, contact_impulse, contact_point, contact_normal, contact_separation;
  BatchArray<T> contact_count, contact_dropped, contact_overflow_steps;
  // With substeps > 1 and contacts, per body (6 each): the contacts'
  // impulse on it summed over the step's pipeline runs, [linear; angular
  // about the world origin], world axes [N s, N m s]: what the per-body
  // contact forces report over dt. Empty otherwise (the last run's points
  // are then the step's).
  BatchArray<T> contact_wrench;
  // With StepOptions::conserve_linear_momentum, per floating articulation
  // (world axes, 3 each): the momentum the last step's correction could not
  // place on its base's rounded velocity, which the next step adds
  // (batch/step_momentum.cpp). Empty otherwise.
  BatchArray<T> momentum_remainder;

  std::size_t bytes_per_copy() const;
};

// RaiSim's "torque over the step", term by term, for one copy.
struct AppliedTorque {
  Eigen::VectorXd drive;     // tau_cmd - (w_drive / dt) dv
  Eigen::VectorXd passive;   // damping, springs, soft limits, Stribeck friction, fixed tendons' springs
  Eigen::VectorXd friction;  // Coulomb friction impulse / dt
  Eigen::VectorXd limits;    // position and velocity limit, mimic and tendon limit impulses / dt
  Eigen::VectorXd actuators; // the actuators' torques on the joints (strength x G tau_m, strength x r_c tau_m)
};

// One contact point of a copy after a step (Simulator::contacts). With
// substeps, a point of the step's last pipeline run, its force that run's
// impulse over its dt / substeps: a sample of the step, not its mean
// (body_contact_wrenches sums the runs).
struct Contact {
  int shape_a = kGroundShape, shape_b = kGroundShape;  // Model::shapes index, kGroundShape or static_box_shape(i)
  int body_a = -1, body_b = -1;     // moving bodies; -1: the world
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // world, at the start of the step
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(); // world, from A to B
  double separation = 0;            // m, negative: penetration
  Eigen::Vector3d force = Eigen::Vector3d::Zero();   // on B at the point, world [N]: the (last run's) impulse / its dt
  double torsion = 0;               // on B about the normal [N m] (torsional friction)
};

// Everything a copy's next steps depend on: the state, the solver's warm
// start (joint-row impulses, contact points and their impulses), the
// momentum remainder (StepBatch::momentum_remainder; a snapshot without one
// restores into a simulator with the projection as a zero one, and the
// other way round it is dropped), and the
// copy's inputs and per-copy parameters (torques, wrenches, inertial
// parameters, gravity, drive targets and gains, joint damping, armature,
// ground, initial state, fault, actuator commands, the motors' last states
// and the actuators' strengths), in that order in `parameters`; and what
// contacts() and contact_overflow() report of its last step (the points'
// positions, normals and separations, the count, the dropped, the overflow
// steps), in that order in `contact_report`. Restoring a snapshot, into
// this simulator or one built alike, replays the copy bit for bit, reports
// included.
struct CopySnapshot {
  Eigen::VectorXd q, v, joint_impulse, contact_id, contact_impulse, momentum_remainder, parameters, contact_report;
  // StepBatch::contact_wrench (empty without it; restored where both have it, else zero)
  Eigen::VectorXd contact_wrench;
  // applied_torque()'s five sources of the last step (empty without
  // StepOptions::record_applied_torque)
  Eigen::VectorXd applied_torque;
  // StepBatch's motion_q, motion_v, motion_acceleration, motion_unbalanced
  // and motion_recorded (empty without StepOptions::record_motion)
  Eigen::VectorXd recorded_motion;
  // Simulator::scene_key() of the simulator it came from: restore refuses a
  // snapshot of another scene whose arrays happen to have the same sizes.
  // 0 (a snapshot put together by hand) is not checked.
  std::uint64_t scene_key = 0;
};

// CPU seconds per phase of the steps taken while profiling
// (Simulator::set_profiling), summed over threads.
struct StepProfile {
  double dynamics = 0;           // kinematics, joint effects, ABA (all RK4 stages; the trapezoid's second pass)
  double contact_detection = 0;  // shape poses, narrowphase, slot compaction
  double constraint_solve = 0;   // rows, Delassus blocks, PGS/TGS, impulses applied
  double integration = 0;        // positions, applied torques, fault checks, state written back
  double total() const { return dynamics + contact_detection + constraint_solve + integration; }
};

// Contacts dropped for want of capacity.
struct ContactOverflow {
  int dropped = 0;         // in the last step (with substeps: the most any of its pipeline runs dropped)
  int overflow_steps = 0;  // steps that dropped some since the last reset (a step counts once)
};

class Simulator {
 public:
  // dofs: per-DOF joint effects; empty means default_dof_settings(model).
  // Throws std::invalid_argument naming the option or DOF that is wrong,
  // or the first DOF that moves no inertia of its own where the model's
  // mass matrix is singular (at its neutral configuration).
  // caller: leave it defaulted (batch/build_info.hpp). The simulator keeps a
  // reference to the model, which must outlive it (a temporary does not
  // compile).
  Simulator(const Model& model, int copies, const StepOptions& options = {}, std::vector<DofSettings> dofs = {},
            HeaderBuild caller = {});
  Simulator(Model&&, int, const StepOptions& = {}, std::vector<DofSettings> = {}, HeaderBuild = {}) = delete;
  ~Simulator();
  // A simulator moved from throws std::logic_error from its calls until
  // another is assigned to it (a VecEnv moved from, likewise).
  Simulator(Simulator&&) noexcept;
  Simulator& operator=(Simulator&&) noexcept;

  const Model& model() const { return *model_; }
  const StepOptions& options() const { return options_; }
  const std::vector<DofSettings>& dof_settings() const { return dofs_; }
  int copies() const;
  double time() const { return time_; }

  // Advances every copy by options().dt, n times: each block of copies
  // through all n steps before the next (the same bits as n calls). n < 0
  // throws std::invalid_argument; n = 0 does nothing.
  void step(int n = 1);

  // Profiling: per-phase CPU time of the following steps (a clock read per
  // phase and block: a few ns per env-step); turning it on clears the sums.
  void set_profiling(bool on);
  StepProfile profile() const;

  // The stages the pipeline runs for this scene, each with the reason.
  // Reading the plan makes it again when a per-copy input changed it since,
  // so (like the setters) call plan() and describe_plan() from one thread.
  const std::vector<StageDecision>& plan() const;
  std::string describe_plan() const;
  // The drives stiff enough to act as hard constraints (batch/stiff_drives.hpp)
  // at copy 0's configuration with the scene's gains (the DofSettings; not a
  // copy's own from set_drive_gains), where the scene has other hard
  // constraints (limits, velocity limits, contacts) for them to act against;
  // else none.
  std::vector<StiffDrive> stiff_drives() const;
  // What the plan warns of, one line each (describe_plan indents them,
  // `lockstep rollout` prints them on stderr): the stiff drives above; with
  // RK4 or the trapezoid, the DOFs too stiff for its step at copy 0's
  // configuration (fast_joint_modes); the model's mimic tags when their stage is forced off (each such DOF
  // then moves on its own), and mesh shapes, which take no part in contacts
  // (ContactPairs::notes). Empty when there is nothing to say.
  std::vector<std::string> warnings() const;
  // The constraint rows per copy (mimic, limit, velocity-limit and friction rows).
  int row_count() const;

  // State of one copy. set_state also makes it the copy's initial state,
  // the one a reset restores, and clears the copy's warm start.
  Eigen::VectorXd q(int copy) const;
  Eigen::VectorXd v(int copy) const;
  void set_state(int copy, const Eigen::VectorXd& q, const Eigen::VectorXd& v);
  void set_state_all(const Eigen::VectorXd& q, const Eigen::VectorXd& v);
  CopySnapshot snapshot(int copy) const;
  // Throws std::invalid_argument, changing nothing, on a snapshot of another
  // scene, or with values the setters refuse (negative masses or gains, a
  // non-positive-semidefinite inertia, a contact slot holding no candidate
  // of this scene, a fault code that is no Fault).
  void restore(int copy, const CopySnapshot& snapshot);

  // Inputs of one copy; they persist until changed.
  void set_torque(int copy, const Eigen::VectorXd& tau_ff);                     // (nv) feedforward
  void set_drive_target(int copy, const Eigen::VectorXd& q_target, const Eigen::VectorXd& v_target);  // (nq), (nv)
  // (nv) per-copy gains, overriding DofSettings; a copy given gains turns
  // the drive stage on for the scene.
  void set_drive_gains(int copy, const Eigen::VectorXd& kp, const Eigen::VectorXd& kd);
  // (nv) per-copy joint damping [N m s/rad or N s/m], overriding
  // DofSettings::damping; a copy given some turns the damping stage on.
  void set_joint_damping(int copy, const Eigen::VectorXd& damping);
  // (nv) per-copy armature (rotor inertia) [kg m^2 or kg], overriding the model's.
  void set_armature(int copy, const Eigen::VectorXd& armature);
  // (nv) per-copy Coulomb joint friction [N m or N], overriding
  // DofSettings::friction on the DOFs that have friction rows (others ignore
  // it); none on a floating base's DOFs.
  void set_joint_friction(int copy, const Eigen::VectorXd& friction);
  // One body's inertial parameters in one copy: mass [kg], COM in the body
  // frame, rotational inertia about the COM in body axes (symmetric positive
  // semidefinite). Values that leave a DOF with no inertia to move (a leaf
  // link made massless) are not refused here, as the constructor refuses
  // them for the model (that check is a factorisation, too dear for a
  // reset): the copy's next step faults it (NonFiniteState), alone.
  void set_body_inertia(int copy, int body, double mass, const Eigen::Vector3d& com, const Eigen::Matrix3d& inertia);
  // World [force; torque about the body's COM]; the first call turns the
  // wrench stage on (bulk writers through batch<T>() force it On instead).
  void set_link_wrench(int copy, int body, const Eigen::Matrix<double, 6, 1>& wrench);
  void set_gravity(int copy, const Eigen::Vector3d& gravity);
  // (StepOptions::actuators.size()) the torque each actuator is commanded,
  // tau_a at its driven joint [N m or N]; clipped to the motor's operating
  // region in the step (batch/actuators.hpp). Persists like set_torque's.
  void set_actuator_torques(int copy, const Eigen::VectorXd& torques);
  Eigen::VectorXd actuator_torques(int copy) const;
  // (actuators) each actuator's strength in this copy, > 0: the joints get
  // strength x G tau_m (legged_gym's motor strength: weaker or stronger
  // motors and transmissions per copy); 1 by default.
  void set_actuator_strength(int copy, const Eigen::VectorXd& strength);
  Eigen::VectorXd actuator_strength(int copy) const;
  // Each actuator's command, motor speed and torque in the copy's last
  // step (zero before the first and after a reset), in StepOptions::actuators' order.
  std::vector<ActuatorState> actuator_states(int copy) const;

  // Faults: the reason a copy was flagged (None when healthy).
  Fault fault(int copy) const;
  int fault_count() const;
  void clear_fault(int copy);
  // Back to the initial state, warm start, fault, contact report, applied
  // torques and actuator states cleared.
  void reset(int copy);

  AppliedTorque applied_torque(int copy) const;  // needs record_applied_torque
  // The force and torque each joint transmitted from the parent to its child
  // body in the copy's last step (RaiSim's force and torque at the joint,
  // PhysX's link incoming joint force; needs
  // StepOptions::record_motion): one column per body, [force; torque
  // about the joint origin (the child body's origin)], world axes at the
  // start of the step. It is RNEA on the step's motion, with gravity, the
  // link wrenches, the contact forces and link damping: constraint force and actuation
  // together. Along a joint's own axes it is what applied_torque() sums, less
  // the armature's share (armature x acceleration). A Free joint transmits
  // only its feedforward force, and what the implicit gyroscopic force
  // changed in the step (O(h |w| |a|) per unit inertia). With substeps: the
  // last pipeline run (applied_torque() is the runs' mean, so the identity
  // along the axes holds against the last run's torque, not against it). Zero until a step follows a reset or set_state.
  // Read before changing the copy's wrenches, gravity or inertias: the
  // forces are found when read. docs/conventions.md, "Joint forces after a
  // step".
  Eigen::Matrix<double, 6, Eigen::Dynamic> incoming_joint_forces(int copy) const;
  // The classical acceleration of every link's (frame's) origin and its
  // angular acceleration in the copy's last step (needs
  // StepOptions::record_motion): one column per frame, [a; alpha], world
  // axes at the start of the step. The motion's own acceleration: a link
  // in free fall reads g, where an accelerometer on it would read a - g = 0.
  // From the same motion as incoming_joint_forces, with the same caveats;
  // PhysX's link acceleration, there at the COM.
  Eigen::Matrix<double, 6, Eigen::Dynamic> link_accelerations(int copy) const;
  // Both for every copy at once: row c of `out` (copies() rows; 6 nbody,
  // or 6 nframe, columns) is copy c's matrix, its columns one after the
  // other. The same numbers as the per-copy calls, found over blocks of
  // copies in parallel (SIMD lanes, double). The first call makes the
  // arrays all copies' motions are loaded into, and they are kept: call
  // these from one thread at a time.
  void all_incoming_joint_forces(Eigen::Ref<RowMatrix> out) const;
  void all_link_accelerations(Eigen::Ref<RowMatrix> out) const;

  // Contacts. The candidate shape pairs after filtering (and notes on
  // shapes left out); the ground of one copy (plane through (0, 0, height)
  // with the unit normal, and its friction; or its friction alone); the contacts of the last step
  // and their total wrench on each body ([force; torque about the world
  // origin], world axes, one column per body).
  const ContactPairs& contact_pairs() const { return pairs_; }
  void set_ground(int copy, double height, const Eigen::Vector3d& normal, double friction);
  void set_ground_friction(int copy, double friction);
  std::vector<Contact> contacts(int copy) const;
  // With substeps, the step's wrench: its runs' impulses over dt (where
  // contacts() holds the last run's points).
  Eigen::Matrix<double, 6, Eigen::Dynamic> body_contact_wrenches(int copy) const;
  // The force part of body_contact_wrenches into forces[3 nbody]; allocates nothing.
  void body_contact_forces(int copy, double* forces) const;
  ContactOverflow contact_overflow(int copy) const;
  // Mechanical energy (kinetic + gravity potential) of one copy, in double,
  // with the copy's inertial parameters, armature (1/2 a_k v_k^2 each: what
  // the step conserves) and gravity.
  double energy(int copy) const;

  // The storage, for bulk reads and writes; T must be the chosen precision.
  template <class T>
  StepBatch<T>& batch();
  template <class T>
  const StepBatch<T>& batch() const;
  // The bytes the simulator keeps for each copy: the batch's arrays (state,
  // inputs, per-copy parameters, warm starts, contacts) and the per-copy
  // flags of which parameters are the copy's own. Everything else it holds
  // (the step's scratch, per worker block) does not grow with the copies.
  std::size_t bytes_per_copy() const;
  // What a snapshot's arrays mean: a hash of the model's joints and links
  // (names, types, DOF layout), the joint rows (kind and DOF), and the
  // contact pairs with their warm-start numbering. Simulators built alike
  // have the same key whatever their precision, lanes or copy count.
  std::uint64_t scene_key() const { return scene_key_; }

  struct Engine;  // the pipeline for one lane type

 private:
  void make_plan() const;  // plan_ from the options and the per-copy inputs so far
  // A per-copy input that changes the plan only marks it stale: it is made
  // again when next read or stepped, so that resetting N copies (each
  // turning its own inertias on) plans once rather than N times.
  void invalidate_plan() { plan_stale_ = true; }
  void refresh_plan() const;  // plan_ and the engine's plan, where stale
  bool contacts_run() const;
  bool contacts_found() const;  // the contacts stage runs and some shape pair may touch
  void check_ground(int copy, const char* what, double friction) const;
  std::string unenforced_mimics() const;
  std::string unenforced_tendons() const;
  StepPlan step_plan() const;
  std::string rows_summary() const;
  void check_copy(int copy, const char* function) const;  // throws std::out_of_range naming the function
  // Copies [first, first + s.copies()) of the last recorded motion into the
  // double state s (its copy i is copy first + i), with their gravity, and
  // their inertias and wrenches as the step took them; with `forces` as
  // the joint forces take it: the motion without its unbalanced share, and
  // each copy's contact forces joined to its wrenches (about the bodies'
  // COMs, from `poses` found with `dynamics`). recorded[i]: whether copy
  // first + i has a step recorded since its reset (s's copy i is left as it
  // was where not). Throws without StepOptions::record_motion, naming
  // `function`.
  template <class Dynamics>
  void load_motions(int first, const Dynamics& dynamics, bool forces, const char* function, BatchState<double>& s,
                    BatchArray<double>& poses, std::vector<char>& recorded) const;
  // One copy's readout, `columns` columns: compute(dynamics, state, values)
  // on its loaded motion; zero without a recorded step.
  template <class Compute>
  Eigen::Matrix<double, 6, Eigen::Dynamic> copy_readout(int copy, int columns, bool forces, const char* function,
                                                        Compute&& compute) const;
  // The link damping weight the joint forces take the recorded motion with
  // (BatchDynamics::transmitted_joint_forces); none when the step has none.
  std::optional<double> recorded_link_damping() const;
  // The bulk readouts' arrays, made on their first call and kept.
  struct MotionScratch;
  MotionScratch& motion_scratch() const;
  void check_velocity(const Eigen::VectorXd& v, const char* what) const;
  // One value per actuator, or std::invalid_argument naming `what`.
  void check_per_actuator(const Eigen::VectorXd& values, const char* what) const;
  void check_per_dof(const Eigen::VectorXd& values, const char* what) const;  // nv finite values >= 0
  // mass >= 0, COM and inertia finite, the inertia symmetric positive
  // semidefinite; the message begins `what: body i (name): `
  void check_body_inertia(int body, double mass, const Eigen::Vector3d& com, const Eigen::Matrix3d& inertia,
                          const char* what) const;
  void check_free_of_floating_bases(const Eigen::VectorXd& values, const char* what) const;
  // Invalidates the plan when a copy's drive gains, damping or wrenches need
  // a stage the plan skips.
  void note_copy_inputs(int copy);
  // Counts, after a write to body `body`'s inertial parameters in the copy
  // (own_before: whether they differed from the model's before it), the
  // copy's bodies with inertias of their own; invalidates the plan when the
  // copy starts or stops having any.
  void note_own_inertia(int copy, int body, bool own_before);
  void count_own_inertia(int copy);  // from scratch, after a restore
  bool body_has_own_inertia(int copy, int body) const;
  // Records which of the copy's per-DOF parameters among `fields` (bits
  // of simulator.cpp's JointParameterField) differ from the scene's;
  // invalidates the plan when the copy starts or stops having any.
  void note_own_joint_parameters(int copy, unsigned fields);
  // out = q with every quaternion normalised; throws on a zero or non-finite one.
  void checked_configuration(const Eigen::VectorXd& q, const char* what, Eigen::VectorXd& out) const;
  // Each Spherical (and with free_joints each Free) joint's quaternion in q
  // to unit length; a zero one is refused, a non-finite one left as it is.
  void normalize_quaternions(Eigen::VectorXd& q, const char* what, bool free_joints) const;
  template <class F>
  decltype(auto) visit(F&& f) const;
  // f(const Contact&) for each contact of the copy's last step (the caller
  // checks the copy).
  template <class F>
  void visit_contacts(int copy, F&& f) const;
  // f(contact, body, sign) for each moving body a contact of the copy's last
  // step acts on: sign 1 on B (Contact::force acts on it), -1 on A.
  template <class F>
  void visit_body_contacts(int copy, F&& f) const;
  // f(body, i, x) for entry i of each body's contact wrench of the step
  // (StepBatch::contact_wrench over dt), and true; false, calling nothing,
  // without one (one run per step: visit_body_contacts holds the step).
  template <class F>
  bool visit_step_contact_wrenches(int copy, F&& f) const;

  HeaderBuildCheck header_check_;  // first: runs before any other member is built
  const Model* model_;
  StepOptions options_;
  std::vector<DofSettings> dofs_;
  mutable std::vector<StageDecision> plan_;
  mutable bool plan_stale_ = false;
  ContactPairs pairs_;
  std::uint64_t scene_key_ = 0;
  double time_ = 0.0;
  bool per_copy_gains_ = false;  // set_drive_gains gave some copy a drive
  bool per_copy_damping_ = false;  // set_joint_damping gave some copy damping
  bool wrenches_used_ = false;   // set_link_wrench was called
  // Per copy: how many bodies have inertial parameters other than the
  // model's (Stage::PerCopyInertia runs while some copy has any), and which
  // per-DOF parameters differ from the scene's, as JointParameterField bits
  // (Stage::PerCopyJointParameters).
  std::vector<int> own_inertia_bodies_;
  std::vector<unsigned char> own_joint_parameters_;
  Eigen::VectorXd model_inertia_;     // BatchState::model_inertia_params
  JointParameters joint_parameters_;  // scene_joint_parameters
  Eigen::VectorXd configuration_;  // set_state's normalised q, kept so that a reset allocates nothing
  std::unique_ptr<Engine> engine_;  // null once moved from
  // The engine; throws std::logic_error once the simulator was moved from
  // (a clear error where using it dereferenced null).
  Engine& engine() const;
  mutable std::unique_ptr<MotionScratch> motion_scratch_;
  // The engine's batch, in the precision it runs (the other is null): the
  // per-copy accessors reach it without a cast.
  StepBatch<float>* float_batch_ = nullptr;
  StepBatch<double>* double_batch_ = nullptr;
};

}  // namespace lockstep
