#include "batch/actuators.hpp"

#include "batch/require.hpp"

#include <cmath>
#include <set>

namespace lockstep {

namespace {

// DOF `dof` of `model`, checked to exist and not to be a floating base's.
void require_driven_dof(const Model& model, int dof, const std::string& where, const std::string& what) {
  require(dof >= 0 && dof < model.nv,
          [&] { return where + what + " " + std::to_string(dof) + " outside [0, " + std::to_string(model.nv) + ")"; });
  require(model.body_joint[model.dof_body[dof]] != JointType::Free, [&] {
    return where + what + " " + std::to_string(dof) + " (" + model.dof_name[dof] + ") is a floating base's";
  });
}

}  // namespace

std::vector<std::string> actuator_names(const std::vector<Actuator>& actuators) {
  std::vector<std::string> names;
  for (const Actuator& a : actuators) names.push_back(a.name);
  return names;
}

void validate_actuators(const Model& model, const std::vector<Actuator>& actuators, Precision precision) {
  std::set<std::string> names;
  for (std::size_t i = 0; i < actuators.size(); ++i) {
    const Actuator& a = actuators[i];
    const std::string where = "actuator " + std::to_string(i) + " (" + a.name + "): ";
    require(!a.name.empty(), "actuator " + std::to_string(i) + ": has no name");
    require(names.insert(a.name).second, where + "the name is another actuator's");
    require_driven_dof(model, a.dof, where, "DOF");
    const std::string finite = finite_word(precision);
    // > 0 in the precision too: float flushes 1e-50 to zero, and a zero
    // gear divides the command by zero
    auto positive = [&](double x, const char* field) {
      require(finite_in(precision, x) && x >= smallest_normal(precision),
              [&] { return where + field + " must be " + finite + " and > 0 (a normal number), got " + number_text(x); });
    };
    positive(a.gear, "gear");
    positive(a.torque_constant, "torque_constant");
    positive(a.bus_voltage, "bus_voltage");
    positive(a.resistance, "resistance");
    positive(a.velocity_constant, "velocity_constant");
    require(a.peak_torque >= smallest_normal(precision) &&
                (a.peak_torque == Model::kInfinity || finite_in(precision, a.peak_torque)),
            [&] {
              return where + "peak_torque must be > 0 (a normal number) and " + finite + " (+inf for none), got " +
                     number_text(a.peak_torque);
            });
    // the constants the step takes: each may be in range while these are not
    positive(a.stall_torque(), "the stall torque K_t V_bus / R");
    positive(a.back_emf_damping(), "the back-EMF damping K_t / (R K_v)");
    std::set<int> coupled;
    for (const auto& coupling : a.couplings) {
      const int dof = coupling.first;
      const double ratio = coupling.second;
      require_driven_dof(model, dof, where, "coupled DOF");
      require(dof != a.dof, [&] { return where + "coupled DOF " + std::to_string(dof) + " is the driven DOF"; });
      require(coupled.insert(dof).second, [&] { return where + "coupled DOF " + std::to_string(dof) + " given twice"; });
      require(finite_in(precision, ratio), [&] {
        return where + "the ratio of coupled DOF " + std::to_string(dof) + " must be " + finite + ", got " +
               number_text(ratio);
      });
    }
  }
}

}  // namespace lockstep
