#include "batch/batch_dynamics.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <string>

namespace lockstep {

template <class L>
BatchDynamics<L>::BatchDynamics(const Model& model) : model_(&model), km_(model), workspaces_(km_) {}

template <class L>
template <class F>
void BatchDynamics<L>::for_each_block(int blocks, F&& f) const {
  tbb::parallel_for(tbb::blocked_range<int>(0, blocks), [&](const tbb::blocked_range<int>& range) {
    Workspace<L>& ws = workspaces_.local();
    for (int b = range.begin(); b != range.end(); ++b) f(b, ws);
  });
}

template <class L>
void BatchDynamics<L>::check(const BatchArray<Scalar>& array, int copies, int size, const char* what,
                             const char* field) const {
  if (array.copies() != copies || array.size() != size || array.width() != kWidth)
    throw std::invalid_argument(std::string(what) + (field ? std::string(" state ") + field : std::string()) +
                                ": expected an array of " + std::to_string(copies) + " copies x " +
                                std::to_string(size) + " values x " + std::to_string(kWidth) + " lanes, got " +
                                std::to_string(array.copies()) + " x " + std::to_string(array.size()) + " x " +
                                std::to_string(array.width()));
}

// A state built for another model or lane width would be read out of
// bounds: every field is checked, not only the outputs.
template <class L>
void BatchDynamics<L>::check(const BatchState<Scalar>& s, const char* what) const {
  const int copies = s.copies(), nv = km_.nv, nbody = km_.nbody;
  check(s.q, copies, km_.nq, what, "q");
  check(s.v, copies, nv, what, "v");
  check(s.tau, copies, nv, what, "tau");
  check(s.qacc, copies, nv, what, "qacc");
  check(s.wrench, copies, 6 * nbody, what, "wrench");
  check(s.inertia, copies, BatchState<Scalar>::kInertiaParams * nbody, what, "inertia");
  check(s.gravity, copies, 3, what, "gravity");
}

template <class L>
void BatchDynamics<L>::frame_poses(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "frame_poses");
  check(out, s.copies(), 12 * km_.nframe, "frame_poses");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    frame_transforms<L>(km_, ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::frame_velocities(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "frame_velocities");
  check(out, s.copies(), 6 * km_.nframe, "frame_velocities");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    body_velocities<L>(km_, s.v.block(b), ws);
    lockstep::frame_velocities<L>(km_, ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::body_poses(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "body_poses");
  check(out, s.copies(), 12 * km_.nbody, "body_poses");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    Scalar* o = out.block(b);
    for (int i = 0; i < km_.nbody; ++i) {
      const Transform<L>& X = ws.world[i];
      for (int k = 0; k < 9; ++k) lane::store(X.R.m[k], o + (12 * i + k) * kWidth);
      lane::store(X.p.x, o + (12 * i + 9) * kWidth);
      lane::store(X.p.y, o + (12 * i + 10) * kWidth);
      lane::store(X.p.z, o + (12 * i + 11) * kWidth);
    }
  });
}

template <class L>
void BatchDynamics<L>::frame_accelerations(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "frame_accelerations");
  check(out, s.copies(), 6 * km_.nframe, "frame_accelerations");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    // RNEA's forward pass leaves the bodies' velocities and accelerations;
    // without gravity and wrenches, the motion's own
    BlockInputs<Scalar> in = block_inputs(s, b);
    in.gravity = nullptr;
    in.wrench = nullptr;
    rnea<L>(km_, in, ws, nullptr);
    lockstep::frame_accelerations<L>(km_, ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::forward_dynamics(const BatchState<Scalar>& s, BatchArray<Scalar>& qacc) const {
  check(s, "forward_dynamics");
  check(qacc, s.copies(), km_.nv, "forward_dynamics");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    BlockInputs<Scalar> in = block_inputs(s, b);
    in.qacc = nullptr;
    aba<L>(km_, in, ws, qacc.block(b));
  });
}

template <class L>
void BatchDynamics<L>::inverse_dynamics(const BatchState<Scalar>& s, BatchArray<Scalar>& tau) const {
  check(s, "inverse_dynamics");
  check(tau, s.copies(), km_.nv, "inverse_dynamics");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    BlockInputs<Scalar> in = block_inputs(s, b);
    in.tau = nullptr;
    rnea<L>(km_, in, ws, tau.block(b));
  });
}

// RNEA with a chosen subset of the inputs: the generalized-force utilities.
#define LOCKSTEP_RNEA_TERM(NAME, USE_V, USE_GRAVITY, USE_WRENCH)                            \
  template <class L>                                                                       \
  void BatchDynamics<L>::NAME(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const { \
    check(s, #NAME);                                                                       \
    check(out, s.copies(), km_.nv, #NAME);                                                 \
    for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {                            \
      joint_transforms<L>(km_, s.q.block(b), ws);                                          \
      if (km_.needs_world(USE_WRENCH, USE_GRAVITY)) world_transforms<L>(km_, ws);               \
      BlockInputs<Scalar> in;                                                              \
      in.inertia = s.inertia.block(b);                                                     \
      if (USE_V) in.v = s.v.block(b);                                                      \
      if (USE_GRAVITY) in.gravity = s.gravity.block(b);                                    \
      if (USE_WRENCH) in.wrench = s.wrench.block(b);                                       \
      rnea<L>(km_, in, ws, out.block(b));                                                  \
    });                                                                                    \
  }
LOCKSTEP_RNEA_TERM(bias_force, true, true, false)
LOCKSTEP_RNEA_TERM(coriolis_force, true, false, false)
LOCKSTEP_RNEA_TERM(gravity_force, false, true, false)
#undef LOCKSTEP_RNEA_TERM

template <class L>
void BatchDynamics<L>::external_force(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "external_force");
  check(out, s.copies(), km_.nv, "external_force");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    BlockInputs<Scalar> in;
    in.inertia = s.inertia.block(b);
    in.wrench = s.wrench.block(b);
    Scalar* o = out.block(b);
    rnea<L>(km_, in, ws, o);  // = -sum J^T F
    for (int k = 0; k < km_.nv; ++k) lane::store(-lane::load<L>(o + k * kWidth), o + k * kWidth);
  });
}

template <class L>
void BatchDynamics<L>::mass_matrix(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "mass_matrix");
  check(out, s.copies(), km_.nv * km_.nv, "mass_matrix");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    crba<L>(km_, s.inertia.block(b), ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::inverse_mass_matrix(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "inverse_mass_matrix");
  check(out, s.copies(), km_.nv * km_.nv, "inverse_mass_matrix");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    lockstep::inverse_mass_matrix<L>(km_, s.inertia.block(b), ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::com_jacobian(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "com_jacobian");
  check(out, s.copies(), 6 * km_.nbody * km_.nv, "com_jacobian");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    lockstep::com_jacobian<L>(km_, s.inertia.block(b), ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::point_jacobian(const BatchState<Scalar>& s, int frame, const Eigen::Vector3d& offset,
                                      BatchArray<Scalar>& out) const {
  check(s, "point_jacobian");
  check(out, s.copies(), 6 * km_.nv, "point_jacobian");
  if (frame < 0 || frame >= km_.nframe)
    throw std::out_of_range("point_jacobian: frame index " + std::to_string(frame) + " outside [0, " +
                            std::to_string(km_.nframe) + ")");
  // The point in its body's coordinates (fixed), then in the world per lane.
  const int body = model_->frame_body[frame];
  const Eigen::Vector3d local = model_->frame_placement[frame] * offset;
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    const Vec3<L> x_body = {L(Scalar(local.x())), L(Scalar(local.y())), L(Scalar(local.z()))};
    if (body < 0) {  // fixed to the world: nothing moves it
      for (int k = 0; k < 6 * km_.nv; ++k) lane::store(L(0), out.block(b) + k * kWidth);
      return;
    }
    const Vec3<L> x = spatial::add(ws.world[body].p, spatial::rotate(ws.world[body].R, x_body));
    lockstep::point_jacobian<L>(km_, ws, body, x, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::kinetic_energy(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "kinetic_energy");
  check(out, s.copies(), 1, "kinetic_energy");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    lane::store(lockstep::kinetic_energy<L>(km_, block_inputs(s, b), ws), out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::potential_energy(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "potential_energy");
  check(out, s.copies(), 1, "potential_energy");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    lane::store(lockstep::potential_energy<L>(km_, block_inputs(s, b), ws), out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::linear_momentum(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  constexpr std::size_t W = lane::width_v<L>;
  check(s, "linear_momentum");
  check(out, s.copies(), 3, "linear_momentum");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    subtree_momentum<L>(km_, s.inertia.block(b), s.v.block(b), ws);
    Vec3<L> sum = {L(0), L(0), L(0)};
    for (int body = 0; body < km_.nbody; ++body)
      if (km_.body_parent[body] < 0) sum = spatial::add(sum, root_momentum(ws, body));
    lane::store(sum.x, out.block(b));
    lane::store(sum.y, out.block(b) + W);
    lane::store(sum.z, out.block(b) + 2 * W);
  });
}

template <class L>
void BatchDynamics<L>::incoming_joint_forces(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const {
  check(s, "incoming_joint_forces");
  check(out, s.copies(), 6 * km_.nbody, "incoming_joint_forces");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    BlockInputs<Scalar> in = block_inputs(s, b);
    in.qacc = nullptr;
    lockstep::incoming_joint_forces<L>(km_, in, ws, reinterpret_cast<Scalar*>(ws.vector.data()), out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::transmitted_joint_forces(const BatchState<Scalar>& s, BatchArray<Scalar>& out,
                                                std::optional<Scalar> link_damping_weight) const {
  check(s, "transmitted_joint_forces");
  check(out, s.copies(), 6 * km_.nbody, "transmitted_joint_forces");
  for_each_block(s.q.blocks(), [&](int b, Workspace<L>& ws) {
    joint_transforms<L>(km_, s.q.block(b), ws);
    world_transforms<L>(km_, ws);
    BlockInputs<Scalar> in = block_inputs(s, b);
    in.link_damping = link_damping_weight.has_value();
    in.link_damping_weight = link_damping_weight.value_or(0);
    lockstep::transmitted_joint_forces<L>(km_, in, ws, out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::integrate(const BatchArray<Scalar>& q, const BatchArray<Scalar>& v, Scalar dt,
                                 BatchArray<Scalar>& q_out) const {
  check(q, q.copies(), km_.nq, "integrate q");
  check(v, q.copies(), km_.nv, "integrate v");
  check(q_out, q.copies(), km_.nq, "integrate q_out");
  for_each_block(q.blocks(), [&](int b, Workspace<L>&) {
    lockstep::integrate<L>(km_, q.block(b), v.block(b), dt, q_out.block(b));
  });
}

template <class L>
void BatchDynamics<L>::difference(const BatchArray<Scalar>& q0, const BatchArray<Scalar>& q1,
                                  BatchArray<Scalar>& v_out) const {
  check(q0, q0.copies(), km_.nq, "difference q0");
  check(q1, q0.copies(), km_.nq, "difference q1");
  check(v_out, q0.copies(), km_.nv, "difference v_out");
  for_each_block(q0.blocks(), [&](int b, Workspace<L>&) {
    lockstep::difference<L>(km_, q0.block(b), q1.block(b), v_out.block(b));
  });
}

template class BatchDynamics<float>;
template class BatchDynamics<double>;
template class BatchDynamics<lane::simd<float>>;
template class BatchDynamics<lane::simd<double>>;

}  // namespace lockstep
