// MuJoCo as the peer of `lockstep bench`: the same URDF, the same dt, the
// same PD holding the same pose, contacts off, timed in the same run.
// Compiled only when the MuJoCo headers and library are found (the build
// then defines LOCKSTEP_HAVE_MUJOCO); docs/cli.md describes the output.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace lockstep::cli {

struct MujocoScene {
  std::string urdf_path;
  bool floating_base = true;
  double dt = 0.002;
  double kp = 0.0;  // N m/rad on every hinge and slide joint
  double kd = 0.0;  // N m s/rad
  // Drive targets by URDF joint name (rad or m); joints not named hold 0.
  std::vector<std::pair<std::string, double>> targets;
  double base_height = 0.0;  // initial z of the floating root
};

// One thread count: each thread steps its own mjData `steps` times per
// repeat; `seconds` is the median wall time of a repeat.
struct MujocoTiming {
  int threads = 1;
  long steps = 0;  // per thread and repeat
  double seconds = 0.0;
};

struct MujocoReport {
  std::string version;
  int nq = 0, nv = 0, nbody = 0;
  std::vector<std::string> notes;  // what was done to the URDF and the model, in order
  std::vector<MujocoTiming> timings;
  double max_pose_error = 0.0;  // max |q - q_target| over the driven joints after the last repeat (rad or m)
};

// Loads `scene.urdf_path` into MuJoCo (meshes stripped, a floating root
// added when asked) and times it for each thread count. Throws
// std::runtime_error with MuJoCo's message when the model does not load.
MujocoReport run_mujoco_peer(const MujocoScene& scene, const std::vector<int>& threads, long steps, int repeats);

}  // namespace lockstep::cli
