// `lockstep dynamics`: the dynamics quantities of one state, as JSON
// (docs/cli.md).
#include "batch/copy_dynamics.hpp"
#include "tools/cli.hpp"
#include "io/json.hpp"
#include "io/joint_state.hpp"

#include <ostream>
#include <utility>

namespace lockstep::cli {

namespace {

std::string vector_json(const Eigen::VectorXd& x) {
  std::string s = "[";
  for (Eigen::Index i = 0; i < x.size(); ++i) s += (i ? ", " : "") + json::number(x[i]);
  return s + "]";
}

// Row-major nested arrays, one row per line at `indent`.
std::string matrix_json(const Eigen::MatrixXd& m, const std::string& indent) {
  if (m.rows() == 0) return "[]";
  std::string s = "[";
  for (Eigen::Index r = 0; r < m.rows(); ++r)
    s += (r ? ",\n" : "\n") + indent + "  " + vector_json(m.row(r).transpose());
  return s + "\n" + indent + "]";
}

// Finite inputs may give results that are not (|qd| of 1e200 squared),
// which would be written as null: refused naming the state's file.
void require_finite(const Eigen::MatrixXd& result, const char* what, Precision precision, const std::string& path) {
  if (!result.allFinite())
    throw StateError(path + ": the state's " + what + " is not finite in " + precision_name(precision) +
                     ": its velocities, torques or positions are too large");
}

}  // namespace

int run_dynamics(const std::vector<std::string>& args, std::ostream& out) {
  const ParsedArgs parsed = parse_args(args, {"--floating-base"}, {"--state", "--precision"});
  if (parsed.positional.size() != 1) throw UsageError("dynamics needs exactly one MODEL.urdf");
  const std::string* state_path = parsed.value("--state");
  if (!state_path) throw UsageError("dynamics needs --state STATE.json");
  const std::string* precision_option = parsed.value("--precision");
  const Precision precision = precision_option ? parse_precision(*precision_option) : Precision::Double;

  const LoadedModel loaded = load_model(parsed.positional[0], parsed.has("--floating-base"), false);
  const Model& model = loaded.model;
  const JointState state = read_state(model, json::parse_file(*state_path), *state_path, precision);

  const CopyDynamics dynamics(model, precision);
  const Eigen::MatrixXd mass_matrix = dynamics.mass_matrix(state.q);
  const Eigen::VectorXd bias = dynamics.bias_force(state.q, state.v);
  const Eigen::VectorXd gravity = dynamics.gravity_force(state.q);
  const Eigen::VectorXd qacc = dynamics.forward_dynamics(state.q, state.v, state.tau);
  const double kinetic = dynamics.kinetic_energy(state.q, state.v);
  const double potential = dynamics.potential_energy(state.q);
  const std::vector<Eigen::Isometry3d> frames = dynamics.frame_poses(state.q);
  const std::pair<const char*, Eigen::MatrixXd> results[] = {
      {"mass matrix", mass_matrix},
      {"bias force", bias},
      {"gravity force", gravity},
      {"acceleration", qacc},
      {"kinetic energy", Eigen::MatrixXd::Constant(1, 1, kinetic)},
      {"potential energy", Eigen::MatrixXd::Constant(1, 1, potential)}};
  for (const auto& [what, result] : results) require_finite(result, what, precision, *state_path);

  out << "{\n";
  out << "  \"model\": " << json::quote(loaded.path) << ",\n";
  out << "  \"floating_base\": " << (loaded.floating_base ? "true" : "false") << ",\n";
  out << "  \"precision\": " << json::quote(precision_name(precision)) << ",\n";
  out << "  \"dof_names\": [";
  for (int d = 0; d < model.nv; ++d) out << (d ? ", " : "") << json::quote(model.dof_name[d]);
  out << "],\n";
  out << "  \"q\": " << vector_json(state.q) << ",\n";
  out << "  \"qd\": " << vector_json(state.v) << ",\n";
  out << "  \"tau\": " << vector_json(state.tau) << ",\n";
  out << "  \"mass_matrix\": " << matrix_json(mass_matrix, "  ") << ",\n";
  out << "  \"bias\": " << vector_json(bias) << ",\n";
  out << "  \"gravity\": " << vector_json(gravity) << ",\n";
  out << "  \"qacc\": " << vector_json(qacc) << ",\n";
  out << "  \"kinetic_energy\": " << json::number(kinetic) << ",\n";
  out << "  \"potential_energy\": " << json::number(potential) << ",\n";
  out << "  \"links\": {";
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const Eigen::Vector3d p = frames[f].translation();
    out << (f ? "," : "") << "\n    " << json::quote(model.frame_name[f]) << ": {\"position\": " << vector_json(p)
        << ", \"rotation\": [";
    const Eigen::Matrix3d r = frames[f].rotation();
    for (int row = 0; row < 3; ++row) out << (row ? ", " : "") << vector_json(r.row(row).transpose());
    out << "]}";
  }
  out << (frames.empty() ? "}\n" : "\n  }\n");
  out << "}\n";
  return kExitOk;
}

}  // namespace lockstep::cli
