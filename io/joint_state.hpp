// Reading a single state (q, qd, tau) keyed by URDF joint name: the input of
// `lockstep dynamics` and the initial state of a scene file (docs/cli.md).
#pragma once

#include "batch/precision.hpp"
#include "layout/model.hpp"
#include "io/json.hpp"

#include <stdexcept>
#include <string>

namespace lockstep {

// Invalid state input; the message names the source and the key.
class StateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// q (nq), v (nv), tau (nv) in low-level order.
struct JointState {
  Eigen::VectorXd q;
  Eigen::VectorXd v;
  Eigen::VectorXd tau;
};

// `root` is an object with optional members "q", "qd" and "tau", each an
// object keyed by joint name: a number for a 1-DOF joint, an array for a
// Free joint (q [x,y,z,qw,qx,qy,qz], qd body-frame [vx,vy,vz,wx,wy,wz], tau 6)
// or a Spherical joint (q [qw,qx,qy,qz], qd and tau 3). Joints not given are
// at the neutral configuration with zero velocity and torque. A quaternion
// must have unit norm within 1e-3 and is then normalised. Throws StateError
// for unknown keys or joints, wrong types or sizes, non-finite values, and
// with Precision::Float values beyond float's range.
JointState read_state(const Model& model, const json::Value& root, const std::string& source,
                      Precision precision = Precision::Double);

// One configuration (nq) from an object keyed by joint name, in the format
// of the state's "q": joints not given are neutral. Errors are named
// `where.joint`.
Eigen::VectorXd read_configuration(const Model& model, const json::Value& entries, const std::string& where);
// The same for one velocity (nv) in the format of the state's "qd": joints
// not given are at rest.
Eigen::VectorXd read_velocity(const Model& model, const json::Value& entries, const std::string& where);

}  // namespace lockstep
