// The immutable articulation model: topology, parameters, frames, shapes and
// the name maps, in low-level (parent-first) order. Built by ModelBuilder or
// the URDF importer; never changed afterwards.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

namespace lockstep {

// Joint types a body can hang on. Fixed joints exist only in the builder:
// they are fused into the parent body and survive as frames.
enum class JointType : std::uint8_t { Free, Spherical, Revolute, Prismatic, Fixed };

const char* joint_type_name(JointType type);
int joint_nq(JointType type);   // configuration size: Free 7, Spherical 4, 1-DOF 1, Fixed 0
int joint_nv(JointType type);   // velocity size:      Free 6, Spherical 3, 1-DOF 1, Fixed 0

enum class ShapeType : std::uint8_t { Sphere, Box, Cylinder, Capsule, Mesh };
const char* shape_type_name(ShapeType type);

// A collision shape attached to a body. Cylinders and capsules are along the
// shape frame's z axis (URDF convention).
struct Shape {
  ShapeType type = ShapeType::Sphere;
  int body = -1;                    // -1: the static world
  int frame = -1;                   // the URDF link it was declared on
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // in the body frame
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // sphere (r,0,0); box half extents; cylinder/capsule (r, half length, 0)
  std::string mesh_path;            // Mesh, or a Box fitted to the mesh file by the URDF importer
  Eigen::Vector3d mesh_scale = Eigen::Vector3d::Ones();
};

// A mimic tag: q[dof] = multiplier * q[leader_dof] + offset. The
// simulation step holds it with a solver row (Stage::MimicJoints,
// docs/conventions.md "Mimic joints"); the dynamics queries ignore it.
struct Mimic {
  int dof = -1;
  int leader_dof = -1;
  double multiplier = 1.0;
  double offset = 0.0;
};

// A fixed tendon (PhysX's fixed tendon): its length is a weighted sum of
// joint positions, l = sum_i c_i q_i over revolute and prismatic joints. A
// spring-damper pulls l towards rest_length + offset, and its limits keep l
// within [lower_limit, upper_limit]: hard one-sided rows with
// limit_stiffness 0, springs of that stiffness past them otherwise. The
// simulation step holds it with solver rows (Stage::FixedTendons,
// docs/conventions.md "Fixed tendons"); the dynamics queries ignore it.
struct TendonJoint {
  int dof = -1;
  double coefficient = 1.0;  // c_i: length per unit of the joint's position (m/rad, or m/m)
};

struct FixedTendon {
  std::string name;
  std::vector<TendonJoint> joints;
  double stiffness = 0.0;  // force per unit length past rest_length + offset (0: no spring)
  double damping = 0.0;    // force per unit of the length's rate (0: no damper)
  double rest_length = 0.0;
  double offset = 0.0;     // added to rest_length: PhysX's offset, the tendon's actuation
  double lower_limit = -std::numeric_limits<double>::infinity();
  double upper_limit = std::numeric_limits<double>::infinity();
  double limit_stiffness = 0.0;  // 0: hard limits; > 0: a spring of this stiffness past a limit

  bool has_spring() const { return stiffness > 0 || damping > 0; }
  bool has_limits() const { return std::isfinite(lower_limit) || std::isfinite(upper_limit); }
};

struct Articulation {
  std::string name;
  bool floating_base = false;
  int first_body = 0;   // bodies [first_body, first_body + body_count)
  int body_count = 0;
  int root_frame = -1;  // the frame of the root link
};

// Field names follow `object_property`; the shape of each array is given.
// Body frames are joint frames: a Revolute or Prismatic joint moves along the
// body frame's z axis (the importer rotates frames to make it so).
struct Model {
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();

  int nbody = 0;  // moving bodies (the world is body -1)
  int nq = 0;     // configuration size
  int nv = 0;     // velocity size = number of DOFs
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};

  // bodies (nbody), parent-first: body_parent[i] < i
  std::vector<int> body_parent;                   // -1: the world
  std::vector<JointType> body_joint;              // the inbound joint (never Fixed)
  std::vector<Eigen::Isometry3d> body_placement;  // joint frame in the parent body frame at q = 0
  std::vector<int> body_q_offset;                 // first entry of the joint in q
  std::vector<int> body_dof_offset;               // first entry of the joint in v (low-level DOF index)
  std::vector<int> body_articulation;
  std::vector<int> body_frame;                    // the frame (URDF link) the body is named after
  std::vector<double> body_mass;                  // kg, fused fixed children included
  std::vector<Eigen::Vector3d> body_com;          // centre of mass in the body frame
  std::vector<Eigen::Matrix3d> body_inertia;      // rotational inertia about the COM, body axes
  std::vector<std::string> joint_name;            // the inbound joint's name
  // 1: gravity acts on the body (the default); 0: it is switched off for the
  // body and every link fused into it (LinkSpec::gravity)
  std::vector<std::uint8_t> body_gravity;
  // LinkSpec::linear_damping and angular_damping of the body's own link [1/s]
  std::vector<double> body_linear_damping, body_angular_damping;

  // dofs (nv), low-level order
  std::vector<std::string> dof_name;   // joint name, or joint name + [k] for multi-DOF joints
  std::vector<int> dof_body;
  std::vector<int> dof_parent;         // previous DOF on the path to the root, -1 at a root
  std::vector<double> dof_lower;       // position limits (-inf/+inf when unlimited)
  std::vector<double> dof_upper;
  std::vector<double> dof_velocity_limit;  // +inf when none
  std::vector<double> dof_effort_limit;    // +inf when none
  std::vector<double> dof_damping;
  std::vector<double> dof_friction;
  std::vector<double> dof_armature;
  std::vector<double> dof_spring_stiffness;  // joint spring (RaiSim's URDF <dynamics stiffness>), 0 when none
  std::vector<double> dof_spring_rest;       // its rest position (<dynamics spring_mount>)

  // frames: every link the user declared, in low-level order
  std::vector<std::string> frame_name;
  std::vector<int> frame_body;                    // -1: fixed to the world
  std::vector<Eigen::Isometry3d> frame_placement; // link frame in the body frame
  std::vector<int> frame_parent;                  // parent link's frame, -1 for a root
  std::vector<std::string> frame_joint_name;      // the URDF joint above the link ("" for a root)
  std::vector<JointType> frame_joint_type;        // Fixed when the link was fused
  std::vector<Eigen::Vector3d> frame_joint_axis;  // axis as declared, in the link frame
  std::vector<int> frame_articulation;
  std::vector<double> frame_mass;                 // the link's own mass as written (its body's mass lumps fused links)

  std::vector<Shape> shapes;
  std::vector<Mimic> mimics;
  std::vector<FixedTendon> fixed_tendons;
  std::vector<Articulation> articulations;

  // Name lookups; each throws std::out_of_range naming the missing name.
  int frame_index(const std::string& name) const;
  int joint_index(const std::string& name) const;  // == body index of a moving joint
  int dof_index(const std::string& name) const;
  int articulation_index(const std::string& name) const;

  // The first mimic tag DOF `dof` follows, or null.
  const Mimic* mimic_of(int dof) const;

  double total_mass() const;
  // The links gravity is switched off on: each such body's own link (the
  // one it is named after), in body order.
  std::vector<std::string> links_without_gravity() const;
  // How many bodies have linear or angular damping.
  int damped_bodies() const;
  // q at the zero configuration: identity quaternions, zero elsewhere.
  Eigen::VectorXd neutral_configuration() const;

  std::unordered_map<std::string, int> frame_by_name;
  std::unordered_map<std::string, int> joint_by_name;
  std::unordered_map<std::string, int> dof_by_name;
};

}  // namespace lockstep
