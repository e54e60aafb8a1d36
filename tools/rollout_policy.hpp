// The built-in policies of `lockstep rollout`: simple open- and closed-loop
// action generators that exercise a scene without a learned policy.
//
//   zero    every action 0 (zero torque, or position targets at 0)
//   hold    position targets at the scene's drive targets (its initial pose
//           unless it names others); in torque mode a PD torque toward them
//           (kp 50 N m/rad, kd 1 N m s/rad, clamped to the effort limit);
//           with actuator torques the same PD, commanded to the first
//           actuator on each joint (others add only the wave), unclamped
//   sine    hold plus amplitude * sin(2 pi 0.5 Hz t + 0.5 j) on column j
//   random  hold plus amplitude * U(-1, 1), drawn per (seed, copy, step, column)
//           with Philox, so a copy's actions never depend on the batch
//
// The amplitude is 0.3 rad (at most half a limited joint's range) for
// position targets, 0.3 of the effort limit (1 N m without one) for
// torques, and 0.3 of the most an actuator's motor gives at rest,
// G min(tau_peak, tau_stall), for actuator torques.
#pragma once

#include "batch/vec_env.hpp"

#include <cstdint>
#include <string>

namespace lockstep::cli {

enum class PolicyKind { Zero, Hold, Sine, Random };
// Throws UsageError for an unknown name.
PolicyKind parse_policy(const std::string& name);
const char* policy_name(PolicyKind kind);

class Policy {
 public:
  Policy(PolicyKind kind, const VecEnv& env, std::uint64_t seed);
  // The actions of env step `step` (N x action_size) from the observations.
  void act(const VecEnv& env, std::int64_t step, RowMatrix& actions);

 private:
  PolicyKind kind_;
  std::uint64_t seed_;
  Eigen::VectorXd hold_;       // (actions) the drive targets, or 0 for torques
  Eigen::VectorXd amplitude_;  // (actions)
  Eigen::VectorXd effort_;     // (actions) the torque clamp
  std::vector<int> q_index_;   // (actions) the column's entry in q (1-DOF joints), -1 otherwise
  std::vector<char> holds_;    // (actions) the column carries its DOF's hold PD (torque modes)
  Eigen::VectorXd wave_;       // (actions) scratch of act(): the sine policy's wave at this step
};

}  // namespace lockstep::cli
