// The joint effects of one simulation step over a block: PD drives, joint
// damping, springs, spring-damper limits, smooth (Stribeck) friction and
// actuators.
//
// Every stiff term is integrated implicitly (backward Euler; dt below is the
// weight the integrator passes, StepEngine::joint_term_weight: the step h
// for semi-implicit Euler, h/2 for the trapezoid, 0 for RK4): it is
// evaluated at the end of the step, q1 = q0 + dt v1, v1 = v0 + dv, so for a
// force k (q_ref - q) + c (v_ref - v) the step sees
//   explicit part  k (q_ref - q0 - dt v0) + c (v_ref - v0),
//   implicit part  -(dt c + dt^2 k) dv / dt,
// and dt c + dt^2 k joins the joint's articulated inertia inside ABA
// (RaiSim, "Joint torque of a simulation step", step 4; the diagonal w):
//   (M + diag(w)) dv = dt (tau_explicit - h).
// An Acceleration drive scales both parts by the joint's articulated inertia
// D = S^T IA S + armature, known only inside ABA; so does the effort clamp,
// which bounds feedforward + explicit PD together (RaiSim step 1). Passive
// terms and the actuators' torques (clipped to their motors' operating
// regions instead, step 2) are added after the clamp. Stribeck friction is
// explicit, but for its linear ramp below the fall-off velocity, a damper.
#pragma once

#include "kernels/configuration.hpp"

namespace lockstep {

// Per-DOF parameters of the joint effects, shared by every copy, in the
// working precision; which terms run is decided per scene (the stages).
template <class T>
struct JointTermModel {
  bool drives = false, damping = false, springs = false, soft_limits = false, stribeck = false;
  std::vector<unsigned char> acceleration_drive;  // (nv) 1: gains in 1/s^2, 1/s
  std::vector<T> max_force;                       // (nv) effort limit, +inf when none
  std::vector<T> spring_stiffness, spring_rest;   // (nv)
  std::vector<T> lower, upper;                    // (nv) limits, used by soft limits
  std::vector<T> limit_stiffness, limit_damping;  // (nv) 0 on hard-limited DOFs
  std::vector<T> coulomb, stiction_extra, falloff_velocity, stribeck_velocity;  // (nv) Stribeck model
  // Actuators (batch/actuators.hpp) in the working precision; the DOFs any
  // of them drives, each once, are `actuated` (their actuation is summed
  // afresh per evaluation, the others' stays zero).
  struct Motor {
    int dof;
    T gear, stall_torque, back_emf_damping, peak_torque;
    bool enforce;
    std::vector<std::pair<int, T>> couplings;
  };
  std::vector<Motor> motors;
  std::vector<int> actuated;
};

// Per-block results of joint_term_prepass, read by the ABA policy below.
template <class L>
struct JointTermScratch {
  std::vector<L> pd, pd_implicit;            // (nv) explicit PD force and its w (per unit D for Acceleration drives)
  std::vector<L> passive, passive_implicit;  // (nv) explicit passive force and its w
  std::vector<L> command;                    // (nv) clamped feedforward + PD of the step
  std::vector<L> drive_implicit;             // (nv) w of the drive, after scaling
  std::vector<L> implicit_diagonal;          // (nv) everything added to S^T IA S: the armature and the whole w
  std::vector<L> actuation;                  // (nv) the actuators' joint torques, zero on DOFs none drives
  std::vector<L> motor_speed, motor_torque;  // (motors) omega and tau_m of the last evaluation
  JointTermScratch(int nv, int motors)
      : pd(nv), pd_implicit(nv), passive(nv), passive_implicit(nv), command(nv), drive_implicit(nv),
        implicit_diagonal(nv), actuation(nv, L(lane::scalar_t<L>(0))), motor_speed(motors), motor_torque(motors) {}
};

// Per-lane inputs of the joint effects for one block ([field][lane]).
template <class T>
struct JointTermInputs {
  const T* q = nullptr;         // (nq)
  const T* v = nullptr;         // (nv)
  const T* target_q = nullptr;  // (nq)
  const T* target_v = nullptr;  // (nv)
  const T* stiffness = nullptr; // (nv) kp
  const T* damping = nullptr;   // (nv) kd
  const T* joint_damping = nullptr;  // (nv) viscous damping coefficient
  const T* armature = nullptr;  // (nv) rotor inertia, joins D with w
  const T* actuator_command = nullptr;   // (motors) tau_a, at the driven joints
  const T* actuator_strength = nullptr;  // (motors) the share of tau_m reaching the joints
};

// The actuators' joint torques at the velocity v (batch/actuators.hpp):
// each motor's speed, its commanded torque clipped to the operating region
// (the peak torque, then the voltage lines), and, with the copy's strength
// s, s G tau_m on the driven DOF, s r_c tau_m on each coupled one, summed
// into s.actuation.
template <class L>
void actuator_torques(const JointTermModel<lane::scalar_t<L>>& jm, const JointTermInputs<lane::scalar_t<L>>& in,
                      JointTermScratch<L>& s) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  for (int dof : jm.actuated) s.actuation[dof] = L(T(0));
  for (std::size_t m = 0; m < jm.motors.size(); ++m) {
    const typename JointTermModel<T>::Motor& motor = jm.motors[m];
    const L gear(motor.gear);
    L omega = gear * lane::load<L>(in.v + motor.dof * W);
    for (const auto& [dof, ratio] : motor.couplings) omega = lane::fmadd(L(ratio), lane::load<L>(in.v + dof * W), omega);
    L torque = lane::load<L>(in.actuator_command + m * W) / gear;
    if (motor.enforce) {
      const L stall(motor.stall_torque), peak(motor.peak_torque);
      const L emf = L(motor.back_emf_damping) * omega;
      torque = lane::clamp(lane::clamp(torque, -peak, peak), -stall - emf, stall - emf);
    }
    s.motor_speed[m] = omega;
    s.motor_torque[m] = torque;
    const L delivered = lane::load<L>(in.actuator_strength + m * W) * torque;
    s.actuation[motor.dof] = lane::fmadd(gear, delivered, s.actuation[motor.dof]);
    for (const auto& [dof, ratio] : motor.couplings)
      s.actuation[dof] = lane::fmadd(L(ratio), delivered, s.actuation[dof]);
  }
}

// The smooth dry friction of the articulated-actors reference, opposing v:
// below the fall-off velocity a linear ramp to the peak static force
// coulomb + stiction_extra; above it the Gaussian Stribeck fall-off to coulomb.
template <class L>
inline L stribeck_friction(const L& v, const L& coulomb, const L& extra, const L& falloff, const L& stribeck_v) {
  using T = lane::scalar_t<L>;
  const L speed = lane::abs(v);
  const L peak = coulomb + extra;
  const L ramp = peak * speed / falloff;
  const L x = (speed - falloff) / lane::max(stribeck_v, L(T(1e-30)));
  // exp(-x^2) with x^2 clamped to [0, 80] (exp(-80) ~ 2e-35 is zero here)
  const L decay = lane::exp(-lane::min(x * x, L(T(80))));
  const L sliding = lane::fmadd(extra, lane::select(stribeck_v > L(T(0)), decay, L(T(0))), coulomb);
  const L magnitude = lane::select(speed < falloff, ramp, sliding);
  return lane::select(v > L(T(0)), -magnitude, lane::select(v < L(T(0)), magnitude, L(T(0))));
}

// A spring-damper limit on a coordinate x moving at v: beyond [lower, upper]
// at the predicted end of the step x_end = x0 + dt v0, the force
// k (limit - x_end) - c v pushing back, implicit like the drives (weight
// dt^2 k + dt c); nothing within the range. Added to passive and its weight.
template <class L>
inline void add_soft_limit(const L& x_end, const L& v, lane::scalar_t<L> lower, lane::scalar_t<L> upper,
                           lane::scalar_t<L> stiffness, lane::scalar_t<L> damping, const L& h, const L& h2, L& passive,
                           L& passive_implicit) {
  using T = lane::scalar_t<L>;
  const L kl(stiffness), cl(damping), zero(T(0));
  const L below = L(lower) - x_end, above = L(upper) - x_end;
  const auto under = below > zero, over = above < zero;
  const L push = lane::select(under, below, lane::select(over, above, zero));
  const auto active = under || over;
  passive = passive + lane::select(active, lane::fnmadd(cl, v, kl * push), zero);
  passive_implicit = passive_implicit + lane::select(active, lane::fmadd(h2, kl, h * cl), zero);
}

// Fills the scratch's explicit forces and implicit weights for one block.
// Each DOF's four values are summed in registers and stored once; the
// scratch's data pointers are taken once, since a SIMD store may alias any
// memory and would make the compiler reload them after every store.
template <class L>
void joint_term_prepass(const KernelModel<lane::scalar_t<L>>& km, const JointTermModel<lane::scalar_t<L>>& jm,
                        lane::scalar_t<L> dt, const JointTermInputs<lane::scalar_t<L>>& in,
                        JointTermScratch<L>& s) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const L zero(T(0));
  const L h(dt), h2(dt * dt);
  L* const pd_out = s.pd.data();
  L* const pd_implicit_out = s.pd_implicit.data();
  L* const passive_out = s.passive.data();
  L* const passive_implicit_out = s.passive_implicit.data();
  for (int b = 0; b < km.nbody; ++b) {
    const JointType type = km.body_joint[b];
    const int qo = km.body_q_offset[b], k0 = km.body_dof_offset[b];
    if (type == JointType::Free) {  // the root takes no drive, spring or limit; damping on its body-frame twist
      for (int k = k0; k < k0 + 6; ++k) {
        pd_out[k] = zero, pd_implicit_out[k] = zero, passive_out[k] = zero, passive_implicit_out[k] = zero;
        if (!jm.damping) continue;
        const L c = lane::load<L>(in.joint_damping + k * W);
        passive_out[k] = -(c * lane::load<L>(in.v + k * W));
        passive_implicit_out[k] = h * c;
      }
      continue;
    }
    const bool spherical = type == JointType::Spherical;
    const int n = spherical ? 3 : 1;
    // position error to the drive target, per DOF
    L error[3];
    // a spherical joint's limits bound its rotation vector r = log(q), whose
    // components move at (about: exactly for small or single-axis turns) its
    // DOFs' velocities, the child-frame angular velocity
    L rotation[3];
    if (spherical) {
      // RaiSim: the rotation vector of q^-1 q_target, in the joint's child frame
      const Quaternion<L> a = load_quaternion<L>(in.q + qo * W);
      const Quaternion<L> c = load_quaternion<L>(in.target_q + qo * W);
      const Vec3<L> e = quaternion_log(quaternion_multiply(Quaternion<L>{a.w, -a.x, -a.y, -a.z}, c));
      error[0] = e.x, error[1] = e.y, error[2] = e.z;
      if (jm.soft_limits) {
        const Vec3<L> r = quaternion_log(a);
        rotation[0] = r.x, rotation[1] = r.y, rotation[2] = r.z;
      }
    } else {
      error[0] = lane::load<L>(in.target_q + qo * W) - lane::load<L>(in.q + qo * W);
    }
    for (int i = 0; i < n; ++i) {
      const int k = k0 + i;
      const L v = lane::load<L>(in.v + k * W);
      L pd = zero, pd_implicit = zero, passive = zero, passive_implicit = zero;
      if (jm.drives) {
        const L kp = lane::load<L>(in.stiffness + k * W), kd = lane::load<L>(in.damping + k * W);
        const L predicted_error = lane::fnmadd(h, v, error[i]);  // q_ref - (q0 + dt v0)
        pd = lane::fmadd(kp, predicted_error, kd * (lane::load<L>(in.target_v + k * W) - v));
        pd_implicit = lane::fmadd(h2, kp, h * kd);
      }
      if (jm.damping) {
        const L c = lane::load<L>(in.joint_damping + k * W);
        passive = lane::fnmadd(c, v, passive);
        passive_implicit = lane::fmadd(h, c, passive_implicit);
      }
      if (spherical && jm.soft_limits)
        add_soft_limit(lane::fmadd(h, v, rotation[i]), v, jm.lower[k], jm.upper[k], jm.limit_stiffness[k],
                       jm.limit_damping[k], h, h2, passive, passive_implicit);
      if (!spherical) {  // springs, soft limits and Stribeck of 1-DOF joints
        const L q = lane::load<L>(in.q + qo * W);
        const L q_end = lane::fmadd(h, v, q);  // q0 + dt v0
        if (jm.springs) {
          const L ks(jm.spring_stiffness[k]);
          passive = lane::fmadd(ks, L(jm.spring_rest[k]) - q_end, passive);
          passive_implicit = lane::fmadd(h2, ks, passive_implicit);
        }
        if (jm.soft_limits)
          add_soft_limit(q_end, v, jm.lower[k], jm.upper[k], jm.limit_stiffness[k], jm.limit_damping[k], h, h2, passive,
                         passive_implicit);
        if (jm.stribeck) {
          const L coulomb(jm.coulomb[k]), extra(jm.stiction_extra[k]), falloff(jm.falloff_velocity[k]);
          const L friction = stribeck_friction(v, coulomb, extra, falloff, L(jm.stribeck_velocity[k]));
          passive = passive + friction;
          // The force is F(v0), explicit, taken implicitly as the damper of
          // its secant -F(v0)/v0 (below the fall-off velocity the ramp's
          // slope, peak / falloff): friction then slows the joint and never
          // turns it, v1 = v0 I / (I + h c). Explicit, a light joint
          // chattered across zero once h |F| / I passed |v0|, below the
          // fall-off (h peak / (falloff I) > 2) and above it alike.
          const L ramp_damping = (coulomb + extra) / falloff, speed = lane::abs(v);
          const L secant = lane::select(speed < falloff, ramp_damping, lane::abs(friction) / lane::max(speed, falloff));
          passive_implicit = lane::fmadd(h, secant, passive_implicit);
        }
      }
      pd_out[k] = pd, pd_implicit_out[k] = pd_implicit, passive_out[k] = passive;
      passive_implicit_out[k] = passive_implicit;
    }
  }
  if (!jm.motors.empty()) actuator_torques<L>(jm, in, s);
}

// The ABA joint-terms policy of the step (see aba_with): the clamped
// command plus the passive force as the joint force, the implicit weights
// as w. Records the command and the weights for the solver and the report.
template <class L>
struct StepJointTerms {
  using T = lane::scalar_t<L>;
  const JointTermModel<T>& jm;
  JointTermScratch<L>& s;
  const T* tau_ff;    // (nv) per lane
  const T* armature;  // (nv) per lane: joins D here, since the step's km carries none
  T gyroscopic_step;  // weight of the implicit gyroscopic Jacobian on Free bodies (h/2), 0 for explicit

  T implicit_gyroscopic_step() const { return gyroscopic_step; }

  L apply(int dof, const L& D_without_armature, L& tau) const {
    constexpr std::size_t W = lane::width_v<L>;
    const L armature_k = lane::load<L>(armature + dof * W);
    const L D = D_without_armature + armature_k;
    L pd = s.pd[dof], w_drive = s.pd_implicit[dof];
    if (jm.acceleration_drive[dof]) {
      pd = pd * D;
      w_drive = w_drive * D;
    }
    const L bound(jm.max_force[dof]);
    const L command = lane::clamp(lane::load<L>(tau_ff + dof * W) + pd, -bound, bound);
    s.command[dof] = command;
    s.drive_implicit[dof] = w_drive;
    tau = command + s.passive[dof] + s.actuation[dof];  // zero without actuators
    const L w = w_drive + s.passive_implicit[dof] + armature_k;
    s.implicit_diagonal[dof] = w;
    return w;
  }
};

}  // namespace lockstep
