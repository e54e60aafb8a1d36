#include "io/scene_file.hpp"

#include "batch/contact_pairs.hpp"
#include "batch/copy_dynamics.hpp"
#include "io/joint_state.hpp"
#include "io/json.hpp"
#include "io/urdf_import.hpp"
#include "layout/name_hint.hpp"
#include "layout/rotation.hpp"

#include <algorithm>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <set>
#include <sstream>
#include <tuple>
#include <utility>

namespace lockstep {

namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------
// The format's names for enumerations.

template <class E>
struct Token {
  const char* name;
  E value;
};

constexpr Token<SolverType> kSolvers[] = {{"pgs", SolverType::PGS}, {"tgs", SolverType::TGS}};
constexpr Token<Integrator> kIntegrators[] = {{"semi_implicit_euler", Integrator::SemiImplicitEuler},
                                              {"trapezoid", Integrator::Trapezoid},
                                              {"rk4", Integrator::RK4},
                                              {"explicit_euler", Integrator::ExplicitEuler}};
constexpr Token<Precision> kPrecisions[] = {{"float", Precision::Float}, {"double", Precision::Double}};
constexpr Token<Lanes> kLanes[] = {{"simd", Lanes::Simd}, {"scalar", Lanes::Scalar}};
constexpr Token<DriveType> kDriveTypes[] = {{"force", DriveType::Force}, {"acceleration", DriveType::Acceleration}};
constexpr Token<ActionMode> kActionModes[] = {{"torque", ActionMode::Torque},
                                              {"position_target", ActionMode::PositionTarget},
                                              {"actuator_torque", ActionMode::ActuatorTorque}};

template <class E, std::size_t N>
const char* token_name(const Token<E> (&tokens)[N], E value) {
  for (const Token<E>& t : tokens)
    if (t.value == value) return t.name;
  return "?";
}

// Seeds below 2^53 are written and read as numbers, larger ones as decimal
// strings. A double holds 2^53 exactly, but 2^53 + 1 too reads as 2^53, so
// a number from 2^53 on may not be the seed that was written.
constexpr std::uint64_t kLargestNumberSeed = (std::uint64_t{1} << 53) - 1;

// A ground normal this close to unit length is kept as written, so that a
// written scene reads back bit for bit (normalising twice can move an ulp).
constexpr double kUnitNormalTolerance = 1e-12;

// ---------------------------------------------------------------------------
// Reading.

// Where a value sits, for error messages: the file and the key path.
struct At {
  std::string file;
  std::string path;

  At key(const std::string& name) const { return {file, path.empty() ? name : path + "." + name}; }
  At index(std::size_t i) const { return {file, path + "[" + std::to_string(i) + "]"}; }
  [[noreturn]] void fail(const std::string& what) const {
    throw SceneError(file + ": " + (path.empty() ? "" : path + ": ") + what);
  }
};

void expect_type(const json::Value& v, json::Value::Type type, const At& at, const std::string& expected) {
  if (v.type != type) at.fail("expected " + expected + ", got " + json::type_name(v.type));
}

// An object whose keys must all be among `keys`.
class Object {
 public:
  Object(const json::Value& value, At at, const std::vector<std::string>& keys) : value_(value), at_(std::move(at)) {
    expect_type(value, json::Value::Type::Object, at_, "an object");
    for (const auto& member : value.object)
      if (std::find(keys.begin(), keys.end(), member.first) == keys.end()) {
        std::string known;
        for (const std::string& k : keys) known += (known.empty() ? "" : ", ") + k;
        at_.key(member.first)
            .fail("unknown key" + did_you_mean(member.first, keys) + " (expected one of: " + known + ")");
      }
  }

  const json::Value* find(const std::string& key) const { return value_.find(key); }
  At at(const std::string& key) const { return at_.key(key); }
  const At& at() const { return at_; }

  // Calls read(value, at) with the member `key` when it is present.
  template <class Read>
  void with(const std::string& key, Read&& read) const {
    if (const json::Value* v = find(key)) read(*v, at(key));
  }

 private:
  const json::Value& value_;
  At at_;
};

enum class Bound { Any, NonNegative, Positive, UnitInterval };

double read_number(const json::Value& v, const At& at, Bound bound = Bound::Any) {
  expect_type(v, json::Value::Type::Number, at, "a number");
  const double x = v.number;
  if (!std::isfinite(x)) at.fail("value is not finite");
  if (bound == Bound::NonNegative && !(x >= 0)) at.fail("must be >= 0, got " + json::number(x));
  if (bound == Bound::Positive && !(x > 0)) at.fail("must be > 0, got " + json::number(x));
  if (bound == Bound::UnitInterval && !(x >= 0 && x <= 1)) at.fail("must lie in [0, 1], got " + json::number(x));
  return x;
}

// An integral number in [low, high].
double read_integer(const json::Value& v, const At& at, double low, double high) {
  const double x = read_number(v, at);
  if (x != std::floor(x)) at.fail("expected an integer, got " + json::number(x));
  if (x < low || x > high)
    at.fail("must lie in [" + json::number(low) + ", " + json::number(high) + "], got " + json::number(x));
  return x;
}

bool read_bool(const json::Value& v, const At& at) {
  expect_type(v, json::Value::Type::Bool, at, "true or false");
  return v.boolean;
}

const std::string& read_string(const json::Value& v, const At& at) {
  expect_type(v, json::Value::Type::String, at, "a string");
  return v.string;
}

template <class E, std::size_t N>
E read_token(const json::Value& v, const At& at, const Token<E> (&tokens)[N]) {
  const std::string& name = read_string(v, at);
  std::string known;
  std::vector<std::string> names;
  for (const Token<E>& t : tokens) {
    if (name == t.name) return t.value;
    known += std::string(known.empty() ? "" : ", ") + "\"" + t.name + "\"";
    names.emplace_back(t.name);
  }
  at.fail("unknown value \"" + name + "\"" + did_you_mean(name, names) + " (expected one of: " + known + ")");
}

// An array of `size` finite numbers.
Eigen::VectorXd read_numbers(const json::Value& v, const At& at, int size, Bound bound = Bound::Any) {
  const std::string expected = "an array of " + std::to_string(size) + " numbers";
  expect_type(v, json::Value::Type::Array, at, expected);
  if (static_cast<int>(v.array.size()) != size)
    at.fail("expected " + expected + ", got " + std::to_string(v.array.size()) + " entries");
  Eigen::VectorXd out(size);
  for (int k = 0; k < size; ++k) out[k] = read_number(v.array[k], at.index(k), bound);
  return out;
}

Eigen::Vector3d read_vector3(const json::Value& v, const At& at, Bound bound = Bound::Any) {
  return read_numbers(v, at, 3, bound);
}

// The setters below overwrite `out` only when `key` is present.
void set_number(const Object& o, const std::string& key, double& out, Bound bound = Bound::Any) {
  o.with(key, [&](const json::Value& v, const At& at) { out = read_number(v, at, bound); });
}

void set_int(const Object& o, const std::string& key, int& out, int low, int high = INT_MAX) {
  o.with(key, [&](const json::Value& v, const At& at) { out = static_cast<int>(read_integer(v, at, low, high)); });
}

void set_bool(const Object& o, const std::string& key, bool& out) {
  o.with(key, [&](const json::Value& v, const At& at) { out = read_bool(v, at); });
}

template <class E, std::size_t N>
void set_token(const Object& o, const std::string& key, E& out, const Token<E> (&tokens)[N]) {
  o.with(key, [&](const json::Value& v, const At& at) { out = read_token(v, at, tokens); });
}

// ---- the model

// Loads the URDF; every failure is a SceneError naming the URDF.
Scene bare_scene(const std::string& urdf_path, bool floating_base) {
  Scene scene;
  scene.source = urdf_path;
  scene.model_path = urdf_path;
  scene.floating_base = floating_base;
  UrdfOptions options;
  options.floating_base = floating_base;
  try {
    scene.model = load_urdf(urdf_path, options, {}, &scene.warnings);
  } catch (const std::exception& e) {
    const std::string what = e.what();
    throw SceneError(what.find(urdf_path) == std::string::npos ? urdf_path + ": " + what : what);
  }
  scene.env.dofs = default_dof_settings(scene.model);
  return scene;
}

bool is_floating_root(const Model& model, int body) { return model.body_joint[body] == JointType::Free; }

// The body of a moving, non-root joint named `name`; fails naming it otherwise.
int actuated_joint(const Model& model, const std::string& name, const At& at) {
  const auto it = model.joint_by_name.find(name);
  if (it != model.joint_by_name.end()) {
    if (is_floating_root(model, it->second))
      at.fail("joint \"" + name + "\" is the floating base: it takes no drive or joint dynamics");
    return it->second;
  }
  if (std::find(model.frame_joint_name.begin(), model.frame_joint_name.end(), name) != model.frame_joint_name.end())
    at.fail("joint \"" + name + "\" is fixed and has no DOF");
  at.fail("unknown joint \"" + name + "\"" + did_you_mean(name, model.joint_name) +
          " (run `lockstep info` to list the joints)");
}

// ---- drives and joint dynamics: a "default" entry for every DOF that is not
// a floating root's, then "joints" overriding by URDF joint name (all DOFs
// of a joint together).

struct DriveEntry {
  std::optional<double> kp, kd, max_force;
  std::optional<DriveType> type;

  static DriveEntry read(const json::Value& v, const At& at) {
    const Object o(v, at, {"kp", "kd", "max_force", "type"});
    DriveEntry e;
    o.with("kp", [&](const json::Value& x, const At& a) { e.kp = read_number(x, a, Bound::NonNegative); });
    o.with("kd", [&](const json::Value& x, const At& a) { e.kd = read_number(x, a, Bound::NonNegative); });
    // null: no effort limit
    o.with("max_force", [&](const json::Value& x, const At& a) {
      e.max_force = x.type == json::Value::Type::Null ? Model::kInfinity : read_number(x, a, Bound::Positive);
    });
    o.with("type", [&](const json::Value& x, const At& a) { e.type = read_token(x, a, kDriveTypes); });
    return e;
  }

  void apply(DofSettings& d) const {
    if (kp) d.drive_stiffness = *kp;
    if (kd) d.drive_damping = *kd;
    if (max_force) d.max_force = *max_force;
    if (type) d.drive_type = *type;
  }
};

struct DynamicsEntry {
  std::optional<double> damping, friction;

  static DynamicsEntry read(const json::Value& v, const At& at) {
    const Object o(v, at, {"damping", "friction"});
    DynamicsEntry e;
    o.with("damping", [&](const json::Value& x, const At& a) { e.damping = read_number(x, a, Bound::NonNegative); });
    o.with("friction", [&](const json::Value& x, const At& a) { e.friction = read_number(x, a, Bound::NonNegative); });
    return e;
  }

  void apply(DofSettings& d) const {
    if (damping) d.damping = *damping;
    if (friction) d.friction = *friction;
  }
};

template <class Entry>
void read_per_joint(const json::Value& v, const At& at, const Model& model, std::vector<DofSettings>& dofs) {
  const Object o(v, at, {"default", "joints"});
  o.with("default", [&](const json::Value& x, const At& a) {
    const Entry entry = Entry::read(x, a);
    for (int k = 0; k < model.nv; ++k)
      if (!is_floating_root(model, model.dof_body[k])) entry.apply(dofs[k]);
  });
  o.with("joints", [&](const json::Value& x, const At& a) {
    expect_type(x, json::Value::Type::Object, a, "an object keyed by joint name");
    for (const auto& [name, entry_value] : x.object) {
      const int body = actuated_joint(model, name, a.key(name));
      const Entry entry = Entry::read(entry_value, a.key(name));
      for (int k = 0; k < joint_nv(model.body_joint[body]); ++k) entry.apply(dofs[model.body_dof_offset[body] + k]);
    }
  });
}

// A warning for each revolute or prismatic joint the object `named` (keyed
// by joint name) sets to a position outside the joint's limits in q: a value
// in degrees where radians are meant, say. The step would clamp it at once.
void warn_outside_limits(const Model& model, const json::Value& named, const Eigen::VectorXd& q, const At& at,
                         std::vector<std::string>& warnings) {
  for (const auto& [name, value] : named.object) {
    const int body = model.joint_by_name.at(name);  // read_configuration checked the names
    const JointType type = model.body_joint[body];
    if (type != JointType::Revolute && type != JointType::Prismatic) continue;
    const int k = model.body_dof_offset[body];
    const double x = q[model.body_q_offset[body]];
    if (x >= model.dof_lower[k] && x <= model.dof_upper[k]) continue;
    warnings.push_back(at.file + ": " + at.key(name).path + ": " + json::number(x) + " lies outside the joint's limits [" +
                       json::number(model.dof_lower[k]) + ", " + json::number(model.dof_upper[k]) + "] " +
                       (type == JointType::Revolute ? "(radians)" : "(metres)"));
  }
}

// ---- the initial state: read_state's format, without "tau"

void read_initial_state(const json::Value& v, const At& at, const Model& model, VecEnvOptions& env,
                        std::vector<std::string>& warnings) {
  const Object keys(v, at, {"q", "qd"});
  const json::Value* q = v.find("q");
  const json::Value* qd = v.find("qd");
  // Errors name the key path as every other scene error: initial_state.q.FL_knee.
  const auto where = [&](const char* key) { return at.file + ": " + at.key(key).path; };
  try {
    env.initial_q = q ? read_configuration(model, *q, where("q")) : model.neutral_configuration();
    env.initial_v = qd ? read_velocity(model, *qd, where("qd")) : Eigen::VectorXd::Zero(model.nv);
  } catch (const StateError& e) {
    throw SceneError(e.what());
  }
  if (q) warn_outside_limits(model, *q, env.initial_q, at.key("q"), warnings);
}

// Drive targets: joint-name keyed like initial_state's "q".
void read_drive_targets(const json::Value& v, const At& at, const Model& model, VecEnvOptions& env,
                        std::vector<std::string>& warnings) {
  try {
    env.drive_target_q = read_configuration(model, v, at.file + ": " + at.path);
  } catch (const StateError& e) {
    throw SceneError(e.what());
  }
  warn_outside_limits(model, v, env.drive_target_q, at, warnings);
}

// ---- contacts

const std::vector<std::string> kSurfaceKeys = {"friction", "restitution", "layers", "collides_with"};

std::vector<std::string> with_surface_keys(std::vector<std::string> keys) {
  keys.insert(keys.end(), kSurfaceKeys.begin(), kSurfaceKeys.end());
  return keys;
}

void set_mask(const Object& o, const std::string& key, std::uint32_t& out) {
  o.with(key, [&](const json::Value& v, const At& at) {
    out = static_cast<std::uint32_t>(read_integer(v, at, 0, 4294967295.0));
  });
}

// Overwrites the surface properties `o` gives.
void read_surface(const Object& o, ShapeContact& c) {
  set_number(o, "friction", c.friction, Bound::NonNegative);
  set_number(o, "restitution", c.restitution, Bound::UnitInterval);
  set_mask(o, "layers", c.layers);
  set_mask(o, "collides_with", c.collides_with);
}

void read_ground(const json::Value& v, const At& at, ContactSettings& c) {
  const Object o(v, at, with_surface_keys({"height", "normal"}));
  c.ground = true;
  set_number(o, "height", c.ground_height);
  o.with("normal", [&](const json::Value& x, const At& a) {
    const Eigen::Vector3d n = read_vector3(x, a);
    const double norm = n.norm();
    if (!(norm > 1e-9)) a.fail("the normal must not be zero");
    c.ground_normal = std::abs(norm - 1.0) <= kUnitNormalTolerance ? n : Eigen::Vector3d(n / norm);
  });
  read_surface(o, c.ground_contact);
}

// URDF's convention: R = Rz(yaw) Ry(pitch) Rx(roll).
Eigen::Matrix3d rotation_from_rpy(const Eigen::Vector3d& rpy) {
  return (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

// Three rows of three numbers forming a proper rotation (kept as written).
Eigen::Matrix3d read_rotation(const json::Value& v, const At& at) {
  expect_type(v, json::Value::Type::Array, at, "an array of 3 rows of 3 numbers");
  if (v.array.size() != 3) at.fail("expected 3 rows of 3 numbers, got " + std::to_string(v.array.size()) + " rows");
  Eigen::Matrix3d r;
  for (int i = 0; i < 3; ++i) r.row(i) = read_vector3(v.array[i], at.index(i)).transpose();
  if (!is_rotation(r)) at.fail("not a rotation matrix (orthonormal, determinant +1)");
  return r;
}

StaticBox read_box(const json::Value& v, const At& at) {
  const Object o(v, at, with_surface_keys({"size", "position", "rpy", "rotation"}));
  StaticBox box;
  o.with("size", [&](const json::Value& x, const At& a) {
    box.half_extents = 0.5 * read_vector3(x, a, Bound::Positive);
  });
  o.with("position", [&](const json::Value& x, const At& a) { box.pose.translation() = read_vector3(x, a); });
  if (o.find("rpy") && o.find("rotation")) o.at("rotation").fail("give \"rpy\" or \"rotation\", not both");
  o.with("rpy", [&](const json::Value& x, const At& a) { box.pose.linear() = rotation_from_rpy(read_vector3(x, a)); });
  o.with("rotation", [&](const json::Value& x, const At& a) { box.pose.linear() = read_rotation(x, a); });
  read_surface(o, box.contact);
  return box;
}

void read_boxes(const json::Value& v, const At& at, ContactSettings& c) {
  expect_type(v, json::Value::Type::Array, at, "an array of boxes");
  for (std::size_t i = 0; i < v.array.size(); ++i) c.boxes.push_back(read_box(v.array[i], at.index(i)));
}

int link_frame(const Model& model, const std::string& name, const At& at) {
  const auto it = model.frame_by_name.find(name);
  if (it == model.frame_by_name.end()) at.fail("unknown link \"" + name + "\"" + did_you_mean(name, model.frame_name));
  return it->second;
}

// The moving body named after link `name`, for a setting (`what`, such as
// "gravity") that is made per moving body: a link fused into another body
// or fixed to the world is refused.
int moving_body(const Model& model, const std::string& name, const At& at, const std::string& what) {
  const int body = model.frame_body[link_frame(model, name, at)];
  if (body < 0) at.fail("link \"" + name + "\" is fixed to the world: its " + what + " moves nothing");
  const std::string& head = model.frame_name[model.body_frame[body]];
  if (head != name)
    at.fail("link \"" + name + "\" is fixed to link \"" + head + "\" and moves with it as one body; name \"" + head +
            "\" (" + what + " is set per moving body)");
  return body;
}

// "links_without_gravity": links whose moving body gravity does not act on
// (Model::body_gravity).
void read_links_without_gravity(const json::Value& v, const At& at, Model& model) {
  expect_type(v, json::Value::Type::Array, at, "an array of link names");
  std::set<int> listed;
  for (std::size_t i = 0; i < v.array.size(); ++i) {
    const At item = at.index(i);
    const std::string& name = read_string(v.array[i], item);
    const int body = moving_body(model, name, item, "gravity");
    if (!listed.insert(body).second) item.fail("link \"" + name + "\" is listed twice");
    model.body_gravity[body] = 0;  // the URDF's own switch may have it off already
  }
}

// "link_damping": {"linear": c, "angular": c} for every moving body, then
// "links": {"link": {"linear": c, "angular": c}} for single bodies, each
// named after its own link (Model::body_linear_damping, [1/s]); a value
// left out stays as it was.
void read_link_damping(const json::Value& v, const At& at, Model& model) {
  const Object o(v, at, {"linear", "angular", "links"});
  auto read_pair = [&](const Object& values, auto&& set) {
    values.with("linear", [&](const json::Value& x, const At& a) {
      set(model.body_linear_damping, read_number(x, a, Bound::NonNegative));
    });
    values.with("angular", [&](const json::Value& x, const At& a) {
      set(model.body_angular_damping, read_number(x, a, Bound::NonNegative));
    });
  };
  read_pair(o, [](std::vector<double>& per_body, double c) { std::fill(per_body.begin(), per_body.end(), c); });
  o.with("links", [&](const json::Value& links, const At& links_at) {
    expect_type(links, json::Value::Type::Object, links_at, "an object keyed by link name");
    for (const auto& [name, entry] : links.object) {
      const At entry_at = links_at.key(name);
      const Object values(entry, entry_at, {"linear", "angular"});
      const int body = moving_body(model, name, entry_at, "link damping");
      read_pair(values, [body](std::vector<double>& per_body, double c) { per_body[body] = c; });
    }
  });
}

// The member `key` of o, which must be there.
const json::Value& required_member(const Object& o, const char* key) {
  const json::Value* value = o.find(key);
  if (!value) o.at().fail(std::string("missing key \"") + key + "\"");
  return *value;
}

// A DOF named as `lockstep info` lists them ("knee", "ball[1]").
int named_dof(const Model& model, const std::string& name, const At& at) {
  const auto it = model.dof_by_name.find(name);
  if (it == model.dof_by_name.end())
    at.fail("unknown joint \"" + name + "\"" + did_you_mean(name, model.dof_name) +
            " (run `lockstep info` to list the joints)");
  return it->second;
}

// The same, not a floating base's.
int actuated_dof(const Model& model, const std::string& name, const At& at) {
  const int dof = named_dof(model, name, at);
  if (model.body_joint[model.dof_body[dof]] == JointType::Free)
    at.fail("joint \"" + name + "\" is the floating base: it takes no actuator");
  return dof;
}

// "fixed_tendons": Model::fixed_tendons, in order; each names its joints
// with their coefficients, "limits" being [lower, upper] with null for no
// limit on that side.
void read_fixed_tendons(const json::Value& v, const At& at, Model& model) {
  expect_type(v, json::Value::Type::Array, at, "an array of fixed tendons");
  for (std::size_t i = 0; i < v.array.size(); ++i) {
    const Object o(v.array[i], at.index(i),
                   {"name", "joints", "stiffness", "damping", "rest_length", "offset", "limits", "limit_stiffness"});
    FixedTendon t;
    t.name = read_string(required_member(o, "name"), o.at("name"));
    if (t.name.empty()) o.at("name").fail("must not be empty");
    for (const FixedTendon& other : model.fixed_tendons)
      if (other.name == t.name) o.at("name").fail("\"" + t.name + "\" names another fixed tendon");
    const json::Value& joints = required_member(o, "joints");
    expect_type(joints, json::Value::Type::Object, o.at("joints"), "an object of coefficients keyed by joint name");
    if (joints.object.empty()) o.at("joints").fail("must name at least one joint");
    for (const auto& [name, coefficient] : joints.object) {
      const At joint_at = o.at("joints").key(name);
      const int dof = named_dof(model, name, joint_at);
      const JointType type = model.body_joint[model.dof_body[dof]];
      if (type != JointType::Revolute && type != JointType::Prismatic)
        joint_at.fail("\"" + name + "\" is a DOF of a " + joint_type_name(type) +
                      " joint: a tendon spans revolute and prismatic joints");
      const double c = read_number(coefficient, joint_at);
      if (c == 0.0) joint_at.fail("the coefficient must not be zero");
      t.joints.push_back({dof, c});
    }
    o.with("stiffness",
           [&](const json::Value& x, const At& k) { t.stiffness = read_number(x, k, Bound::NonNegative); });
    o.with("damping", [&](const json::Value& x, const At& k) { t.damping = read_number(x, k, Bound::NonNegative); });
    o.with("rest_length", [&](const json::Value& x, const At& k) { t.rest_length = read_number(x, k); });
    o.with("offset", [&](const json::Value& x, const At& k) { t.offset = read_number(x, k); });
    o.with("limit_stiffness",
           [&](const json::Value& x, const At& k) { t.limit_stiffness = read_number(x, k, Bound::NonNegative); });
    o.with("limits", [&](const json::Value& x, const At& k) {
      expect_type(x, json::Value::Type::Array, k, "[lower, upper], null for no limit");
      if (x.array.size() != 2) k.fail("expected 2 values, got " + std::to_string(x.array.size()));
      auto side = [&](std::size_t j, double none) {
        return x.array[j].type == json::Value::Type::Null ? none : read_number(x.array[j], k.index(j));
      };
      t.lower_limit = side(0, -Model::kInfinity);
      t.upper_limit = side(1, Model::kInfinity);
      if (t.lower_limit > t.upper_limit) k.fail("the lower limit lies above the upper");
    });
    model.fixed_tendons.push_back(std::move(t));
  }
}

// "actuators": motors behind gearboxes (batch/actuators.hpp), in order.
void read_actuators(const json::Value& v, const At& at, const Model& model, std::vector<Actuator>& actuators) {
  expect_type(v, json::Value::Type::Array, at, "an array of actuators");
  for (std::size_t i = 0; i < v.array.size(); ++i) {
    const Object o(v.array[i], at.index(i),
                   {"name", "joint", "gear", "couplings", "torque_constant", "bus_voltage", "resistance",
                    "velocity_constant", "peak_torque", "enforce_operating_region"});
    Actuator a;
    a.name = read_string(required_member(o, "name"), o.at("name"));
    if (a.name.empty()) o.at("name").fail("must not be empty");
    for (const Actuator& other : actuators)
      if (other.name == a.name) o.at("name").fail("\"" + a.name + "\" names another actuator");
    a.dof = actuated_dof(model, read_string(required_member(o, "joint"), o.at("joint")), o.at("joint"));
    o.with("gear", [&](const json::Value& x, const At& k) { a.gear = read_number(x, k, Bound::Positive); });
    o.with("couplings", [&](const json::Value& x, const At& k) {
      expect_type(x, json::Value::Type::Object, k, "an object of ratios keyed by joint name");
      for (const auto& [name, ratio] : x.object) {
        const int dof = actuated_dof(model, name, k.key(name));
        if (dof == a.dof) k.key(name).fail("the driven joint itself");
        a.couplings.emplace_back(dof, read_number(ratio, k.key(name)));
      }
    });
    a.torque_constant = read_number(required_member(o, "torque_constant"), o.at("torque_constant"), Bound::Positive);
    a.bus_voltage = read_number(required_member(o, "bus_voltage"), o.at("bus_voltage"), Bound::Positive);
    a.resistance = read_number(required_member(o, "resistance"), o.at("resistance"), Bound::Positive);
    a.velocity_constant =
        read_number(required_member(o, "velocity_constant"), o.at("velocity_constant"), Bound::Positive);
    // null: no peak torque
    o.with("peak_torque", [&](const json::Value& x, const At& k) {
      a.peak_torque = x.type == json::Value::Type::Null ? Model::kInfinity : read_number(x, k, Bound::Positive);
    });
    o.with("enforce_operating_region",
           [&](const json::Value& x, const At& k) { a.enforce_operating_region = read_bool(x, k); });
    actuators.push_back(std::move(a));
  }
}

// "links": surface properties of every shape declared on a URDF link.
void read_link_surfaces(const json::Value& v, const At& at, const Model& model, ContactSettings& c) {
  expect_type(v, json::Value::Type::Object, at, "an object keyed by link name");
  if (c.shapes.empty()) c.shapes.resize(model.shapes.size());
  for (const auto& [name, entry] : v.object) {
    const At entry_at = at.key(name);
    const int frame = link_frame(model, name, entry_at);
    const Object o(entry, entry_at, kSurfaceKeys);
    bool found = false;
    for (std::size_t s = 0; s < model.shapes.size(); ++s)
      if (model.shapes[s].frame == frame) {
        read_surface(o, c.shapes[s]);
        found = true;
      }
    if (!found) entry_at.fail("link \"" + name + "\" has no collision shapes");
  }
}

// [["link_a", "link_b"], ...]
std::vector<std::pair<std::string, std::string>> read_link_pairs(const json::Value& v, const At& at,
                                                                 const Model& model) {
  expect_type(v, json::Value::Type::Array, at, "an array of [link, link] pairs");
  std::vector<std::pair<std::string, std::string>> pairs;
  for (std::size_t i = 0; i < v.array.size(); ++i) {
    const json::Value& pair = v.array[i];
    const At pair_at = at.index(i);
    expect_type(pair, json::Value::Type::Array, pair_at, "a pair of link names");
    if (pair.array.size() != 2) pair_at.fail("expected 2 link names, got " + std::to_string(pair.array.size()));
    for (std::size_t k = 0; k < 2; ++k)
      link_frame(model, read_string(pair.array[k], pair_at.index(k)), pair_at.index(k));
    pairs.emplace_back(pair.array[0].string, pair.array[1].string);
  }
  return pairs;
}

void read_contacts(const json::Value& v, const At& at, const Model& model, StepOptions& step) {
  const Object o(v, at,
                 {"enabled", "self_collision", "capacity", "margin", "speculative_speed", "stiffness", "damping", "bounce_threshold",
                  "max_depenetration_speed", "torsional_friction", "links", "enabled_pairs", "disabled_pairs"});
  ContactSettings& c = step.contacts;
  o.with("enabled", [&](const json::Value& x, const At& a) {
    if (!read_bool(x, a)) step.force(Stage::Contacts, StageMode::Off);
  });
  o.with("self_collision", [&](const json::Value& x, const At& a) {
    c.self_collision.assign(read_bool(x, a) ? model.articulations.size() : 0, true);
  });
  set_int(o, "capacity", c.capacity, 1, kMaxContactCapacity);
  set_number(o, "margin", c.margin, Bound::NonNegative);
  set_number(o, "speculative_speed", c.speculative_speed, Bound::NonNegative);
  set_number(o, "stiffness", c.stiffness, Bound::NonNegative);
  set_number(o, "damping", c.damping, Bound::NonNegative);
  set_number(o, "bounce_threshold", c.bounce_threshold, Bound::NonNegative);
  set_number(o, "max_depenetration_speed", c.max_depenetration_speed, Bound::Positive);
  set_number(o, "torsional_friction", c.torsional_friction, Bound::NonNegative);
  o.with("links", [&](const json::Value& x, const At& a) { read_link_surfaces(x, a, model, c); });
  o.with("enabled_pairs", [&](const json::Value& x, const At& a) { c.enabled_pairs = read_link_pairs(x, a, model); });
  o.with("disabled_pairs", [&](const json::Value& x, const At& a) { c.disabled_pairs = read_link_pairs(x, a, model); });
}

// ---- step, environment, randomisation

void read_step(const json::Value& v, const At& at, StepOptions& s) {
  const Object o(v, at,
                 {"dt", "substeps", "solver", "iterations", "integrator", "precision", "lanes", "error_reduction",
                  "warm_start", "implicit_gyroscopic", "conserve_linear_momentum", "reset_on_fault",
                  "record_applied_torque", "record_motion"});
  set_number(o, "dt", s.dt, Bound::Positive);
  set_int(o, "substeps", s.substeps, 1);
  set_token(o, "solver", s.solver, kSolvers);
  set_int(o, "iterations", s.iterations, 1);
  set_token(o, "integrator", s.integrator, kIntegrators);
  set_token(o, "precision", s.precision, kPrecisions);
  set_token(o, "lanes", s.lanes, kLanes);
  set_number(o, "error_reduction", s.error_reduction, Bound::UnitInterval);
  set_number(o, "warm_start", s.warm_start, Bound::UnitInterval);
  set_bool(o, "implicit_gyroscopic", s.implicit_gyroscopic);
  set_bool(o, "conserve_linear_momentum", s.conserve_linear_momentum);
  set_bool(o, "reset_on_fault", s.reset_on_fault);
  set_bool(o, "record_applied_torque", s.record_applied_torque);
  set_bool(o, "record_motion", s.record_motion);
}

// A number below 2^53, or a string of decimal digits for any 64-bit seed.
std::uint64_t read_seed(const json::Value& v, const At& at) {
  if (v.type != json::Value::Type::String) {
    const double x = read_number(v, at);
    if (x > static_cast<double>(kLargestNumberSeed))
      at.fail("a seed from 2^53 on must be a decimal string (\"9007199254740993\"): as a number it may have been "
              "rounded, got " + json::number(x));
    return static_cast<std::uint64_t>(read_integer(v, at, 0, static_cast<double>(kLargestNumberSeed)));
  }
  const std::string& s = v.string;
  std::uint64_t seed = 0;
  const auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), seed);
  if (s.empty() || error != std::errc() || end != s.data() + s.size())
    at.fail("expected an integer in [0, 2^64) as a number or a decimal string, got \"" + s + "\"");
  return seed;
}

void read_env(const json::Value& v, const At& at, VecEnvOptions& env) {
  const Object o(v, at, {"action_mode", "control_steps", "episode_steps", "auto_reset", "seed"});
  set_token(o, "action_mode", env.action_mode, kActionModes);
  set_int(o, "control_steps", env.control_steps, 1);
  set_int(o, "episode_steps", env.episode_steps, 0);
  set_bool(o, "auto_reset", env.auto_reset);
  o.with("seed", [&](const json::Value& x, const At& a) { env.seed = read_seed(x, a); });
}

std::vector<std::string> randomization_names() {
  std::vector<std::string> names;
  for (const RandomizationField& f : randomization_fields()) names.emplace_back(f.name);
  return names;
}

void read_randomization(const json::Value& v, const At& at, Randomization& r) {
  const Object o(v, at, randomization_names());
  for (const RandomizationField& f : randomization_fields())
    o.with(f.name, [&](const json::Value& x, const At& a) {
      const Eigen::VectorXd pair = read_numbers(x, a, 2);
      r.*f.range = {pair[0], pair[1]};
    });
  r.randomize_ground_friction = o.find("ground_friction") != nullptr;
}

// ---- the whole file

const std::vector<std::string> kTopKeys = {
    "model",    "floating_base", "gravity",  "links_without_gravity", "link_damping",   "fixed_tendons", "initial_state",
    "drive_targets", "ground",   "boxes",    "contacts",              "drives",         "joint_dynamics", "actuators",
    "step",     "env",           "randomization"};

// The model path: relative paths from the scene file's folder.
std::string resolve_model_path(const std::string& scene_path, const Object& root) {
  const json::Value* model = root.find("model");
  if (!model) root.at().fail("\"model\" is missing (the URDF path, relative to this file's folder)");
  const fs::path path = read_string(*model, root.at("model"));
  if (path.empty()) root.at("model").fail("the path is empty");
  return (path.is_absolute() ? path : fs::path(scene_path).parent_path() / path).lexically_normal().string();
}

// Wraps the library's own checks (std::invalid_argument) as scene errors.
template <class Check>
void check(const std::string& file, Check&& run) {
  try {
    run();
  } catch (const std::invalid_argument& e) {
    throw SceneError(file + ": " + e.what());
  }
}

// How far a shape with world pose P reaches from its origin against the
// unit direction n: its support along -n.
double depth_along(const Shape& s, const Eigen::Isometry3d& P, const Eigen::Vector3d& n) {
  const Eigen::Vector3d a = P.linear().transpose() * n;  // n in the shape's axes
  switch (s.type) {
    case ShapeType::Sphere: return s.size.x();
    case ShapeType::Capsule: return std::abs(a.z()) * s.size.y() + s.size.x();
    case ShapeType::Cylinder:  // the rim's lowest point: the axis's end, then the radius across
      return std::abs(a.z()) * s.size.y() + s.size.x() * std::sqrt(std::max(0.0, 1.0 - a.z() * a.z()));
    case ShapeType::Box: return a.cwiseAbs().dot(s.size);
    case ShapeType::Mesh: break;  // collides with nothing (a mesh whose file was found became a Box)
  }
  return 0.0;
}

// The lowest point along the plane normal n of the shapes on moving bodies
// at q: its height n . x - offset and its shape; nullopt without shapes.
std::optional<std::pair<double, int>> lowest_shape(const Model& model, const Eigen::VectorXd& q,
                                                   const Eigen::Vector3d& n, double offset) {
  const std::vector<Eigen::Isometry3d> bodies = CopyDynamics(model).body_poses(q);
  std::optional<std::pair<double, int>> lowest;
  for (int i = 0; i < static_cast<int>(model.shapes.size()); ++i) {
    const Shape& s = model.shapes[i];
    if (s.body < 0 || s.type == ShapeType::Mesh) continue;
    const Eigen::Isometry3d P = bodies[s.body] * s.pose;
    const double height = n.dot(P.translation()) - offset - depth_along(s, P, n);
    if (!lowest || height < lowest->first) lowest = std::make_pair(height, i);
  }
  return lowest;
}

Scene read_scene_file(const std::string& path, bool floating_base, bool ground) {
  json::Value root_value;
  try {
    root_value = json::parse_file(path);
  } catch (const json::ParseError& e) {
    throw SceneError(e.what());
  }
  const Object root(root_value, At{path, ""}, kTopKeys);
  const std::string model_path = resolve_model_path(path, root);
  root.with("floating_base", [&](const json::Value& v, const At& at) { floating_base |= read_bool(v, at); });
  Scene scene;
  try {
    scene = bare_scene(model_path, floating_base);
  } catch (const SceneError& e) {
    root.at("model").fail(e.what());
  }
  scene.source = path;
  Model& model = scene.model;
  VecEnvOptions& env = scene.env;
  root.with("gravity", [&](const json::Value& v, const At& at) { model.gravity = read_vector3(v, at); });
  root.with("links_without_gravity",
            [&](const json::Value& v, const At& at) { read_links_without_gravity(v, at, model); });
  root.with("link_damping", [&](const json::Value& v, const At& at) { read_link_damping(v, at, model); });
  root.with("fixed_tendons", [&](const json::Value& v, const At& at) { read_fixed_tendons(v, at, model); });
  root.with("initial_state",
            [&](const json::Value& v, const At& at) { read_initial_state(v, at, model, env, scene.value_warnings); });
  root.with("drive_targets",
            [&](const json::Value& v, const At& at) { read_drive_targets(v, at, model, env, scene.value_warnings); });
  root.with("ground", [&](const json::Value& v, const At& at) { read_ground(v, at, env.step.contacts); });
  env.step.contacts.ground |= ground;
  root.with("boxes", [&](const json::Value& v, const At& at) { read_boxes(v, at, env.step.contacts); });
  root.with("contacts", [&](const json::Value& v, const At& at) { read_contacts(v, at, model, env.step); });
  root.with("drives", [&](const json::Value& v, const At& at) { read_per_joint<DriveEntry>(v, at, model, env.dofs); });
  root.with("joint_dynamics",
            [&](const json::Value& v, const At& at) { read_per_joint<DynamicsEntry>(v, at, model, env.dofs); });
  root.with("actuators",
            [&](const json::Value& v, const At& at) { read_actuators(v, at, model, env.step.actuators); });
  root.with("step", [&](const json::Value& v, const At& at) { read_step(v, at, env.step); });
  root.with("env", [&](const json::Value& v, const At& at) { read_env(v, at, env); });
  root.with("randomization", [&](const json::Value& v, const At& at) { read_randomization(v, at, env.randomization); });
  if (env.randomization.randomize_ground_friction && !env.step.contacts.ground)
    root.at("randomization").key("ground_friction").fail("the scene has no ground");
  check(path, [&] { validate_contact_settings(model, env.step.contacts); });
  check(path, [&] { validate_randomization(env.randomization); });
  check(path, [&] { validate_actuators(model, env.step.actuators, env.step.precision); });
  return scene;
}

// ---------------------------------------------------------------------------
// Writing: a json::Value tree, printed with short values on one line.

using Member = std::pair<std::string, json::Value>;

json::Value number_value(double x) {
  json::Value v;
  v.type = json::Value::Type::Number;
  v.number = x;
  return v;
}

json::Value bool_value(bool b) {
  json::Value v;
  v.type = json::Value::Type::Bool;
  v.boolean = b;
  return v;
}

json::Value string_value(std::string s) {
  json::Value v;
  v.type = json::Value::Type::String;
  v.string = std::move(s);
  return v;
}

json::Value array_value(std::vector<json::Value> items) {
  json::Value v;
  v.type = json::Value::Type::Array;
  v.array = std::move(items);
  return v;
}

json::Value object_value(std::vector<Member> members) {
  json::Value v;
  v.type = json::Value::Type::Object;
  v.object = std::move(members);
  return v;
}

json::Value numbers_value(const Eigen::Ref<const Eigen::VectorXd>& x) {
  std::vector<json::Value> items;
  for (Eigen::Index k = 0; k < x.size(); ++k) items.push_back(number_value(x[k]));
  return array_value(std::move(items));
}

// One value on one line.
std::string inline_text(const json::Value& v) {
  switch (v.type) {
    case json::Value::Type::Null: return "null";
    case json::Value::Type::Bool: return v.boolean ? "true" : "false";
    case json::Value::Type::Number: return json::number(v.number);
    case json::Value::Type::String: return json::quote(v.string);
    case json::Value::Type::Array: {
      std::string out = "[";
      for (std::size_t i = 0; i < v.array.size(); ++i) out += (i ? ", " : "") + inline_text(v.array[i]);
      return out + "]";
    }
    case json::Value::Type::Object: {
      std::string out = "{";
      for (std::size_t i = 0; i < v.object.size(); ++i)
        out += (i ? ", " : "") + json::quote(v.object[i].first) + ": " + inline_text(v.object[i].second);
      return out + "}";
    }
  }
  return "null";
}

constexpr std::size_t kLineWidth = 100;

// Arrays and objects that fit on the line after `indent` stay on it; others
// get a line per item.
void write_value(const json::Value& v, std::size_t indent, std::string& out) {
  const std::string line = inline_text(v);
  const bool container = v.is_array() || v.is_object();
  if (!container || indent + line.size() <= kLineWidth) {
    out += line;
    return;
  }
  const std::string pad(indent + 2, ' ');
  const std::size_t count = v.is_array() ? v.array.size() : v.object.size();
  out += v.is_array() ? "[\n" : "{\n";
  for (std::size_t i = 0; i < count; ++i) {
    out += pad;
    if (v.is_object()) out += json::quote(v.object[i].first) + ": ";
    write_value(v.is_array() ? v.array[i] : v.object[i].second, indent + 2, out);
    out += i + 1 < count ? ",\n" : "\n";
  }
  out += std::string(indent, ' ') + (v.is_array() ? "]" : "}");
}

[[noreturn]] void inexpressible(const std::string& what) {
  throw std::invalid_argument("scene_to_json: " + what + " cannot be written in a scene file");
}

// A joint's value in the initial state: a number for 1-DOF joints, else an array.
json::Value joint_entry(const Eigen::VectorXd& x, int offset, int size) {
  return size == 1 ? number_value(x[offset]) : numbers_value(x.segment(offset, size));
}

// Every joint's entry of a configuration (nq).
json::Value configuration_value(const Model& model, const Eigen::VectorXd& q) {
  std::vector<Member> joints;
  for (int b = 0; b < model.nbody; ++b)
    joints.emplace_back(model.joint_name[b], joint_entry(q, model.body_q_offset[b], joint_nq(model.body_joint[b])));
  return object_value(std::move(joints));
}

// Every joint's entry; an empty initial_q or initial_v is the neutral
// configuration or rest.
json::Value initial_state_value(const Model& model, const VecEnvOptions& env) {
  const Eigen::VectorXd q0 = env.initial_q.size() > 0 ? env.initial_q : model.neutral_configuration();
  const Eigen::VectorXd v0 = env.initial_v.size() > 0 ? env.initial_v : Eigen::VectorXd::Zero(model.nv);
  if (q0.size() != model.nq || v0.size() != model.nv)
    inexpressible("an initial state of " + std::to_string(q0.size()) + " + " + std::to_string(v0.size()) +
                  " values for a model with nq " + std::to_string(model.nq) + " and nv " + std::to_string(model.nv));
  std::vector<Member> qd;
  for (int b = 0; b < model.nbody; ++b)
    qd.emplace_back(model.joint_name[b], joint_entry(v0, model.body_dof_offset[b], joint_nv(model.body_joint[b])));
  return object_value({{"q", configuration_value(model, q0)}, {"qd", object_value(std::move(qd))}});
}

std::vector<Member> surface_members(const ShapeContact& c) {
  return {{"friction", number_value(c.friction)},
          {"restitution", number_value(c.restitution)},
          {"layers", number_value(c.layers)},
          {"collides_with", number_value(c.collides_with)}};
}

json::Value ground_value(const ContactSettings& c) {
  std::vector<Member> m = {{"height", number_value(c.ground_height)}, {"normal", numbers_value(c.ground_normal)}};
  for (Member& s : surface_members(c.ground_contact)) m.push_back(std::move(s));
  return object_value(std::move(m));
}

json::Value box_value(const StaticBox& box) {
  std::vector<Member> m = {{"size", numbers_value(2.0 * box.half_extents)},
                           {"position", numbers_value(box.pose.translation())}};
  // The rotation as its matrix, which reads back exactly (rpy would not).
  if (box.pose.linear() != Eigen::Matrix3d::Identity()) {
    std::vector<json::Value> rows;
    for (int i = 0; i < 3; ++i) rows.push_back(numbers_value(box.pose.linear().row(i).transpose()));
    m.emplace_back("rotation", array_value(std::move(rows)));
  }
  for (Member& s : surface_members(box.contact)) m.push_back(std::move(s));
  return object_value(std::move(m));
}

auto surface_fields(const ShapeContact& c) { return std::tie(c.friction, c.restitution, c.layers, c.collides_with); }

// Per-shape surfaces, by the link each shape was declared on.
json::Value link_surfaces_value(const Model& model, const ContactSettings& c) {
  if (c.shapes.size() != model.shapes.size())
    inexpressible(std::to_string(c.shapes.size()) + " shape surfaces for a model with " +
                  std::to_string(model.shapes.size()) + " shapes");
  std::vector<Member> links;
  for (std::size_t f = 0; f < model.frame_name.size(); ++f) {
    const ShapeContact* first = nullptr;
    for (std::size_t s = 0; s < model.shapes.size(); ++s) {
      if (model.shapes[s].frame != static_cast<int>(f)) continue;
      if (!first) first = &c.shapes[s];
      else if (surface_fields(*first) != surface_fields(c.shapes[s]))
        inexpressible("different surfaces for the shapes of link \"" + model.frame_name[f] + "\"");
    }
    if (first) links.emplace_back(model.frame_name[f], object_value(surface_members(*first)));
  }
  return object_value(std::move(links));
}

json::Value link_pairs_value(const std::vector<std::pair<std::string, std::string>>& pairs) {
  std::vector<json::Value> items;
  for (const auto& [a, b] : pairs) items.push_back(array_value({string_value(a), string_value(b)}));
  return array_value(std::move(items));
}

bool self_collision_flag(const Model& model, const ContactSettings& c) {
  const std::vector<bool>& on = c.self_collision;
  if (std::none_of(on.begin(), on.end(), [](bool b) { return b; })) return false;
  if (on.size() != model.articulations.size() || !std::all_of(on.begin(), on.end(), [](bool b) { return b; }))
    inexpressible("self-collision on some articulations only");
  return true;
}

json::Value contacts_value(const Model& model, const StepOptions& step) {
  const ContactSettings& c = step.contacts;
  const StageMode mode = step.stages[static_cast<int>(Stage::Contacts)];
  if (mode == StageMode::On) inexpressible("the contacts stage forced on");
  std::vector<Member> m = {{"enabled", bool_value(mode == StageMode::Auto)},
                           {"self_collision", bool_value(self_collision_flag(model, c))},
                           {"capacity", number_value(c.capacity)},
                           {"margin", number_value(c.margin)},
                           {"speculative_speed", number_value(c.speculative_speed)},
                           {"stiffness", number_value(c.stiffness)},
                           {"damping", number_value(c.damping)},
                           {"bounce_threshold", number_value(c.bounce_threshold)},
                           {"max_depenetration_speed", number_value(c.max_depenetration_speed)},
                           {"torsional_friction", number_value(c.torsional_friction)}};
  if (!c.shapes.empty()) m.emplace_back("links", link_surfaces_value(model, c));
  if (!c.enabled_pairs.empty()) m.emplace_back("enabled_pairs", link_pairs_value(c.enabled_pairs));
  if (!c.disabled_pairs.empty()) m.emplace_back("disabled_pairs", link_pairs_value(c.disabled_pairs));
  return object_value(std::move(m));
}

// The DofSettings fields a scene file sets, and all of them (update when
// DofSettings gains a field).
template <class Dof>
auto file_fields(Dof& d) {
  return std::tie(d.drive_stiffness, d.drive_damping, d.max_force, d.drive_type, d.damping, d.friction);
}
auto all_fields(const DofSettings& d) {
  return std::tuple_cat(file_fields(d), std::tie(d.spring_stiffness, d.spring_rest, d.friction_model, d.stiction_extra,
                                                 d.falloff_velocity, d.stribeck_velocity, d.lower, d.upper,
                                                 d.limit_stiffness, d.limit_damping, d.velocity_limit));
}

// Checks that `dofs` differ from the model's defaults only where a scene
// file can say so: the file fields of non-root DOFs, equal across a joint.
void check_expressible(const Model& model, const std::vector<DofSettings>& dofs) {
  if (static_cast<int>(dofs.size()) != model.nv)
    inexpressible(std::to_string(dofs.size()) + " DOF settings for a model with " + std::to_string(model.nv) + " DOFs");
  const std::vector<DofSettings> defaults = default_dof_settings(model);
  for (int k = 0; k < model.nv; ++k) {
    const int body = model.dof_body[k];
    DofSettings d = dofs[k];
    if (!is_floating_root(model, body)) file_fields(d) = file_fields(defaults[k]);
    if (all_fields(d) != all_fields(defaults[k]))
      inexpressible("DOF " + model.dof_name[k] +
                    "'s settings (a scene file sets only the drive, damping and friction of non-root joints)");
    if (file_fields(dofs[k]) != file_fields(dofs[model.body_dof_offset[body]]))
      inexpressible("different settings for the DOFs of joint " + model.joint_name[body]);
  }
}

// Every actuated joint's drive and dynamics, explicitly.
std::pair<json::Value, json::Value> dof_values(const Model& model, const std::vector<DofSettings>& dofs) {
  check_expressible(model, dofs);
  std::vector<Member> drives, dynamics;
  for (int b = 0; b < model.nbody; ++b) {
    if (is_floating_root(model, b)) continue;
    const DofSettings& d = dofs[model.body_dof_offset[b]];
    const json::Value drive = object_value({{"kp", number_value(d.drive_stiffness)},
                                            {"kd", number_value(d.drive_damping)},
                                            {"max_force", number_value(d.max_force)},  // inf: null
                                            {"type", string_value(token_name(kDriveTypes, d.drive_type))}});
    drives.emplace_back(model.joint_name[b], drive);
    dynamics.emplace_back(model.joint_name[b], object_value({{"damping", number_value(d.damping)},
                                                             {"friction", number_value(d.friction)}}));
  }
  return {object_value({{"joints", object_value(std::move(drives))}}),
          object_value({{"joints", object_value(std::move(dynamics))}})};
}

json::Value step_value(const StepOptions& s) {
  for (int k = 0; k < kStageCount; ++k)
    if (k != static_cast<int>(Stage::Contacts) && s.stages[k] != StageMode::Auto)
      inexpressible(std::string("the ") + stage_name(static_cast<Stage>(k)) + " stage forced on or off");
  return object_value({{"dt", number_value(s.dt)},
                       {"substeps", number_value(s.substeps)},
                       {"solver", string_value(token_name(kSolvers, s.solver))},
                       {"iterations", number_value(s.iterations)},
                       {"integrator", string_value(token_name(kIntegrators, s.integrator))},
                       {"precision", string_value(token_name(kPrecisions, s.precision))},
                       {"lanes", string_value(token_name(kLanes, s.lanes))},
                       {"error_reduction", number_value(s.error_reduction)},
                       {"warm_start", number_value(s.warm_start)},
                       {"implicit_gyroscopic", bool_value(s.implicit_gyroscopic)},
                       {"conserve_linear_momentum", bool_value(s.conserve_linear_momentum)},
                       {"reset_on_fault", bool_value(s.reset_on_fault)},
                       {"record_applied_torque", bool_value(s.record_applied_torque)},
                       {"record_motion", bool_value(s.record_motion)}});
}

json::Value env_value(const VecEnvOptions& env) {
  const json::Value seed = env.seed <= kLargestNumberSeed ? number_value(static_cast<double>(env.seed))
                                                             : string_value(std::to_string(env.seed));
  return object_value({{"action_mode", string_value(token_name(kActionModes, env.action_mode))},
                       {"control_steps", number_value(env.control_steps)},
                       {"episode_steps", number_value(env.episode_steps)},
                       {"auto_reset", bool_value(env.auto_reset)},
                       {"seed", seed}});
}

// Every range; the ground friction range only when it is drawn (it is
// unused otherwise, and writing it would switch it on).
json::Value randomization_value(const Randomization& r) {
  std::vector<Member> m;
  for (const RandomizationField& f : randomization_fields()) {
    if (f.range == &Randomization::ground_friction && !r.randomize_ground_friction) continue;
    const UniformRange& range = r.*f.range;
    m.emplace_back(f.name, array_value({number_value(range.low), number_value(range.high)}));
  }
  return object_value(std::move(m));
}

}  // namespace

Scene load_scene(const std::string& path) { return read_scene_file(path, false, false); }

std::optional<double> resting_root_height(const Model& model, Eigen::VectorXd q) {
  for (int b = 0; b < model.nbody; ++b)
    if (is_floating_root(model, b)) q[model.body_q_offset[b] + 2] = 0;
  const std::optional<std::pair<double, int>> lowest = lowest_shape(model, q, Eigen::Vector3d::UnitZ(), 0.0);
  if (!lowest) return std::nullopt;
  return -lowest->first;
}

Scene scene_from_urdf(const std::string& urdf_path, bool floating_base, bool ground) {
  Scene scene = bare_scene(urdf_path, floating_base);
  scene.env.step.contacts.ground = ground;
  if (ground && floating_base) {  // the rest stays empty: VecEnv fills it (fill_initial_state)
    Eigen::VectorXd q = scene.model.neutral_configuration();
    if (const std::optional<double> height = resting_root_height(scene.model, q))
      for (int b = 0; b < scene.model.nbody; ++b)
        if (is_floating_root(scene.model, b)) q[scene.model.body_q_offset[b] + 2] = *height;
    scene.env.initial_q = q;
  }
  return scene;
}

Scene load_scene_or_urdf(const std::string& path, bool floating_base, bool ground) {
  if (fs::path(path).extension() == ".json") return read_scene_file(path, floating_base, ground);
  return scene_from_urdf(path, floating_base, ground);
}

void disable_contacts(Scene& scene) { scene.env.step.force(Stage::Contacts, StageMode::Off); }

// A fixed base standing at the plane's height, or a floating root left at
// z = 0: a violent start no one meant.
std::optional<std::string> ground_start_warning(const Scene& scene) {
  const ContactSettings& contacts = scene.env.step.contacts;
  if (!contacts.ground || scene.env.step.stages[static_cast<int>(Stage::Contacts)] == StageMode::Off) return std::nullopt;
  const Model& model = scene.model;
  const Eigen::VectorXd q = scene.env.initial_q.size() == model.nq ? scene.env.initial_q : model.neutral_configuration();
  const Eigen::Vector4d plane = ground_plane(contacts.ground_normal, contacts.ground_height);
  const std::optional<std::pair<double, int>> lowest = lowest_shape(model, q, plane.head<3>(), plane[3]);
  if (!lowest || lowest->first > -0.01) return std::nullopt;
  const bool fixed = std::none_of(model.body_joint.begin(), model.body_joint.end(),
                                  [](JointType j) { return j == JointType::Free; });
  std::ostringstream out;
  out.precision(3);
  out << scene.source << ": the initial state puts " << describe_shape(model, lowest->second) << " "
      << -lowest->first << " m inside the ground; its contacts will push it out at up to "
      << contacts.max_depenetration_speed << " m/s"
      << (fixed ? " (the base is fixed: with a floating base the robot starts standing on the ground)"
                : " (initial_state.q sets the root's height)");
  return out.str();
}

json::Value actuators_value(const Model& model, const std::vector<Actuator>& actuators) {
  validate_actuators(model, actuators, Precision::Double);
  std::vector<json::Value> items;
  for (const Actuator& a : actuators) {
    std::vector<Member> couplings;
    for (const auto& [dof, ratio] : a.couplings) couplings.emplace_back(model.dof_name[dof], number_value(ratio));
    items.push_back(object_value({{"name", string_value(a.name)},
                                  {"joint", string_value(model.dof_name[a.dof])},
                                  {"gear", number_value(a.gear)},
                                  {"couplings", object_value(std::move(couplings))},
                                  {"torque_constant", number_value(a.torque_constant)},
                                  {"bus_voltage", number_value(a.bus_voltage)},
                                  {"resistance", number_value(a.resistance)},
                                  {"velocity_constant", number_value(a.velocity_constant)},
                                  {"peak_torque", number_value(a.peak_torque)},  // inf: null
                                  {"enforce_operating_region", bool_value(a.enforce_operating_region)}}));
  }
  return array_value(std::move(items));
}

json::Value fixed_tendons_value(const Model& model) {
  std::vector<json::Value> items;
  auto limit = [](double x) { return std::isinf(x) ? json::Value{} : number_value(x); };  // none: null
  for (const FixedTendon& t : model.fixed_tendons) {
    std::vector<Member> joints;
    for (const TendonJoint& j : t.joints) joints.emplace_back(model.dof_name[j.dof], number_value(j.coefficient));
    items.push_back(object_value({{"name", string_value(t.name)},
                                  {"joints", object_value(std::move(joints))},
                                  {"stiffness", number_value(t.stiffness)},
                                  {"damping", number_value(t.damping)},
                                  {"rest_length", number_value(t.rest_length)},
                                  {"offset", number_value(t.offset)},
                                  {"limits", array_value({limit(t.lower_limit), limit(t.upper_limit)})},
                                  {"limit_stiffness", number_value(t.limit_stiffness)}}));
  }
  return array_value(std::move(items));
}

std::string scene_to_json(const Scene& scene) {
  const Model& model = scene.model;
  const VecEnvOptions& env = scene.env;
  const ContactSettings& contacts = env.step.contacts;
  auto [drives, dynamics] = dof_values(model, env.dofs.empty() ? default_dof_settings(model) : env.dofs);
  std::vector<Member> m = {{"model", string_value(fs::absolute(scene.model_path).lexically_normal().string())},
                           {"floating_base", bool_value(scene.floating_base)},
                           {"gravity", numbers_value(model.gravity)}};
  std::vector<json::Value> without_gravity;
  for (const std::string& link : model.links_without_gravity()) without_gravity.push_back(string_value(link));
  if (!without_gravity.empty()) m.emplace_back("links_without_gravity", array_value(std::move(without_gravity)));
  std::vector<Member> damped;
  for (int b = 0; b < model.nbody; ++b)
    if (model.body_linear_damping[b] != 0 || model.body_angular_damping[b] != 0)
      damped.emplace_back(model.frame_name[model.body_frame[b]],
                          object_value({{"linear", number_value(model.body_linear_damping[b])},
                                        {"angular", number_value(model.body_angular_damping[b])}}));
  if (!damped.empty()) m.emplace_back("link_damping", object_value({{"links", object_value(std::move(damped))}}));
  if (!model.fixed_tendons.empty()) m.emplace_back("fixed_tendons", fixed_tendons_value(model));
  if (env.initial_q.size() > 0 || env.initial_v.size() > 0)
    m.emplace_back("initial_state", initial_state_value(model, env));
  if (env.drive_target_q.size() > 0) {
    if (env.drive_target_q.size() != model.nq)
      inexpressible("drive targets of " + std::to_string(env.drive_target_q.size()) + " values for nq " +
                    std::to_string(model.nq));
    m.emplace_back("drive_targets", configuration_value(model, env.drive_target_q));
  }
  if (contacts.ground) m.emplace_back("ground", ground_value(contacts));
  if (!contacts.boxes.empty()) {
    std::vector<json::Value> boxes;
    for (const StaticBox& box : contacts.boxes) boxes.push_back(box_value(box));
    m.emplace_back("boxes", array_value(std::move(boxes)));
  }
  m.emplace_back("contacts", contacts_value(model, env.step));
  m.emplace_back("drives", std::move(drives));
  m.emplace_back("joint_dynamics", std::move(dynamics));
  if (!env.step.actuators.empty()) m.emplace_back("actuators", actuators_value(model, env.step.actuators));
  m.emplace_back("step", step_value(env.step));
  m.emplace_back("env", env_value(env));
  m.emplace_back("randomization", randomization_value(env.randomization));
  std::string out;
  write_value(object_value(std::move(m)), 0, out);
  return out + "\n";
}

}  // namespace lockstep
