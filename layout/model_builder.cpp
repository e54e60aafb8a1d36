#include "layout/model_builder.hpp"
#include "layout/rotation.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <tuple>
#include <unordered_map>
#include <unordered_set>
#include <utility>

namespace lockstep {

std::vector<int> body_head_links(const ArticulationSpec& spec) {
  const int n = static_cast<int>(spec.links.size());
  std::unordered_map<std::string, int> index;
  std::vector<int> heads(n, spec.floating_base ? 0 : -1);
  for (int i = 0; i < n; ++i) {
    const LinkSpec& link = spec.links[i];
    index.emplace(link.name, i);
    if (i == 0) continue;
    heads[i] = link.joint.type != JointType::Fixed ? i : heads[index.at(link.parent)];
  }
  return heads;
}

namespace {

bool is_moving(JointType type) {
  return type == JointType::Revolute || type == JointType::Prismatic || type == JointType::Spherical;
}

bool is_one_dof(JointType type) { return type == JointType::Revolute || type == JointType::Prismatic; }

// "file.urdf" or "articulation 'arm'": the prefix of every message about `spec`.
std::string where(const ArticulationSpec& spec) {
  if (!spec.source.empty()) return spec.source;
  return "articulation '" + spec.name + "'";
}

// "file:LINE" where the spec came from a file and knows the line
std::string where(const ArticulationSpec& spec, int line) {
  return line > 0 && !spec.source.empty() ? spec.source + ":" + std::to_string(line) : where(spec);
}

std::string link_ctx(const ArticulationSpec& spec, const LinkSpec& link) {
  return where(spec, link.source_line) + ": link '" + link.name + "'";
}

std::string joint_ctx(const ArticulationSpec& spec, const LinkSpec& link) {
  return where(spec, link.joint.source_line) + ": joint '" + link.joint.name + "' (to link '" + link.name + "')";
}

bool finite(const Eigen::Isometry3d& pose) { return pose.matrix().allFinite(); }

void check_pose(const Eigen::Isometry3d& pose, const std::string& ctx, const char* what) {
  if (!finite(pose)) throw ModelError(ctx + ": " + what + " has a non-finite entry");
  if (!is_rotation(pose.linear())) throw ModelError(ctx + ": " + what + " rotation is not a proper rotation matrix");
}

// Minimal rotation R with R * e_z = a (a unit); rotation by pi about x for a = -z.
Eigen::Matrix3d rotation_z_to(const Eigen::Vector3d& a) {
  const Eigen::Vector3d v = Eigen::Vector3d::UnitZ().cross(a);
  const double s = v.norm();
  if (s == 0.0) {
    if (a.z() > 0.0) return Eigen::Matrix3d::Identity();
    return Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  }
  return Eigen::AngleAxisd(std::atan2(s, a.z()), v / s).toRotationMatrix();
}

Eigen::Isometry3d pure_rotation(const Eigen::Matrix3d& r) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = r;
  return t;
}

// Eigenvalues (ascending) of the symmetric part of an inertia matrix.
Eigen::Vector3d principal_moments(const Eigen::Matrix3d& inertia) {
  const Eigen::Matrix3d sym = 0.5 * (inertia + inertia.transpose());
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(sym, Eigen::EigenvaluesOnly).eigenvalues();
}

std::string num(double v) {
  std::ostringstream out;
  out.precision(17);
  out << v;
  return out.str();
}

// One body's accumulated inertial contributions (body frame).
struct Lump {
  struct Part {
    double mass;
    Eigen::Vector3d com;
    Eigen::Matrix3d inertia;
  };
  std::vector<Part> parts;

  void result(double& mass, Eigen::Vector3d& com, Eigen::Matrix3d& inertia) const {
    mass = 0.0;
    com.setZero();
    inertia.setZero();
    int massive = 0;
    const Part* only = nullptr;
    for (const Part& p : parts) {
      mass += p.mass;
      if (p.mass > 0.0) {
        ++massive;
        only = &p;
      }
    }
    if (massive == 1) {
      com = only->com;  // exact: no m * c / m round-off
    } else if (mass > 0.0) {
      for (const Part& p : parts) com += p.mass * p.com;
      com /= mass;
    }
    for (const Part& p : parts) {
      inertia += p.inertia;
      if (p.mass > 0.0 && massive > 1) {
        const Eigen::Vector3d d = p.com - com;
        inertia += p.mass * (d.squaredNorm() * Eigen::Matrix3d::Identity() - d * d.transpose());
      }
    }
  }
};

}  // namespace

ModelBuilder::ModelBuilder(BuildOptions options) : options_(options) {}

void ModelBuilder::set_gravity(const Eigen::Vector3d& gravity) {
  if (!gravity.allFinite()) throw ModelError("gravity has a non-finite component");
  gravity_ = gravity;
}

void ModelBuilder::warn_or_throw(const std::string& problem, const std::string& kept) {
  if (options_.strict) throw ModelError(problem + " (an error in strict mode)");
  warnings_.push_back(kept.empty() ? problem : problem + "; " + kept);
}

std::string ModelBuilder::root_joint_name(const ArticulationSpec& spec) {
  return spec.links.front().joint.name.empty() ? spec.name + "_root" : spec.links.front().joint.name;
}

void ModelBuilder::check_inertial(const ArticulationSpec& spec, const LinkSpec& link) const {
  const std::string ctx = link_ctx(spec, link);
  const InertialSpec& in = link.inertial;
  if (!std::isfinite(in.mass)) throw ModelError(ctx + ": mass is not finite");
  if (in.mass < 0.0) throw ModelError(ctx + ": negative mass " + num(in.mass));
  check_pose(in.origin, ctx, "inertial origin");
  if (!in.inertia.allFinite()) throw ModelError(ctx + ": inertia has a non-finite entry");
  const Eigen::Vector3d ev = principal_moments(in.inertia);
  const double scale = std::max(ev.cwiseAbs().maxCoeff(), std::numeric_limits<double>::min());
  const double asym = (in.inertia - in.inertia.transpose()).cwiseAbs().maxCoeff();
  if (asym > 1e-9 * scale) throw ModelError(ctx + ": inertia matrix is not symmetric");
  if (ev[0] < -options_.inertia_eigen_tolerance * scale)
    throw ModelError(ctx + ": inertia matrix is not positive semi-definite (eigenvalue " + num(ev[0]) + ")");
  for (const auto& [what, value] : {std::pair{"linear damping", link.linear_damping},
                                    std::pair{"angular damping", link.angular_damping}})
    if (!(value >= 0.0 && std::isfinite(value)))
      throw ModelError(ctx + ": " + what + " must be a finite number >= 0, got " + num(value));
}

void ModelBuilder::check_joint(const ArticulationSpec& spec, const LinkSpec& link) const {
  const JointSpec& j = link.joint;
  const std::string ctx = joint_ctx(spec, link);
  if (j.name.empty()) throw ModelError(link_ctx(spec, link) + ": the joint to this link has no name");
  if (j.type == JointType::Free)
    throw ModelError(ctx + ": floating joint inside the tree is not supported (only the root may float)");
  check_pose(j.origin, ctx, "origin");
  if (!j.axis.allFinite()) throw ModelError(ctx + ": axis has a non-finite component");
  if (is_one_dof(j.type) && j.axis.cwiseAbs().maxCoeff() == 0.0) throw ModelError(ctx + ": zero axis");
  if (is_one_dof(j.type) && j.limited) {
    if (!std::isfinite(j.lower) || !std::isfinite(j.upper))
      throw ModelError(ctx + ": position limits must be finite numbers");
    if (j.lower > j.upper)
      throw ModelError(ctx + ": lower limit " + num(j.lower) + " exceeds upper limit " + num(j.upper));
  }
  const std::pair<const char*, double> nonneg[] = {{"velocity limit", j.velocity_limit},
                                                   {"effort limit", j.effort_limit},
                                                   {"damping", j.damping},
                                                   {"friction", j.friction},
                                                   {"armature", j.armature},
                                                   {"spring stiffness", j.spring_stiffness}};
  for (const auto& [what, v] : nonneg) {
    if (std::isnan(v) || v == -Model::kInfinity) throw ModelError(ctx + ": " + what + " is not a number");
    if ((v == Model::kInfinity) && std::string(what).find("limit") == std::string::npos)
      throw ModelError(ctx + ": " + what + " is infinite");
    if (v < 0.0) throw ModelError(ctx + ": negative " + what + " " + num(v));
  }
  if (!std::isfinite(j.spring_rest)) throw ModelError(ctx + ": spring rest position is not finite");
  if (j.spring_stiffness != 0.0 && !is_one_dof(j.type))
    throw ModelError(ctx + ": a spring must be on a revolute or prismatic joint");
  if (!j.mimic.leader_joint.empty()) {
    if (!is_one_dof(j.type)) throw ModelError(ctx + ": a mimic joint must be revolute or prismatic");
    if (j.mimic.leader_joint == j.name) throw ModelError(ctx + ": mimics itself");
    if (!std::isfinite(j.mimic.multiplier) || !std::isfinite(j.mimic.offset))
      throw ModelError(ctx + ": mimic multiplier/offset is not finite");
  }
}

int ModelBuilder::add_articulation(const ArticulationSpec& spec_in) {
  ArticulationSpec spec = spec_in;
  if (spec.name.empty()) spec.name = "articulation" + std::to_string(articulations_.size());
  const std::string src = where(spec);
  if (spec.links.empty()) throw ModelError(src + ": articulation has no links");
  for (const ArticulationSpec& other : articulations_)
    if (other.name == spec.name) throw ModelError(src + ": duplicate articulation name '" + spec.name + "'");
  check_pose(spec.root_pose, src, "root pose");

  // Topology: one root first, parents listed before children, unique names.
  std::unordered_map<std::string, int> index;
  const int n = static_cast<int>(spec.links.size());
  std::vector<int> parent(n, -1);
  for (int i = 0; i < n; ++i) {
    const LinkSpec& link = spec.links[i];
    if (link.name.empty()) throw ModelError(src + ": link " + std::to_string(i) + " has no name");
    if (!index.emplace(link.name, i).second) throw ModelError(link_ctx(spec, link) + ": duplicate link name");
    if (i == 0) {
      if (!link.parent.empty())
        throw ModelError(link_ctx(spec, link) + ": the first link must be the root (no parent), but its parent is '" +
                         link.parent + "'");
      continue;
    }
    if (link.parent.empty())
      throw ModelError(link_ctx(spec, link) + ": several roots ('" + spec.links[0].name + "' and '" + link.name + "')");
    if (link.parent == link.name) throw ModelError(link_ctx(spec, link) + ": the link is its own parent");
    const auto it = index.find(link.parent);
    if (it == index.end()) {
      bool later = false;
      for (int k = i + 1; k < n; ++k) later = later || spec.links[k].name == link.parent;
      throw ModelError(link_ctx(spec, link) + (later ? ": parent '" + link.parent + "' is listed after the child"
                                                     : ": parent link '" + link.parent + "' does not exist"));
    }
    parent[i] = it->second;
  }

  // Model-wide unique link and joint names.
  std::unordered_map<std::string, std::string> links_seen, joints_seen;  // name -> articulation
  for (const ArticulationSpec& other : articulations_) {
    for (std::size_t i = 0; i < other.links.size(); ++i) {
      links_seen.emplace(other.links[i].name, other.name);
      if (i == 0) {
        if (other.floating_base) joints_seen.emplace(root_joint_name(other), other.name);
      } else {
        joints_seen.emplace(other.links[i].joint.name, other.name);
      }
    }
  }
  for (int i = 0; i < n; ++i) {
    const LinkSpec& link = spec.links[i];
    const auto l = links_seen.find(link.name);
    if (l != links_seen.end())
      throw ModelError(link_ctx(spec, link) + ": link name already used in articulation '" + l->second +
                       "' (articulation '" + spec.name + "')");
    const bool named = i > 0 || spec.floating_base;
    if (!named) continue;
    if (i > 0) check_joint(spec, link);
    const std::string jname = i == 0 ? root_joint_name(spec) : link.joint.name;
    const auto j = joints_seen.find(jname);
    if (j != joints_seen.end()) {
      const std::string in = j->second == spec.name ? "this articulation" : "articulation '" + j->second + "'";
      throw ModelError(where(spec) + ": joint '" + jname + "' (to link '" + link.name + "'): joint name already used in " +
                       in + " (articulation '" + spec.name + "')");
    }
    joints_seen.emplace(jname, spec.name);
  }

  // Inertials, shapes.
  for (const LinkSpec& link : spec.links) {
    check_inertial(spec, link);
    for (std::size_t s = 0; s < link.shapes.size(); ++s) {
      const Shape& shape = link.shapes[s];
      const std::string ctx = link_ctx(spec, link) + ": collision shape " + std::to_string(s);
      check_pose(shape.pose, ctx, "pose");
      if (!shape.size.allFinite() || !shape.mesh_scale.allFinite())
        throw ModelError(ctx + ": non-finite size or scale");
      if ((shape.size.array() < 0.0).any()) throw ModelError(ctx + ": negative size");
    }
  }

  // Mass of each link's subtree (fused or not): moving joints need some.
  std::vector<double> subtree(n, 0.0);
  for (int i = n - 1; i >= 0; --i) {
    subtree[i] += spec.links[i].inertial.mass;
    if (i > 0) subtree[parent[i]] += subtree[i];
  }
  for (int i = 1; i < n; ++i)
    if (is_moving(spec.links[i].joint.type) && subtree[i] == 0.0)
      throw ModelError(joint_ctx(spec, spec.links[i]) + ": moves a massless subtree (link '" + spec.links[i].name +
                       "' and its descendants have no mass)");
  if (spec.floating_base && subtree[0] == 0.0)
    throw ModelError(src + ": floating articulation '" + spec.name + "' has no mass");

  // Tolerated imperfections.
  const std::vector<int> heads = body_head_links(spec);
  std::vector<bool> on_world(n);
  for (int i = 0; i < n; ++i) on_world[i] = heads[i] < 0;
  // Gravity and link damping are set per moving body: a link with mass
  // fused into one must agree with the link the body is named after, whose
  // settings the body takes (a massless link has no weight and nothing to
  // damp, and links fused into the world carry nothing that moves).
  auto gravity_text = [](const LinkSpec& l) { return std::string(l.gravity ? "on" : "off"); };
  auto damping_text = [](const LinkSpec& l) {
    return "linear " + num(l.linear_damping) + ", angular " + num(l.angular_damping);
  };
  for (int i = 1; i < n; ++i) {
    const LinkSpec& link = spec.links[i];
    if (on_world[i] || link.inertial.mass == 0.0) continue;
    const LinkSpec& head = spec.links[heads[i]];
    const bool damping_differs =
        link.linear_damping != head.linear_damping || link.angular_damping != head.angular_damping;
    for (const auto& [what, differs, text] : {std::tuple{"gravity", link.gravity != head.gravity, +gravity_text},
                                              std::tuple{"damping", damping_differs, +damping_text}})
      if (differs)
        throw ModelError(link_ctx(spec, link) + ": " + what + " " + text(link) + ", but it is fixed to link '" +
                         head.name + "', which has " + what + " " + text(head) + " (" + what +
                         " is set per moving body: every link with mass fixed to it must agree)");
  }
  for (int i = 0; i < n; ++i) {
    const LinkSpec& link = spec.links[i];
    const InertialSpec& in = link.inertial;
    if (in.mass == 0.0) {
      if (i > 0 && link.joint.type == JointType::Fixed && !on_world[i])
        warn_or_throw(link_ctx(spec, link) + ": massless link on a fixed joint (a frame only)");
      continue;
    }
    const Eigen::Vector3d ev = principal_moments(in.inertia);
    const double scale = ev.cwiseAbs().maxCoeff();
    if (in.inertia.cwiseAbs().maxCoeff() <= 1e-12 * std::max(1.0, in.mass)) {
      warn_or_throw(link_ctx(spec, link) + ": point mass (mass " + num(in.mass) + " with no rotational inertia)");
      continue;
    }
    if (ev[0] + ev[1] < ev[2] - 1e-9 * scale)
      warn_or_throw(link_ctx(spec, link) + ": principal moments of inertia (" + num(ev[0]) + ", " + num(ev[1]) + ", " +
                        num(ev[2]) + ") violate the triangle inequality",
                    "kept as written");
  }

  articulations_.push_back(std::move(spec));
  return static_cast<int>(articulations_.size()) - 1;
}

Model ModelBuilder::finalize() const {
  Model m;
  m.gravity = gravity_;

  struct Pending {  // mimic tags resolved once every joint is known
    int art, link, dof;
  };
  std::vector<Pending> pending;
  std::vector<Lump> lumps;

  for (int a = 0; a < static_cast<int>(articulations_.size()); ++a) {
    const ArticulationSpec& spec = articulations_[a];
    const int n = static_cast<int>(spec.links.size());
    std::unordered_map<std::string, int> index;
    std::vector<std::vector<int>> children(n);
    for (int i = 0; i < n; ++i) index.emplace(spec.links[i].name, i);
    for (int i = 1; i < n; ++i) children[index.at(spec.links[i].parent)].push_back(i);

    // Depth-first order from the root, children in listed order.
    std::vector<int> order;
    std::vector<int> stack{0};
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      order.push_back(i);
      for (auto c = children[i].rbegin(); c != children[i].rend(); ++c) stack.push_back(*c);
    }

    Articulation art;
    art.name = spec.name;
    art.floating_base = spec.floating_base;
    art.first_body = m.nbody;
    art.root_frame = static_cast<int>(m.frame_name.size());

    std::vector<int> frame_of(n, -1);
    for (const int i : order) {
      const LinkSpec& link = spec.links[i];
      // the root's joint gives only the Free joint's name (root_joint_name):
      // its DOFs take the defaults, as those of a joint without a spec
      static const JointSpec kRootJoint;
      const JointSpec& j = i == 0 ? kRootJoint : link.joint;
      const int f = static_cast<int>(m.frame_name.size());
      frame_of[i] = f;
      const int pf = i == 0 ? -1 : frame_of[index.at(link.parent)];
      int body = -1;
      Eigen::Isometry3d placement = Eigen::Isometry3d::Identity();
      JointType ftype = JointType::Fixed;
      std::string jname = i == 0 ? "" : j.name;
      Eigen::Vector3d axis = i == 0 ? Eigen::Vector3d::Zero() : j.axis;

      auto new_body = [&](JointType type, const std::string& name, int parent_body, const Eigen::Isometry3d& at) {
        const int b = m.nbody++;
        m.body_parent.push_back(parent_body);
        m.body_joint.push_back(type);
        m.body_placement.push_back(at);
        m.body_q_offset.push_back(m.nq);
        m.body_dof_offset.push_back(m.nv);
        m.body_articulation.push_back(a);
        m.body_frame.push_back(f);
        m.joint_name.push_back(name);
        m.joint_by_name[name] = b;
        m.body_gravity.push_back(link.gravity ? 1 : 0);
        m.body_linear_damping.push_back(link.linear_damping);
        m.body_angular_damping.push_back(link.angular_damping);
        const int nv = joint_nv(type);
        for (int k = 0; k < nv; ++k) {
          const std::string dname = nv == 1 ? name : name + "[" + std::to_string(k) + "]";
          const int d = m.nv + k;
          int dparent = d - 1;
          if (k == 0) dparent = parent_body < 0 ? -1 : m.body_dof_offset[parent_body] + joint_nv(m.body_joint[parent_body]) - 1;
          m.dof_name.push_back(dname);
          if (!m.dof_by_name.emplace(dname, d).second)
            throw ModelError(where(spec) + ": joint '" + name + "': its DOF name '" + dname +
                             "' is already another DOF's (rename one of the joints)");
          m.dof_body.push_back(b);
          m.dof_parent.push_back(dparent);
          const bool limited = is_one_dof(type) && j.limited;
          m.dof_lower.push_back(limited ? j.lower : -Model::kInfinity);
          m.dof_upper.push_back(limited ? j.upper : Model::kInfinity);
          m.dof_velocity_limit.push_back(j.velocity_limit);
          m.dof_effort_limit.push_back(j.effort_limit);
          m.dof_damping.push_back(j.damping);
          m.dof_friction.push_back(j.friction);
          m.dof_armature.push_back(j.armature);
          m.dof_spring_stiffness.push_back(j.spring_stiffness);
          m.dof_spring_rest.push_back(j.spring_rest);
        }
        m.nq += joint_nq(type);
        m.nv += nv;
        lumps.emplace_back();
        return b;
      };

      if (i == 0) {
        if (spec.floating_base) {
          ftype = JointType::Free;
          jname = root_joint_name(spec);
          body = new_body(JointType::Free, jname, -1, Eigen::Isometry3d::Identity());
        } else {
          placement = spec.root_pose;
        }
      } else if (is_moving(j.type)) {
        ftype = j.type;
        Eigen::Matrix3d ra = Eigen::Matrix3d::Identity();
        // scaled by its largest entry first: the norm of (1e200, 0, 0) or
        // (1.7e308, 1.7e308, 0) overflows, that of 1e-200 underflows
        if (is_one_dof(j.type)) ra = rotation_z_to((j.axis / j.axis.cwiseAbs().maxCoeff()).normalized());
        const Eigen::Isometry3d at = m.frame_placement[pf] * j.origin * pure_rotation(ra);
        body = new_body(j.type, j.name, m.frame_body[pf], at);
        placement = pure_rotation(ra.transpose());
        if (!j.mimic.leader_joint.empty()) pending.push_back({a, i, m.body_dof_offset[body]});
      } else {
        body = m.frame_body[pf];
        placement = m.frame_placement[pf] * j.origin;
      }

      m.frame_name.push_back(link.name);
      m.frame_by_name[link.name] = f;
      m.frame_body.push_back(body);
      m.frame_placement.push_back(placement);
      m.frame_parent.push_back(pf);
      m.frame_joint_name.push_back(jname);
      m.frame_joint_type.push_back(ftype);
      m.frame_joint_axis.push_back(axis);
      m.frame_articulation.push_back(a);
      m.frame_mass.push_back(link.inertial.mass);

      if (body >= 0) {  // the world keeps no mass
        const InertialSpec& in = link.inertial;
        const Eigen::Matrix3d r = placement.linear() * in.origin.linear();
        lumps[body].parts.push_back({in.mass, placement * in.origin.translation(), r * in.inertia * r.transpose()});
      }
      for (const Shape& s : link.shapes) {
        Shape shape = s;
        shape.body = body;
        shape.frame = f;
        shape.pose = placement * s.pose;
        m.shapes.push_back(shape);
      }
    }
    art.body_count = m.nbody - art.first_body;
    m.articulations.push_back(art);
  }

  m.body_mass.resize(m.nbody);
  m.body_com.resize(m.nbody);
  m.body_inertia.resize(m.nbody);
  for (int b = 0; b < m.nbody; ++b) lumps[b].result(m.body_mass[b], m.body_com[b], m.body_inertia[b]);

  for (const Pending& p : pending) {
    const ArticulationSpec& spec = articulations_[p.art];
    const LinkSpec& link = spec.links[p.link];
    const std::string& leader = link.joint.mimic.leader_joint;
    const auto it = m.joint_by_name.find(leader);
    if (it == m.joint_by_name.end())
      throw ModelError(joint_ctx(spec, link) + ": mimic leader joint '" + leader + "' is not a moving joint of the model");
    if (!is_one_dof(m.body_joint[it->second]))
      throw ModelError(joint_ctx(spec, link) + ": mimic leader joint '" + leader + "' is not revolute or prismatic");
    Mimic mimic;
    mimic.dof = p.dof;
    mimic.leader_dof = m.body_dof_offset[it->second];
    mimic.multiplier = link.joint.mimic.multiplier;
    mimic.offset = link.joint.mimic.offset;
    m.mimics.push_back(mimic);
  }
  // A chain of mimic tags must end at a joint that follows none: in a cycle
  // (a follows b, b follows a) no joint leads.
  std::map<int, int> leader_of;
  for (const Mimic& mimic : m.mimics) leader_of[mimic.dof] = mimic.leader_dof;
  for (std::size_t i = 0; i < m.mimics.size(); ++i) {
    std::string chain = m.dof_name[m.mimics[i].dof];
    for (int dof = m.mimics[i].leader_dof, hops = 0; hops <= static_cast<int>(m.mimics.size()); ++hops) {
      chain += " follows " + m.dof_name[dof];
      if (dof == m.mimics[i].dof) {
        const Pending& p = pending[i];
        throw ModelError(joint_ctx(articulations_[p.art], articulations_[p.art].links[p.link]) +
                         ": mimic tags form a cycle (" + chain + ")");
      }
      const auto next = leader_of.find(dof);
      if (next == leader_of.end()) break;
      dof = next->second;
    }
  }
  return m;
}

}  // namespace lockstep
