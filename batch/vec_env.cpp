#include "batch/vec_env.hpp"

#include "batch/require.hpp"

#include <Eigen/Geometry>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <stdexcept>

namespace lockstep {

namespace {

bool is_free_dof(const Model& m, int k) { return m.body_joint[m.dof_body[k]] == JointType::Free; }

// The mimic tags, a DOF's first only, each after the tag of its leader's
// (a chain's targets follow its head's): (follower q, leader q,
// multiplier, offset). The loader refuses cycles; a tag left in one
// (added by hand) is left out.
std::vector<VecEnv::MimicTarget> ordered_mimics(const Model& m) {
  auto q_of = [&](int k) { return m.body_q_offset[m.dof_body[k]]; };  // revolute or prismatic: one q each
  std::vector<VecEnv::MimicTarget> out;
  std::vector<bool> placed(m.nv, false);
  for (bool progress = true; progress;) {
    progress = false;
    for (int k = 0; k < m.nv; ++k) {
      const Mimic* mimic = m.mimic_of(k);
      if (!mimic || placed[k] || (m.mimic_of(mimic->leader_dof) && !placed[mimic->leader_dof])) continue;
      out.push_back({q_of(k), q_of(mimic->leader_dof), mimic->multiplier, mimic->offset});
      placed[k] = progress = true;
    }
  }
  return out;
}

VecEnvOptions checked(const Model& model, VecEnvOptions o) {
  require(model.nbody > 0,
          "VecEnv: the model has no moving body (a fixed base without joints): there is nothing to step or observe");
  require(o.control_steps >= 1, "VecEnv: control_steps must be at least 1, got " + std::to_string(o.control_steps));
  require(o.episode_steps >= 0,
          "VecEnv: episode_steps must be >= 0 (0: no truncation), got " + std::to_string(o.episode_steps));
  validate_randomization(o.randomization);
  fill_initial_state(model, o);
  require(o.initial_q.size() == model.nq, "VecEnv: initial_q expects " + std::to_string(model.nq) + " values, got " +
                                              std::to_string(o.initial_q.size()));
  require(o.initial_v.size() == model.nv, "VecEnv: initial_v expects " + std::to_string(model.nv) + " values, got " +
                                              std::to_string(o.initial_v.size()));
  require(o.drive_target_q.size() == model.nq, "VecEnv: drive_target_q expects " + std::to_string(model.nq) +
                                                   " values, got " + std::to_string(o.drive_target_q.size()));
  for (const auto& entry : {std::pair{&o.initial_q, "initial_q"}, std::pair{&o.initial_v, "initial_v"},
                            std::pair{&o.drive_target_q, "drive_target_q"}}) {
    const Eigen::VectorXd& values = *entry.first;
    for (Eigen::Index i = 0; i < values.size(); ++i)
      require(std::isfinite(values[i]), [&] {
        return std::string("VecEnv: ") + entry.second + " must be finite, entry " + std::to_string(i) + " is " +
               number_text(values[i]);
      });
  }
  if (o.dofs.empty()) o.dofs = default_dof_settings(model);
  // The torque of every source is an observation.
  o.step.record_applied_torque = true;
  return o;
}

}  // namespace

void fill_initial_state(const Model& model, VecEnvOptions& options) {
  if (options.initial_q.size() == 0) options.initial_q = model.neutral_configuration();
  if (options.initial_v.size() == 0) options.initial_v = Eigen::VectorXd::Zero(model.nv);
  if (options.drive_target_q.size() == 0) options.drive_target_q = options.initial_q;
}

const char* action_mode_name(ActionMode mode) {
  switch (mode) {
    case ActionMode::Torque: return "torque";
    case ActionMode::PositionTarget: return "position_target";
    case ActionMode::ActuatorTorque: return "actuator_torque";
  }
  return "?";
}

Observations::Observations(int copies, const Model& model, bool contacts, bool motion, int actuators)
    : q(RowMatrix::Zero(copies, model.nq)), qd(RowMatrix::Zero(copies, model.nv)),
      base_position(RowMatrix::Zero(copies, 3)), base_orientation(RowMatrix::Zero(copies, 4)),
      base_linear_velocity_world(RowMatrix::Zero(copies, 3)), base_angular_velocity_world(RowMatrix::Zero(copies, 3)),
      base_linear_velocity_base(RowMatrix::Zero(copies, 3)), base_angular_velocity_base(RowMatrix::Zero(copies, 3)),
      projected_gravity(RowMatrix::Zero(copies, 3)), applied_torque(RowMatrix::Zero(copies, model.nv)),
      contact_force(RowMatrix::Zero(copies, contacts ? 3 * model.nbody : 0)),
      joint_force(RowMatrix::Zero(copies, motion ? 6 * model.nbody : 0)),
      link_acceleration(RowMatrix::Zero(copies, motion ? 6 * static_cast<int>(model.frame_name.size()) : 0)),
      motor_speed(RowMatrix::Zero(copies, actuators)), motor_torque(RowMatrix::Zero(copies, actuators)) {}

VecEnv::VecEnv(const Model& model, int copies, VecEnvOptions options, HeaderBuild caller)
    : header_check_(caller),
      options_(checked(model, std::move(options))),
      sim_(model, copies, options_.step, options_.dofs) {
  const bool mimics_held = sim_.plan()[static_cast<int>(Stage::MimicJoints)].runs;
  if (mimics_held) {
    mimic_targets_ = ordered_mimics(model);
    // the targets of every reset, which the drives hold in the torque modes
    follow_leaders(options_.drive_target_q.data(), 1, 1);
  }
  if (options_.action_mode == ActionMode::ActuatorTorque) {
    const std::vector<Actuator>& actuators = options_.step.actuators;
    require(!actuators.empty(), "VecEnv: actuator_torque actions need actuators (StepOptions::actuators is empty)");
    for (std::size_t a = 0; a < actuators.size(); ++a) {  // the actuator's command
      action_dofs_.push_back(actuators[a].dof);
      action_field_.push_back(static_cast<int>(a));
    }
  } else {
    // a DOF that follows a mimic tag the step holds takes no action: with
    // position targets its target follows its leader's (follow_leaders)
    for (int k = 0; k < model.nv; ++k)
      if (!is_free_dof(model, k) && !(mimics_held && model.mimic_of(k))) action_dofs_.push_back(k);
    for (int k : action_dofs_)  // the DOF's torque, or the first target coordinate of its joint
      action_field_.push_back(options_.action_mode == ActionMode::Torque ? k : model.body_q_offset[model.dof_body[k]]);
  }
  if (!model.articulations.empty()) {
    const Articulation& first = model.articulations.front();
    if (first.floating_base) {
      base_q_ = model.body_q_offset[first.first_body];
      base_v_ = model.body_dof_offset[first.first_body];
    } else if (model.frame_body[first.root_frame] < 0) {
      fixed_base_pose_ = model.frame_placement[first.root_frame];
    }
  }
  if (options_.action_mode == ActionMode::PositionTarget)
    for (int k : action_dofs_)  // an action column without a gain would be ignored
      require(options_.dofs[k].drive_stiffness > 0,
              "VecEnv: position_target actions need a drive gain (DofSettings::drive_stiffness > 0) on every actuated "
              "DOF; " +
                  model.dof_name[k] + " (DOF " + std::to_string(k) + ") has " +
                  std::to_string(options_.dofs[k].drive_stiffness));
  contacts_ = sim_.plan()[static_cast<int>(Stage::Contacts)].runs;
  const bool motion = options_.step.record_motion;
  const int actuators = static_cast<int>(options_.step.actuators.size());
  observations_ = Observations(copies, model, contacts_, motion, actuators);
  terminal_ = Observations(copies, model, contacts_, motion, actuators);
  reward_out_ = Eigen::VectorXd::Zero(copies);
  reward_actions_ = RowMatrix::Zero(copies, action_size());
  terminated_.assign(copies, 0);
  truncated_.assign(copies, 0);
  faulted_.assign(copies, 0);
  last_fault_.assign(copies, Fault::None);
  episode_step_.assign(copies, 0);
  reset_count_.assign(copies, 0);
  pending_reset_.assign(copies, 1);  // every copy until its first reset
  ended_.reserve(copies);  // step() fills it without allocating
}

void VecEnv::reset() {
  std::vector<int> all(copies());
  for (int c = 0; c < copies(); ++c) all[c] = c;
  restart(all);
}

void VecEnv::reset(const std::vector<int>& which) {
  for (int c : which) require_copy_index(c, copies(), "VecEnv", "reset");
  restart(which);
}

void VecEnv::reset_masked(const std::vector<std::uint8_t>& mask) {
  if (static_cast<int>(mask.size()) != copies())
    throw std::invalid_argument("VecEnv::reset_masked: the mask has " + std::to_string(mask.size()) +
                                " entries for " + std::to_string(copies()) + " copies");
  std::vector<int> which;
  for (int c = 0; c < copies(); ++c)
    if (mask[c]) which.push_back(c);
  restart(which);
}

void VecEnv::restart(const std::vector<int>& which) {
  for (int c : which) last_fault_[c] = Fault::None, pending_reset_[c] = 0;
  reset_copies(which);
  // steps once no copy waits for a reset, whichever form gave it
  ready_ = std::none_of(pending_reset_.begin(), pending_reset_.end(), [](unsigned char p) { return p != 0; });
}

void VecEnv::reset_copies(const std::vector<int>& which) {
  for (int c : which) {
    randomize(c, reset_count_[c]);
    ++reset_count_[c];
    episode_step_[c] = 0;
  }
  observe(&which, observations_);
}

// The copy's parameters and initial state for its reset number `reset`:
// the configured values, each drawn field applied (docs/environments.md).
void VecEnv::randomize(int c, std::uint32_t reset) {
  const Model& m = model();
  const Randomization& r = options_.randomization;
  const std::uint64_t seed = options_.seed;
  auto value = [&](UniformRange Randomization::*range, int k) { return draw(r, range, seed, c, reset, k); };

  for (int b = 0; b < m.nbody; ++b) {
    const double scale = value(&Randomization::mass_scale, b);
    Eigen::Vector3d com = m.body_com[b];
    for (int axis = 0; axis < 3; ++axis) com[axis] += value(&Randomization::com_offset, 3 * b + axis);
    sim_.set_body_inertia(c, b, scale * m.body_mass[b], com, scale * m.body_inertia[b]);
  }
  const ContactSettings& contact = options_.step.contacts;
  // without contacts running (forced off, or no shape pairs) there is no
  // ground to give a friction; the other draws do not depend on this one.
  // The copy's ground keeps its height and normal (set_ground's, say a
  // terrain per copy).
  if (r.randomize_ground_friction && contact.ground && contacts_)
    sim_.set_ground_friction(c, value(&Randomization::ground_friction, 0));

  // the draws go into vectors kept from reset to reset: a reset allocates nothing
  ResetScratch& scratch = reset_scratch_;
  Eigen::VectorXd &kp = scratch.kp, &kd = scratch.kd, &damping = scratch.damping, &armature = scratch.armature,
                  &friction = scratch.friction;
  for (Eigen::VectorXd* x : {&kp, &kd, &damping, &armature, &friction}) x->setZero(m.nv);
  for (int k = 0; k < m.nv; ++k) {
    const DofSettings& d = options_.dofs[k];
    damping[k] = d.damping * value(&Randomization::damping_scale, k);
    if (d.friction_model == FrictionModel::Coulomb)
      friction[k] = d.friction * value(&Randomization::joint_friction_scale, k);
    armature[k] = m.dof_armature[k];
    if (is_free_dof(m, k)) continue;  // a floating root takes no drive and no rotor
    kp[k] = d.drive_stiffness * value(&Randomization::kp_scale, k);
    kd[k] = d.drive_damping * value(&Randomization::kd_scale, k);
    armature[k] += value(&Randomization::armature_add, k);
  }
  sim_.set_drive_gains(c, kp, kd);
  sim_.set_joint_damping(c, damping);
  sim_.set_armature(c, armature);
  sim_.set_joint_friction(c, friction);
  Eigen::VectorXd& strength = scratch.strength;
  strength.resize(static_cast<Eigen::Index>(options_.step.actuators.size()));
  for (Eigen::Index a = 0; a < strength.size(); ++a)
    strength[a] = value(&Randomization::actuator_strength_scale, static_cast<int>(a));
  sim_.set_actuator_strength(c, strength);
  Eigen::Vector3d gravity = m.gravity;
  for (int axis = 0; axis < 3; ++axis) gravity[axis] += value(&Randomization::gravity_offset, axis);
  sim_.set_gravity(c, gravity);

  // Initial state: the configured one plus noise.
  Eigen::VectorXd &q = scratch.q, &v = scratch.v;
  q = options_.initial_q, v = options_.initial_v;
  for (int b = 0; b < m.nbody; ++b) {
    const int qo = m.body_q_offset[b], k0 = m.body_dof_offset[b];
    switch (m.body_joint[b]) {
      case JointType::Revolute:
      case JointType::Prismatic: {
        // clamped to the limits, widened to the configured position where a
        // scene starts a joint outside them (kept as written, with a warning)
        const DofSettings& d = options_.dofs[k0];
        const double start = q[qo];
        q[qo] = std::clamp(start + value(&Randomization::joint_position_noise, k0), std::min(d.lower, start),
                           std::max(d.upper, start));
        v[k0] += value(&Randomization::joint_velocity_noise, k0);
        break;
      }
      case JointType::Spherical:
        for (int i = 0; i < 3; ++i) v[k0 + i] += value(&Randomization::joint_velocity_noise, k0 + i);
        break;
      case JointType::Free: {
        q[qo] += value(&Randomization::root_position_noise, k0);
        q[qo + 1] += value(&Randomization::root_position_noise, k0 + 1);
        const double yaw = value(&Randomization::root_yaw_noise, b);
        const Eigen::Quaterniond turned = Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())) *
                                          Eigen::Quaterniond(q[qo + 3], q[qo + 4], q[qo + 5], q[qo + 6]);
        q.segment<4>(qo + 3) << turned.w(), turned.x(), turned.y(), turned.z();
        for (int i = 0; i < 6; ++i) v[k0 + i] += value(&Randomization::root_velocity_noise, k0 + i);
        break;
      }
      case JointType::Fixed:
        break;
    }
  }
  sim_.set_state(c, q, v);  // also the copy's initial state
  sim_.reset(c);            // warm start, contact counters and fault cleared
  scratch.zero.setZero(m.nv);
  sim_.set_torque(c, scratch.zero);
  sim_.set_drive_target(c, options_.drive_target_q, scratch.zero);
}

template <class F>
void VecEnv::visit_batch(F&& f) {
  if (options_.step.precision == Precision::Float)
    f(sim_.batch<float>());
  else
    f(sim_.batch<double>());
}

template <class F>
void VecEnv::visit_batch(F&& f) const {
  if (options_.step.precision == Precision::Float)
    f(sim_.batch<float>());
  else
    f(sim_.batch<double>());
}

void VecEnv::apply_actions(const Eigen::Ref<const RowMatrix>& actions) {
  const Model& m = model();
  const bool actuators = options_.action_mode == ActionMode::ActuatorTorque;
  const bool torque = options_.action_mode == ActionMode::Torque || actuators;
  visit_batch([&](auto& b) {
    using T = std::decay_t<decltype(b.state.q.at(0, 0))>;
    const int W = b.state.q.width();
    // block by block, each action column into its field's lanes
    tbb::parallel_for(tbb::blocked_range<int>(0, b.state.q.blocks(), 16), [&](const tbb::blocked_range<int>& range) {
      for (int block = range.begin(); block < range.end(); ++block) {
        const int first = block * W, lanes = std::min(W, copies() - first);
        T* out = actuators ? b.actuator_command.block(block) : torque ? b.state.tau.block(block) : b.target_q.block(block);
        for (int a = 0; a < action_size();) {
          const int field = action_field_[a];
          if (torque || m.body_joint[m.dof_body[action_dofs_[a]]] != JointType::Spherical) {
            for (int l = 0; l < lanes; ++l) out[field * W + l] = static_cast<T>(actions(first + l, a));
            ++a;
            continue;
          }
          // a rotation vector r: the target exp(r) (a non-finite r faults the copy)
          for (int l = 0; l < lanes; ++l) {
            const Eigen::Vector3d rotation(actions(first + l, a), actions(first + l, a + 1), actions(first + l, a + 2));
            const double angle = rotation.norm();
            const Eigen::Quaterniond turn = angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation / angle))
                                                      : Eigen::Quaterniond::Identity();
            const double wxyz[4] = {turn.w(), turn.x(), turn.y(), turn.z()};
            for (int i = 0; i < 4; ++i)
              out[(field + i) * W + l] = static_cast<T>(std::isfinite(angle) ? wxyz[i] : angle);
          }
          a += 3;
        }
        if (!torque) follow_leaders(out, W, lanes);
      }
    });
  });
}

// The mimic followers' position targets from their leaders':
// q_f = multiplier q_l + offset, so that a follower's drive agrees with
// the tag the step holds rather than pulling against it.
template <class T>
void VecEnv::follow_leaders(T* target_q, int width, int lanes) const {
  for (const MimicTarget& m : mimic_targets_)
    for (int l = 0; l < lanes; ++l)
      target_q[m.follower_q * width + l] =
          static_cast<T>(m.multiplier * static_cast<double>(target_q[m.leader_q * width + l]) + m.offset);
}

std::vector<std::string> VecEnv::action_names() const {
  if (options_.action_mode == ActionMode::ActuatorTorque) return actuator_names(options_.step.actuators);
  std::vector<std::string> names;
  for (int k : action_dofs_) names.push_back(model().dof_name[k]);
  return names;
}

Eigen::VectorXd VecEnv::position_action(const Eigen::VectorXd& q) const {
  if (options_.action_mode == ActionMode::ActuatorTorque)
    throw std::logic_error(
        "VecEnv::position_action: the actions are actuator torques (action_mode actuator_torque), not joint "
        "positions");
  const Model& m = model();
  if (q.size() != m.nq)
    throw std::invalid_argument("VecEnv::position_action: q must have " + std::to_string(m.nq) + " values, got " +
                                std::to_string(q.size()));
  Eigen::VectorXd action(action_size());
  for (int a = 0; a < action_size();) {
    const int body = m.dof_body[action_dofs_[a]], qo = m.body_q_offset[body];
    if (m.body_joint[body] != JointType::Spherical) {
      action[a++] = q[qo];
      continue;
    }
    const Eigen::AngleAxisd turn(Eigen::Quaterniond(q[qo], q[qo + 1], q[qo + 2], q[qo + 3]).normalized());
    action.segment<3>(a) = turn.angle() * turn.axis();
    a += 3;
  }
  return action;
}

void VecEnv::step(const Eigen::Ref<const RowMatrix>& actions) {
  if (!ready_)
    throw std::logic_error(
        "VecEnv::step: reset every copy first (reset()): before the first step, and after a step whose reward "
        "function threw");
  if (actions.rows() != copies() || actions.cols() != action_size())
    throw std::invalid_argument("VecEnv::step: actions must be " + std::to_string(copies()) + " x " +
                                std::to_string(action_size()) + ", got " + std::to_string(actions.rows()) + " x " +
                                std::to_string(actions.cols()));
  apply_actions(actions);
  sim_.step(options_.control_steps);
  observe(nullptr, observations_);

  // sized anew: a reward function that resized them (refused below) leaves
  // the next step sound
  reward_out_.setZero(copies());
  terminated_.assign(copies(), 0);
  if (reward_) {
    reward_actions_ = actions;
    try {
      reward_(observations_, reward_actions_, reward_out_, terminated_);
      if (reward_out_.size() != copies() || static_cast<int>(terminated_.size()) != copies())
        throw std::logic_error("VecEnv::step: the reward function resized its outputs: reward has " +
                               std::to_string(reward_out_.size()) + " entries and terminated " +
                               std::to_string(terminated_.size()) + ", both must stay " + std::to_string(copies()));
    } catch (...) {
      // the simulator stepped and the episodes did not: no step until a reset
      ready_ = false;
      std::fill(pending_reset_.begin(), pending_reset_.end(), 1);
      throw;
    }
  }
  visit_batch([&](const auto& b) {
    for (int c = 0; c < copies(); ++c) last_fault_[c] = static_cast<Fault>(static_cast<int>(b.fault.at(c, 0)));
  });
  ended_.clear();
  for (int c = 0; c < copies(); ++c) {
    faulted_[c] = last_fault_[c] != Fault::None;
    if (faulted_[c]) terminated_[c] = 1, reward_out_[c] = 0;
    ++episode_step_[c];
    truncated_[c] = !terminated_[c] && options_.episode_steps > 0 && episode_step_[c] >= options_.episode_steps;
    if (terminated_[c] || truncated_[c]) ended_.push_back(c);
  }
  ++steps_;
  if (!options_.auto_reset || ended_.empty()) return;
  copy_rows(ended_, observations_, terminal_);
  reset_copies(ended_);  // fault() keeps the last step's reason
}

namespace {

// Every matrix of the observations.
template <class O>
auto observation_fields(O& o) {
  return std::array{&o.q, &o.qd, &o.base_position, &o.base_orientation, &o.base_linear_velocity_world,
                    &o.base_angular_velocity_world, &o.base_linear_velocity_base, &o.base_angular_velocity_base,
                    &o.projected_gravity, &o.applied_torque, &o.contact_force, &o.joint_force,
                    &o.link_acceleration, &o.motor_speed, &o.motor_torque};
}

// Asks for the cache lines of rows [first, first + count) of every
// observation matrix, for writing. A block's rows were written a whole step
// ago and are far out of cache by now. Writing them column by column keeps
// up to 16 lines missing at once; asking one block ahead hides those misses
// behind the block in hand.
void prefetch_rows(Observations& o, int first, int count) {
  for (RowMatrix* m : observation_fields(o)) {
    const char* begin = reinterpret_cast<const char*>(m->data() + static_cast<std::ptrdiff_t>(first) * m->cols());
    const std::size_t bytes = static_cast<std::size_t>(count) * m->cols() * sizeof(double);
    for (std::size_t at = 0; at < bytes; at += 64) __builtin_prefetch(begin + at, 1, 3);
  }
}

}  // namespace

void VecEnv::copy_rows(const std::vector<int>& rows, const Observations& from, Observations& to) {
  const auto source = observation_fields(from);
  const auto target = observation_fields(to);
  for (std::size_t f = 0; f < source.size(); ++f)
    for (int c : rows) target[f]->row(c) = source[f]->row(c);
}

namespace {

// Rows [first, first + lanes) of `out` from one block's fields [field][lane]
// (the batch's layout, width W), columns [0, fields).
template <class T>
void transpose_block(const T* block, int fields, int W, int first, int lanes, RowMatrix& out) {
  for (int k = 0; k < fields; ++k)
    for (int l = 0; l < lanes; ++l) out(first + l, k) = block[k * W + l];
}

}  // namespace

// The observation rows of one block's copies: the state fields transposed
// from the batch, then the base, gravity and contact forces copy by copy.
template <class Batch>
void VecEnv::observe_block(const Batch& b, int block, Observations& o) const {
  const Model& m = model();
  const int W = b.state.q.width(), first = block * W, lanes = std::min(W, copies() - first);
  if (first + W < copies()) prefetch_rows(o, first + W, std::min(W, copies() - first - W));
  transpose_block(b.state.q.block(block), m.nq, W, first, lanes, o.q);
  transpose_block(b.state.v.block(block), m.nv, W, first, lanes, o.qd);
  // the applied torque: the sum of its five sources, in double
  const auto *drive = b.applied_drive.block(block), *passive = b.applied_passive.block(block);
  const auto *friction = b.applied_friction.block(block), *limits = b.applied_limits.block(block);
  const auto* actuation = b.applied_actuation.block(block);
  for (int k = 0; k < m.nv; ++k)
    for (int l = 0; l < lanes; ++l) {
      const int i = k * W + l;
      o.applied_torque(first + l, k) = double(drive[i]) + double(passive[i]) + double(friction[i]) + double(limits[i]) +
                                       double(actuation[i]);
    }
  // the motors: command, speed and torque per actuator in the batch
  const auto* motors = b.actuator_state.block(block);
  for (int a = 0; a < o.motor_speed.cols(); ++a)
    for (int l = 0; l < lanes; ++l) {
      o.motor_speed(first + l, a) = motors[(3 * a + 1) * W + l];
      o.motor_torque(first + l, a) = motors[(3 * a + 2) * W + l];
    }
  const auto* gravity = b.state.gravity.block(block);
  for (int l = 0; l < lanes; ++l) {
    const int c = first + l;
    Eigen::Vector3d position, linear_base = Eigen::Vector3d::Zero(), angular_base = Eigen::Vector3d::Zero();
    Eigen::Quaterniond orientation;
    if (base_q_ >= 0) {
      position = o.q.row(c).segment<3>(base_q_).transpose();
      orientation = Eigen::Quaterniond(o.q(c, base_q_ + 3), o.q(c, base_q_ + 4), o.q(c, base_q_ + 5), o.q(c, base_q_ + 6));
      linear_base = o.qd.row(c).segment<3>(base_v_).transpose();
      angular_base = o.qd.row(c).segment<3>(base_v_ + 3).transpose();
    } else {
      position = fixed_base_pose_.translation();
      orientation = Eigen::Quaterniond(fixed_base_pose_.linear());
    }
    const Eigen::Matrix3d R = orientation.normalized().toRotationMatrix();  // a float quaternion is unit to ~1e-7
    o.base_position.row(c) = position.transpose();
    o.base_orientation.row(c) << orientation.w(), orientation.x(), orientation.y(), orientation.z();
    o.base_linear_velocity_base.row(c) = linear_base.transpose();
    o.base_angular_velocity_base.row(c) = angular_base.transpose();
    o.base_linear_velocity_world.row(c) = (R * linear_base).transpose();
    o.base_angular_velocity_world.row(c) = (R * angular_base).transpose();
    const Eigen::Vector3d g(gravity[l], gravity[W + l], gravity[2 * W + l]);
    const double norm = g.norm();
    const Eigen::Vector3d down = norm > 0 ? Eigen::Vector3d(R.transpose() * g / norm) : Eigen::Vector3d::Zero();
    o.projected_gravity.row(c) = down.transpose();
    if (o.contact_force.cols() > 0) sim_.body_contact_forces(c, o.contact_force.row(c).data());
  }
}

void VecEnv::observe(const std::vector<int>* which, Observations& o) const {
  const bool motion = o.joint_force.cols() > 0;
  visit_batch([&](const auto& b) {
    const int W = b.state.q.width();
    if (which) {  // the blocks holding these copies (the others' rows are refreshed unchanged)
      int last = -1;
      for (int c : *which)
        if (c / W != last) observe_block(b, last = c / W, o);
      // the readouts of these copies: zero where a reset left no step behind
      // (without the per-copy call's allocations, so that an auto-reset
      // allocates nothing), a restored one's own
      if (motion)
        for (int c : *which) {
          if (b.motion_recorded.at(c, 0) == 0) {
            o.joint_force.row(c).setZero();
            o.link_acceleration.row(c).setZero();
            continue;
          }
          const Eigen::Matrix<double, 6, Eigen::Dynamic> f = sim_.incoming_joint_forces(c);
          const Eigen::Matrix<double, 6, Eigen::Dynamic> a = sim_.link_accelerations(c);
          o.joint_force.row(c) = Eigen::Map<const Eigen::RowVectorXd>(f.data(), f.size());
          o.link_acceleration.row(c) = Eigen::Map<const Eigen::RowVectorXd>(a.data(), a.size());
        }
      return;
    }
    tbb::parallel_for(tbb::blocked_range<int>(0, b.state.q.blocks()), [&](const tbb::blocked_range<int>& range) {
      for (int block = range.begin(); block < range.end(); ++block) observe_block(b, block, o);
    });
  });
  if (which || !motion) return;
  sim_.all_incoming_joint_forces(o.joint_force);
  sim_.all_link_accelerations(o.link_acceleration);
}

Fault VecEnv::fault(int copy) const {
  require_copy_index(copy, copies(), "VecEnv", "fault");
  return last_fault_[copy];
}

EnvCopyState VecEnv::state(int copy) const {
  require_copy_index(copy, copies(), "VecEnv", "state");
  return {sim_.snapshot(copy), episode_step_[copy], reset_count_[copy]};
}

void VecEnv::set_state(int copy, const EnvCopyState& s) {
  require_copy_index(copy, copies(), "VecEnv", "set_state");
  sim_.restore(copy, s.simulator);
  episode_step_[copy] = s.episode_step;
  reset_count_[copy] = s.reset_count;
  last_fault_[copy] = sim_.fault(copy);
  const std::vector<int> one{copy};
  observe(&one, observations_);
}

}  // namespace lockstep
