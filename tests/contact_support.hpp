// Scenes for the contact tests: free bodies with one shape, a scene runner,
// and the stance of the quadrupeds.
#pragma once

#include "batch/copy_dynamics.hpp"
#include "io/urdf_import.hpp"
#include "tools/step_scene.hpp"
#include "tests/sim_support.hpp"

#include <cmath>

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

constexpr double kPi = 3.14159265358979323846;

// A plane through the origin tilted by theta (rad) about y: its normal, the
// downhill direction along it, the rotation that lays a body's z on the
// normal, and the sliding acceleration g (sin - mu cos) of a block on it
// (negative: it sticks).
struct Incline {
  explicit Incline(double theta)
      : theta(theta),
        normal(std::sin(theta), 0, std::cos(theta)),
        downhill(std::cos(theta), 0, -std::sin(theta)),
        tilt(Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitY())) {}
  double sliding(double mu, double g = 9.81) const { return g * (std::sin(theta) - mu * std::cos(theta)); }
  double theta;
  Eigen::Vector3d normal, downhill;
  Eigen::Quaterniond tilt;
};

// A sphere of radius r centred at `at` on its link.
inline Shape sphere_at(double r, const Eigen::Vector3d& at) {
  Shape shape;
  shape.type = ShapeType::Sphere;
  shape.size = Eigen::Vector3d(r, 0, 0);
  shape.pose.translation() = at;
  return shape;
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

// A quadruped's standing pose (the benchmark's, tools/step_scene.hpp) with
// its floating root at the height where its feet touch the plane z = 0.
inline Eigen::VectorXd stance(const Model& model) { return step_scene::make_scene(model, true).q_target; }

}  // namespace lockstep::test
