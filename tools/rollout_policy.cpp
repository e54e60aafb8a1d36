#include "tools/rollout_policy.hpp"

#include "batch/counter_rng.hpp"
#include "tools/cli.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace lockstep::cli {

namespace {

constexpr double kHoldStiffness = 50.0;  // N m/rad, torque-mode hold
constexpr double kHoldDamping = 1.0;     // N m s/rad
constexpr double kSineHz = 0.5;
// Keeps the policy's stream apart from the randomisation's under one seed.
constexpr std::uint64_t kPolicyStream = 0x9e3779b97f4a7c15ull;

}  // namespace

PolicyKind parse_policy(const std::string& name) {
  for (PolicyKind kind : {PolicyKind::Zero, PolicyKind::Hold, PolicyKind::Sine, PolicyKind::Random})
    if (name == policy_name(kind)) return kind;
  throw UsageError("--policy must be zero, hold, sine or random, not \"" + name + "\"");
}

const char* policy_name(PolicyKind kind) {
  switch (kind) {
    case PolicyKind::Zero: return "zero";
    case PolicyKind::Hold: return "hold";
    case PolicyKind::Sine: return "sine";
    case PolicyKind::Random: return "random";
  }
  return "?";
}

Policy::Policy(PolicyKind kind, const VecEnv& env, std::uint64_t seed) : kind_(kind), seed_(seed ^ kPolicyStream) {
  const Model& m = env.model();
  const VecEnvOptions& o = env.options();
  const bool targets = o.action_mode == ActionMode::PositionTarget;
  const int n = env.action_size();
  hold_ = Eigen::VectorXd::Zero(n);
  amplitude_.resize(n);
  wave_.resize(n);
  effort_.resize(n);
  q_index_.assign(n, -1);
  holds_.assign(n, 1);
  const bool actuators = o.action_mode == ActionMode::ActuatorTorque;
  std::vector<char> held(m.nv, 0);  // a DOF whose hold PD an earlier column carries
  for (int j = 0; j < n; ++j) {
    const int dof = env.action_dofs()[j], body = m.dof_body[dof];
    const DofSettings& d = o.dofs[dof];
    const bool one_dof = m.body_joint[body] != JointType::Spherical;
    if (one_dof) q_index_[j] = m.body_q_offset[body];
    effort_[j] = d.max_force;
    if (targets) {
      if (one_dof) hold_[j] = o.drive_target_q[q_index_[j]];
      const double half_range = 0.5 * (d.upper - d.lower);
      amplitude_[j] = std::isfinite(half_range) ? std::min(0.3, half_range) : 0.3;
    } else {
      amplitude_[j] = std::isfinite(d.max_force) ? 0.3 * d.max_force : 1.0;
    }
    if (actuators) {  // bounded by the motor, not by the joint's effort limit
      const Actuator& a = o.step.actuators[j];
      effort_[j] = Model::kInfinity;
      amplitude_[j] = 0.3 * a.gear * std::min(a.peak_torque, a.stall_torque());
      holds_[j] = !held[dof];
      held[dof] = 1;
    }
  }
}

void Policy::act(const VecEnv& env, std::int64_t step, RowMatrix& actions) {
  const int n = env.action_size();
  actions.resize(env.copies(), n);
  const bool torque_hold = env.options().action_mode != ActionMode::PositionTarget && kind_ != PolicyKind::Zero;
  const double t = static_cast<double>(step) * env.options().step.dt * env.options().control_steps;
  // the wave is the same for every copy: one sine per column and step
  for (int j = 0; j < n; ++j)
    wave_[j] = kind_ == PolicyKind::Sine ? amplitude_[j] * std::sin(2 * M_PI * kSineHz * t + 0.5 * j) : 0.0;
  const Observations& obs = env.observations();
  auto act_copy = [&](int c) {
    for (int j = 0; j < n; ++j) {
      if (kind_ == PolicyKind::Zero) {
        actions(c, j) = 0;
        continue;
      }
      double a = wave_[j];
      if (kind_ == PolicyKind::Random) {
        const PhiloxCounter bits =
            philox4x32({static_cast<std::uint32_t>(c), static_cast<std::uint32_t>(step),
                        static_cast<std::uint32_t>(step >> 32), static_cast<std::uint32_t>(j)},
                       seed_);
        a = amplitude_[j] * (2 * unit_double(bits[0], bits[1]) - 1);
      }
      if (!torque_hold) {
        actions(c, j) = hold_[j] + a;
        continue;
      }
      // torque modes: a PD toward the initial pose (1-DOF joints), plus the wave
      const int dof = env.action_dofs()[j];
      const double error = q_index_[j] >= 0 ? env.options().drive_target_q[q_index_[j]] - obs.q(c, q_index_[j]) : 0.0;
      const double pd = holds_[j] ? kHoldStiffness * error - kHoldDamping * obs.qd(c, dof) : 0.0;
      actions(c, j) = std::clamp(pd + a, -effort_[j], effort_[j]);
    }
  };
  // every copy's row on its own: the same bits on any thread count
  tbb::parallel_for(tbb::blocked_range<int>(0, env.copies(), 512), [&](const tbb::blocked_range<int>& copies) {
    for (int c = copies.begin(); c != copies.end(); ++c) act_copy(c);
  });
}

}  // namespace lockstep::cli
