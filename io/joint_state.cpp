#include "io/joint_state.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "layout/name_hint.hpp"

namespace lockstep {

namespace {

constexpr double kQuaternionNormTolerance = 1e-3;

// Which part of the state a key belongs to.
enum class Part { Q, Qd, Tau };

const char* part_name(Part part) {
  switch (part) {
    case Part::Q: return "q";
    case Part::Qd: return "qd";
    case Part::Tau: return "tau";
  }
  return "?";
}

// The layout of an array entry, for error messages.
const char* entry_layout(JointType type, Part part) {
  if (type == JointType::Free) return part == Part::Q ? " [x,y,z,qw,qx,qy,qz]" : part == Part::Qd ? " [vx,vy,vz,wx,wy,wz] (body frame)" : " [fx,fy,fz,tx,ty,tz]";
  if (type == JointType::Spherical) return part == Part::Q ? " [qw,qx,qy,qz]" : part == Part::Qd ? " [wx,wy,wz] (body frame)" : " [tx,ty,tz]";
  return "";
}

// The body whose inbound joint is `name`; throws naming the key otherwise.
int joint_body(const Model& model, const std::string& name, const std::string& where) {
  const auto it = model.joint_by_name.find(name);
  if (it != model.joint_by_name.end()) return it->second;
  for (std::size_t f = 0; f < model.frame_joint_name.size(); ++f)
    if (model.frame_joint_name[f] == name)
      throw StateError(where + ": joint \"" + name + "\" is fixed and has no coordinates");
  for (const Articulation& a : model.articulations)
    if (!a.floating_base && name == a.name + "_root")
      throw StateError(where + ": unknown joint " + json::quote(name) + ": the model is fixed-base; its floating base " +
                       "(this name) exists with --floating-base (in a scene file: \"floating_base\": true)");
  // quoted as JSON: a key with control characters (a NUL ended the message)
  throw StateError(where + ": unknown joint " + json::quote(name) + did_you_mean(name, model.joint_name) +
                   " (run `lockstep info` to list the joints)");
}

// A value the arithmetic of `precision` holds: finite, and within float's
// range for float (a double such as 1e39 is finite but not a float).
double checked_number(double x, const std::string& where, Precision precision) {
  if (!std::isfinite(x)) throw StateError(where + ": value is not finite");
  if (precision == Precision::Float && std::abs(x) > std::numeric_limits<float>::max())
    throw StateError(where + " = " + json::number(x) + " is beyond float's range");
  return x;
}

// Reads one entry into out[offset, offset + size).
void read_entry(const json::Value& value, const std::string& where, JointType type, Part part, int size,
                Precision precision, Eigen::VectorXd& out, int offset) {
  if (size == 1) {
    if (!value.is_number())
      throw StateError(where + ": expected a number, got " + json::type_name(value.type));
    out[offset] = checked_number(value.number, where, precision);
    return;
  }
  const std::string expected = "expected an array of " + std::to_string(size) + " numbers" + entry_layout(type, part);
  if (!value.is_array()) throw StateError(where + ": " + expected + ", got " + json::type_name(value.type));
  if (static_cast<int>(value.array.size()) != size)
    throw StateError(where + ": " + expected + ", got " + std::to_string(value.array.size()) + " entries");
  for (int k = 0; k < size; ++k) {
    const json::Value& item = value.array[k];
    const std::string item_where = where + "[" + std::to_string(k) + "]";
    if (!item.is_number()) throw StateError(item_where + ": expected a number, got " + json::type_name(item.type));
    out[offset + k] = checked_number(item.number, item_where, precision);
  }
  // Quaternions (w, x, y, z): Free q[3..7), Spherical q[0..4).
  if (part == Part::Q && (type == JointType::Free || type == JointType::Spherical)) {
    const int first = offset + (type == JointType::Free ? 3 : 0);
    const double norm = out.segment<4>(first).norm();
    // the message's norm without the squares' overflow (1e200 read as
    // inf, written null) or underflow (1e-200 read as 0)
    if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance))
      throw StateError(where + ": the quaternion (qw,qx,qy,qz) has norm " +
                       json::number(out.segment<4>(first).stableNorm()) + "; it must be 1 within " +
                       json::number(kQuaternionNormTolerance));
    // A quaternion already unit to rounding is kept as written, so reading
    // what was written after a first normalisation gives the same bits.
    if (std::abs(norm - 1.0) > 4 * std::numeric_limits<double>::epsilon()) out.segment<4>(first) /= norm;
  }
}

// `entries`, an object keyed by joint name, into out's layout for `part`;
// a key's errors are named `where.joint`.
void read_entries(const Model& model, const json::Value& entries, const std::string& where, Part part,
                  Precision precision, Eigen::VectorXd& out) {
  if (!entries.is_object())
    throw StateError(where + ": expected an object keyed by joint name, got " + json::type_name(entries.type));
  for (const auto& [name, value] : entries.object) {
    const bool plain = std::none_of(name.begin(), name.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; });
    const std::string at = where + "." + (plain ? name : json::quote(name));
    const int body = joint_body(model, name, at);
    const JointType type = model.body_joint[body];
    if (part == Part::Q) read_entry(value, at, type, part, joint_nq(type), precision, out, model.body_q_offset[body]);
    else read_entry(value, at, type, part, joint_nv(type), precision, out, model.body_dof_offset[body]);
  }
}

}  // namespace

Eigen::VectorXd read_configuration(const Model& model, const json::Value& entries, const std::string& where) {
  Eigen::VectorXd q = model.neutral_configuration();
  read_entries(model, entries, where, Part::Q, Precision::Double, q);
  return q;
}

Eigen::VectorXd read_velocity(const Model& model, const json::Value& entries, const std::string& where) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
  read_entries(model, entries, where, Part::Qd, Precision::Double, v);
  return v;
}

JointState read_state(const Model& model, const json::Value& root, const std::string& source, Precision precision) {
  JointState state;
  state.q = model.neutral_configuration();
  state.v = Eigen::VectorXd::Zero(model.nv);
  state.tau = Eigen::VectorXd::Zero(model.nv);
  if (!root.is_object())
    throw StateError(source + ": expected an object with \"q\", \"qd\" and \"tau\", got " + json::type_name(root.type));
  for (const auto& [key, entries] : root.object) {
    Part part;
    if (key == "q") part = Part::Q;
    else if (key == "qd") part = Part::Qd;
    else if (key == "tau") part = Part::Tau;
    else
      throw StateError(source + ": unknown key \"" + key + "\"" + did_you_mean(key, {"q", "qd", "tau"}) +
                       " (expected \"q\", \"qd\" or \"tau\")");
    Eigen::VectorXd& out = part == Part::Q ? state.q : part == Part::Qd ? state.v : state.tau;
    read_entries(model, entries, source + ": " + part_name(part), part, precision, out);
  }
  return state;
}

}  // namespace lockstep
