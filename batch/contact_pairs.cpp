#include "batch/contact_pairs.hpp"

#include "batch/copy_dynamics.hpp"
#include "kernels/collision.hpp"
#include "kernels/contact_rows.hpp"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <set>
#include <stdexcept>

namespace lockstep {

const char* pair_kind_name(PairKind kind) {
  switch (kind) {
    case PairKind::PlaneSphere: return "plane-sphere";
    case PairKind::PlaneCapsule: return "plane-capsule";
    case PairKind::PlaneBox: return "plane-box";
    case PairKind::PlaneCylinder: return "plane-cylinder";
    case PairKind::SphereSphere: return "sphere-sphere";
    case PairKind::SphereCapsule: return "sphere-capsule";
    case PairKind::SphereBox: return "sphere-box";
    case PairKind::CapsuleCapsule: return "capsule-capsule";
    case PairKind::CapsuleBox: return "capsule-box";
    case PairKind::BoxBox: return "box-box";
  }
  return "unknown";
}

int pair_candidates(PairKind kind) {
  switch (kind) {
    case PairKind::PlaneSphere: return kPlaneSphereCandidates;
    case PairKind::PlaneCapsule: return kPlaneCapsuleCandidates;
    case PairKind::PlaneBox: return kPlaneBoxCandidates;
    case PairKind::PlaneCylinder: return kPlaneCylinderCandidates;
    case PairKind::SphereSphere: return kSphereSphereCandidates;
    case PairKind::SphereCapsule: return kSphereCapsuleCandidates;
    case PairKind::SphereBox: return kSphereBoxCandidates;
    case PairKind::CapsuleCapsule: return kCapsuleCapsuleCandidates;
    case PairKind::CapsuleBox: return kCapsuleBoxCandidates;
    case PairKind::BoxBox: return kBoxBoxCandidates;
  }
  return 0;
}

std::string describe_shape(const Model& model, int shape) {
  if (shape == kGroundShape) return "ground";
  if (shape < kGroundShape) return "static box " + std::to_string(-2 - shape);
  const Shape& s = model.shapes[shape];
  return model.frame_name[s.frame] + " (" + shape_type_name(s.type) + ", shape " + std::to_string(shape) + ")";
}

namespace {

// Shape classes in pair order; cylinders are capsules except against the plane.
enum class ShapeClass { Plane, Sphere, Capsule, Box };

ShapeClass shape_class(ShapeType type) {
  switch (type) {
    case ShapeType::Sphere: return ShapeClass::Sphere;
    case ShapeType::Capsule:
    case ShapeType::Cylinder: return ShapeClass::Capsule;
    default: return ShapeClass::Box;
  }
}

double bound_radius(ShapeType type, const Eigen::Vector3d& size) {
  switch (type) {
    case ShapeType::Sphere: return size.x();
    case ShapeType::Capsule:
    case ShapeType::Cylinder: return size.x() + size.y();
    default: return size.norm();
  }
}

PairKind kind_of(ShapeClass a, ShapeClass b, bool cylinder_b) {
  if (a == ShapeClass::Plane) {
    if (b == ShapeClass::Sphere) return PairKind::PlaneSphere;
    if (b == ShapeClass::Capsule) return cylinder_b ? PairKind::PlaneCylinder : PairKind::PlaneCapsule;
    return PairKind::PlaneBox;
  }
  if (a == ShapeClass::Sphere) {
    if (b == ShapeClass::Sphere) return PairKind::SphereSphere;
    return b == ShapeClass::Capsule ? PairKind::SphereCapsule : PairKind::SphereBox;
  }
  if (a == ShapeClass::Capsule) return b == ShapeClass::Capsule ? PairKind::CapsuleCapsule : PairKind::CapsuleBox;
  return PairKind::BoxBox;
}

double average(double x, double y) { return 0.5 * (x + y); }

bool layers_meet(const ShapeContact& a, const ShapeContact& b) {
  return (a.layers & b.collides_with) != 0 && (b.layers & a.collides_with) != 0;
}

// A shape as a pair side, with its class and contact properties.
struct Side {
  PairSide side;
  ShapeClass cls;
  bool cylinder = false;
  ShapeContact contact;
  int articulation = -1;  // -1: the ground or a static box
  int frame = -1;
};

// Filters between shapes of one articulation (docs/contacts.md): bodies that
// are the same, adjacent, or joined only through bodies without shapes.
class ArticulationFilter {
 public:
  explicit ArticulationFilter(const Model& model) : model_(model), body_has_shape_(model.nbody, false) {
    for (const Shape& s : model.shapes)
      if (s.body >= 0 && s.type != ShapeType::Mesh) body_has_shape_[s.body] = true;
    for (const Shape& s : model.shapes)
      if (s.body < 0 && s.type != ShapeType::Mesh) world_has_shape_.insert(model.frame_articulation[s.frame]);
  }

  // True when bodies a and b (-1: the world) of articulation `art` are
  // joined by a path whose inner bodies all lack shapes.
  bool joined_without_shapes(int a, int b, int art) const {
    std::vector<int> path_a = path_to_world(a), path_b = path_to_world(b);
    // strip the common part above the lowest common ancestor
    int lca = -1;
    while (!path_a.empty() && !path_b.empty() && path_a.back() == path_b.back()) {
      lca = path_a.back();
      path_a.pop_back();
      path_b.pop_back();
    }
    // inner bodies: the remaining paths without their ends a and b, plus the LCA if it is neither
    auto shapeless = [&](int body) {
      return body >= 0 ? !body_has_shape_[body] : world_has_shape_.count(art) == 0;
    };
    for (const std::vector<int>* path : {&path_a, &path_b})
      for (std::size_t i = 1; i < path->size(); ++i)
        if (!shapeless((*path)[i])) return false;
    if (lca != a && lca != b && !shapeless(lca)) return false;
    return true;
  }

 private:
  // body, its parent, ..., the root body, -1 (the world)
  std::vector<int> path_to_world(int body) const {
    std::vector<int> path;
    for (int j = body; j >= 0; j = model_.body_parent[j]) path.push_back(j);
    path.push_back(-1);
    return path;
  }

  const Model& model_;
  std::vector<bool> body_has_shape_;
  std::set<int> world_has_shape_;
};

// "38 mm", "0.4 mm": a length for messages.
std::string millimetres(double metres) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2g mm", metres * 1e3);
  return text;
}

// The pair of two shapes, in the narrowphase's order (the lower class
// first), without its surface properties. A cylinder against another shape
// is the capsule inside it: the segment shortened by the radius at each
// end, so that no cap reaches past the cylinder's ends (a capsule as long
// as the cylinder stuck out by its radius: anymal_b's shank capsules, 5 mm
// below its feet, carried it on a box where the ground's exact cylinders
// let its feet do). A disc (half length below the radius) is its sphere.
ContactPair ordered_pair(const Side& a0, const Side& b0) {
  const bool swap = static_cast<int>(b0.cls) < static_cast<int>(a0.cls);
  const Side& a = swap ? b0 : a0;
  const Side& b = swap ? a0 : b0;
  ContactPair pair{kind_of(a.cls, b.cls, b.cylinder), a.side, b.side};
  if (pair.kind != PairKind::PlaneCylinder)
    for (auto [side, cylinder] : {std::pair{&pair.a, a.cylinder}, std::pair{&pair.b, b.cylinder}})
      if (cylinder) side->size.y() = std::max(side->size.y() - side->size.x(), 0.0);
  return pair;
}

// The least separation the narrowphase finds between two moving shapes
// with their bodies at the given world poses (double, one lane).
double separation_at(const Side& a0, const Side& b0, const std::vector<Eigen::Isometry3d>& body_pose) {
  const ContactPair pair = ordered_pair(a0, b0);
  ContactPairSpec<double> spec;
  spec.kind = pair.kind;
  for (int i = 0; i < 3; ++i) spec.size_a[i] = pair.a.size[i], spec.size_b[i] = pair.b.size[i];
  auto world = [&](const PairSide& side) {
    double flat[12];
    flatten_transform(side.body < 0 ? side.pose : body_pose[side.body] * side.pose, flat);
    return broadcast_transform<double>(flat);
  };
  const Transform<double> A = world(pair.a), B = world(pair.b);
  std::vector<ContactCandidate<double>> points(pair_candidates(spec.kind));
  contact_detail::collide<double>(spec, {0.0, 0.0, 1.0}, 0.0, A, B, points.data());
  double least = std::numeric_limits<double>::infinity();
  for (const ContactCandidate<double>& point : points) least = std::min(least, point.separation);
  return least;
}

}  // namespace

ContactPairs build_contact_pairs(const Model& model, const ContactSettings& settings) {
  ContactPairs out;
  std::vector<Side> sides;
  for (int i = 0; i < static_cast<int>(model.shapes.size()); ++i) {
    const Shape& s = model.shapes[i];
    if (s.type == ShapeType::Mesh) {
      out.notes.push_back(describe_shape(model, i) + ": mesh '" + s.mesh_path +
                          "' takes no part in contacts (give the link a primitive collision shape)");
      continue;
    }
    Side side;
    side.side = {i, s.body, s.pose, s.size, bound_radius(s.type, s.size)};
    side.cls = shape_class(s.type);
    side.cylinder = s.type == ShapeType::Cylinder;
    side.contact = settings.shapes.empty() ? ShapeContact{} : settings.shapes[i];
    side.articulation = model.frame_articulation[s.frame];
    side.frame = s.frame;
    sides.push_back(side);
  }
  for (int i = 0; i < static_cast<int>(settings.boxes.size()); ++i) {
    const StaticBox& box = settings.boxes[i];
    Side side;
    side.side = {static_box_shape(i), -1, box.pose, box.half_extents, box.half_extents.norm()};
    side.cls = ShapeClass::Box;
    side.contact = box.contact;
    sides.push_back(side);
  }

  std::set<std::pair<int, int>> enabled, disabled;  // frame pairs, smaller first
  auto frame_pairs = [&](const std::vector<std::pair<std::string, std::string>>& names, const char* field,
                         std::set<std::pair<int, int>>& into) {
    for (const auto& [x, y] : names) {
      int fx, fy;
      try {
        fx = model.frame_index(x);
        fy = model.frame_index(y);
      } catch (const std::out_of_range& e) {
        throw std::invalid_argument(std::string("ContactSettings::") + field + " (\"" + x + "\", \"" + y +
                                    "\"): " + e.what());
      }
      into.insert(std::minmax(fx, fy));
      // the name cannot lift the first filter below: say so, not nothing
      if (&into == &enabled && model.frame_body[fx] == model.frame_body[fy])
        out.notes.push_back(std::string("enabled pair (\"") + x + "\", \"" + y + "\"): " +
                            (model.frame_body[fx] < 0 ? "both static" : "one body (links fused by fixed joints)") +
                            ", and such shapes never touch");
    }
  };
  frame_pairs(settings.enabled_pairs, "enabled_pairs", enabled);
  frame_pairs(settings.disabled_pairs, "disabled_pairs", disabled);

  const ArticulationFilter filter(model);
  std::vector<Eigen::Isometry3d> body_pose;  // at the neutral configuration, once a self pair needs them
  auto self_collides = [&](int art) {
    return art < static_cast<int>(settings.self_collision.size()) && settings.self_collision[art];
  };
  auto add = [&](const Side& a0, const Side& b0, double friction, double restitution) {
    ContactPair pair = ordered_pair(a0, b0);
    pair.friction = friction;
    pair.restitution = restitution;
    pair.first_candidate = out.candidates;
    out.candidates += pair_candidates(pair.kind);
    out.candidate_pair.resize(out.candidates, static_cast<int>(out.pairs.size()));
    out.pairs.push_back(pair);
  };

  // the ground first: feet and bodies on the floor are the common case
  if (settings.ground)
    for (const Side& s : sides)
      if (s.side.body >= 0 && layers_meet(settings.ground_contact, s.contact)) {
        Side plane;
        plane.cls = ShapeClass::Plane;
        add(plane, s, s.contact.friction, average(s.contact.restitution, settings.ground_contact.restitution));
      }
  for (std::size_t i = 0; i < sides.size(); ++i)
    for (std::size_t j = i + 1; j < sides.size(); ++j) {
      const Side& a = sides[i];
      const Side& b = sides[j];
      if (a.side.body < 0 && b.side.body < 0) continue;  // static against static
      if (a.side.body == b.side.body) continue;          // one rigid body (fused links included)
      bool touch = layers_meet(a.contact, b.contact);
      if (touch && a.articulation >= 0 && a.articulation == b.articulation)
        touch = self_collides(a.articulation) &&
                !filter.joined_without_shapes(a.side.body, b.side.body, a.articulation);
      const std::pair<int, int> key = std::minmax(a.frame, b.frame);
      const bool named = a.frame >= 0 && b.frame >= 0 && (enabled.count(key) || disabled.count(key));
      if (named) touch = enabled.count(key) && !disabled.count(key);
      // Links of one robot whose shapes overlap in its neutral pose (a
      // thigh's box inside the base's) cannot be pushed apart by any
      // motion of the joints: left out unless named (MoveIt's "default"
      // collisions), or they would push each other with forces without
      // bound.
      if (touch && !named && a.articulation >= 0 && a.articulation == b.articulation) {
        if (body_pose.empty()) body_pose = CopyDynamics(model, Precision::Double).body_poses(model.neutral_configuration());
        const double overlap = -separation_at(a, b, body_pose);
        if (overlap > 0) {
          touch = false;
          out.notes.push_back("self-collision: " + describe_shape(model, a.side.shape) + " and " +
                              describe_shape(model, b.side.shape) + " overlap by " + millimetres(overlap) +
                              " in the neutral pose, so they are left out (name them in enabled_pairs to keep them)");
        }
      }
      if (touch)
        add(a, b, average(a.contact.friction, b.contact.friction),
            average(a.contact.restitution, b.contact.restitution));
    }
  return out;
}

}  // namespace lockstep
