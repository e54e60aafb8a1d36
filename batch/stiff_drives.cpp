#include "batch/stiff_drives.hpp"

#include "batch/copy_dynamics.hpp"

#include <algorithm>
#include <cmath>
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

std::vector<StiffDrive> fast_joint_modes(const Model& model, const std::vector<DofSettings>& dofs,
                                         const Eigen::VectorXd& q, double h, double bound, bool link_damping) {
  std::vector<StiffDrive> fast;
  const Eigen::VectorXd inertia = CopyDynamics(model).mass_matrix(q).diagonal();
  // per body, the largest link damping rate of its subtree (children come after their parents)
  std::vector<double> subtree_damping(model.nbody, 0.0);
  for (int b = model.nbody - 1; b >= 0 && link_damping; --b) {
    subtree_damping[b] = std::max({subtree_damping[b], model.body_linear_damping[b], model.body_angular_damping[b]});
    if (model.body_parent[b] >= 0)
      subtree_damping[model.body_parent[b]] = std::max(subtree_damping[model.body_parent[b]], subtree_damping[b]);
  }
  for (int k = 0; k < model.nv; ++k) {
    const DofSettings& d = dofs[k];
    const bool acceleration = d.drive_type == DriveType::Acceleration;
    // per unit of the joint's inertia: s^2 + b s + c = 0
    const double b = (acceleration ? d.drive_damping : d.drive_damping / inertia[k]) + d.damping / inertia[k] +
                     subtree_damping[model.dof_body[k]];
    const double c = (acceleration ? d.drive_stiffness : d.drive_stiffness / inertia[k]) + d.spring_stiffness / inertia[k];
    const double discriminant = b * b - 4 * c;
    const double largest = discriminant >= 0 ? 0.5 * (b + std::sqrt(discriminant)) : std::sqrt(c);
    if (h * largest > bound) fast.push_back({k, h * largest});
  }
  auto larger = [](const StiffDrive& a, const StiffDrive& b) { return a.ratio > b.ratio; };
  std::stable_sort(fast.begin(), fast.end(), larger);
  return fast;
}

std::string describe_fast_joint_modes(const Model& model, const std::vector<StiffDrive>& fast, Integrator integrator) {
  if (fast.empty()) return {};
  const bool rk4 = integrator == Integrator::RK4;
  std::ostringstream out;
  out.precision(3);
  out << (rk4 ? "RK4 takes drives, springs and damping (link damping too) explicitly, and "
              : "the trapezoid takes drives, springs and damping by the implicit trapezoidal rule, and ")
      << fast.size() << " DOF(s) are too stiff for its step (h |lambda| " << fast.front().ratio << " at "
      << model.dof_name[fast.front().dof]
      << (rk4 ? ", diverging above about 2.8)" : ", ringing from step to step above about 18)")
      << ": lower the gains or dt, or use " << (rk4 ? "the semi-implicit Euler or trapezoid integrator, which take "
                                                    "them implicitly"
                                                  : "semi-implicit Euler, which damps them");
  return out.str();
}

std::vector<FastActuator> fast_actuators(const Model& model, const std::vector<DofSettings>& dofs,
                                         const std::vector<Actuator>& actuators, const Eigen::VectorXd& q, double h,
                                         double bound) {
  std::vector<FastActuator> fast;
  if (std::none_of(actuators.begin(), actuators.end(), [](const Actuator& a) { return a.enforce_operating_region; }))
    return fast;
  Eigen::MatrixXd Mt = CopyDynamics(model).mass_matrix(q);
  for (int k = 0; k < model.nv; ++k) {
    const DofSettings& d = dofs[k];
    const double kp = d.drive_type == DriveType::Acceleration ? d.drive_stiffness * Mt(k, k) : d.drive_stiffness;
    const double kd = d.drive_type == DriveType::Acceleration ? d.drive_damping * Mt(k, k) : d.drive_damping;
    Mt(k, k) += h * (kd + d.damping) + h * h * (kp + d.spring_stiffness);
  }
  const Eigen::LDLT<Eigen::MatrixXd> factor(Mt);
  for (std::size_t i = 0; i < actuators.size(); ++i) {
    const Actuator& a = actuators[i];
    if (!a.enforce_operating_region) continue;
    Eigen::VectorXd g = Eigen::VectorXd::Zero(model.nv);
    g[a.dof] = a.gear;
    for (const auto& [dof, ratio] : a.couplings) g[dof] += ratio;
    const double lambda = a.back_emf_damping() * g.dot(factor.solve(g));
    if (h * lambda > bound) fast.push_back({static_cast<int>(i), h * lambda});
  }
  std::stable_sort(fast.begin(), fast.end(),
                   [](const FastActuator& x, const FastActuator& y) { return x.ratio > y.ratio; });
  return fast;
}

std::string describe_fast_actuators(const std::vector<Actuator>& actuators, const std::vector<FastActuator>& fast,
                                    double bound) {
  if (fast.empty()) return {};
  std::ostringstream out;
  out.precision(3);
  const Actuator& first = actuators[fast.front().actuator];
  out << "fast actuators: " << fast.size() << " actuator(s) brake on their voltage lines faster than the step "
      << "can follow, taken explicitly as RaiSim takes them (h b g^T Mt^-1 g " << fast.front().ratio << " at '"
      << first.name << "', diverging above " << bound << " once the motor reaches a voltage line): "
      << "lower dt or use substeps, or check the gear ratio and the motor constants (b = K_t / (R K_v))";
  return out.str();
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
