#include "io/urdf_import.hpp"

#include "io/mesh_bounds.hpp"
#include "io/number_text.hpp"

#include <console_bridge/console.h>
#include <tinyxml2.h>
#include <urdf_parser/urdf_parser.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <unordered_map>

namespace lockstep {

namespace {

namespace fs = std::filesystem;
using tinyxml2::XMLElement;

// "file:LINE: <joint name='j'>" for messages.
std::string at(const std::string& src, const XMLElement* e) {
  return src + ":" + std::to_string(e->GetLineNum());
}

std::string describe(const XMLElement* owner, const XMLElement* e) {
  const char* name = owner->Attribute("name");
  std::string s = std::string(owner->Name()) + " '" + (name ? name : "") + "'";
  if (e != owner) s += " <" + std::string(e->Name()) + ">";
  return s;
}

// Parses the whole of `text` as `count` whitespace-separated finite numbers.
// Returns the reason when it cannot.
std::string parse_numbers(const char* text, int count, double* out) {
  const char* p = text;
  const char* end = text + std::char_traits<char>::length(text);
  for (int k = 0; k < count; ++k) {
    while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
    if (p == end) return "expected " + std::to_string(count) + " numbers";
    const char* word_end = p;
    while (word_end < end && !std::isspace(static_cast<unsigned char>(*word_end))) ++word_end;
    const std::string why = parse_number(std::string_view(p, static_cast<std::size_t>(word_end - p)), out[k]);
    if (!why.empty()) return why;
    if (!std::isfinite(out[k])) return "not a finite number";
    p = word_end;
  }
  while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
  if (p != end) return "expected " + std::to_string(count) + " numbers";
  return "";
}

// Reads attribute `attr` of `e` (count numbers) when present; throws on bad text.
bool read_attr(const std::string& src, const XMLElement* owner, const XMLElement* e, const char* attr, int count,
               double* out) {
  const char* text = e->Attribute(attr);
  if (!text) return false;
  const std::string why = parse_numbers(text, count, out);
  if (!why.empty())
    throw ModelError(at(src, e) + ": " + describe(owner, e) + " attribute " + attr + "=\"" + text + "\": " + why);
  return true;
}

// Validates the numeric attributes of child `tag` of `e` (when present).
void check_child(const std::string& src, const XMLElement* owner, const XMLElement* e, const char* tag,
                 std::initializer_list<std::pair<const char*, int>> attrs) {
  for (const XMLElement* c = e->FirstChildElement(tag); c; c = c->NextSiblingElement(tag)) {
    double v[3];
    for (const auto& [attr, count] : attrs) read_attr(src, owner, c, attr, count, v);
  }
}

Eigen::Isometry3d origin_of(const std::string& src, const XMLElement* owner, const XMLElement* e) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  const XMLElement* o = e->FirstChildElement("origin");
  if (!o) return t;
  double xyz[3] = {0, 0, 0}, rpy[3] = {0, 0, 0};
  read_attr(src, owner, o, "xyz", 3, xyz);
  read_attr(src, owner, o, "rpy", 3, rpy);
  t.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
  t.linear() = (Eigen::AngleAxisd(rpy[2], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(rpy[1], Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rpy[0], Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  return t;
}

Eigen::Isometry3d to_eigen(const urdf::Pose& pose) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translation() = Eigen::Vector3d(pose.position.x, pose.position.y, pose.position.z);
  t.linear() = Eigen::Quaterniond(pose.rotation.w, pose.rotation.x, pose.rotation.y, pose.rotation.z).toRotationMatrix();
  return t;
}

// Resolves a mesh reference; empty when no such file exists.
std::string resolve_mesh(const std::string& ref, const fs::path& base) {
  std::error_code ec;
  const std::string pkg_scheme = "package://", file_scheme = "file://";
  if (ref.compare(0, pkg_scheme.size(), pkg_scheme) == 0) {
    const std::string rest = ref.substr(pkg_scheme.size());
    const std::size_t slash = rest.find('/');
    const std::string pkg = rest.substr(0, slash);
    const std::string inner = slash == std::string::npos ? "" : rest.substr(slash + 1);
    // a bare file name's base is empty, which fs::absolute refuses: the current folder
    for (fs::path d = fs::absolute(base.empty() ? fs::path(".") : base, ec);; d = d.parent_path()) {
      for (const fs::path& candidate : {d / pkg / inner, d.filename() == pkg ? d / inner : fs::path()})
        if (!candidate.empty() && fs::is_regular_file(candidate, ec)) return candidate.lexically_normal().string();
      if (d == d.parent_path()) break;
    }
    return "";
  }
  fs::path p = ref.compare(0, file_scheme.size(), file_scheme) == 0 ? fs::path(ref.substr(file_scheme.size())) : fs::path(ref);
  if (p.is_relative()) p = base / p;
  return fs::is_regular_file(p, ec) ? p.lexically_normal().string() : "";
}

// Collision elements of one link, straight from the XML (urdfdom 3 knows no capsules).
std::vector<Shape> read_collisions(const std::string& src, const XMLElement* link, const std::string& link_name,
                                   const fs::path& base, std::vector<std::string>& warnings) {
  std::vector<Shape> shapes;
  for (const XMLElement* c = link->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision")) {
    const XMLElement* geometry = c->FirstChildElement("geometry");
    const XMLElement* g = geometry ? geometry->FirstChildElement() : nullptr;
    if (!g) throw ModelError(at(src, c) + ": " + describe(link, c) + " has no geometry");
    Shape shape;
    shape.pose = origin_of(src, link, c);
    const std::string type = g->Name();
    double v[3] = {0, 0, 0};
    auto need = [&](const char* attr, int count) {
      if (!read_attr(src, link, g, attr, count, v))
        throw ModelError(at(src, g) + ": " + describe(link, g) + " is missing attribute " + attr);
    };
    if (type == "box") {
      need("size", 3);
      shape.type = ShapeType::Box;
      shape.size = 0.5 * Eigen::Vector3d(v[0], v[1], v[2]);
    } else if (type == "sphere") {
      need("radius", 1);
      shape.type = ShapeType::Sphere;
      shape.size = Eigen::Vector3d(v[0], 0.0, 0.0);
    } else if (type == "cylinder" || type == "capsule") {
      need("radius", 1);
      const double radius = v[0];
      need("length", 1);
      shape.type = type == "cylinder" ? ShapeType::Cylinder : ShapeType::Capsule;
      shape.size = Eigen::Vector3d(radius, 0.5 * v[0], 0.0);
    } else if (type == "mesh") {
      const char* file = g->Attribute("filename");
      if (!file) throw ModelError(at(src, g) + ": " + describe(link, g) + " is missing attribute filename");
      if (read_attr(src, link, g, "scale", 3, v)) shape.mesh_scale = Eigen::Vector3d(v[0], v[1], v[2]);
      shape.mesh_path = resolve_mesh(file, base);
      const std::string mesh_at = at(src, g) + ": link '" + link_name + "': mesh file '" + file + "'";
      if (shape.mesh_path.empty()) {
        warnings.push_back(mesh_at + " not found; collision geometry skipped");
        continue;
      }
      // The mesh becomes the box that bounds its scaled vertices in the mesh
      // frame; path and scale stay on the shape to say where it came from.
      Eigen::AlignedBox3d bounds;
      try {
        bounds = mesh_bounds(shape.mesh_path, shape.mesh_scale);
      } catch (const MeshFileError& e) {
        const std::string resolved = shape.mesh_path != file ? " (" + shape.mesh_path + ")" : "";
        warnings.push_back(mesh_at + resolved + ": " + e.what() + "; collision geometry skipped");
        continue;
      }
      const Eigen::Vector3d sizes = bounds.sizes(), centre = bounds.center();
      shape.type = ShapeType::Box;
      shape.size = 0.5 * sizes;
      shape.pose = shape.pose * Eigen::Translation3d(centre);
      std::ostringstream fitted;
      fitted << mesh_at << " fitted with a box " << sizes.x() << " x " << sizes.y() << " x " << sizes.z()
             << " m centred at (" << centre.x() << ", " << centre.y() << ", " << centre.z() << ") in the mesh frame";
      warnings.push_back(fitted.str());
    } else {
      warnings.push_back(at(src, g) + ": link '" + link_name + "': unsupported collision geometry <" + type +
                         ">; skipped");
      continue;
    }
    if ((shape.size.array() < 0.0).any())
      throw ModelError(at(src, g) + ": " + describe(link, g) + " has a negative size");
    shapes.push_back(shape);
  }
  return shapes;
}

// Collects urdfdom's console messages instead of letting them reach stderr.
class CaptureOutput : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR) errors += (errors.empty() ? "" : "; ") + text;
  }
  std::string errors;
};

urdf::ModelInterfaceSharedPtr parse_with_urdfdom(const std::string& xml, std::string& errors) {
  static std::mutex mutex;  // console_bridge's handler is process-wide
  std::lock_guard<std::mutex> lock(mutex);
  CaptureOutput capture;
  console_bridge::useOutputHandler(&capture);
  urdf::ModelInterfaceSharedPtr model;
  try {
    model = urdf::parseURDF(xml);
  } catch (const std::exception& e) {
    capture.errors += (capture.errors.empty() ? "" : "; ") + std::string(e.what());
  }
  console_bridge::restorePreviousOutputHandler();
  errors = capture.errors;
  return model;
}

struct RawJoint {
  const XMLElement* element;
  std::string name, type, parent, child;
};

// Gazebo's link extension <gazebo reference="link"> with <gravity> or the
// older <turnGravityOff>, each an SDF bool (true/false/1/0, any case,
// whitespace around it ignored): whether gravity acts on each link the
// file switches, once per link. A reference naming no link is an error
// only where it carries one of these elements (Gazebo's joint extensions
// share the tag).
std::map<std::string, bool> gravity_switches(const std::string& src, const XMLElement* robot,
                                             const std::map<std::string, XMLElement*>& links) {
  std::map<std::string, bool> gravity;
  for (const XMLElement* g = robot->FirstChildElement("gazebo"); g; g = g->NextSiblingElement("gazebo")) {
    const char* reference = g->Attribute("reference");
    for (const char* tag : {"gravity", "turnGravityOff"}) {
      const XMLElement* e = g->FirstChildElement(tag);
      if (!e) continue;
      const std::string where = at(src, e) + ": <" + tag + ">";
      if (!reference) throw ModelError(where + " outside a <gazebo reference=\"link\"> element");
      if (!links.count(reference)) throw ModelError(where + ": <gazebo reference=\"" + reference + "\"> names no link");
      const std::string written = e->GetText() ? e->GetText() : "";
      const auto first = written.find_first_not_of(" \t\r\n"), last = written.find_last_not_of(" \t\r\n");
      std::string text = first == std::string::npos ? "" : written.substr(first, last - first + 1);
      for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      const bool truth = text == "true" || text == "1";
      if (!truth && text != "false" && text != "0")
        throw ModelError(where + ": expected true, false, 1 or 0, got '" + written + "'");
      if (!gravity.emplace(reference, truth != (std::string(tag) == "turnGravityOff")).second)
        throw ModelError(where + ": link '" + reference + "' has its gravity switched already");
    }
  }
  return gravity;
}

// Gravity per moving body, as Gazebo lumps links fixed together: a body
// takes the switch of its first link (parent-first) that the file switches,
// and every link in it follows; a link fixed to it that the file switches
// the other way is a warning. Links fixed to the world move with nothing.
void apply_gravity_switches(ArticulationSpec& spec, const std::map<std::string, bool>& switches,
                            const std::string& prefix, std::vector<std::string>& warnings) {
  const int n = static_cast<int>(spec.links.size());
  const std::vector<int> head = body_head_links(spec);  // -1: fixed to the world
  std::map<int, std::pair<bool, std::string>> body_switch;  // head -> (gravity, the link that set it)
  for (int i = 0; i < n; ++i) {
    const LinkSpec& link = spec.links[i];
    const auto it = switches.find(link.name.substr(prefix.size()));
    if (it == switches.end()) continue;
    if (head[i] < 0) {
      warnings.push_back(spec.source + ":" + std::to_string(link.source_line) + ": link '" + link.name +
                         "': Gazebo gravity switch ignored: the link is fixed to the world, gravity moves nothing there");
      continue;
    }
    const auto [set, inserted] = body_switch.emplace(head[i], std::pair{it->second, link.name});
    if (!inserted && set->second.first != it->second)
      warnings.push_back(spec.source + ":" + std::to_string(link.source_line) + ": link '" + link.name +
                         "': Gazebo gravity switch (" +
                         (it->second ? "on" : "off") + ") ignored: the link is fixed to link '" +
                         spec.links[head[i]].name + "' and moves with it as one body, whose gravity link '" +
                         set->second.second + "' switches " + (set->second.first ? "on" : "off"));
  }
  for (int i = 0; i < n; ++i) {
    const auto it = body_switch.find(head[i]);
    spec.links[i].gravity = it == body_switch.end() || it->second.first;
  }
}

}  // namespace

ArticulationSpec urdf_articulation_from_string(const std::string& xml, const std::string& src,
                                               const UrdfOptions& options, std::vector<std::string>* warnings_out) {
  std::vector<std::string> warnings;
  tinyxml2::XMLDocument doc;
  if (doc.Parse(xml.c_str(), xml.size()) != tinyxml2::XML_SUCCESS)
    throw ModelError(src + ":" + std::to_string(doc.ErrorLineNum()) + ": not valid XML (" + doc.ErrorName() +
                     "); a URDF is an XML file whose root element is <robot>");
  XMLElement* robot = doc.RootElement();
  if (!robot || std::string(robot->Name()) != "robot")
    throw ModelError(src + ": the root element is not <robot>");
  const char* robot_name = robot->Attribute("name");
  if (!robot_name || !*robot_name) throw ModelError(at(src, robot) + ": <robot> has no name");

  // Links and joints as written, with every number we read checked as text.
  std::map<std::string, XMLElement*> links;
  std::vector<std::string> link_order;
  for (XMLElement* l = robot->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
    const char* name = l->Attribute("name");
    if (!name || !*name) throw ModelError(at(src, l) + ": <link> has no name");
    if (!links.emplace(name, l).second) throw ModelError(at(src, l) + ": duplicate link '" + name + "'");
    link_order.push_back(name);
    for (const XMLElement* in = l->FirstChildElement("inertial"); in; in = in->NextSiblingElement("inertial")) {
      check_child(src, l, in, "origin", {{"xyz", 3}, {"rpy", 3}});
      check_child(src, l, in, "mass", {{"value", 1}});
      check_child(src, l, in, "inertia", {{"ixx", 1}, {"ixy", 1}, {"ixz", 1}, {"iyy", 1}, {"iyz", 1}, {"izz", 1}});
    }
  }
  if (links.empty()) throw ModelError(src + ": the robot has no links");

  std::vector<RawJoint> joints;
  std::set<std::string> joint_names;
  std::map<std::string, const RawJoint*> parent_joint;
  for (XMLElement* j = robot->FirstChildElement("joint"); j; j = j->NextSiblingElement("joint")) {
    RawJoint raw{j, "", "", "", ""};
    const char* name = j->Attribute("name");
    if (!name || !*name) throw ModelError(at(src, j) + ": <joint> has no name");
    raw.name = name;
    if (!joint_names.insert(raw.name).second) throw ModelError(at(src, j) + ": duplicate joint '" + raw.name + "'");
    const char* type = j->Attribute("type");
    raw.type = type ? type : "";
    if (raw.type == "floating")
      throw ModelError(at(src, j) + ": joint '" + raw.name +
                       "': floating joint inside the tree is not supported (use UrdfOptions::floating_base for the root)");
    if (raw.type == "planar") throw ModelError(at(src, j) + ": joint '" + raw.name + "': planar joints are not supported");
    if (raw.type != "revolute" && raw.type != "continuous" && raw.type != "prismatic" && raw.type != "fixed")
      throw ModelError(at(src, j) + ": joint '" + raw.name + "': unknown joint type '" + raw.type + "'");
    for (const char* tag : {"parent", "child"}) {
      const XMLElement* e = j->FirstChildElement(tag);
      const char* link = e ? e->Attribute("link") : nullptr;
      if (!link) throw ModelError(at(src, j) + ": joint '" + raw.name + "' has no <" + tag + " link=...>");
      if (!links.count(link))
        throw ModelError(at(src, e) + ": joint '" + raw.name + "': " + tag + " link '" + link + "' does not exist");
      (std::string(tag) == "parent" ? raw.parent : raw.child) = link;
    }
    check_child(src, j, j, "origin", {{"xyz", 3}, {"rpy", 3}});
    check_child(src, j, j, "axis", {{"xyz", 3}});
    check_child(src, j, j, "limit", {{"lower", 1}, {"upper", 1}, {"effort", 1}, {"velocity", 1}});
    // stiffness and spring_mount: RaiSim's joint spring
    check_child(src, j, j, "dynamics", {{"damping", 1}, {"friction", 1}, {"stiffness", 1}, {"spring_mount", 1}});
    check_child(src, j, j, "mimic", {{"multiplier", 1}, {"offset", 1}});
    joints.push_back(raw);
  }

  // The joint graph must be one tree: urdfdom accepts a cycle beside a tree.
  for (const RawJoint& j : joints) {
    const auto [it, fresh] = parent_joint.emplace(j.child, &j);
    if (!fresh)
      throw ModelError(at(src, j.element) + ": link '" + j.child + "' has two parents (joints '" + it->second->name +
                       "' and '" + j.name + "')");
  }
  std::map<std::string, std::vector<const RawJoint*>> children;
  for (const RawJoint& j : joints) children[j.parent].push_back(&j);
  std::vector<std::string> roots;
  for (const std::string& l : link_order)
    if (!parent_joint.count(l)) roots.push_back(l);
  std::set<std::string> reached;
  std::vector<std::string> stack = roots;
  while (!stack.empty()) {
    const std::string l = stack.back();
    stack.pop_back();
    reached.insert(l);
    for (const RawJoint* j : children[l]) stack.push_back(j->child);
  }
  for (const std::string& l : link_order) {
    if (reached.count(l)) continue;
    std::string cycle, cur = l;  // walk up until a link repeats: that is the cycle
    std::set<std::string> seen;
    while (seen.insert(cur).second) cur = parent_joint.at(cur)->parent;
    const std::string start = cur;
    do {
      cycle += "'" + cur + "' <- ";
      cur = parent_joint.at(cur)->parent;
    } while (cur != start);
    throw ModelError(at(src, parent_joint.at(start)->element) + ": the joints form a cycle: " + cycle + "'" + start + "'");
  }
  if (roots.size() != 1) {
    std::string names;
    for (const std::string& r : roots) names += (names.empty() ? "'" : ", '") + r + "'";
    throw ModelError(src + ": several root links (" + names + "); a URDF must be one tree");
  }

  // urdfdom reads the values; collisions and visuals are taken out first
  // (urdfdom 3 rejects geometry it does not know, such as <capsule>).
  const fs::path base = fs::path(src).parent_path();
  std::map<std::string, std::vector<Shape>> shapes;
  for (const std::string& name : link_order) {
    XMLElement* l = links.at(name);
    shapes[name] = read_collisions(src, l, options.name_prefix + name, base, warnings);
    for (const char* tag : {"collision", "visual"})
      while (XMLElement* e = l->FirstChildElement(tag)) l->DeleteChild(e);
  }
  // and the robot's materials, which only visuals use: urdfdom logs an
  // error for one without a colour, which would refuse the file below
  while (XMLElement* e = robot->FirstChildElement("material")) robot->DeleteChild(e);
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  std::string urdfdom_errors;
  const urdf::ModelInterfaceSharedPtr model = parse_with_urdfdom(printer.CStr(), urdfdom_errors);
  // urdfdom may log an error and still return a model, with the part it
  // could not read left at zero (an <inertial> whose <mass> it cannot
  // parse, an <inertia> without its products): refused all the same
  if (!model || !urdfdom_errors.empty())
    throw ModelError(src + ": invalid URDF: " + (urdfdom_errors.empty() ? "rejected by urdfdom" : urdfdom_errors));

  const std::map<std::string, bool> gravity = gravity_switches(src, robot, links);
  ArticulationSpec spec;
  spec.name = options.name_prefix + robot_name;
  spec.source = src;
  spec.floating_base = options.floating_base;
  spec.root_pose = options.root_pose;
  const std::string& prefix = options.name_prefix;

  struct Visit {
    std::string link;
    const RawJoint* joint;
  };
  std::vector<Visit> todo{{roots.front(), nullptr}};
  while (!todo.empty()) {
    const Visit v = todo.back();
    todo.pop_back();
    const auto& kids = children[v.link];
    for (auto k = kids.rbegin(); k != kids.rend(); ++k) todo.push_back({(*k)->child, *k});

    LinkSpec link;
    link.name = prefix + v.link;
    link.shapes = shapes[v.link];
    link.source_line = links.at(v.link)->GetLineNum();
    const urdf::LinkConstSharedPtr ul = model->getLink(v.link);
    if (ul && ul->inertial) {
      const urdf::Inertial& in = *ul->inertial;
      link.inertial.mass = in.mass;
      link.inertial.origin = to_eigen(in.origin);
      link.inertial.inertia << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
    }
    if (v.joint) {
      const urdf::JointConstSharedPtr uj = model->getJoint(v.joint->name);
      if (!uj) throw ModelError(at(src, v.joint->element) + ": joint '" + v.joint->name + "' was not read by urdfdom");
      link.parent = prefix + v.joint->parent;
      JointSpec& j = link.joint;
      j.name = prefix + uj->name;
      j.source_line = v.joint->element->GetLineNum();
      j.origin = to_eigen(uj->parent_to_joint_origin_transform);
      j.axis = Eigen::Vector3d(uj->axis.x, uj->axis.y, uj->axis.z);
      switch (uj->type) {
        case urdf::Joint::REVOLUTE:
        case urdf::Joint::CONTINUOUS: j.type = JointType::Revolute; break;
        case urdf::Joint::PRISMATIC: j.type = JointType::Prismatic; break;
        case urdf::Joint::FIXED: j.type = JointType::Fixed; break;
        default:
          throw ModelError(at(src, v.joint->element) + ": joint '" + uj->name + "': unsupported joint type");
      }
      std::string placeholders;
      if (uj->limits && j.type != JointType::Fixed) {
        const urdf::JointLimits& lim = *uj->limits;
        if (uj->type != urdf::Joint::CONTINUOUS) {
          j.limited = !(lim.lower == 0.0 && lim.upper == 0.0);
          if (j.limited) {
            j.lower = lim.lower;
            j.upper = lim.upper;
          } else {
            placeholders += " lower == upper == 0";
          }
        }
        if (lim.velocity == 0.0) placeholders += " velocity=0";
        else j.velocity_limit = lim.velocity;
        if (lim.effort == 0.0) placeholders += " effort=0";
        else j.effort_limit = lim.effort;
      }
      if (!placeholders.empty())
        warnings.push_back(at(src, v.joint->element) + ": joint '" + j.name + "': limit" + placeholders +
                           " read as no limit");
      if (uj->dynamics) {
        j.damping = uj->dynamics->damping;
        j.friction = uj->dynamics->friction;
      }
      // urdfdom does not read RaiSim's spring attributes (checked as numbers above)
      if (const XMLElement* d = v.joint->element->FirstChildElement("dynamics")) {
        read_attr(src, v.joint->element, d, "stiffness", 1, &j.spring_stiffness);
        read_attr(src, v.joint->element, d, "spring_mount", 1, &j.spring_rest);
      }
      if (uj->mimic && j.type == JointType::Fixed) {
        // ignored, but a tag naming no joint or itself is malformed all the same
        const std::string& leader = uj->mimic->joint_name;
        if (leader == uj->name || !model->getJoint(leader))
          throw ModelError(at(src, v.joint->element) + ": joint '" + j.name + "': mimic tag names " +
                           (leader == uj->name ? "the joint itself" : "joint '" + leader + "', which does not exist"));
        warnings.push_back(at(src, v.joint->element) + ": joint '" + j.name + "': mimic tag on a fixed joint ignored");
      } else if (uj->mimic) {
        j.mimic.leader_joint = prefix + uj->mimic->joint_name;
        j.mimic.multiplier = uj->mimic->multiplier;
        j.mimic.offset = uj->mimic->offset;
      }
    }
    spec.links.push_back(std::move(link));
  }
  apply_gravity_switches(spec, gravity, prefix, warnings);

  if (warnings_out) warnings_out->insert(warnings_out->end(), warnings.begin(), warnings.end());
  return spec;
}

ArticulationSpec urdf_articulation_from_file(const std::string& path, const UrdfOptions& options,
                                             std::vector<std::string>* warnings) {
  std::error_code ignored;
  // a relative path also as the absolute one it was looked for at
  const std::string where = std::filesystem::path(path).is_absolute()
                                ? path
                                : path + " (" + std::filesystem::absolute(path, ignored).string() + ")";
  if (std::filesystem::is_directory(path, ignored)) throw ModelError(where + ": is a directory, not a URDF file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ModelError(where + ": cannot open the URDF file");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw ModelError(where + ": cannot read the URDF file");
  if (text.str().empty()) throw ModelError(where + ": the file is empty");
  return urdf_articulation_from_string(text.str(), path, options, warnings);
}

int add_urdf(ModelBuilder& builder, const std::string& path, const UrdfOptions& options) {
  std::vector<std::string> warnings;
  const ArticulationSpec spec = urdf_articulation_from_file(path, options, &warnings);
  for (const std::string& w : warnings) builder.add_warning(w);
  return builder.add_articulation(spec);
}

Model load_urdf(const std::string& path, const UrdfOptions& options, const BuildOptions& build,
                std::vector<std::string>* warnings) {
  ModelBuilder builder(build);
  add_urdf(builder, path, options);
  Model model = builder.finalize();
  if (warnings) warnings->insert(warnings->end(), builder.warnings().begin(), builder.warnings().end());
  return model;
}

}  // namespace lockstep
