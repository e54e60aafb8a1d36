#include "layout/model.hpp"

#include <stdexcept>

#include "layout/name_hint.hpp"

namespace lockstep {

const char* joint_type_name(JointType type) {
  switch (type) {
    case JointType::Free: return "free";
    case JointType::Spherical: return "spherical";
    case JointType::Revolute: return "revolute";
    case JointType::Prismatic: return "prismatic";
    case JointType::Fixed: return "fixed";
  }
  return "unknown";
}

int joint_nq(JointType type) {
  switch (type) {
    case JointType::Free: return 7;
    case JointType::Spherical: return 4;
    case JointType::Revolute:
    case JointType::Prismatic: return 1;
    case JointType::Fixed: return 0;
  }
  return 0;
}

int joint_nv(JointType type) {
  switch (type) {
    case JointType::Free: return 6;
    case JointType::Spherical: return 3;
    case JointType::Revolute:
    case JointType::Prismatic: return 1;
    case JointType::Fixed: return 0;
  }
  return 0;
}

const char* shape_type_name(ShapeType type) {
  switch (type) {
    case ShapeType::Sphere: return "sphere";
    case ShapeType::Box: return "box";
    case ShapeType::Cylinder: return "cylinder";
    case ShapeType::Capsule: return "capsule";
    case ShapeType::Mesh: return "mesh";
  }
  return "unknown";
}

namespace {
[[noreturn]] void throw_missing(const std::string& name, const char* what, const std::vector<std::string>& names) {
  throw std::out_of_range(std::string("model has no ") + what + " named '" + name + "'" + did_you_mean(name, names));
}

int lookup(const std::unordered_map<std::string, int>& map, const std::string& name, const char* what,
           const std::vector<std::string>& names) {
  const auto it = map.find(name);
  if (it == map.end()) throw_missing(name, what, names);
  return it->second;
}
}  // namespace

int Model::frame_index(const std::string& name) const { return lookup(frame_by_name, name, "link", frame_name); }
int Model::joint_index(const std::string& name) const {
  return lookup(joint_by_name, name, "moving joint", joint_name);
}
int Model::dof_index(const std::string& name) const { return lookup(dof_by_name, name, "DOF", dof_name); }

const Mimic* Model::mimic_of(int dof) const {
  for (const Mimic& mimic : mimics)
    if (mimic.dof == dof) return &mimic;
  return nullptr;
}

int Model::articulation_index(const std::string& name) const {
  std::vector<std::string> names;
  for (std::size_t i = 0; i < articulations.size(); ++i) {
    if (articulations[i].name == name) return static_cast<int>(i);
    names.push_back(articulations[i].name);
  }
  throw_missing(name, "articulation", names);
}

std::vector<std::string> Model::links_without_gravity() const {
  std::vector<std::string> links;
  for (int b = 0; b < nbody; ++b)
    if (!body_gravity[b]) links.push_back(frame_name[body_frame[b]]);
  return links;
}

int Model::damped_bodies() const {
  int count = 0;
  for (int b = 0; b < nbody; ++b) count += body_linear_damping[b] != 0.0 || body_angular_damping[b] != 0.0;
  return count;
}

double Model::total_mass() const {
  double mass = 0.0;
  for (double m : body_mass) mass += m;
  return mass;
}

Eigen::VectorXd Model::neutral_configuration() const {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(nq);
  for (int b = 0; b < nbody; ++b) {
    const int o = body_q_offset[b];
    if (body_joint[b] == JointType::Free) q[o + 3] = 1.0;
    if (body_joint[b] == JointType::Spherical) q[o] = 1.0;
  }
  return q;
}

}  // namespace lockstep
