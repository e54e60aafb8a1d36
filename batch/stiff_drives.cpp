#include "batch/stiff_drives.hpp"

#include "batch/copy_dynamics.hpp"

#include <algorithm>
#include <sstream>

namespace lockstep {

std::vector<StiffDrive> stiff_drives(const Model& model, const std::vector<DofSettings>& dofs,
                                     const Eigen::VectorXd& q, double h) {
  std::vector<StiffDrive> stiff;
  const bool driven = std::any_of(dofs.begin(), dofs.end(), [](const DofSettings& d) { return d.drive_stiffness > 0; });
  if (!driven) return stiff;
  const Eigen::VectorXd inertia = CopyDynamics(model).mass_matrix(q).diagonal();
  for (int k = 0; k < model.nv; ++k) {
    const DofSettings& d = dofs[k];
    if (d.drive_stiffness <= 0) continue;
    const double implicit = d.drive_stiffness * h * h;
    const double ratio = d.drive_type == DriveType::Acceleration ? implicit : implicit / inertia[k];
    if (ratio >= 1.0) stiff.push_back({k, ratio});
  }
  auto stiffer = [](const StiffDrive& a, const StiffDrive& b) { return a.ratio > b.ratio; };
  std::stable_sort(stiff.begin(), stiff.end(), stiffer);
  return stiff;
}

std::string describe_stiff_drives(const Model& model, const std::vector<StiffDrive>& stiff, int substeps) {
  if (stiff.empty()) return {};
  std::ostringstream out;
  out.precision(3);
  out << "stiff drives: " << stiff.size() << " DOF(s) close half or more of their position error in one "
      << (substeps > 1 ? "substep" : "step") << " (kp h^2 / M_kk " << stiff.front().ratio << " at "
      << model.dof_name[stiff.front().dof] << "); held against a limit or contact they need many iterations: "
      << "lower kp, or more substeps (ratio / substeps^2)";
  return out.str();
}

}  // namespace lockstep
