// `lockstep info`: the tree of a model, as a table or as JSON (docs/cli.md).
#include "tools/cli.hpp"
#include "io/json.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <ostream>
#include <sstream>

namespace lockstep::cli {

namespace {

std::string body_name(const Model& model, int body) {
  return body < 0 ? "world" : model.frame_name[model.body_frame[body]];
}

// A frame is fused when it rides on a body it does not name (its fixed joint
// was merged into that body).
bool frame_fused(const Model& model, int frame) {
  const int body = model.frame_body[frame];
  return body >= 0 && model.body_frame[body] != frame;
}

std::string limit_text(double x) {
  if (std::isinf(x)) return x > 0 ? "inf" : "-inf";
  std::ostringstream s;
  s << std::setprecision(6) << x;
  return s.str();
}

// A table with left-aligned columns, each as wide as its widest cell.
class Table {
 public:
  explicit Table(std::vector<std::string> header) { rows_.push_back(std::move(header)); }
  void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
  void print(std::ostream& out) const {
    std::vector<std::size_t> width(rows_.front().size(), 0);
    for (const auto& row : rows_)
      for (std::size_t c = 0; c < row.size(); ++c) width[c] = std::max(width[c], row[c].size());
    for (const auto& row : rows_) {
      std::string line = " ";
      for (std::size_t c = 0; c < row.size(); ++c) {
        line += " " + row[c];
        if (c + 1 < row.size()) line += std::string(width[c] - row[c].size(), ' ');
      }
      while (!line.empty() && line.back() == ' ') line.pop_back();
      out << line << "\n";
    }
  }

 private:
  std::vector<std::vector<std::string>> rows_;
};

std::string mass_text(double mass) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(4) << mass;
  return s.str();
}

}  // namespace

void print_info_text(const LoadedModel& loaded, std::ostream& out) {
  const Model& m = loaded.model;
  out << "model: " << loaded.path << (loaded.floating_base ? " (floating base)" : " (fixed base)") << "\n";
  out << "bodies " << m.nbody << ", nq " << m.nq << ", nv (DOFs) " << m.nv << ", frames " << m.frame_name.size()
      << ", total mass " << mass_text(m.total_mass()) << " kg"
      << (loaded.floating_base ? "" : " (the moving bodies; links welded to the world do not count)") << "\n";

  out << "\narticulations (" << m.articulations.size() << "):\n";
  Table articulations({"index", "name", "base", "bodies", "root link"});
  for (std::size_t a = 0; a < m.articulations.size(); ++a) {
    const Articulation& art = m.articulations[a];
    const std::string range = art.body_count == 0 ? "none"
        : std::to_string(art.first_body) + ".." + std::to_string(art.first_body + art.body_count - 1);
    articulations.add({std::to_string(a), art.name, art.floating_base ? "floating" : "fixed", range,
                       art.root_frame >= 0 ? m.frame_name[art.root_frame] : "-"});
  }
  articulations.print(out);

  out << "\nbodies (" << m.nbody << ", low-level order):\n";
  Table bodies({"index", "name", "parent", "joint", "type", "q", "dof", "mass [kg]", "gravity",
                "damping lin/ang [1/s]"});
  for (int b = 0; b < m.nbody; ++b) {
    const bool damped = m.body_linear_damping[b] != 0 || m.body_angular_damping[b] != 0;
    bodies.add({std::to_string(b), body_name(m, b), body_name(m, m.body_parent[b]), m.joint_name[b],
                joint_type_name(m.body_joint[b]), std::to_string(m.body_q_offset[b]),
                std::to_string(m.body_dof_offset[b]), mass_text(m.body_mass[b]), m.body_gravity[b] ? "on" : "off",
                damped ? json::number(m.body_linear_damping[b]) + " / " + json::number(m.body_angular_damping[b]) : "-"});
  }
  bodies.print(out);

  out << "\nframes (" << m.frame_name.size() << ", URDF links):\n";
  Table frames({"index", "name", "body", "joint", "type", "mass", "note"});
  for (std::size_t f = 0; f < m.frame_name.size(); ++f) {
    const int body = m.frame_body[f];
    const std::string note = body < 0 ? "fixed to the world"
        : frame_fused(m, int(f)) ? "fused into body " + std::to_string(body) + " (" + body_name(m, body) + ")" : "";
    frames.add({std::to_string(f), m.frame_name[f], body < 0 ? "world" : std::to_string(body),
                m.frame_joint_name[f].empty() ? "-" : m.frame_joint_name[f], joint_type_name(m.frame_joint_type[f]),
                mass_text(m.frame_mass[f]), note});
  }
  frames.print(out);

  out << "\nDOFs (" << m.nv << "):\n";
  Table dofs({"index", "name", "body", "lower", "upper", "velocity limit", "effort limit", "mimic"});
  for (int d = 0; d < m.nv; ++d) {
    const Mimic* mimic = m.mimic_of(d);
    dofs.add({std::to_string(d), m.dof_name[d], std::to_string(m.dof_body[d]), limit_text(m.dof_lower[d]),
              limit_text(m.dof_upper[d]), limit_text(m.dof_velocity_limit[d]), limit_text(m.dof_effort_limit[d]),
              mimic ? limit_text(mimic->multiplier) + " x " + m.dof_name[mimic->leader_dof] + " + " +
                          limit_text(mimic->offset)
                    : "-"});
  }
  dofs.print(out);

  out << "\nwarnings (" << loaded.warnings.size() << ")" << (loaded.warnings.empty() ? ": none\n" : ":\n");
  for (const std::string& w : loaded.warnings) out << "  " << w << "\n";
}

void print_info_json(const LoadedModel& loaded, std::ostream& out) {
  using json::number;
  using json::quote;
  const Model& m = loaded.model;
  const auto name_or_null = [&](int body) { return body < 0 ? std::string("null") : quote(body_name(m, body)); };
  out << "{\n";
  out << "  \"model\": " << quote(loaded.path) << ",\n";
  out << "  \"floating_base\": " << (loaded.floating_base ? "true" : "false") << ",\n";
  out << "  \"nbody\": " << m.nbody << ",\n  \"nq\": " << m.nq << ",\n  \"nv\": " << m.nv << ",\n";
  out << "  \"total_mass\": " << number(m.total_mass()) << ",\n";
  out << "  \"gravity\": [" << number(m.gravity.x()) << ", " << number(m.gravity.y()) << ", "
      << number(m.gravity.z()) << "],\n";

  out << "  \"articulations\": [";
  for (std::size_t a = 0; a < m.articulations.size(); ++a) {
    const Articulation& art = m.articulations[a];
    out << (a ? "," : "") << "\n    {\"index\": " << a << ", \"name\": " << quote(art.name)
        << ", \"floating_base\": " << (art.floating_base ? "true" : "false") << ", \"first_body\": " << art.first_body
        << ", \"body_count\": " << art.body_count << ", \"root_link\": "
        << (art.root_frame >= 0 ? quote(m.frame_name[art.root_frame]) : "null") << "}";
  }
  out << "\n  ],\n";

  out << "  \"bodies\": [";
  for (int b = 0; b < m.nbody; ++b) {
    const JointType type = m.body_joint[b];
    out << (b ? "," : "") << "\n    {\"index\": " << b << ", \"name\": " << quote(body_name(m, b))
        << ", \"parent\": " << m.body_parent[b] << ", \"parent_name\": " << name_or_null(m.body_parent[b])
        << ", \"joint\": " << quote(m.joint_name[b]) << ", \"joint_type\": " << quote(joint_type_name(type))
        << ", \"q_offset\": " << m.body_q_offset[b] << ", \"nq\": " << joint_nq(type)
        << ", \"dof_offset\": " << m.body_dof_offset[b] << ", \"nv\": " << joint_nv(type)
        << ", \"articulation\": " << m.body_articulation[b] << ", \"mass\": " << number(m.body_mass[b])
        << ", \"gravity\": " << (m.body_gravity[b] ? "true" : "false")
        << ", \"linear_damping\": " << number(m.body_linear_damping[b])
        << ", \"angular_damping\": " << number(m.body_angular_damping[b]) << "}";
  }
  out << "\n  ],\n";

  out << "  \"frames\": [";
  for (std::size_t f = 0; f < m.frame_name.size(); ++f) {
    const int body = m.frame_body[f];
    out << (f ? "," : "") << "\n    {\"index\": " << f << ", \"name\": " << quote(m.frame_name[f])
        << ", \"body\": " << body << ", \"body_name\": " << name_or_null(body)
        << ", \"parent\": " << m.frame_parent[f]
        << ", \"joint\": " << (m.frame_joint_name[f].empty() ? "null" : quote(m.frame_joint_name[f]))
        << ", \"joint_type\": " << quote(joint_type_name(m.frame_joint_type[f]))
        << ", \"fused\": " << (frame_fused(m, int(f)) ? "true" : "false")
        << ", \"mass\": " << number(m.frame_mass[f]) << "}";
  }
  out << "\n  ],\n";

  out << "  \"dofs\": [";
  for (int d = 0; d < m.nv; ++d) {
    out << (d ? "," : "") << "\n    {\"index\": " << d << ", \"name\": " << quote(m.dof_name[d])
        << ", \"body\": " << m.dof_body[d] << ", \"parent\": " << m.dof_parent[d]
        << ", \"lower\": " << number(m.dof_lower[d]) << ", \"upper\": " << number(m.dof_upper[d])
        << ", \"velocity_limit\": " << number(m.dof_velocity_limit[d])
        << ", \"effort_limit\": " << number(m.dof_effort_limit[d]) << ", \"mimic\": ";
    if (const Mimic* mimic = m.mimic_of(d))
      out << "{\"leader\": " << quote(m.dof_name[mimic->leader_dof]) << ", \"multiplier\": " << number(mimic->multiplier)
          << ", \"offset\": " << number(mimic->offset) << "}";
    else
      out << "null";
    out << "}";
  }
  out << "\n  ],\n";

  out << "  \"warnings\": [";
  for (std::size_t w = 0; w < loaded.warnings.size(); ++w)
    out << (w ? "," : "") << "\n    " << quote(loaded.warnings[w]);
  out << (loaded.warnings.empty() ? "]\n" : "\n  ]\n");
  out << "}\n";
}

int run_info(const std::vector<std::string>& args, std::ostream& out) {
  const ParsedArgs parsed = parse_args(args, {"--floating-base", "--json", "--strict"}, {});
  if (parsed.positional.size() != 1) throw UsageError("info needs exactly one MODEL.urdf");
  const LoadedModel loaded = load_model(parsed.positional[0], parsed.has("--floating-base"), parsed.has("--strict"));
  if (parsed.has("--json")) print_info_json(loaded, out);
  else print_info_text(loaded, out);
  return kExitOk;
}

}  // namespace lockstep::cli
