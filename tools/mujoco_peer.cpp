// `lockstep bench`'s MuJoCo peer (tools/mujoco_peer.hpp).
#include "tools/mujoco_peer.hpp"

#include <mujoco/mujoco.h>
#include <tinyxml2.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace lockstep::cli {

namespace {

using tinyxml2::XMLElement;

constexpr const char* kVfsName = "lockstep_peer.urdf";

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
  notes.push_back("removed " + std::to_string(visuals) + " <visual> and " + std::to_string(meshes) +
                  " mesh <collision> elements (their mesh files are not needed without contacts)");

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

ModelPtr load_from_memory(const std::string& xml, const std::string& source) {
  // mjVFS holds 2000 file names inline (about 2 MB): keep it off the stack.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), kVfsName, static_cast<int>(xml.size())) != 0)
    throw std::runtime_error("MuJoCo: cannot create the in-memory file for " + source);
  const int index = mj_findFileVFS(vfs.get(), kVfsName);
  std::copy(xml.begin(), xml.end(), static_cast<char*>(vfs->filedata[index]));
  char error[1000] = "";
  ModelPtr model(mj_loadXML(kVfsName, vfs.get(), error, sizeof error));
  mj_deleteVFS(vfs.get());
  if (!model) throw std::runtime_error("MuJoCo cannot load " + source + ": " + error);
  return model;
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

// The initial state: the drive targets, the floating root at base_height.
void reset(const mjModel* m, mjData* d, const std::vector<Drive>& drives, double base_height) {
  mj_resetData(m, d);
  for (int j = 0; j < m->njnt; ++j)
    if (m->jnt_type[j] == mjJNT_FREE) d->qpos[m->jnt_qposadr[j] + 2] = base_height;
  for (const Drive& drive : drives) d->qpos[drive.qpos] = drive.target;
}

// `steps` steps with the PD applied explicitly through qfrc_applied.
void step_with_pd(const mjModel* m, mjData* d, const std::vector<Drive>& drives, double kp, double kd, long steps) {
  for (long s = 0; s < steps; ++s) {
    for (const Drive& drive : drives)
      d->qfrc_applied[drive.dof] = kp * (drive.target - d->qpos[drive.qpos]) - kd * d->qvel[drive.dof];
    mj_step(m, d);
  }
}

double median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// Wall time of `threads` threads each stepping its own data `steps` times,
// from a common start until the last one finishes.
double time_threads(const mjModel* m, std::vector<DataPtr>& data, const std::vector<Drive>& drives,
                    const MujocoScene& scene, long steps) {
  std::atomic<int> ready{0};
  std::atomic<bool> go{false};
  std::vector<std::thread> workers;
  for (DataPtr& d : data) {
    reset(m, d.get(), drives, scene.base_height);
    workers.emplace_back([&, d = d.get()] {
      ready.fetch_add(1);
      while (!go.load(std::memory_order_acquire)) std::this_thread::yield();
      step_with_pd(m, d, drives, scene.kp, scene.kd, steps);
    });
  }
  while (ready.load() < static_cast<int>(data.size())) std::this_thread::yield();
  const auto start = std::chrono::steady_clock::now();
  go.store(true, std::memory_order_release);
  for (std::thread& w : workers) w.join();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

MujocoReport run_mujoco_peer(const MujocoScene& scene, const std::vector<int>& threads, long steps, int repeats) {
  MujocoReport report;
  report.version = mj_versionString();
  const std::string xml = prepare_urdf(scene, report.notes);
  ModelPtr model = load_from_memory(xml, scene.urdf_path);
  mjModel* m = model.get();
  if (scene.floating_base && (m->njnt == 0 || m->jnt_type[0] != mjJNT_FREE))
    throw std::runtime_error("MuJoCo did not make the root a free joint");
  m->opt.timestep = scene.dt;
  m->opt.disableflags |= mjDSBL_CONTACT;
  report.nq = m->nq;
  report.nv = m->nv;
  report.nbody = m->nbody - 1;  // without the world
  std::ostringstream options;
  options << "contacts disabled (mjDSBL_CONTACT), timestep " << scene.dt << " s, integrator "
          << (m->opt.integrator == mjINT_EULER ? "Euler" : "not Euler") << ", " << m->nu << " actuators";
  report.notes.push_back(options.str());
  report.notes.push_back("PD kp (q_target - q) - kd v applied explicitly through qfrc_applied before every "
                         "mj_step, on every hinge and slide joint");

  const std::vector<Drive> drives = drives_of(m, scene);
  for (int k : threads) {
    std::vector<DataPtr> data;
    for (int t = 0; t < k; ++t) data.emplace_back(mj_makeData(m));
    time_threads(m, data, drives, scene, std::max(1L, steps / 10));  // warm-up
    std::vector<double> seconds;
    for (int r = 0; r < repeats; ++r) seconds.push_back(time_threads(m, data, drives, scene, steps));
    report.timings.push_back({k, steps, median(seconds)});
    double error = 0.0;
    for (const Drive& drive : drives) error = std::max(error, std::abs(data.front()->qpos[drive.qpos] - drive.target));
    report.max_pose_error = error;
  }
  return report;
}

}  // namespace lockstep::cli
