// tools/step_scene.hpp: the standing pose `lockstep bench` and `lockstep
// rollout` give a bare URDF, and the copies `lockstep bench --spread` steps,
// each holding a pose of its own.
#include "tools/cli.hpp"
#include "tools/step_scene.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

namespace lockstep {
namespace {

const std::string kQuadruped = std::string(LOCKSTEP_MODELS_DIR) + "/quadruped.urdf";

bool one_dof(const Model& m, int b) {
  return m.body_joint[b] == JointType::Revolute || m.body_joint[b] == JointType::Prismatic;
}

// Every quadruped the standing pose names, bundled and shared: its targets
// lie within the URDF's joint limits, so that no drive holds a joint
// against its limit (the bundled quadruped's knees once had target 0,
// outside [-2.7, -0.3], and the robot stood on two feet).
TEST(StandingPose, EveryTargetLiesWithinItsJointsLimits) {
  const std::string shared = LOCKSTEP_SHARED_MODELS_DIR;
  int checked = 0;
  for (const std::string& path :
       {kQuadruped, shared + "/anymal_b.urdf", shared + "/a1.urdf", shared + "/solo12.urdf"}) {
    if (!std::filesystem::exists(path)) continue;
    const Scene scene = cli::load_cli_scene(path, true, true, false);
    const Model& m = scene.model;
    int named = 0;
    for (const auto& [joint, target] : step_scene::standing_pose(m)) {
      const DofSettings& dof = scene.env.dofs[m.body_dof_offset[m.joint_index(joint)]];
      EXPECT_GE(target, dof.lower) << path << " " << joint;
      EXPECT_LE(target, dof.upper) << path << " " << joint;
      named += target != 0.0;
    }
    EXPECT_EQ(named, 8) << path << ": a thigh and a knee target on each of four legs";
    ++checked;
  }
  EXPECT_GE(checked, 1);
}

// Every bundled and shared URDF as a bare URDF's scene: every drive target
// lies within its joint's limits (a zero outside them moved to the nearer
// limit), so the pose error the bench reports measures the drives, not a
// target no joint can reach (the Allegro hand's thumb, 0.263 rad from its
// lower limit, and the Panda's fourth joint once read as that error).
TEST(StandingPose, EveryModelsSceneTargetsLieWithinTheLimits) {
  int checked = 0;
  for (const std::string& dir : {std::string(LOCKSTEP_MODELS_DIR), std::string(LOCKSTEP_SHARED_MODELS_DIR)}) {
    if (!std::filesystem::is_directory(dir)) continue;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      if (entry.path().extension() != ".urdf") continue;
      const Scene scene = cli::load_cli_scene(entry.path().string(), false, false, false);
      const Model& m = scene.model;
      for (int b = 0; b < m.nbody; ++b) {
        if (!one_dof(m, b)) continue;
        const double target = scene.env.drive_target_q[m.body_q_offset[b]];
        const DofSettings& dof = scene.env.dofs[m.body_dof_offset[b]];
        EXPECT_GE(target, dof.lower) << entry.path() << " " << m.joint_name[b];
        EXPECT_LE(target, dof.upper) << entry.path() << " " << m.joint_name[b];
        EXPECT_EQ(scene.env.initial_q[m.body_q_offset[b]], target) << entry.path() << " " << m.joint_name[b];
      }
      ++checked;
    }
  }
  EXPECT_GE(checked, 1);
}

TEST(CopyPoses, EveryCopyButTheFirstHoldsItsOwnPoseWithinTheSpreadAndTheLimits) {
  const Scene scene = cli::load_cli_scene(kQuadruped, true, true, false);
  const Model& m = scene.model;
  const double spread = 0.1;
  const int copies = 64;
  const step_scene::CopyPoses poses = step_scene::copy_poses(m, scene.env.dofs, scene.env.drive_target_q,
                                                             scene.env.initial_q, copies, spread);
  ASSERT_EQ(poses.target.cols(), copies);
  ASSERT_EQ(poses.q0.cols(), copies);
  EXPECT_EQ(poses.target_of(0), scene.env.drive_target_q);
  EXPECT_EQ(poses.q0_of(0), scene.env.initial_q);
  const int z = m.body_q_offset[0] + 2;
  const double scene_height = *resting_root_height(m, scene.env.drive_target_q);
  for (int c = 1; c < copies; ++c) {
    int moved = 0;
    for (int b = 0; b < m.nbody; ++b) {
      if (!one_dof(m, b)) continue;
      const int i = m.body_q_offset[b];
      const DofSettings& dof = scene.env.dofs[m.body_dof_offset[b]];
      EXPECT_LE(std::abs(poses.target_of(c)[i] - scene.env.drive_target_q[i]), spread) << "copy " << c << ", " << b;
      EXPECT_GE(poses.target_of(c)[i], dof.lower);
      EXPECT_LE(poses.target_of(c)[i], dof.upper);
      EXPECT_EQ(poses.q0_of(c)[i], poses.target_of(c)[i]);  // at rest in its own pose
      moved += poses.target_of(c)[i] != scene.env.drive_target_q[i];
    }
    EXPECT_GT(moved, 0) << "copy " << c;
    EXPECT_NE(poses.target_of(c), poses.target_of(c - 1));
    // its lowest shape where the scene's is: the root moved by the change of
    // the resting height (1e-12 m: the sum of two heights of about 0.5 m)
    const double height = *resting_root_height(m, poses.target_of(c));
    EXPECT_NEAR(poses.q0_of(c)[z] - scene.env.initial_q[z], height - scene_height, 1e-12) << "copy " << c;
    EXPECT_EQ(poses.target_of(c)[z], poses.q0_of(c)[z]);
  }
}

TEST(CopyPoses, AJointsOffsetStopsAtItsLimit) {
  const Scene scene = cli::load_cli_scene(kQuadruped, true, true, false);
  const Model& m = scene.model;
  const step_scene::CopyPoses poses =
      step_scene::copy_poses(m, scene.env.dofs, scene.env.drive_target_q, scene.env.initial_q, 16, 10.0);
  int at_limit = 0;
  for (int c = 1; c < 16; ++c)
    for (int b = 0; b < m.nbody; ++b) {
      if (!one_dof(m, b)) continue;
      const double x = poses.target_of(c)[m.body_q_offset[b]];
      const DofSettings& dof = scene.env.dofs[m.body_dof_offset[b]];
      EXPECT_GE(x, dof.lower);
      EXPECT_LE(x, dof.upper);
      at_limit += x == dof.lower || x == dof.upper;
    }
  // offsets of up to 10 rad against ranges of 1.6 rad or less: most land on a limit
  EXPECT_GT(at_limit, 15 * 12 / 2);
}

TEST(CopyPoses, AreTheSameInEveryCallAndAllTheSceneWithoutSpread) {
  const Scene scene = cli::load_cli_scene(kQuadruped, true, true, false);
  const Model& m = scene.model;
  const auto poses = [&](int copies, double spread) {
    return step_scene::copy_poses(m, scene.env.dofs, scene.env.drive_target_q, scene.env.initial_q, copies, spread);
  };
  const step_scene::CopyPoses few = poses(8, 0.05), many = poses(32, 0.05), none = poses(8, 0.0);
  for (int c = 0; c < 8; ++c) {
    EXPECT_EQ(few.target_of(c), many.target_of(c)) << "copy " << c;  // seeded by the copy, not by the batch
    EXPECT_EQ(few.q0_of(c), many.q0_of(c)) << "copy " << c;
    EXPECT_EQ(none.target_of(c), scene.env.drive_target_q);  // one column kept for all
    EXPECT_EQ(none.target.cols(), 1);
    EXPECT_EQ(none.q0_of(c), scene.env.initial_q);
  }
}

}  // namespace
}  // namespace lockstep
