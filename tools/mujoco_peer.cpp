// `lockstep bench`'s MuJoCo peer (tools/mujoco_peer.hpp).
#include "tools/mujoco_peer.hpp"

#include <mujoco/mujoco.h>
#include <tinyxml2.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace lockstep::cli {

namespace {

using tinyxml2::XMLElement;

constexpr const char* kVfsName = "lockstep_peer.urdf";
constexpr const char* kVfsMjcfName = "lockstep_peer.xml";
constexpr const char* kGroundName = "lockstep_ground";

bool has_mesh_geometry(const XMLElement* element) {
  const XMLElement* geometry = element->FirstChildElement("geometry");
  return geometry && geometry->FirstChildElement("mesh");
}

// Removes the children named `tag` of every link that `drop` selects;
// returns how many.
template <class Drop>
int remove_link_children(XMLElement* robot, const char* tag, Drop drop) {
  int removed = 0;
  for (XMLElement* link = robot->FirstChildElement("link"); link; link = link->NextSiblingElement("link")) {
    XMLElement* child = link->FirstChildElement(tag);
    while (child) {
      XMLElement* next = child->NextSiblingElement(tag);
      if (drop(child)) {
        link->DeleteChild(child);
        ++removed;
      }
      child = next;
    }
  }
  return removed;
}

// The link no joint has as its child; empty when there is none or several.
std::string root_link(const XMLElement* robot) {
  std::set<std::string> children;
  for (const XMLElement* j = robot->FirstChildElement("joint"); j; j = j->NextSiblingElement("joint"))
    if (const XMLElement* child = j->FirstChildElement("child"))
      if (const char* name = child->Attribute("link")) children.insert(name);
  std::string root;
  for (const XMLElement* l = robot->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
    const char* name = l->Attribute("name");
    if (!name || children.count(name)) continue;
    if (!root.empty()) return "";
    root = name;
  }
  return root;
}

int count_collisions(const XMLElement* robot) {
  int n = 0;
  for (const XMLElement* link = robot->FirstChildElement("link"); link; link = link->NextSiblingElement("link"))
    for (const XMLElement* c = link->FirstChildElement("collision"); c; c = c->NextSiblingElement("collision")) ++n;
  return n;
}

std::string print(const tinyxml2::XMLDocument& doc) {
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  return std::string(printer.CStr(), static_cast<std::size_t>(printer.CStrSize() - 1));
}

// A URDF whose root link is "world" (MuJoCo's world body) floats when the
// one joint from the world becomes a floating joint, as lockstep floats it:
// its Free root joint carries the world link, into which the fixed child
// is fused.
void float_world_child(XMLElement* robot, const std::string& path, std::vector<std::string>& notes) {
  XMLElement* from_world = nullptr;
  for (XMLElement* j = robot->FirstChildElement("joint"); j; j = j->NextSiblingElement("joint")) {
    const XMLElement* parent = j->FirstChildElement("parent");
    const char* link = parent ? parent->Attribute("link") : nullptr;
    if (!link || std::string(link) != "world") continue;
    if (from_world) throw std::runtime_error(path + ": more than one joint from the link \"world\"; none floated");
    from_world = j;
  }
  const char* type = from_world ? from_world->Attribute("type") : nullptr;
  if (!type || std::string(type) != "fixed")
    throw std::runtime_error(path + ": the root link \"world\" needs exactly one fixed joint to float");
  from_world->SetAttribute("type", "floating");
  const char* name = from_world->Attribute("name");
  notes.push_back(std::string("made the fixed joint \"") + (name ? name : "") +
                  "\" from the URDF's own link \"world\" floating (a floating joint on the world becomes a free joint)");
}

// The URDF as MuJoCo 2.2 can load it: without the mesh files it would look
// for, with the compiler options the benchmark relies on, and, for a
// floating base, with the root on a floating joint (MuJoCo's URDF import
// welds the root link to the world).
std::string prepare_urdf(const MujocoScene& scene, std::vector<std::string>& notes) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(scene.urdf_path.c_str()) != tinyxml2::XML_SUCCESS)
    throw std::runtime_error(scene.urdf_path + ": " + doc.ErrorStr());
  XMLElement* robot = doc.FirstChildElement("robot");
  if (!robot) throw std::runtime_error(scene.urdf_path + ": no <robot> element");

  const int visuals = remove_link_children(robot, "visual", [](const XMLElement*) { return true; });
  const int meshes = remove_link_children(robot, "collision", has_mesh_geometry);
  if (scene.ground) {
    const int kept = count_collisions(robot);
    notes.push_back("removed " + std::to_string(visuals) + " <visual> and " + std::to_string(meshes) +
                    " mesh <collision> elements (MuJoCo gets no mesh collisions; lockstep fits a box to a mesh whose file exists: " +
                    (kept > 0 ? "the robot touches the ground only through its " + std::to_string(kept) +
                                    " remaining primitive <collision> shapes, spheres, boxes and cylinders)"
                              : std::string("no <collision> shape is left, nothing touches the ground)")));
  } else {
    notes.push_back("removed " + std::to_string(visuals) + " <visual> and " + std::to_string(meshes) +
                    " mesh <collision> elements (their mesh files are not needed without contacts)");
  }

  if (!robot->FirstChildElement("mujoco")) {
    XMLElement* mujoco = doc.NewElement("mujoco");
    XMLElement* compiler = doc.NewElement("compiler");
    compiler->SetAttribute("discardvisual", "true");
    compiler->SetAttribute("fusestatic", "true");
    compiler->SetAttribute("balanceinertia", "true");
    mujoco->InsertEndChild(compiler);
    robot->InsertFirstChild(mujoco);
    notes.push_back("added <mujoco><compiler discardvisual=\"true\" fusestatic=\"true\" "
                    "balanceinertia=\"true\"/></mujoco> (fusestatic: MuJoCo's URDF default, fixed joints fused; "
                    "balanceinertia: MuJoCo rejects an inertia that violates A + B >= C, which lockstep keeps "
                    "with a warning)");
  } else {
    notes.push_back("kept the URDF's own <mujoco> element");
  }

  if (scene.floating_base) {
    const std::string root = root_link(robot);
    if (root.empty()) throw std::runtime_error(scene.urdf_path + ": no single root link to float");
    if (root == "world") {
      float_world_child(robot, scene.urdf_path, notes);
      return print(doc);
    }
    const char* robot_name = robot->Attribute("name");
    const std::string joint_name = std::string(robot_name ? robot_name : "robot") + "_root";
    XMLElement* world = doc.NewElement("link");
    world->SetAttribute("name", "world");
    XMLElement* joint = doc.NewElement("joint");
    joint->SetAttribute("name", joint_name.c_str());
    joint->SetAttribute("type", "floating");
    joint->InsertNewChildElement("parent")->SetAttribute("link", "world");
    joint->InsertNewChildElement("child")->SetAttribute("link", root.c_str());
    robot->InsertEndChild(world);
    robot->InsertEndChild(joint);
    notes.push_back("added a link \"world\" and a floating joint \"" + joint_name + "\" from it to \"" + root +
                    "\" (MuJoCo's URDF import welds the root link to the world; a floating joint on the world "
                    "becomes a free joint)");
  }

  return print(doc);
}

struct ModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
using ModelPtr = std::unique_ptr<mjModel, ModelDeleter>;
using DataPtr = std::unique_ptr<mjData, DataDeleter>;

// Loads `xml` (URDF or MJCF) through an in-memory file named `vfs_name`.
ModelPtr load_from_memory(const std::string& xml, const std::string& source, const char* vfs_name = kVfsName) {
  // mjVFS holds 2000 file names inline (about 2 MB): keep it off the stack.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), vfs_name, static_cast<int>(xml.size())) != 0)
    throw std::runtime_error("MuJoCo: cannot create the in-memory file for " + source);
  const int index = mj_findFileVFS(vfs.get(), vfs_name);
  std::copy(xml.begin(), xml.end(), static_cast<char*>(vfs->filedata[index]));
  char error[1000] = "";
  ModelPtr model(mj_loadXML(vfs_name, vfs.get(), error, sizeof error));
  mj_deleteVFS(vfs.get());
  if (!model) throw std::runtime_error("MuJoCo cannot load " + source + ": " + error);
  return model;
}

// The model MuJoCo last loaded from XML (`m`, just loaded from the URDF),
// as MJCF text. MuJoCo 2.2 saves it only to a file: a temporary one,
// removed again.
std::string save_last_xml(const mjModel* m, const std::string& source) {
  std::string path = (std::filesystem::temp_directory_path() / "lockstep_mujoco_peer_XXXXXX.xml").string();
  const int fd = mkstemps(path.data(), 4);
  if (fd < 0) throw std::runtime_error("cannot create a temporary file for the MJCF of " + source);
  close(fd);
  char error[1000] = "";
  const int saved = mj_saveLastXML(path.c_str(), m, error, sizeof error);
  std::ifstream in(path, std::ios::binary);
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  std::remove(path.c_str());
  if (!saved || xml.empty()) throw std::runtime_error("MuJoCo cannot save " + source + " as MJCF: " + error);
  return xml;
}

std::string numbers(const double* values, int n) {
  std::ostringstream out;
  out.precision(17);
  for (int i = 0; i < n; ++i) out << (i ? " " : "") << values[i];
  return out.str();
}

int geom_size_count(int type) {
  switch (type) {
    case mjGEOM_SPHERE: return 1;
    case mjGEOM_CAPSULE:
    case mjGEOM_CYLINDER: return 2;
    default: return 3;
  }
}

int named_id(const mjModel* m, mjtObj type, const XMLElement* element, const char* what) {
  const char* name = element->Attribute("name");
  const int id = name ? mj_name2id(m, type, name) : -1;
  if (id < 0)
    throw std::runtime_error(std::string("MuJoCo's MJCF has a ") + what + " \"" + (name ? name : "") +
                             "\" that its model of the URDF does not have");
  return id;
}

// MuJoCo 2.2's MJCF writer keeps 6 significant digits: puts the numbers of
// `m` (the model the MJCF was saved from) back into the bodies, inertials,
// joints and geoms of `body` (id `id`) and its subtree, at full precision.
void restore_numbers(XMLElement* body, int id, const mjModel* m) {
  if (id > 0) {
    for (const char* frame : {"euler", "axisangle", "xyaxes", "zaxis"}) body->DeleteAttribute(frame);
    body->SetAttribute("pos", numbers(m->body_pos + 3 * id, 3).c_str());
    body->SetAttribute("quat", numbers(m->body_quat + 4 * id, 4).c_str());
    XMLElement* inertial = body->FirstChildElement("inertial");
    if (!inertial) inertial = body->InsertNewChildElement("inertial");
    inertial->DeleteAttribute("fullinertia");
    inertial->SetAttribute("pos", numbers(m->body_ipos + 3 * id, 3).c_str());
    inertial->SetAttribute("quat", numbers(m->body_iquat + 4 * id, 4).c_str());
    inertial->SetAttribute("mass", numbers(m->body_mass + id, 1).c_str());
    inertial->SetAttribute("diaginertia", numbers(m->body_inertia + 3 * id, 3).c_str());
  }
  int geom = m->body_geomadr[id];
  for (XMLElement* child = body->FirstChildElement(); child; child = child->NextSiblingElement()) {
    const std::string tag = child->Name();
    if (tag == "body") {
      restore_numbers(child, named_id(m, mjOBJ_BODY, child, "body"), m);
    } else if (tag == "joint") {
      const int j = named_id(m, mjOBJ_JOINT, child, "joint");
      if (m->jnt_type[j] == mjJNT_FREE) continue;
      child->SetAttribute("pos", numbers(m->jnt_pos + 3 * j, 3).c_str());
      child->SetAttribute("axis", numbers(m->jnt_axis + 3 * j, 3).c_str());
      if (m->jnt_limited[j]) child->SetAttribute("range", numbers(m->jnt_range + 2 * j, 2).c_str());
      const int dof = m->jnt_dofadr[j];
      child->SetAttribute("damping", numbers(m->dof_damping + dof, 1).c_str());
      child->SetAttribute("frictionloss", numbers(m->dof_frictionloss + dof, 1).c_str());
      child->SetAttribute("armature", numbers(m->dof_armature + dof, 1).c_str());
    } else if (tag == "geom") {
      if (geom < 0 || geom >= m->body_geomadr[id] + m->body_geomnum[id] || m->geom_bodyid[geom] != id)
        throw std::runtime_error("MuJoCo's MJCF has more geoms on a body than its model of the URDF");
      for (const char* frame : {"euler", "axisangle", "xyaxes", "zaxis", "fromto"}) child->DeleteAttribute(frame);
      child->SetAttribute("pos", numbers(m->geom_pos + 3 * geom, 3).c_str());
      child->SetAttribute("quat", numbers(m->geom_quat + 4 * geom, 4).c_str());
      child->SetAttribute("size", numbers(m->geom_size + 3 * geom, geom_size_count(m->geom_type[geom])).c_str());
      ++geom;
    }
  }
}

std::string friction_of(double mu) {
  // MuJoCo's defaults for the torsional and rolling coefficients.
  std::ostringstream out;
  out << mu << " 0.005 0.0001";
  return out.str();
}

void set_geoms(XMLElement* element, const char* contype, const char* conaffinity, const std::string& friction,
               int& geoms) {
  for (XMLElement* child = element->FirstChildElement(); child; child = child->NextSiblingElement()) {
    const std::string tag = child->Name();
    if (tag == "geom") {
      child->SetAttribute("contype", contype);
      child->SetAttribute("conaffinity", conaffinity);
      child->SetAttribute("friction", friction.c_str());
      ++geoms;
    } else if (tag == "body") {
      set_geoms(child, contype, conaffinity, friction, geoms);
    }
  }
}

// The MJCF of the robot with the ground plane and the contact filters.
std::string add_ground(const std::string& mjcf, const mjModel* from, const MujocoScene& scene,
                       std::vector<std::string>& notes) {
  tinyxml2::XMLDocument doc;
  if (doc.Parse(mjcf.c_str(), mjcf.size()) != tinyxml2::XML_SUCCESS)
    throw std::runtime_error(scene.urdf_path + ": cannot read MuJoCo's own MJCF: " + doc.ErrorStr());
  XMLElement* root = doc.FirstChildElement("mujoco");
  XMLElement* world = root ? root->FirstChildElement("worldbody") : nullptr;
  if (!world) throw std::runtime_error(scene.urdf_path + ": MuJoCo's MJCF has no <worldbody>");
  restore_numbers(world, 0, from);

  const std::string friction = friction_of(scene.friction);
  int geoms = 0;
  // Geoms on the world body itself (fused static links of a fixed base) are
  // robot geoms as well.
  set_geoms(world, "1", scene.self_collision ? "1" : "0", friction, geoms);

  XMLElement* ground = doc.NewElement("geom");
  ground->SetAttribute("name", kGroundName);
  ground->SetAttribute("type", "plane");
  ground->SetAttribute("pos", "0 0 0");
  ground->SetAttribute("size", "0 0 1");
  ground->SetAttribute("contype", "0");
  ground->SetAttribute("conaffinity", "1");
  ground->SetAttribute("friction", friction.c_str());
  world->InsertFirstChild(ground);

  notes.push_back("loaded that URDF, saved MuJoCo's model of it as MJCF (mj_saveLastXML) and loaded the MJCF "
                  "with these changes:");
  notes.push_back("wrote the poses, masses, inertias, joint axes, ranges, damping and friction and the geom sizes back from the URDF's "
                  "model at full precision (MuJoCo 2.2's MJCF writer keeps 6 significant digits)");
  notes.push_back(std::string("added the plane \"") + kGroundName +
                  "\" at z = 0, normal +z, infinite, to the world body (contype 0, conaffinity 1)");
  if (scene.self_collision)
    notes.push_back("set contype 1 and conaffinity 1 on the " + std::to_string(geoms) +
                    " robot geoms: they collide with the ground and with each other (MuJoCo's default filter "
                    "still skips pairs of a parent and a child body, and fused links are one body)");
  else
    notes.push_back("set contype 1 and conaffinity 0 on the " + std::to_string(geoms) +
                    " robot geoms: they collide with the ground only, never with each other");
  std::ostringstream mu;
  mu << "friction " << scene.friction << " (sliding), 0.005 (torsional) and 0.0001 (rolling, both MuJoCo's "
     << "defaults) on the ground and on every robot geom; condim 3 (MuJoCo's default: normal force and sliding "
     << "friction, no torsional or rolling friction)";
  notes.push_back(mu.str());
  if (!scene.floating_base)
    notes.push_back("the root link stays welded to the world where the URDF puts it (base_height moves only a "
                    "floating root): the plane at z = 0 meets whatever of the robot reaches below its origin");
  return print(doc);
}

// Throws unless `a` (loaded from the URDF) and `b` (from the MJCF MuJoCo
// saved of it, with the plane as its first geom) are the same multibody:
// bodies, joints, masses, inertias, collision shapes.
void check_same_model(const mjModel* a, const mjModel* b, const std::string& source) {
  std::string differs;
  const auto same = [&differs](const char* what, int index, double x, double y) {
    if (!differs.empty() || std::abs(x - y) <= 1e-12 + 1e-12 * std::max(std::abs(x), std::abs(y))) return;
    std::ostringstream out;
    out << what << "[" << index << "] " << x << " from the URDF, " << y << " from the MJCF";
    differs = out.str();
  };
  same("nq", 0, a->nq, b->nq);
  same("nv", 0, a->nv, b->nv);
  same("nbody", 0, a->nbody, b->nbody);
  same("njnt", 0, a->njnt, b->njnt);
  same("ngeom (plus the plane)", 0, a->ngeom + 1, b->ngeom);
  if (!differs.empty()) throw std::runtime_error(source + ": the MJCF MuJoCo saved of the URDF differs: " + differs);
  for (int i = 0; i < a->nbody; ++i) {
    same("body_parentid", i, a->body_parentid[i], b->body_parentid[i]);
    same("body_mass", i, a->body_mass[i], b->body_mass[i]);
    for (int k = 0; k < 3; ++k) {
      same("body_pos", 3 * i + k, a->body_pos[3 * i + k], b->body_pos[3 * i + k]);
      same("body_ipos", 3 * i + k, a->body_ipos[3 * i + k], b->body_ipos[3 * i + k]);
      same("body_inertia", 3 * i + k, a->body_inertia[3 * i + k], b->body_inertia[3 * i + k]);
    }
    for (int k = 0; k < 4; ++k) {
      same("body_quat", 4 * i + k, a->body_quat[4 * i + k], b->body_quat[4 * i + k]);
      same("body_iquat", 4 * i + k, a->body_iquat[4 * i + k], b->body_iquat[4 * i + k]);
    }
  }
  for (int j = 0; j < a->njnt; ++j) {
    same("jnt_type", j, a->jnt_type[j], b->jnt_type[j]);
    same("jnt_bodyid", j, a->jnt_bodyid[j], b->jnt_bodyid[j]);
    same("jnt_limited", j, a->jnt_limited[j], b->jnt_limited[j]);
    for (int k = 0; k < 2; ++k) same("jnt_range", 2 * j + k, a->jnt_range[2 * j + k], b->jnt_range[2 * j + k]);
    for (int k = 0; k < 3; ++k) same("jnt_axis", 3 * j + k, a->jnt_axis[3 * j + k], b->jnt_axis[3 * j + k]);
  }
  for (int v = 0; v < a->nv; ++v) {
    same("dof_damping", v, a->dof_damping[v], b->dof_damping[v]);
    same("dof_armature", v, a->dof_armature[v], b->dof_armature[v]);
    same("dof_frictionloss", v, a->dof_frictionloss[v], b->dof_frictionloss[v]);
  }
  for (int g = 0; g < a->ngeom; ++g) {
    same("geom_type", g, a->geom_type[g], b->geom_type[g + 1]);
    same("geom_bodyid", g, a->geom_bodyid[g], b->geom_bodyid[g + 1]);
    for (int k = 0; k < 3; ++k) {
      same("geom_size", 3 * g + k, a->geom_size[3 * g + k], b->geom_size[3 * (g + 1) + k]);
      same("geom_pos", 3 * g + k, a->geom_pos[3 * g + k], b->geom_pos[3 * (g + 1) + k]);
    }
    for (int k = 0; k < 4; ++k) same("geom_quat", 4 * g + k, a->geom_quat[4 * g + k], b->geom_quat[4 * (g + 1) + k]);
  }
  if (!differs.empty()) throw std::runtime_error(source + ": the MJCF MuJoCo saved of the URDF differs: " + differs);
}

// A hinge or slide joint's drive: qpos and qvel addresses and the target.
struct Drive {
  int qpos = 0;
  int dof = 0;
  double target = 0.0;
};

std::vector<Drive> drives_of(const mjModel* m, const MujocoScene& scene) {
  std::vector<Drive> drives;
  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
    Drive drive{m->jnt_qposadr[j], m->jnt_dofadr[j], 0.0};
    const char* name = mj_id2name(m, mjOBJ_JOINT, j);
    for (const auto& [joint, target] : scene.targets)
      if (name && joint == name) drive.target = target;
    drives.push_back(drive);
  }
  return drives;
}

// The MuJoCo body of a link named in links_without_gravity.
int weightless_body(const mjModel* m, const std::string& link) {
  const int id = mj_name2id(m, mjOBJ_BODY, link.c_str());
  if (id <= 0) throw std::runtime_error("MuJoCo's model has no body \"" + link + "\" to switch gravity off on");
  return id;
}

// The initial state: the drive targets, the floating root at base_height.
void reset(const mjModel* m, mjData* d, const std::vector<Drive>& drives, double base_height) {
  mj_resetData(m, d);
  for (int j = 0; j < m->njnt; ++j)
    if (m->jnt_type[j] == mjJNT_FREE) d->qpos[m->jnt_qposadr[j] + 2] = base_height;
  for (const Drive& drive : drives) d->qpos[drive.qpos] = drive.target;
}

// Without mju_user_warning, MuJoCo prints each warning and appends it to
// MUJOCO_LOG.TXT in the working directory. While the peer runs its
// warnings come here instead, and the report gives them with the counts
// of d->warning.
constexpr std::size_t kWarningMessagesKept = 4;
std::mutex warning_mutex;
std::vector<std::string>* warning_sink = nullptr;

void collect_warning(const char* message) {
  const std::lock_guard<std::mutex> lock(warning_mutex);
  if (warning_sink && warning_sink->size() < kWarningMessagesKept &&
      std::find(warning_sink->begin(), warning_sink->end(), message) == warning_sink->end())
    warning_sink->emplace_back(message);
}

class CollectedWarnings {
 public:
  explicit CollectedWarnings(std::vector<std::string>& sink) : previous_(mju_user_warning) {
    const std::lock_guard<std::mutex> lock(warning_mutex);
    warning_sink = &sink;
    mju_user_warning = collect_warning;
  }
  ~CollectedWarnings() {
    const std::lock_guard<std::mutex> lock(warning_mutex);
    mju_user_warning = previous_;
    warning_sink = nullptr;
  }
  CollectedWarnings(const CollectedWarnings&) = delete;
  CollectedWarnings& operator=(const CollectedWarnings&) = delete;

 private:
  void (*previous_)(const char*);
};

constexpr const char* kWarningNames[mjNWARNING] = {
    "mjWARN_INERTIA", "mjWARN_CONTACTFULL", "mjWARN_CNSTRFULL", "mjWARN_VGEOMFULL",
    "mjWARN_BADQPOS", "mjWARN_BADQVEL",     "mjWARN_BADQACC",   "mjWARN_BADCTRL"};

// Sums over the steps of one run of one mjData.
struct Sums {
  double base_height = 0.0;  // of the root's z after each step
  double contacts = 0.0;     // of d->ncon of each step
  long resets = 0;           // steps after which d->time went back: mj_step reset the data (a bad qpos, qvel or qacc)
};

// `steps` steps with the PD applied explicitly through qfrc_applied;
// `root_z` is the qpos address of the floating root's z, -1 without one.
Sums step_with_pd(const mjModel* m, mjData* d, const std::vector<Drive>& drives, double kp, double kd, long steps,
                  int root_z, const std::vector<int>& weightless) {
  Sums sums;
  for (long s = 0; s < steps; ++s) {
    for (const Drive& drive : drives)
      d->qfrc_applied[drive.dof] = kp * (drive.target - d->qpos[drive.qpos]) - kd * d->qvel[drive.dof];
    // -m g at the COM (xfrc_applied acts there, world axes), written every
    // step: an mj_step that resets the data clears it
    for (int body : weightless)
      for (int k = 0; k < 3; ++k) d->xfrc_applied[6 * body + k] = -m->body_mass[body] * m->opt.gravity[k];
    const double time = d->time;
    mj_step(m, d);
    if (d->time <= time) ++sums.resets;
    if (root_z >= 0) sums.base_height += d->qpos[root_z];
    sums.contacts += d->ncon;
  }
  return sums;
}

double median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// What went wrong over the runs of all data: resets and warnings by kind.
struct Trouble {
  long resets = 0;
  long warnings[mjNWARNING] = {};
};

// Wall time of `threads` threads each stepping its own data `steps` times,
// from a common start until the last one finishes; `first` gets the sums
// of the first data, `trouble` adds the resets and warnings of all of them.
double time_threads(const mjModel* m, std::vector<DataPtr>& data, const std::vector<Drive>& drives,
                    const MujocoScene& scene, long steps, int root_z, const std::vector<int>& weightless, Sums& first,
                    Trouble& trouble) {
  std::atomic<int> ready{0};
  std::atomic<bool> go{false};
  std::vector<std::thread> workers;
  std::vector<Sums> sums(data.size());
  for (std::size_t i = 0; i < data.size(); ++i) {
    reset(m, data[i].get(), drives, scene.base_height);
    workers.emplace_back([&, i] {
      ready.fetch_add(1);
      while (!go.load(std::memory_order_acquire)) std::this_thread::yield();
      sums[i] = step_with_pd(m, data[i].get(), drives, scene.kp, scene.kd, steps, root_z, weightless);
    });
  }
  while (ready.load() < static_cast<int>(data.size())) std::this_thread::yield();
  const auto start = std::chrono::steady_clock::now();
  go.store(true, std::memory_order_release);
  for (std::thread& w : workers) w.join();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  first = sums.front();
  for (std::size_t i = 0; i < data.size(); ++i) {
    trouble.resets += sums[i].resets;
    for (int w = 0; w < mjNWARNING; ++w) trouble.warnings[w] += data[i]->warning[w].number;
  }
  return seconds;
}

}  // namespace

MujocoReport run_mujoco_peer(const MujocoScene& scene, const std::vector<int>& threads, long steps, int repeats) {
  MujocoReport report;
  const CollectedWarnings collected(report.warning_messages);
  report.version = mj_versionString();
  const std::string xml = prepare_urdf(scene, report.notes);
  ModelPtr model = load_from_memory(xml, scene.urdf_path);
  if (scene.ground) {
    const std::string mjcf = add_ground(save_last_xml(model.get(), scene.urdf_path), model.get(), scene, report.notes);
    ModelPtr with_ground = load_from_memory(mjcf, scene.urdf_path + " (as MJCF with the ground)", kVfsMjcfName);
    check_same_model(model.get(), with_ground.get(), scene.urdf_path);
    report.notes.push_back("checked: the MJCF loads as the same bodies, joints, masses, inertias and collision "
                           "shapes as the URDF, plus the plane");
    model = std::move(with_ground);
  }
  mjModel* m = model.get();
  if (scene.floating_base && (m->njnt == 0 || m->jnt_type[0] != mjJNT_FREE))
    throw std::runtime_error("MuJoCo did not make the root a free joint");
  m->opt.timestep = scene.dt;
  if (!scene.ground) m->opt.disableflags |= mjDSBL_CONTACT;
  for (int k = 0; k < 3; ++k) m->opt.gravity[k] = scene.gravity[k];
  std::vector<int> weightless;
  if (!scene.links_without_gravity.empty()) {
    std::string links;
    for (const std::string& link : scene.links_without_gravity) {
      weightless.push_back(weightless_body(m, link));
      links += (links.empty() ? "\"" : ", \"") + link + "\"";
    }
    report.notes.push_back("gravity cancelled on " + links +
                           " by the force -m g at each one's COM through xfrc_applied before every mj_step (MuJoCo "
                           "2.2.2 has no per-body gravity switch)");
  }
  report.nq = m->nq;
  report.nv = m->nv;
  report.nbody = m->nbody - 1;  // without the world
  std::ostringstream options;
  if (scene.ground)
    options << "contacts enabled with MuJoCo's defaults (" << (m->opt.cone == mjCONE_PYRAMIDAL ? "pyramidal" : "elliptic")
            << " friction cone, " << (m->opt.solver == mjSOL_NEWTON ? "Newton" : m->opt.solver == mjSOL_CG ? "CG" : "PGS")
            << " solver, at most " << m->opt.iterations << " iterations, geom margin 0, default solref and solimp)";
  else
    options << "contacts disabled (mjDSBL_CONTACT)";
  options << ", timestep " << scene.dt << " s, gravity (" << scene.gravity[0] << ", " << scene.gravity[1] << ", "
          << scene.gravity[2] << ") m/s², integrator "
          << (m->opt.integrator == mjINT_EULER ? "Euler" : "not Euler") << ", " << m->nu << " actuators";
  report.notes.push_back(options.str());
  report.notes.push_back("PD kp (q_target - q) - kd v applied explicitly through qfrc_applied before every "
                         "mj_step, on every hinge and slide joint");

  const std::vector<Drive> drives = drives_of(m, scene);
  const int root_z = m->njnt > 0 && m->jnt_type[0] == mjJNT_FREE ? m->jnt_qposadr[0] + 2 : -1;
  Trouble timed;  // the warm-ups' are not reported
  for (int k : threads) {
    std::vector<DataPtr> data;
    for (int t = 0; t < k; ++t) data.emplace_back(mj_makeData(m));
    Sums sums;
    Trouble warm_up;
    time_threads(m, data, drives, scene, std::max(1L, steps / 10), root_z, weightless, sums, warm_up);
    std::vector<double> seconds;
    for (int r = 0; r < repeats; ++r)
      seconds.push_back(time_threads(m, data, drives, scene, steps, root_z, weightless, sums, timed));
    report.timings.push_back({k, steps, median(seconds)});
    report.mean_base_height = steps > 0 ? sums.base_height / static_cast<double>(steps) : 0.0;
    report.mean_contacts = steps > 0 ? sums.contacts / static_cast<double>(steps) : 0.0;
    double error = 0.0;
    for (const Drive& drive : drives) error = std::max(error, std::abs(data.front()->qpos[drive.qpos] - drive.target));
    report.max_pose_error = error;
  }
  report.resets = timed.resets;
  for (int w = 0; w < mjNWARNING; ++w)
    if (timed.warnings[w] > 0) report.warnings.emplace_back(kWarningNames[w], timed.warnings[w]);
  report.diverged = timed.resets > 0 || timed.warnings[mjWARN_BADQPOS] > 0 || timed.warnings[mjWARN_BADQVEL] > 0 ||
                    timed.warnings[mjWARN_BADQACC] > 0;
  return report;
}

}  // namespace lockstep::cli
