// A vectorised environment over the simulator: N copies of a scene that a
// learning loop resets and steps together, with actions in and observations
// out through contiguous buffers, per-copy randomisation at reset, episode
// bookkeeping (terminated, truncated, auto-reset with the terminal
// observation kept) and fault isolation.
//
//   lockstep::VecEnvOptions options;
//   options.action_mode = lockstep::ActionMode::PositionTarget;
//   options.episode_steps = 1000;
//   options.randomization.mass_scale = {0.9, 1.1};
//   lockstep::VecEnv env(model, 4096, options);
//   env.set_reward([](const lockstep::Observations& obs, const lockstep::RowMatrix& actions,
//                     Eigen::VectorXd& reward, std::vector<std::uint8_t>& terminated) { ... });
//   env.reset();
//   for (;;) {
//     policy(env.observations(), actions);   // actions: N x env.action_size()
//     env.step(actions);
//     // env.reward(), env.terminated(), env.truncated(), env.terminal_observations()
//   }
//
// Everything a copy does depends only on its own inputs, the seed and its
// own reset count: never on threads, batch size or the other copies.
#pragma once

#include "batch/randomization.hpp"
#include "batch/simulator.hpp"

#include <Eigen/Geometry>

#include <cstdint>
#include <functional>
#include <vector>

namespace lockstep {

// What an action sets, for each DOF that is not a floating root's (the
// actuated DOFs, low-level order): its feedforward torque, or its drive's
// position target (velocity target 0). A Spherical joint's three values are
// then a rotation vector r: target quaternion exp(r). ActuatorTorque: one
// value per actuator (StepOptions::actuators, in their order), the torque
// it is commanded (Simulator::set_actuator_torques).
enum class ActionMode { Torque, PositionTarget, ActuatorTorque };
const char* action_mode_name(ActionMode mode);

struct VecEnvOptions {
  StepOptions step;
  std::vector<DofSettings> dofs;  // empty: default_dof_settings(model)
  ActionMode action_mode = ActionMode::Torque;
  int control_steps = 1;   // simulator steps per env step, the action held
  int episode_steps = 0;   // env steps before an episode is truncated; 0: never
  bool auto_reset = true;  // a copy whose episode ended restarts within the same step()
  std::uint64_t seed = 0;
  Randomization randomization;
  // The initial state before noise ((nq), (nv)); empty: the neutral
  // configuration at rest.
  Eigen::VectorXd initial_q, initial_v;
  // (nq) the drives' position targets set at every reset (velocity target
  // 0): what they hold in Torque mode; actions replace them in
  // PositionTarget mode. Empty: initial_q.
  Eigen::VectorXd drive_target_q;
};

// Fills the state VecEnvOptions may leave empty: initial_q (the neutral
// configuration), initial_v (rest), drive_target_q (initial_q).
void fill_initial_state(const Model& model, VecEnvOptions& options);

// Observations, one row per copy, each field contiguous (row-major): read
// them in place. The base is the first articulation's root body: its pose
// and twist from q and v when it floats, else the fixed root frame at rest.
struct Observations {
  RowMatrix q, qd;                          // (N x nq), (N x nv), low-level order; qd as v (Free: body-frame twist)
  RowMatrix base_position;                  // (N x 3) world
  RowMatrix base_orientation;               // (N x 4) world, w x y z
  RowMatrix base_linear_velocity_world;     // (N x 3) of the base frame's origin
  RowMatrix base_angular_velocity_world;    // (N x 3)
  RowMatrix base_linear_velocity_base;      // (N x 3) the same two in base axes
  RowMatrix base_angular_velocity_base;     // (N x 3)
  RowMatrix projected_gravity;              // (N x 3) unit gravity direction in base axes
  RowMatrix applied_torque;                 // (N x nv) joint torque of the last simulator step, all sources (RaiSim's)
  RowMatrix contact_force;                  // (N x 3 nbody) net contact force on each body, world [N]; no columns without contacts
  // With StepOptions::record_motion (else no columns), of the env step's
  // last simulator step: each joint's force on its body, [force; torque
  // about the joint origin] per body (Simulator::incoming_joint_forces), and
  // each link's [acceleration of its origin; angular acceleration] per
  // frame (Simulator::link_accelerations), world axes.
  RowMatrix joint_force;                    // (N x 6 nbody)
  RowMatrix link_acceleration;              // (N x 6 nframe)
  // With actuators (StepOptions::actuators, else no columns), each motor's
  // speed omega [rad/s] and torque tau_m [N m] in the env step's last
  // simulator step (Simulator::actuator_states), in the actuators' order.
  RowMatrix motor_speed;                    // (N x actuators)
  RowMatrix motor_torque;                   // (N x actuators)
  Observations() = default;
  Observations(int copies, const Model& model, bool contacts, bool motion, int actuators);
};

// The user's reward and termination, called once per step() after the
// simulation with the new observations and the step's actions; reward and
// terminated come in zeroed (N). A faulted copy is terminated with reward 0
// whatever the function says.
using RewardFunction = std::function<void(const Observations& observations, const RowMatrix& actions,
                                          Eigen::VectorXd& reward, std::vector<std::uint8_t>& terminated)>;

// A copy's whole state: the simulator's snapshot (state, inputs, per-copy
// parameters, solver warm start) and its episode bookkeeping. Writing it
// into a copy of an environment built with the same model and options
// replays the copy bit for bit.
struct EnvCopyState {
  CopySnapshot simulator;
  int episode_step = 0;
  std::uint32_t reset_count = 0;
};

class VecEnv {
 public:
  // A mimic follower's position target from its leader's (apply_actions).
  struct MimicTarget {
    int follower_q, leader_q;
    double multiplier, offset;
  };

  // Throws std::invalid_argument naming the option that is wrong. Reset
  // every copy before the first step() (reset(), or the other forms
  // covering them all). Keeps a reference to the model, which
  // must outlive it (a temporary does not compile).
  VecEnv(const Model& model, int copies, VecEnvOptions options, HeaderBuild caller = {});  // caller: leave it defaulted
  VecEnv(Model&&, int, VecEnvOptions, HeaderBuild = {}) = delete;

  const Model& model() const { return sim_.model(); }
  const VecEnvOptions& options() const { return options_; }
  int copies() const { return sim_.copies(); }
  int action_size() const { return static_cast<int>(action_dofs_.size()); }
  // DOF of each action column (an actuator's: the DOF it drives)
  const std::vector<int>& action_dofs() const { return action_dofs_; }
  // Each action column's name: its DOF's, or its actuator's.
  std::vector<std::string> action_names() const;
  // The PositionTarget action row (action_size() values) whose targets are
  // the configuration q (nq): each actuated joint's coordinate, a Spherical
  // joint's quaternion as its rotation vector. E.g. the row that holds the
  // initial pose: position_action(options().initial_q). Not with
  // ActuatorTorque actions (std::logic_error).
  Eigen::VectorXd position_action(const Eigen::VectorXd& q) const;
  void set_reward(RewardFunction reward) { reward_ = std::move(reward); }

  // Restart copies: new randomisation draws and initial-state noise (their
  // reset count goes up), warm start and faults cleared, episode step 0,
  // observations rewritten. The mask has one entry per copy (non-zero: reset).
  void reset();
  void reset(const std::vector<int>& copies);
  void reset_masked(const std::vector<std::uint8_t>& mask);

  // One env step: the actions (N x action_size()) held for control_steps
  // simulator steps, then observations, reward, termination and truncation;
  // with auto_reset the copies that ended are reset after their terminal
  // observation is kept. A non-finite action faults its copy only.
  void step(const Eigen::Ref<const RowMatrix>& actions);

  const Observations& observations() const { return observations_; }
  // Rows of the copies that ended in the last step, as they ended (before
  // the auto-reset); other rows are stale: an earlier ending's, or zeros
  // before a copy's first.
  const Observations& terminal_observations() const { return terminal_; }
  const Eigen::VectorXd& reward() const { return reward_out_; }
  const std::vector<std::uint8_t>& terminated() const { return terminated_; }
  const std::vector<std::uint8_t>& truncated() const { return truncated_; }
  // Copies whose state or inputs went non-finite in the last step (they are
  // also terminated, and reset with auto_reset); fault() gives the reason
  // seen in the last step until an explicit reset.
  const std::vector<std::uint8_t>& faulted() const { return faulted_; }
  Fault fault(int copy) const;
  const std::vector<int>& episode_step() const { return episode_step_; }
  const std::vector<std::uint32_t>& reset_count() const { return reset_count_; }
  std::int64_t steps() const { return steps_; }  // env steps since construction

  EnvCopyState state(int copy) const;
  void set_state(int copy, const EnvCopyState& state);

  // The simulator underneath, for what this class does not wrap.
  Simulator& simulator() { return sim_; }
  const Simulator& simulator() const { return sim_; }

 private:
  // A reset asked for: the copies' fault reasons cleared, then reset_copies.
  void restart(const std::vector<int>& copies);
  // New draws, reset count up, episode step 0, observation rows rewritten.
  void reset_copies(const std::vector<int>& copies);
  void randomize(int copy, std::uint32_t reset);
  void apply_actions(const Eigen::Ref<const RowMatrix>& actions);
  template <class T>
  void follow_leaders(T* target_q, int width, int lanes) const;
  // Observation rows of `copies` (all when null) from the simulator.
  void observe(const std::vector<int>* copies, Observations& out) const;
  template <class Batch>
  void observe_block(const Batch& batch, int block, Observations& out) const;
  static void copy_rows(const std::vector<int>& rows, const Observations& from, Observations& to);
  // f(sim_.batch<T>()) for the chosen precision T.
  template <class F>
  void visit_batch(F&& f);
  template <class F>
  void visit_batch(F&& f) const;

  HeaderBuildCheck header_check_;  // first: runs before any other member is built
  VecEnvOptions options_;
  Simulator sim_;
  std::vector<int> action_dofs_;
  std::vector<int> action_field_;  // per action column: its field of tau (Torque) or target_q (PositionTarget)
  std::vector<MimicTarget> mimic_targets_;  // followers whose targets follow their leaders', in that order
  Eigen::Isometry3d fixed_base_pose_ = Eigen::Isometry3d::Identity();  // the base when it does not float
  // The first articulation's floating root: its entries in q and v; -1 when
  // it does not float (the first articulation may be static, its bodies none)
  int base_q_ = -1, base_v_ = -1;
  bool ready_ = false;  // no copy waits for a reset
  // Copies a reset must restart before the env steps: every copy before its
  // first reset, and every copy once a step's reward function threw (its
  // simulator had stepped, its counters, faults and resets had not).
  std::vector<unsigned char> pending_reset_;
  bool contacts_ = false;  // the contacts stage runs: the copies keep a ground of their own
  RewardFunction reward_;
  // the step's actions as the RowMatrix the reward function takes: copied
  // into, where binding step()'s Ref to it made a new matrix every step
  RowMatrix reward_actions_;
  Observations observations_, terminal_;
  Eigen::VectorXd reward_out_;
  std::vector<std::uint8_t> terminated_, truncated_, faulted_;
  std::vector<Fault> last_fault_;
  std::vector<int> episode_step_;
  std::vector<int> ended_;  // copies whose episode ended in the last step
  std::vector<std::uint32_t> reset_count_;
  std::int64_t steps_ = 0;
  struct ResetScratch {  // randomize's vectors, kept so that a reset allocates nothing
    Eigen::VectorXd kp, kd, damping, armature, friction, strength, q, v, zero;
  } reset_scratch_;
};

}  // namespace lockstep
