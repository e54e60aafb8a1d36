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
#include "batch/step_engine.hpp"
#include "kernels/momentum.hpp"

namespace lockstep {

// Needs ws.local at q0 (the step's ABA ran there) and s.u1 still in the
// frames of the start of the step. A root's ws.local is its world pose.
template <class L>
void StepEngine<L>::linear_momentum_target(int block, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const StepBatch<T>& B = batch_;
  const int nv = km_.nv;
  const T* inertia = this->inertia(block);
  // v0 plus the rows' velocity change: P is linear in the velocity.
  T* velocity = fields(s.v_stage);
  for (int k = 0; k < nv; ++k)
    lane::store(s.solving ? s.u0[k] + (s.u1[k] - s.u_free[k]) : s.u0[k], velocity + k * W);
  subtree_momentum<L>(km_, inertia, velocity, s.ws);
  // momentum_target first sums each articulation's external force (world
  // axes), then becomes P(q0, v0 + v1 - u*) + h (force + m g)
  for (int root : floating_roots_) {
    s.articulation_mass[root] = L(T(0));
    const int dof0 = km_.body_dof_offset[root];
    const Vec3<L> base_force = {s.terms.command[dof0], s.terms.command[dof0 + 1], s.terms.command[dof0 + 2]};
    s.momentum_target[root] = spatial::rotate(s.ws.local[root].R, base_force);
  }
  const T* wrench = plan_.wrenches ? B.state.wrench.block(block) : nullptr;
  for (int b = 0; b < km_.nbody; ++b) {
    const int root = momentum_root_[b];
    if (root < 0) continue;
    s.articulation_mass[root] = s.articulation_mass[root] + lane::load<L>(inertia + kInertiaParams * b * W);
    if (wrench) {
      const T* F = wrench + 6 * b * W;
      const Vec3<L> force = {lane::load<L>(F), lane::load<L>(F + W), lane::load<L>(F + 2 * W)};
      s.momentum_target[root] = spatial::add(s.momentum_target[root], force);
    }
  }
  const T* g = B.state.gravity.block(block);
  const Vec3<L> gravity = {lane::load<L>(g), lane::load<L>(g + W), lane::load<L>(g + 2 * W)};
  for (int root : floating_roots_) {
    const Vec3<L> force = spatial::add(s.momentum_target[root], spatial::scale(s.articulation_mass[root], gravity));
    s.momentum_target[root] = spatial::add(root_momentum(s.ws, root), spatial::scale(L(h), force));
  }
}

template <class L>
void StepEngine<L>::keep_linear_momentum(int block, const T* q1, Scratch& s) {
  joint_transforms<L>(km_, q1, s.ws);
  subtree_momentum<L>(km_, this->inertia(block), fields(s.u1), s.ws);
  for (int root : floating_roots_) {
    const Vec3<L> change = spatial::sub(s.momentum_target[root], root_momentum(s.ws, root));
    const Vec3<L> dv = spatial::rotate_back(s.ws.local[root].R, spatial::scale(L(T(1)) / s.articulation_mass[root], change));
    const int dof0 = km_.body_dof_offset[root];
    s.u1[dof0] = s.u1[dof0] + dv.x;
    s.u1[dof0 + 1] = s.u1[dof0 + 1] + dv.y;
    s.u1[dof0 + 2] = s.u1[dof0 + 2] + dv.z;
  }
}

#define LOCKSTEP_STEP_MOMENTUM(L)                                                    \
  template void StepEngine<L>::linear_momentum_target(int, lane::scalar_t<L>, Scratch&); \
  template void StepEngine<L>::keep_linear_momentum(int, const lane::scalar_t<L>*, Scratch&);
LOCKSTEP_STEP_MOMENTUM(float)
LOCKSTEP_STEP_MOMENTUM(double)
LOCKSTEP_STEP_MOMENTUM(lane::simd<float>)
LOCKSTEP_STEP_MOMENTUM(lane::simd<double>)

}  // namespace lockstep
