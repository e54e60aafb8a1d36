// Drives so stiff that one (sub)step closes most of their error. Alone
// an implicit drive stays stable at any gain, but held against a joint limit
// or a contact by such a drive, a mechanism's rows have a slow mode that
// Gauss-Seidel removes only over many iterations (PhysX's "Articulation
// Drive Stability"; docs/contacts.md, the stiff finger). The remedy is the
// one PhysX gives: lower gains, or a shorter step (StepOptions::substeps).
#pragma once

#include "batch/actuators.hpp"
#include "batch/step_options.hpp"
#include "layout/model.hpp"

#include <string>
#include <vector>

namespace lockstep {

struct StiffDrive {
  int dof = -1;
  // kp h^2 / M_kk (force drives) or kp h^2 (acceleration drives): the
  // implicit drive's inertia against the joint's own. Above 1, one step
  // closes more than half of the position error of the joint alone.
  // (fast_joint_modes: h |lambda| instead.)
  double ratio = 0.0;
};

// The driven DOFs whose ratio is at least 1 at configuration q for the
// (sub)step h, the stiffest first. M_kk is the mass matrix's diagonal at q,
// armature included.
std::vector<StiffDrive> stiff_drives(const Model& model, const std::vector<DofSettings>& dofs,
                                     const Eigen::VectorXd& q, double h);

// One line, without indent or newline, for Simulator::describe_plan and the
// command-line tool's warnings; empty when no drive is stiff.
std::string describe_stiff_drives(const Model& model, const std::vector<StiffDrive>& stiff, int substeps);

// The DOFs whose drive, spring and damping give the joint alone a mode
// faster than the step can follow: h |lambda| above `bound` at
// configuration q (|lambda| the larger root of M_kk s^2 + (kd + c) s +
// (kp + k_spring), or of s^2 + kd s + kp for Acceleration drives), with
// ratio = h |lambda|, the largest first. RK4 takes those forces explicitly
// and diverges above about 2.8 (kRk4Bound); the trapezoid takes them by
// the implicit trapezoidal rule, whose error on such a mode changes sign
// every step and shrinks by less than a fifth per step above 18
// (kTrapezoidRingBound: (x/2 - 1) / (x/2 + 1) > 0.8). docs/stability.md
// section 7. With `link_damping` (RK4, which takes it explicitly too) the
// links' damping joins kd + c per unit inertia by its bound: the largest
// c of the bodies the DOF moves (J^T D J <= c M per body).
constexpr double kRk4Bound = 2.78;  // RK4's stability interval on the negative real axis: [-2.785, 0]
constexpr double kTrapezoidRingBound = 18.0;
std::vector<StiffDrive> fast_joint_modes(const Model& model, const std::vector<DofSettings>& dofs,
                                         const Eigen::VectorXd& q, double h, double bound, bool link_damping = false);
// One line as above for the integrator that meets them (RK4 or the
// trapezoid); empty when there are none.
std::string describe_fast_joint_modes(const Model& model, const std::vector<StiffDrive>& fast, Integrator integrator);

// An actuator whose back-EMF braking is too fast for the step. On a
// voltage line the motor's torque is tau_stall - b omega with omega = g^T v
// (g: G on the driven DOF, r_c on the coupled ones), so the joints feel the
// damping b g g^T, which the step takes explicitly at the velocity it
// starts from (RaiSim's law, batch/actuators.hpp). Against the step's
// inertia Mt = M + diag(w) (w: the implicit drives', damping's and
// springs' weights) that damping's one mode decays at lambda = b g^T Mt^-1
// g, and explicitly the velocity on it is multiplied by 1 - h lambda per
// step: it grows, alternating in sign, once h lambda passes 2 (the Eulers
// and the trapezoid's predictor; RK4 2.78). ratio = h lambda at q with the
// nominal strength 1, the largest first; only actuators whose region is
// enforced.
struct FastActuator {
  int actuator = -1;
  double ratio = 0.0;
};
constexpr double kExplicitDampingBound = 2.0;
std::vector<FastActuator> fast_actuators(const Model& model, const std::vector<DofSettings>& dofs,
                                         const std::vector<Actuator>& actuators, const Eigen::VectorXd& q, double h,
                                         double bound);
// One line for Simulator::warnings; empty when there are none.
std::string describe_fast_actuators(const std::vector<Actuator>& actuators, const std::vector<FastActuator>& fast,
                                    double bound);

}  // namespace lockstep
