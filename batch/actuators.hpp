// Actuators: electric motors behind gearboxes driving joints, with the
// motor operating region that bounds a DC motor's torque by its speed
// (RaiSim's actuators, "Joint torque of a simulation step", step 2).
//
// An actuator drives DOF `dof` through the gear ratio G and may be coupled
// to further DOFs c with ratios r_c. Each copy commands it a torque tau_a
// at the driven joint (Simulator::set_actuator_torques). The motor turns at
//   omega = G v_dof + sum_c r_c v_c
// (the transmission's own speed: the power G tau_m v_dof + sum r_c tau_m v_c
// it delivers is tau_m omega), and its torque is
//   tau_m = clamp(clamp(tau_a / G, -tau_peak, tau_peak), -tau_stall - b omega, tau_stall - b omega)
// with the stall torque tau_stall = K_t V_bus / R and the back-EMF damping
// b = K_t / (R K_v): the current limit, then the voltage lines of the
// torque-speed plane (the torque the bus voltage can drive against the
// back-EMF). Where both leave room, that is the torque nearest tau_a / G
// in the region. Past the speed where the voltage lines leave no torque
// within +-tau_peak (|omega| > (tau_stall + tau_peak) / b), the back-EMF
// drives a current the driver cannot limit, and the motor brakes with the
// least torque the voltage allows. Without the region enforced,
// tau_m = tau_a / G. With the copy's strength s (1 unless set), the
// actuator adds s G tau_m to the driven DOF and s r_c tau_m to each coupled
// one, after the effort clamp of feedforward + PD and unclamped by it
// (RaiSim: effort limits do not clip actuator torques, and the operating
// region clips nothing else). The torque is explicit, evaluated at the
// velocity the step (or RK4's stage) starts from.
//
// RaiSim's output damping and output friction of an actuator are the
// driven joint's damping and friction here: add them to its DofSettings.
#pragma once

#include "batch/precision.hpp"
#include "layout/model.hpp"

#include <string>
#include <utility>
#include <vector>

namespace lockstep {

struct Actuator {
  std::string name;  // for messages and readouts; unique among the actuators
  int dof = -1;      // the driven DOF (low-level index; not a floating base's)
  double gear = 1.0;  // G > 0: joint torque per motor torque, motor speed per joint speed
  // (DOF, ratio r_c): further DOFs the motor drives, each other than `dof`
  std::vector<std::pair<int, double>> couplings;
  double torque_constant = 0.0;    // K_t [N m / A] > 0
  double bus_voltage = 0.0;        // V_bus [V] > 0
  double resistance = 0.0;         // R [ohm] > 0, the winding's
  double velocity_constant = 0.0;  // K_v [rad / (s V)] > 0: motor speed per volt of back-EMF
  double peak_torque = Model::kInfinity;  // tau_peak [N m] > 0, at the motor (+inf: none)
  bool enforce_operating_region = true;   // false: tau_m = tau_a / G, unclipped

  double stall_torque() const { return torque_constant * bus_voltage / resistance; }
  double back_emf_damping() const { return torque_constant / (resistance * velocity_constant); }
};

// One actuator's last evaluation in a copy's last step (RaiSim's
// getActuatorStates: with RK4, its last stage). All zero before the
// copy's first step and after a reset.
struct ActuatorState {
  double command = 0;       // tau_a that evaluation took, at the driven joint [N m]
  double motor_speed = 0;   // omega [rad/s]
  double motor_torque = 0;  // tau_m [N m]
  bool clipped = false;     // tau_m != tau_a / G: the operating region bound it
};

// Throws std::invalid_argument naming the actuator (index and name) and
// the field: a DOF out of range or on a floating base, couplings on the
// driven DOF or twice on one, non-positive constants, or any of them, a
// ratio or the stall torque and back-EMF damping they give not finite in
// `precision`, names empty or repeated.
void validate_actuators(const Model& model, const std::vector<Actuator>& actuators, Precision precision);

// Their names, in order (VecEnv's action columns, rollout files' columns).
std::vector<std::string> actuator_names(const std::vector<Actuator>& actuators);

}  // namespace lockstep
