#include "batch/contact_settings.hpp"

#include "batch/require.hpp"
#include "layout/model.hpp"
#include "layout/rotation.hpp"

#include <cmath>
#include <stdexcept>

namespace lockstep {

namespace {

std::string number(double x) { return std::to_string(x); }

void check_surface(const ShapeContact& c, const std::string& where) {
  require(std::isfinite(c.friction) && c.friction >= 0,
          where + ": friction must be finite and >= 0, got " + number(c.friction));
  require(c.restitution >= 0 && c.restitution <= 1,
          where + ": restitution must lie in [0, 1], got " + number(c.restitution));
}

}  // namespace

void validate_contact_settings(const Model& model, const ContactSettings& s) {
  const std::string at = "ContactSettings::";
  require(s.capacity >= 1 && s.capacity <= kMaxContactCapacity,
          at + "capacity must lie in [1, " + std::to_string(kMaxContactCapacity) + "] points per copy, got " +
              std::to_string(s.capacity));
  require(std::isfinite(s.margin) && s.margin >= 0, at + "margin must be finite and >= 0, got " + number(s.margin));
  require(std::isfinite(s.speculative_speed) && s.speculative_speed >= 0,
          at + "speculative_speed must be finite and >= 0, got " + number(s.speculative_speed));
  require(std::isfinite(s.stiffness) && s.stiffness >= 0,
          at + "stiffness must be finite and >= 0 (0: rigid), got " + number(s.stiffness));
  require(std::isfinite(s.damping) && s.damping >= 0, at + "damping must be finite and >= 0, got " + number(s.damping));
  require(std::isfinite(s.max_depenetration_speed) && s.max_depenetration_speed > 0,
          at + "max_depenetration_speed must be finite and > 0, got " + number(s.max_depenetration_speed));
  require(std::isfinite(s.bounce_threshold) && s.bounce_threshold >= 0,
          at + "bounce_threshold must be finite and >= 0, got " + number(s.bounce_threshold));
  require(std::isfinite(s.torsional_friction) && s.torsional_friction >= 0,
          at + "torsional_friction must be finite and >= 0, got " + number(s.torsional_friction));
  require(std::isfinite(s.ground_height), at + "ground_height must be finite");
  require(s.ground_normal.allFinite() && s.ground_normal.norm() > 1e-9,
          at + "ground_normal must be a finite non-zero vector");
  check_surface(s.ground_contact, at + "ground_contact");
  require(s.shapes.empty() || s.shapes.size() == model.shapes.size(),
          at + "shapes has " + std::to_string(s.shapes.size()) + " entries for a model with " +
              std::to_string(model.shapes.size()) + " shapes (give one per shape, or none)");
  for (std::size_t i = 0; i < s.shapes.size(); ++i)
    check_surface(s.shapes[i], at + "shapes[" + std::to_string(i) + "] (link " +
                                   model.frame_name[model.shapes[i].frame] + ")");
  for (std::size_t i = 0; i < s.boxes.size(); ++i) {
    const StaticBox& box = s.boxes[i];
    const std::string where = at + "boxes[" + std::to_string(i) + "]";
    require(box.half_extents.allFinite() && (box.half_extents.array() > 0).all(),
            where + ": half_extents must be finite and positive");
    require(box.pose.matrix().allFinite(), where + ": pose must be finite");
    require(is_rotation(box.pose.linear()), where + ": pose's rotation is not a rotation matrix (orthonormal, det +1)");
    check_surface(box.contact, where);
  }
  require(s.self_collision.size() <= model.articulations.size(),
          at + "self_collision has " + std::to_string(s.self_collision.size()) + " entries for a model with " +
              std::to_string(model.articulations.size()) + " articulations");
}

}  // namespace lockstep
