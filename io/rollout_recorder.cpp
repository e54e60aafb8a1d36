#include "io/rollout_recorder.hpp"

#include "batch/build_info.hpp"
#include "io/sha256.hpp"

#include <tbb/parallel_for.h>

#include <chrono>
#include <cstring>
#include <stdexcept>
#include <filesystem>

namespace lockstep {

namespace {

// The datasets every file has, in file order; after them the optional ones
// (rollout_step_datasets).
enum Dataset : int { kQ, kQd, kActions, kAppliedTorque, kReward, kTerminated, kTruncated, kFaulted, kOptional };

ElementType state_type(const VecEnv& env) {
  return env.options().step.precision == Precision::Float ? ElementType::Float32 : ElementType::Float64;
}

bool has_contacts(const VecEnv& env) { return env.observations().contact_force.cols() > 0; }
bool has_motion(const VecEnv& env) { return env.observations().joint_force.cols() > 0; }
bool has_actuators(const VecEnv& env) { return env.observations().motor_speed.cols() > 0; }

// Column names of q: a joint's name, or name[x] ... for multi-entry joints.
std::vector<std::string> q_names(const Model& m) {
  std::vector<std::string> names(m.nq);
  for (int b = 0; b < m.nbody; ++b) {
    const int at = m.body_q_offset[b];
    const std::string& joint = m.joint_name[b];
    switch (m.body_joint[b]) {
      case JointType::Free: {
        const char* parts[] = {"x", "y", "z", "qw", "qx", "qy", "qz"};
        for (int i = 0; i < 7; ++i) names[at + i] = joint + "[" + parts[i] + "]";
        break;
      }
      case JointType::Spherical: {
        const char* parts[] = {"qw", "qx", "qy", "qz"};
        for (int i = 0; i < 4; ++i) names[at + i] = joint + "[" + parts[i] + "]";
        break;
      }
      default:
        names[at] = joint;
    }
  }
  return names;
}

std::vector<std::string> body_names(const Model& m) {
  std::vector<std::string> names;
  for (int b = 0; b < m.nbody; ++b) names.push_back(m.frame_name[m.body_frame[b]]);
  return names;
}

template <class T>
StaticDataset static_matrix(const char* name, const RowMatrix& values, const char* description) {
  StaticDataset d{name, ElementTypeOf<T>::value,
                  {static_cast<std::size_t>(values.rows()), static_cast<std::size_t>(values.cols())}, {}, description};
  d.data.resize(values.size() * sizeof(T));
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    const T x = static_cast<T>(values.data()[i]);
    std::memcpy(d.data.data() + i * sizeof(T), &x, sizeof(T));
  }
  return d;
}

std::vector<Attribute> run_attributes(const VecEnv& env, const RolloutInfo& info) {
  const Model& m = env.model();
  const VecEnvOptions& o = env.options();
  const std::vector<std::string> action_names = env.action_names();
  std::vector<Attribute> a = {
      {"lockstep_version", std::string(lockstep_version())},
      {"build", build_description()},
      {"scene", info.scene_json},
      {"model_file", std::filesystem::absolute(info.model_path).lexically_normal().string()},
      {"model_sha256", sha256_file(info.model_path)},
      {"policy", info.policy},
      {"envs", static_cast<std::int64_t>(env.copies())},
      {"dt", o.step.dt},
      {"control_steps", static_cast<std::int64_t>(o.control_steps)},
      {"substeps", static_cast<std::int64_t>(o.step.substeps)},
      {"solver", std::string(solver_name(o.step.solver))},
      {"iterations", static_cast<std::int64_t>(o.step.iterations)},
      {"integrator", std::string(integrator_name(o.step.integrator))},
      {"precision", std::string(precision_name(o.step.precision))},
      {"seed", static_cast<std::int64_t>(o.seed)},  // two's complement from 2^63 (docs/rollout_files.md)
      {"action_mode", std::string(action_mode_name(o.action_mode))},
      {"episode_steps", static_cast<std::int64_t>(o.episode_steps)},
      {"auto_reset", static_cast<std::int64_t>(o.auto_reset)},
      {"q_names", q_names(m)},
      {"dof_names", m.dof_name},
      {"action_names", action_names},
      {"body_names", body_names(m)},
      {"link_names", m.frame_name},
      {"actuator_names", actuator_names(o.step.actuators)},
      {"randomization.randomize_ground_friction", static_cast<std::int64_t>(o.randomization.randomize_ground_friction)},
  };
  for (const RandomizationField& f : randomization_fields()) {
    const UniformRange& range = o.randomization.*f.range;
    a.push_back({std::string("randomization.") + f.name, std::vector<double>{range.low, range.high}});
  }
  a.insert(a.end(), info.extra.begin(), info.extra.end());
  return a;
}

// out[i] = T(in[i]) for i in [0, n), in slices on the TBB threads. A frame
// is megabytes at thousands of copies; copied on one thread it left the
// others idle for a fifth of the stepping time at 16 threads
// (docs/performance.md, "The README job on 16 threads").
template <class T, class S>
void convert(const S* in, Eigen::Index n, T* out) {
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, n, Eigen::Index(1) << 14),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index i = r.begin(); i != r.end(); ++i) out[i] = static_cast<T>(in[i]);
                    });
}

// A whole observation field into a frame of `T`s (one contiguous run: the
// field is row-major), then the rows of the copies that ended from the
// terminal observation.
template <class T>
void put_field(void* frame, const RowMatrix& now, const RowMatrix& terminal, const std::vector<int>& ended) {
  T* out = static_cast<T*>(frame);
  const Eigen::Index cols = now.cols();
  convert(now.data(), now.size(), out);
  for (int c : ended)
    for (Eigen::Index k = 0; k < cols; ++k) out[c * cols + k] = static_cast<T>(terminal(c, k));
}

// The per-step datasets in file order (enum Dataset).
std::vector<StepDataset> rollout_step_datasets(const VecEnv& env) {
  const Model& m = env.model();
  const std::size_t n = env.copies();
  const ElementType state = state_type(env);
  std::vector<StepDataset> d = {
      {"q", state, {n, std::size_t(m.nq)}, "configuration after the step (terminal where the episode ended), q_names"},
      {"qd", state, {n, std::size_t(m.nv)}, "generalized velocity after the step (Free: body-frame twist), dof_names"},
      {"actions", ElementType::Float64, {n, std::size_t(env.action_size())}, "the step's actions, action_names"},
      {"applied_torque", state, {n, std::size_t(m.nv)}, "joint torque of the last simulator step, all sources, dof_names"},
      {"reward", ElementType::Float64, {n}, "the reward function's value (0 without one)"},
      {"terminated", ElementType::UInt8, {n}, "the episode ended: the reward function or a fault"},
      {"truncated", ElementType::UInt8, {n}, "the episode reached episode_steps"},
      {"faulted", ElementType::UInt8, {n}, "non-finite inputs or state in the step (then terminated and reset)"},
  };
  if (has_contacts(env))
    d.push_back({"contact_force", state, {n, std::size_t(m.nbody), 3}, "net contact force on each body, world [N]"});
  if (has_motion(env)) {
    d.push_back({"joint_force", state, {n, std::size_t(m.nbody), 6},
                 "each joint's force on its body, world: force [N], torque about the joint origin [N m]"});
    d.push_back({"link_acceleration", state, {n, m.frame_name.size(), 6},
                 "each link's origin acceleration [m/s^2] and angular acceleration [rad/s^2], world"});
  }
  if (has_actuators(env)) {
    const std::size_t actuators = env.options().step.actuators.size();
    d.push_back({"motor_speed", state, {n, actuators}, "each actuator's motor speed [rad/s], actuator_names"});
    d.push_back({"motor_torque", state, {n, actuators}, "each actuator's motor torque [N m], actuator_names"});
  }
  return d;
}

}  // namespace

RolloutRecorder::RolloutRecorder(const VecEnv& env, const std::string& path, const RolloutInfo& info,
                                 RolloutFileOptions file)
    : env_(env), path_(path), env_steps_recorded_(env.steps()) {
  ended_.reserve(env.copies());  // record() allocates nothing
  const Observations& o = env.observations();
  std::vector<StaticDataset> statics;
  if (state_type(env) == ElementType::Float32) {
    statics = {static_matrix<float>("initial_q", o.q, "configuration before the first step"),
               static_matrix<float>("initial_qd", o.qd, "velocity before the first step")};
  } else {
    statics = {static_matrix<double>("initial_q", o.q, "configuration before the first step"),
               static_matrix<double>("initial_qd", o.qd, "velocity before the first step")};
  }
  writer_ = std::make_unique<RolloutWriter>(path, rollout_step_datasets(env), std::move(statics),
                                            run_attributes(env, info), file);
}

RolloutRecorder::~RolloutRecorder() = default;

void RolloutRecorder::record(const RowMatrix& actions) {
  if (actions.rows() != env_.copies() || actions.cols() != env_.action_size())
    throw std::invalid_argument(path_ + ": record: actions must be " + std::to_string(env_.copies()) + " x " +
                                std::to_string(env_.action_size()) + " (copies x action_size), got " +
                                std::to_string(actions.rows()) + " x " + std::to_string(actions.cols()));
  if (env_.steps() == env_steps_recorded_)
    throw std::logic_error(path_ + ": record: the environment has not stepped since the last record (env step " +
                           std::to_string(env_.steps()) + ")");
  env_steps_recorded_ = env_.steps();
  const auto start = std::chrono::steady_clock::now();
  const Observations &now = env_.observations(), &terminal = env_.terminal_observations();
  // a copy that ended was reset: its step ended in the terminal row
  ended_.clear();
  if (env_.options().auto_reset)
    for (int c = 0; c < env_.copies(); ++c)
      if (env_.terminated()[c] || env_.truncated()[c]) ended_.push_back(c);
  const bool single = state_type(env_) == ElementType::Float32;
  auto put = [&](int dataset, const RowMatrix& field, const RowMatrix& at_end) {
    if (single) put_field<float>(writer_->frame(dataset), field, at_end, ended_);
    else put_field<double>(writer_->frame(dataset), field, at_end, ended_);
  };
  put(kQ, now.q, terminal.q);
  put(kQd, now.qd, terminal.qd);
  put(kAppliedTorque, now.applied_torque, terminal.applied_torque);
  int optional = kOptional;  // rollout_step_datasets' order
  if (now.contact_force.cols() > 0) put(optional++, now.contact_force, terminal.contact_force);
  if (now.joint_force.cols() > 0) {
    put(optional++, now.joint_force, terminal.joint_force);
    put(optional++, now.link_acceleration, terminal.link_acceleration);
  }
  if (now.motor_speed.cols() > 0) {
    put(optional++, now.motor_speed, terminal.motor_speed);
    put(optional++, now.motor_torque, terminal.motor_torque);
  }
  convert(actions.data(), actions.size(), writer_->frame_as<double>(kActions));
  std::copy(env_.reward().data(), env_.reward().data() + env_.copies(), writer_->frame_as<double>(kReward));
  std::copy(env_.terminated().begin(), env_.terminated().end(), writer_->frame_as<std::uint8_t>(kTerminated));
  std::copy(env_.truncated().begin(), env_.truncated().end(), writer_->frame_as<std::uint8_t>(kTruncated));
  std::copy(env_.faulted().begin(), env_.faulted().end(), writer_->frame_as<std::uint8_t>(kFaulted));
  writer_->commit();
  ++steps_;
  seconds_recording_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void RolloutRecorder::close(std::vector<Attribute> summary) {
  for (const Attribute& a : summary)
    if (a.name == "steps")
      throw std::invalid_argument(path_ + ": close: the summary attribute 'steps' is the recorder's own (the steps "
                                  "recorded)");
  summary.push_back({"steps", steps_});
  writer_->close(std::move(summary));
}

void RolloutRecorder::close_incomplete() { writer_->close_incomplete(); }

double RolloutRecorder::seconds_waiting() const { return writer_->seconds_waiting(); }
std::int64_t RolloutRecorder::steps_flushed() const { return writer_->steps_flushed(); }

}  // namespace lockstep
