// tools/step_scene.hpp: the standing pose `lockstep bench` and `lockstep
// rollout` give a bare URDF.
#include "tools/cli.hpp"
#include "tools/step_scene.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace lockstep {
namespace {

const std::string kQuadruped = std::string(LOCKSTEP_MODELS_DIR) + "/quadruped.urdf";

// Every quadruped the standing pose names, bundled and shared: its targets
// lie within the URDF's joint limits, so that no drive holds a joint
// against its limit (the bundled quadruped's knees once had target 0,
// outside [-2.7, -0.3], and the robot stood on two feet).
TEST(StandingPose, EveryTargetLiesWithinItsJointsLimits) {
  const std::string shared = LOCKSTEP_SHARED_MODELS_DIR;
  int checked = 0;
  for (const std::string& path : {kQuadruped, shared + "/anymal_b.urdf", shared + "/a1.urdf", shared + "/solo12.urdf"}) {
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

}  // namespace
}  // namespace lockstep
