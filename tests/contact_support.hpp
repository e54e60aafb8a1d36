// Scenes for the contact tests: free bodies with one shape, a scene runner,
// and the stance of the quadrupeds.
#pragma once

#include "batch/copy_dynamics.hpp"
#include "io/urdf_import.hpp"
#include "tests/sim_support.hpp"

namespace lockstep::test {

// Expects f() to throw std::invalid_argument whose message holds `piece`.
template <class F>
void expect_invalid(F&& f, const std::string& piece) {
  try {
    f();
    ADD_FAILURE() << "no std::invalid_argument (expected one naming '" << piece << "')";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(piece), std::string::npos) << "message '" << e.what() << "' lacks '" << piece << "'";
  }
}

// A free body of mass m carrying one shape, as an articulation spec.
inline ArticulationSpec free_shape_spec(const std::string& name, ShapeType type, const Eigen::Vector3d& size,
                                        double mass) {
  ArticulationSpec spec;
  spec.name = name;
  spec.floating_base = true;
  LinkSpec body;
  body.name = name;
  body.inertial.mass = mass;
  Eigen::Vector3d moments;
  if (type == ShapeType::Sphere) {
    moments.setConstant(0.4 * mass * size.x() * size.x());
  } else {  // box half extents
    const Eigen::Vector3d s = size.cwiseAbs2();
    moments = mass / 3.0 * Eigen::Vector3d(s.y() + s.z(), s.x() + s.z(), s.x() + s.y());
  }
  body.inertial.inertia = moments.asDiagonal();
  Shape shape;
  shape.type = type;
  shape.size = size;
  body.shapes.push_back(shape);
  spec.links.push_back(body);
  return spec;
}

inline Model single_body(ShapeType type, const Eigen::Vector3d& size, double mass) {
  ModelBuilder builder;
  builder.add_articulation(free_shape_spec("body", type, size, mass));
  return builder.finalize();
}

// A Free joint's q at position p and orientation R.
inline Eigen::VectorXd free_pose(const Eigen::Vector3d& p, const Eigen::Quaterniond& R = Eigen::Quaterniond::Identity()) {
  Eigen::VectorXd q(7);
  q << p, R.w(), R.x(), R.y(), R.z();
  return q;
}

// The stance both quadrupeds are held in: hips 0, thighs and knees bent so
// that the feet are under the hips.
inline Eigen::VectorXd stance(const Model& model) {
  Eigen::VectorXd q = model.neutral_configuration();
  for (int k = 0; k < model.nv; ++k) {
    const std::string& name = model.dof_name[k];
    const int body = model.dof_body[k];
    if (model.body_joint[body] == JointType::Free) continue;
    const int i = model.body_q_offset[body];
    const bool front = name.find("F_") != std::string::npos || name.find("F") == 1;
    if (name.find("HFE") != std::string::npos) q[i] = front ? 0.4 : -0.4;        // anymal_b
    if (name.find("KFE") != std::string::npos) q[i] = front ? -0.8 : 0.8;
    if (name.find("thigh_joint") != std::string::npos) q[i] = 0.8;               // a1
    if (name.find("calf_joint") != std::string::npos) q[i] = -1.6;
  }
  return q;
}

}  // namespace lockstep::test
