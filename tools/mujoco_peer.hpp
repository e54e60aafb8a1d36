// MuJoCo as the peer of `lockstep bench`: the same URDF, the same dt, the
// same PD holding the same pose, timed in the same run; contacts off, or,
// with `ground`, the robot standing on a plane with contacts on.
// Compiled only when the MuJoCo headers and library are found (the build
// then defines LOCKSTEP_HAVE_MUJOCO); docs/cli.md describes the output.
#pragma once

#include <string>
#include <utility>
#include <array>
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
  std::array<double, 3> gravity{0.0, 0.0, -9.81};  // m/s², world
  // Links gravity does not act on (Model::body_gravity): MuJoCo 2.2.2 has
  // no such switch, so their weight is cancelled through xfrc_applied.
  std::vector<std::string> links_without_gravity;
  // Contacts: off unless `ground`, which keeps the URDF's primitive
  // collision shapes (spheres, boxes, cylinders; mesh collisions are still
  // removed), adds a plane at z = 0 with normal +z and turns contacts on.
  bool ground = false;
  double friction = 1.0;        // sliding friction of the ground and of every robot geom
  bool self_collision = false;  // robot geoms also collide with each other (MuJoCo still skips parent-child pairs)
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
  // Over every timed step of the last repeat of the first thread's mjData
  // (last thread count): the mean z of the floating root (0 without one)
  // and the mean number of contacts d->ncon (0 with contacts off).
  double mean_base_height = 0.0;
  double mean_contacts = 0.0;
  // MuJoCo's warnings over every timed step of every mjData (d->warning),
  // by kind ("mjWARN_BADQACC", ...), only those that occurred, and the
  // first few messages MuJoCo wrote for them (kept here instead of its
  // stdout and MUJOCO_LOG.TXT in the working directory).
  std::vector<std::pair<std::string, long>> warnings;
  std::vector<std::string> warning_messages;
  // Timed steps after which an mjData's time went back: mj_step found a
  // bad qpos, qvel or qacc and reset the data (its warning counts restart
  // with it, so they understate this).
  long resets = 0;
  // Any reset or bad-state warning: the timed steps were not all the same
  // work as lockstep's.
  bool diverged = false;
};

// Loads `scene.urdf_path` into MuJoCo (meshes stripped, a floating root
// added when asked; with `ground`, saved as MJCF, given the plane and the
// contact settings, and loaded again) and times it for each thread count. Throws
// std::runtime_error with MuJoCo's message when the model does not load.
MujocoReport run_mujoco_peer(const MujocoScene& scene, const std::vector<int>& threads, long steps, int repeats);

}  // namespace lockstep::cli
