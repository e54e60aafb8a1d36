// StepOptions::conserve_linear_momentum: each floating articulation leaves
// the step with exactly its momentum before it plus the impulse of the
// external forces on it.
//
// Semi-implicit Euler changes a floating robot's momentum by O(h^2) per step
// even without external forces: the velocities are found at q0, where the
// internal forces cancel, but the momentum is read at q1 with the COM
// Jacobian of q1. Over a time it drifts by O(h) (docs/contacts.md, a ball
// hitting a free-floating anymal_b: 5.4e-4 of the momentum at dt = 2 ms).
// The projection below removes that drift: one translation velocity added to
// the whole articulation (its base's linear velocity) changes its momentum by
// its mass times that velocity and nothing else does, so
//   dv = (P_target - P(q1, v1)) / m,
//   P_target = P(q0, v0) + h (m g + sum F_wrench + R0 f_base) + P(q0, v1 - u*),
// with f_base the feedforward force on the Free joint's linear DOFs (body
// axes), and P(q0, v1 - u*) the impulse of the solver rows: they change the
// velocities by Mt^-1 J^T lambda at q0, Mt = M + diag(w), whose momentum is
// J^T lambda on the base's linear DOFs rotated to the world (internal rows
// cancel there) as long as w is zero on the Free joint, which is why a
// floating base with damping or armature is refused (Simulator). The
// correction is of the integrator's own order, O(h^2) per step; it is a
// projection onto the momentum's invariant set (E. Hairer, C. Lubich,
// G. Wanner, "Geometric Numerical Integration", 2nd ed., sec. IV.4).
//
// In float the base's velocity holds a correction only to ulp(v): what
// lands there differs from dv, and the same way step after step along a
// smooth motion, which drifts the momentum by a few 1e-8 of |P| per step.
// The shortfall r = P_target - P(q1, v1 + dv) is carried in the batch
// (StepBatch::momentum_remainder) and added to the next step's target, so
// that it is placed later instead of lost (error feedback): the momentum
// then stays within a few ulps of the exact balance. P_target is kept in
// two parts, P(q0, v0) and the small h F + P(q0, v1 - u*) + r, and
// differences of momenta are taken before the small part is added, so that
// float keeps the small part's digits.
#include "batch/step_engine.hpp"
#include "kernels/momentum.hpp"

namespace lockstep {

// Needs ws.local at q0 (the step's ABA ran there) and s.u1 still in the
// frames of the start of the step. A root's ws.local is its world pose.
template <class L>
void StepEngine<L>::linear_momentum_target(int block, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const StepBatch<T>& B = batch_;
  const T* inertia = this->inertia(block);
  // momentum_added first sums each articulation's external force (world
  // axes), then becomes h (force + m g) + r, then takes the rows' impulse
  for (int root : floating_roots_) {
    s.articulation_mass[root] = L(T(0));
    const int dof0 = km_.body_dof_offset[root];
    const Vec3<L> base_force = {s.terms.command[dof0], s.terms.command[dof0 + 1], s.terms.command[dof0 + 2]};
    s.momentum_added[root] = spatial::rotate(s.ws.local[root].R, base_force);
  }
  const T* wrench = plan_.wrenches ? B.state.wrench.block(block) : nullptr;
  const Vec3<L> gravity = load_vec3<L>(B.state.gravity.block(block));
  for (int b = 0; b < km_.nbody; ++b) {
    const int root = momentum_root_[b];
    if (root < 0) continue;
    const L mass = lane::load<L>(inertia + kInertiaParams * b * W);
    s.articulation_mass[root] = s.articulation_mass[root] + mass;
    if (wrench) s.momentum_added[root] = spatial::add(s.momentum_added[root], load_vec3<L>(wrench + 6 * b * W));
    // a body without gravity: its weight, added below with the rest, is not there
    if (!km_.body_gravity[b]) s.momentum_added[root] = spatial::sub(s.momentum_added[root], spatial::scale(mass, gravity));
  }
  const T* remainder = B.momentum_remainder.block(block);
  for (std::size_t i = 0; i < floating_roots_.size(); ++i) {
    const int root = floating_roots_[i];
    const Vec3<L> force = spatial::add(s.momentum_added[root], spatial::scale(s.articulation_mass[root], gravity));
    s.momentum_added[root] = spatial::add(load_vec3<L>(remainder + 3 * i * W), spatial::scale(L(h), force));
  }
  // P(q0, v0): the very sum, of the very state, that ended the last step,
  // so that the remainder carried from there fits it exactly
  subtree_momentum<L>(km_, inertia, fields(s.u0), s.ws);
  for (int root : floating_roots_) s.momentum_target[root] = root_momentum(s.ws, root);
  // The rows' impulse P(q0, v1 - u*) (P is linear in v), a sum of its own:
  // added to v0 before the sum, it would round at ulp(P) every step it acts
  if (!s.solving) return;
  T* velocity_change = fields(s.v_stage);
  for (int k = 0; k < km_.nv; ++k) lane::store(s.u1[k] - s.u_free[k], velocity_change + k * W);
  subtree_momentum<L>(km_, inertia, velocity_change, s.ws);
  for (int root : floating_roots_) s.momentum_added[root] = spatial::add(s.momentum_added[root], root_momentum(s.ws, root));
}

template <class L>
void StepEngine<L>::keep_linear_momentum(int block, const T* q1, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const T* inertia = this->inertia(block);
  // P_target - P(q1, v): the difference of the large parts first
  auto shortfall = [&](int root) {
    return spatial::add(spatial::sub(s.momentum_target[root], root_momentum(s.ws, root)), s.momentum_added[root]);
  };
  joint_transforms<L>(km_, q1, s.ws);
  subtree_momentum<L>(km_, inertia, fields(s.u1), s.ws);
  for (int root : floating_roots_) {
    const Vec3<L> world_dv = spatial::scale(L(T(1)) / s.articulation_mass[root], shortfall(root));
    const Vec3<L> dv = spatial::rotate_back(s.ws.local[root].R, world_dv);
    const int dof0 = km_.body_dof_offset[root];
    s.u1[dof0] = s.u1[dof0] + dv.x;
    s.u1[dof0 + 1] = s.u1[dof0 + 1] + dv.y;
    s.u1[dof0 + 2] = s.u1[dof0 + 2] + dv.z;
    if (options_.record_motion) record_momentum_correction(block, root, world_dv, h);
  }
  subtree_momentum<L>(km_, inertia, fields(s.u1), s.ws);
  T* remainder = batch_.momentum_remainder.block(block);
  for (std::size_t i = 0; i < floating_roots_.size(); ++i) store_vec3(shortfall(floating_roots_[i]), remainder + 3 * i * W);
}

// The base's velocity change from the correction, world_dv, is part of
// the step's motion (a translation of the whole articulation) that the
// step's forces do not balance: world_dv / h joins the recorded
// acceleration, in the base's frame at the start of the step like the rest
// of it, and its unbalanced share.
template <class L>
void StepEngine<L>::record_momentum_correction(int block, int root, const Vec3<L>& world_dv, T h) {
  constexpr std::size_t W = lane::width_v<L>;
  const T* q0 = batch_.state.q.block(block) + (km_.body_q_offset[root] + 3) * W;  // the base's quaternion (w, x, y, z)
  const Mat3<L> R0 = quaternion_rotation(lane::load<L>(q0), lane::load<L>(q0 + W), lane::load<L>(q0 + 2 * W),
                                         lane::load<L>(q0 + 3 * W));
  const Vec3<L> da = spatial::rotate_back(R0, spatial::scale(L(T(1) / h), world_dv));
  const int dof0 = km_.body_dof_offset[root];
  for (T* a : {batch_.motion_acceleration.block(block), batch_.motion_unbalanced.block(block)})
    store_vec3(spatial::add(load_vec3<L>(a + dof0 * W), da), a + dof0 * W);
}

#define LOCKSTEP_STEP_MOMENTUM(L)                                                    \
  template void StepEngine<L>::linear_momentum_target(int, lane::scalar_t<L>, Scratch&); \
  template void StepEngine<L>::keep_linear_momentum(int, const lane::scalar_t<L>*, lane::scalar_t<L>, Scratch&); \
  template void StepEngine<L>::record_momentum_correction(int, int, const Vec3<L>&, lane::scalar_t<L>);
LOCKSTEP_STEP_MOMENTUM(float)
LOCKSTEP_STEP_MOMENTUM(double)
LOCKSTEP_STEP_MOMENTUM(lane::simd<float>)
LOCKSTEP_STEP_MOMENTUM(lane::simd<double>)

}  // namespace lockstep
