// Small models for the simulation tests: chains of pendulum links, a free
// box, and helpers to run a Simulator.
#pragma once

#include "batch/simulator.hpp"
#include "tests/test_support.hpp"

namespace lockstep::test {

// A rod of mass m and length l along -z from its joint (a point mass at the
// end when `point`), hanging from a revolute joint about y.
inline LinkSpec rod_link(const std::string& name, const std::string& parent, double mass, double length,
                         double parent_length) {
  LinkSpec link = joint_link(name, parent, JointType::Revolute, Eigen::Vector3d::UnitY(),
                             Eigen::Vector3d(0, 0, -parent_length));
  link.inertial.mass = mass;
  link.inertial.origin.translation() = Eigen::Vector3d(0, 0, -0.5 * length);
  const double i = mass * length * length / 12.0;
  link.inertial.inertia = Eigen::Vector3d(i, i, 1e-6 * mass).asDiagonal();
  return link;
}

// A fixed-base chain of revolute rods (about y) hanging from the world.
inline Model rod_chain(const std::vector<double>& masses, double length) {
  ArticulationSpec spec;
  spec.name = "chain";
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  std::string parent = "base";
  for (std::size_t i = 0; i < masses.size(); ++i) {
    const std::string name = "link" + std::to_string(i);
    spec.links.push_back(rod_link(name, parent, masses[i], length, i == 0 ? 0.0 : length));
    parent = name;
  }
  ModelBuilder builder;
  builder.add_articulation(spec);
  return builder.finalize();
}

// One link turning about z through its COM (no gravity torque), with the
// given moment of inertia about the axis; limits when lower < upper.
inline Model spinner(double inertia, double lower = -Model::kInfinity, double upper = Model::kInfinity) {
  ArticulationSpec spec;
  spec.name = "spinner";
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  LinkSpec link = joint_link("wheel", "base", JointType::Revolute, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero());
  link.inertial.mass = 1.0;
  link.inertial.inertia = Eigen::Vector3d(inertia, inertia, inertia).asDiagonal();
  link.joint.limited = lower < upper && (std::isfinite(lower) || std::isfinite(upper));
  link.joint.lower = lower;
  link.joint.upper = upper;
  spec.links.push_back(link);
  ModelBuilder builder;
  builder.add_articulation(spec);
  return builder.finalize();
}

// A free box of the given half sizes and mass.
inline Model free_box(const Eigen::Vector3d& half, double mass) {
  ArticulationSpec spec;
  spec.name = "box";
  spec.floating_base = true;
  LinkSpec body;
  body.name = "box";
  body.inertial.mass = mass;
  const Eigen::Vector3d s = half.cwiseAbs2();
  body.inertial.inertia = (mass / 3.0 * Eigen::Vector3d(s.y() + s.z(), s.x() + s.z(), s.x() + s.y())).asDiagonal();
  spec.links.push_back(body);
  ModelBuilder builder;
  builder.add_articulation(spec);
  return builder.finalize();
}

}  // namespace lockstep::test
