// Builds an immutable Model from articulations described link by link,
// parent-first, in the spirit of the parallel links/joints arrays of an
// articulated-actor description. The URDF importer produces the same specs.
#pragma once

#include "layout/model.hpp"

#include <stdexcept>
#include <string>
#include <vector>

namespace lockstep {

// Raised for any invalid model input; the message names the source (file or
// articulation) and the element (link, joint, index).
class ModelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct InertialSpec {
  double mass = 0.0;
  // COM position and the orientation of the inertia axes, in the link frame.
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();  // about the COM, in `origin` axes
};

struct MimicSpec {
  std::string leader_joint;  // empty: no mimic
  double multiplier = 1.0;
  double offset = 0.0;
};

struct JointSpec {
  std::string name;
  JointType type = JointType::Fixed;
  // The joint frame in the parent link frame (URDF <origin>).
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();  // Revolute/Prismatic, in the joint frame
  bool limited = false;                             // position limits apply
  double lower = -Model::kInfinity;
  double upper = Model::kInfinity;
  double velocity_limit = Model::kInfinity;
  double effort_limit = Model::kInfinity;
  double damping = 0.0;
  double friction = 0.0;
  double armature = 0.0;
  // a joint spring, Revolute/Prismatic only (RaiSim's URDF <dynamics
  // stiffness spring_mount>): torque spring_stiffness (spring_rest - q)
  double spring_stiffness = 0.0;
  double spring_rest = 0.0;
  MimicSpec mimic;
  int source_line = 0;  // the joint's line in ArticulationSpec::source, for messages (0: none)
};

struct LinkSpec {
  std::string name;
  std::string parent;  // empty for the articulation's root link
  JointSpec joint;     // the joint from `parent` to this link (for the root only its name counts: root_joint_name)
  InertialSpec inertial;
  // Whether gravity acts on the link (PhysX's eDISABLE_GRAVITY switched
  // off). It is a property of a moving body, which takes its switch from
  // the link it is named after: every link with mass fused into it by fixed
  // joints must agree.
  bool gravity = true;
  // Viscous damping of the link's motion [1/s], PhysX's linear and angular
  // damping of a link: the wrench -linear_damping m v_com, -angular_damping
  // I_com w at its COM, which alone would slow a free body as exp(-c t).
  // Per moving body, like gravity; the simulation step takes it (implicitly
  // with the Eulers: docs/conventions.md, "Link damping"), the dynamics
  // queries ignore it.
  double linear_damping = 0.0;
  double angular_damping = 0.0;
  std::vector<Shape> shapes;  // body/frame fields are filled in by the builder; pose in the link frame
  int source_line = 0;        // the link's line in ArticulationSpec::source, for messages (0: none)
};

struct ArticulationSpec {
  std::string name;    // used in error messages and lookups
  std::string source;  // file it came from, if any (error messages)
  bool floating_base = false;  // root hangs on a Free joint, else fixed to the world
  Eigen::Isometry3d root_pose = Eigen::Isometry3d::Identity();  // fixed base: root link in the world
  std::vector<LinkSpec> links;  // parent-first
};

// For each link of an articulation listed parent-first (parents known):
// the index of the link its moving body is named after (the link itself on
// a moving joint, or a floating root), the link it is fixed to otherwise;
// -1 for a link fixed to the world.
std::vector<int> body_head_links(const ArticulationSpec& spec);

struct BuildOptions {
  // Turn the warnings for tolerated imperfections (massless frames, point
  // masses, triangle-inequality violations) into errors.
  bool strict = false;
  // Relative size below which a negative inertia eigenvalue counts as
  // round-off (clamped for checks, kept as written) rather than an error.
  double inertia_eigen_tolerance = 1e-12;
};

class ModelBuilder {
 public:
  explicit ModelBuilder(BuildOptions options = {});

  // Validates the articulation and appends it to the forest; returns its index.
  // Throws ModelError naming the articulation (and source) and element.
  // A floating root's Free joint is named by the root link's joint.name, or
  // "<articulation name>_root" when that is empty. Warnings: massless links
  // on fixed joints fused into a moving body (those fused into the world are
  // dropped anyway), point masses, and principal moments violating the
  // triangle inequality; values are kept as written.
  int add_articulation(const ArticulationSpec& spec);

  void set_gravity(const Eigen::Vector3d& gravity);

  // Fuses fixed joints, orients body frames so joint axes are z, lays out
  // DOFs in low-level order and builds the name maps.
  Model finalize() const;

  // Warnings collected so far, each naming its source and element.
  const std::vector<std::string>& warnings() const { return warnings_; }

  // Appends a warning from an importer (missing mesh files, reinterpreted
  // limits); never raised to an error by `strict`.
  void add_warning(const std::string& message) { warnings_.push_back(message); }

 private:
  // A warning (problem, then what was done about it: `kept`), or under
  // BuildOptions::strict a ModelError saying that strict mode rejects it.
  void warn_or_throw(const std::string& problem, const std::string& kept = "");
  void check_inertial(const ArticulationSpec& spec, const LinkSpec& link) const;
  void check_joint(const ArticulationSpec& spec, const LinkSpec& link) const;
  // The Free root joint's name: the root link's joint.name if given, else
  // the articulation name + "_root".
  static std::string root_joint_name(const ArticulationSpec& spec);

  BuildOptions options_;
  Eigen::Vector3d gravity_{0.0, 0.0, -9.81};
  std::vector<ArticulationSpec> articulations_;
  std::vector<std::string> warnings_;
};

}  // namespace lockstep
