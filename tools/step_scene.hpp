// The scene the step benchmarks time (`lockstep bench`, bench/step_bench.cpp):
// a model on its own, no contacts, gravity on, a PD drive on every DOF
// except a floating root's, holding a standing pose, every copy starting
// at rest in that pose (or, with copy_poses, each copy in a pose of its
// own). Header-only so that both programs share it without a library of
// their own.
#pragma once

#include "batch/copy_dynamics.hpp"
#include "batch/simulator.hpp"
#include "io/scene_file.hpp"

#include <algorithm>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace lockstep::step_scene {

inline constexpr double kDriveStiffness = 200.0;  // kp [N m/rad]
inline constexpr double kDriveDamping = 5.0;      // kd [N m s/rad]
inline constexpr double kBaseHeight = 0.6;        // initial z of a floating root [m]

// The drive target of one URDF joint: a quadruped's standing pose by joint
// name, 0 for every other joint. ANYmal (LF_HFE, RH_KFE, ...): hip
// abduction 0, front legs HFE +0.4 and KFE -0.8, hind legs HFE -0.4 and
// KFE +0.8 (a leg is front when the name's prefix before '_' has an F,
// hind when it has an H). Unitree A1 (FR_thigh_joint, RL_calf_joint, ...)
// and the bundled quadruped (FL_hip_flex, HR_knee, ...; its scene file
// models/quadruped_scene.json stands the same way): thighs 0.8, calves
// -1.6, hips 0, on every leg.
inline double standing_target(const std::string& joint) {
  const std::size_t underscore = joint.find('_');
  if (underscore == std::string::npos) return 0.0;
  const std::string leg = joint.substr(0, underscore);
  const std::string part = joint.substr(underscore + 1);
  if (part == "thigh_joint" || part == "hip_flex") return 0.8;
  if (part == "calf_joint" || part == "knee") return -1.6;
  const bool front = leg.find('F') != std::string::npos;
  const bool hind = leg.find('H') != std::string::npos;
  if (front == hind) return 0.0;
  const double sign = front ? 1.0 : -1.0;
  if (part == "HFE") return 0.4 * sign;
  if (part == "KFE") return -0.8 * sign;
  return 0.0;
}

// Drive targets of the model's 1-DOF joints, by joint name.
inline std::vector<std::pair<std::string, double>> standing_pose(const Model& model) {
  std::vector<std::pair<std::string, double>> pose;
  for (int b = 0; b < model.nbody; ++b)
    if (model.body_joint[b] == JointType::Revolute || model.body_joint[b] == JointType::Prismatic)
      pose.emplace_back(model.joint_name[b], standing_target(model.joint_name[b]));
  return pose;
}

struct Scene {
  std::vector<DofSettings> dofs;  // the model's defaults plus the drives
  Eigen::VectorXd q_target;       // (nq) the pose; a floating root at its initial pose
  Eigen::VectorXd q0, v0;         // the initial state of every copy
  int driven_dofs = 0;
};

// True when the model's first body floats (a Free joint): its q starts
// with the root's position and orientation.
inline bool free_root(const Model& model) { return model.nbody > 0 && model.body_joint[0] == JointType::Free; }

// The root height at which the pose q's lowest shape (a foot) touches the
// plane z = 0; kBaseHeight when the model has no shapes.
inline double touching_height(const Model& model, const Eigen::VectorXd& q) {
  return resting_root_height(model, q).value_or(kBaseHeight);
}

// The standing pose (standing_pose, each target moved into its joint's
// limits where it lies outside them) under PD drives, every copy at rest
// in it; ground: the floating root starts where the feet touch the plane
// z = 0.
inline Scene make_scene(const Model& model, bool ground = false) {
  Scene scene;
  scene.dofs = default_dof_settings(model);
  for (int d = 0; d < model.nv; ++d) {
    if (model.body_joint[model.dof_body[d]] == JointType::Free) continue;
    scene.dofs[d].drive_stiffness = kDriveStiffness;
    scene.dofs[d].drive_damping = kDriveDamping;
    ++scene.driven_dofs;
  }
  scene.q_target = model.neutral_configuration();
  for (const auto& [joint, target] : standing_pose(model)) {
    // within the joint's limits (a hand's or an arm's 0 may lie outside them)
    const int b = model.joint_index(joint);
    const DofSettings& dof = scene.dofs[model.body_dof_offset[b]];
    scene.q_target[model.body_q_offset[b]] = std::clamp(target, dof.lower, dof.upper);
  }
  const double base_height = ground ? touching_height(model, scene.q_target) : kBaseHeight;
  for (int b = 0; b < model.nbody; ++b)
    if (model.body_joint[b] == JointType::Free) scene.q_target[model.body_q_offset[b] + 2] = base_height;
  scene.q0 = scene.q_target;
  scene.v0 = Eigen::VectorXd::Zero(model.nv);
  return scene;
}

// Each copy's drive target and initial pose (at rest in it): a column per
// copy, or one column for all copies when they are all the same (so that a
// million copies of one pose keep one).
struct CopyPoses {
  Eigen::MatrixXd target, q0;  // (nq x copies), or (nq x 1)

  Eigen::VectorXd target_of(int copy) const { return target.col(target.cols() == 1 ? 0 : copy); }
  Eigen::VectorXd q0_of(int copy) const { return q0.col(q0.cols() == 1 ? 0 : copy); }
};

// Copies that differ, as a training run's do, so that the copies in a block
// of lanes take their own paths through the step: copy c > 0 moves each
// revolute or prismatic joint's target by an offset uniform in
// [-spread, spread] (rad or m), kept within the joint's limits (dofs; a
// target outside them goes no further out), from a generator seeded by c
// (the same copies in every run, precision and build), and starts at rest
// in that pose. A floating root moves up or down by as much as the pose's
// resting height (resting_root_height) differs from `target`'s, so that
// every copy starts as `initial_q` does (touching the ground, where the
// scene's robot does). Copy 0, and every copy when spread is 0, holds
// `target` from `initial_q`.
inline CopyPoses copy_poses(const Model& model, const std::vector<DofSettings>& dofs, const Eigen::VectorXd& target,
                            const Eigen::VectorXd& initial_q, int copies, double spread) {
  const std::optional<double> resting = free_root(model) ? resting_root_height(model, target) : std::nullopt;
  const int columns = spread > 0 ? copies : 1;
  CopyPoses poses{target.replicate(1, columns), initial_q.replicate(1, columns)};
  for (int c = 1; c < columns; ++c) {
    std::mt19937_64 random(static_cast<std::uint64_t>(c));
    auto t = poses.target.col(c);
    auto q0 = poses.q0.col(c);
    for (int b = 0; b < model.nbody; ++b) {
      if (model.body_joint[b] != JointType::Revolute && model.body_joint[b] != JointType::Prismatic) continue;
      const double unit = static_cast<double>(random() >> 11) * 0x1.0p-53;  // [0, 1), the same on every platform
      const DofSettings& dof = dofs[model.body_dof_offset[b]];
      const int i = model.body_q_offset[b];
      // within the limits, or no further outside them than the target itself
      t[i] = q0[i] = std::clamp(t[i] + spread * (2 * unit - 1), std::min(dof.lower, t[i]), std::max(dof.upper, t[i]));
    }
    if (const std::optional<double> height = resting ? resting_root_height(model, t) : std::nullopt) {
      const int z = model.body_q_offset[0] + 2;
      q0[z] += *height - *resting;
      t[z] = q0[z];
    }
  }
  return poses;
}

// A simulator of `copies` copies of the scene, each at its initial state
// with its drive target set.
inline Simulator make_simulator(const Model& model, const Scene& scene, int copies, const StepOptions& options) {
  Simulator sim(model, copies, options, scene.dofs);
  const Eigen::VectorXd v_target = Eigen::VectorXd::Zero(model.nv);
  for (int c = 0; c < copies; ++c) sim.set_drive_target(c, scene.q_target, v_target);
  sim.set_state_all(scene.q0, scene.v0);
  return sim;
}

}  // namespace lockstep::step_scene
