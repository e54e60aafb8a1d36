// Contacts of a scene: which shapes touch which (the ground plane, static
// boxes, the model's shapes and the filters between them) and how contacts
// behave (friction, restitution, compliance). Part of StepOptions; the
// defaults make a rigid, inelastic, frictional contact with friction 1 and
// no ground. Stage::Contacts forced Off turns contacts off entirely.
// docs/contacts.md has the model and the numbers.
#pragma once

#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace lockstep {

struct Model;

// Contact properties of one shape. A contact's friction and restitution are
// the averages of its two surfaces' (PhysX's default combine mode).
struct ShapeContact {
  double friction = 1.0;     // Coulomb coefficient mu
  double restitution = 0.0;  // normal speed kept after an impact, 0..1
  // Bitmask layers: two shapes may touch when each one's layers meet the
  // other's collides_with.
  std::uint32_t layers = 1;
  std::uint32_t collides_with = 0xffffffffu;
};

// A box fixed in the world (a step, a wall, an obstacle), in every copy.
struct StaticBox {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  Eigen::Vector3d half_extents = Eigen::Vector3d::Constant(0.5);
  ShapeContact contact;
};

// The most contact points a copy keeps per step. Each worker's scratch
// holds a block of lanes' rows for that many points, and the contacts'
// dense Delassus block grows with its square: anymal_b standing with 64
// copies took 5 MiB more at 16 points, 327 MiB at 256, 4.7 GiB at 1024.
constexpr int kMaxContactCapacity = 256;

struct ContactSettings {
  // An infinite plane through (0, 0, ground_height) with unit normal
  // ground_normal; height, normal and friction may differ per copy
  // (Simulator::set_ground).
  bool ground = false;
  double ground_height = 0.0;
  Eigen::Vector3d ground_normal = Eigen::Vector3d::UnitZ();
  ShapeContact ground_contact;
  std::vector<StaticBox> boxes;

  // One entry per model shape (Model::shapes), or empty for the defaults.
  std::vector<ShapeContact> shapes;
  // Contacts between links of one articulation, per articulation (empty:
  // off for all). Adjacent links and links joined through shapeless links
  // never touch unless enabled by name; links fused by fixed joints (one
  // body) never touch at all.
  std::vector<bool> self_collision;
  // Link (URDF frame) name pairs, symmetric, overriding every filter above:
  // enabled pairs touch (unless both static or on one body: a note says
  // so), disabled pairs never do.
  std::vector<std::pair<std::string, std::string>> enabled_pairs, disabled_pairs;

  int capacity = 16;      // contact points kept per copy per step (at most kMaxContactCapacity); more are dropped and counted
  // Contacts exist below the separation margin + speculative_speed * h (h
  // the pipeline run's step, dt / substeps)
  // (plus the distance the bodies' free motion can close within the step):
  // speculative rows, which act only once the gap closes. The speed term
  // catches what the solve itself sets moving (a box pushed by a finger
  // into a wall), so a longer run looks further.
  double margin = 0.001;            // m
  double speculative_speed = 0.5;   // m/s
  // Compliance: a spring-damper normal force k (penetration) + c (approach
  // speed), integrated implicitly (backward Euler: it damps as c + k h
  // would, docs/contacts.md). stiffness 0: rigid, with the step's
  // error_reduction removing penetration.
  double stiffness = 0.0;  // N/m
  double damping = 0.0;    // N s/m, used only with stiffness > 0
  double bounce_threshold = 0.2;   // m/s: slower impacts do not bounce
  // m/s: a rigid contact's penetration is pushed out no faster than this
  // (PhysX's maxDepenetrationVelocity), so a body started deep inside
  // another separates instead of flying off; bounces and compliant
  // contacts (their spring sets the force) are not capped.
  double max_depenetration_speed = 1.0;
  double torsional_friction = 0.0; // m: torque about the normal up to this times the normal force (0: none)
};

// Throws std::invalid_argument naming the field (and shape, box or link).
void validate_contact_settings(const Model& model, const ContactSettings& settings);

// The ground through (0, 0, height) with normal `normal` (non-zero, any
// length) as the plane n . x = d the contact kernels read: [n (unit); d].
inline Eigen::Vector4d ground_plane(const Eigen::Vector3d& normal, double height) {
  const Eigen::Vector3d n = normal.normalized();
  return Eigen::Vector4d(n.x(), n.y(), n.z(), n.z() * height);
}

}  // namespace lockstep
