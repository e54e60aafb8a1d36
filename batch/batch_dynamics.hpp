// The dynamics utilities over a whole batch: each runs one kernel over every
// block of lanes, blocks spread over threads by TBB. L is the lane type: a
// SIMD batch (lane::simd<float>, lane::simd<double>) for throughput, or a
// plain float/double for the scalar reference (one copy per block).
//
// Inputs come from a BatchState made by make_state(); outputs go to arrays
// made by make_array(copies, size) with the size each method names.
#pragma once

#include "kernels/kernels.hpp"
#include "layout/batch_state.hpp"

#include <tbb/enumerable_thread_specific.h>

#include <optional>

namespace lockstep {

// The kernel inputs of one block of a batch state.
template <class T>
BlockInputs<T> block_inputs(const BatchState<T>& s, int block) {
  BlockInputs<T> in;
  in.q = s.q.block(block);
  in.v = s.v.block(block);
  in.tau = s.tau.block(block);
  in.qacc = s.qacc.block(block);
  in.wrench = s.wrench.block(block);
  in.inertia = s.inertia.block(block);
  in.gravity = s.gravity.block(block);
  return in;
}

template <class L>
class BatchDynamics {
 public:
  using Scalar = lane::scalar_t<L>;
  static constexpr int kWidth = static_cast<int>(lane::width_v<L>);

  explicit BatchDynamics(const Model& model);  // keeps a reference: the model must outlive it
  explicit BatchDynamics(Model&&) = delete;

  const Model& model() const { return *model_; }
  BatchState<Scalar> make_state(int copies) const { return BatchState<Scalar>(*model_, copies, kWidth); }
  BatchArray<Scalar> make_array(int copies, int size) const { return BatchArray<Scalar>(copies, size, kWidth); }

  // (nframe x 12) world pose of every frame: R row-major (9), then position.
  void frame_poses(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nbody x 12) world pose of every body, same layout.
  void body_poses(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nframe x 6) spatial velocity of every frame at s.q, s.v, world axes:
  // [v; w], v the velocity of the frame's origin (point_jacobian's rows).
  void frame_velocities(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nframe x 6) classical acceleration of every frame's origin and its
  // angular acceleration at s.q, s.v, s.qacc, world axes: [a; alpha]
  // (without gravity: a body at rest reads 0).
  void frame_accelerations(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nv) ABA: joint accelerations from s.q, s.v, s.tau, s.wrench, s.gravity.
  void forward_dynamics(const BatchState<Scalar>& s, BatchArray<Scalar>& qacc) const;
  // (nv) RNEA: joint forces for s.q, s.v, s.qacc, s.wrench, s.gravity.
  void inverse_dynamics(const BatchState<Scalar>& s, BatchArray<Scalar>& tau) const;
  // (nv) Coriolis + centrifugal + gravity: RNEA(q, v, 0) without wrenches.
  void bias_force(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nv) Coriolis + centrifugal only.
  void coriolis_force(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nv) the force that holds the model still against gravity.
  void gravity_force(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nv) sum_i J_i^T F_i of the link wrenches s.wrench.
  void external_force(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nv x nv) CRBA mass matrix with armature, row-major.
  void mass_matrix(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nv x nv) its inverse.
  void inverse_mass_matrix(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (6 nbody x nv) PhysX's dense Jacobian: rows [v_com; w] of every body, world axes.
  void com_jacobian(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (6 x nv) rows [v; w], world axes, of the point at `offset` in frame `frame`.
  void point_jacobian(const BatchState<Scalar>& s, int frame, const Eigen::Vector3d& offset,
                      BatchArray<Scalar>& out) const;
  // (1) kinetic and potential energy.
  void kinetic_energy(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  void potential_energy(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (3) linear momentum, world axes: the sum over all bodies of m v_com.
  void linear_momentum(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nbody x 6) force and torque each joint transmits to its child body under
  // s.tau and s.wrench, world axes, torque about the joint origin.
  void incoming_joint_forces(const BatchState<Scalar>& s, BatchArray<Scalar>& out) const;
  // (nbody x 6) the same during the motion s.qacc (RNEA's per-body forces),
  // with s.wrench and s.gravity; given a link damping weight w, with the
  // links' damping as a simulation step with that weight takes it,
  // -D (v + w a) (kernels/body_terms.hpp): the Simulator's readout.
  void transmitted_joint_forces(const BatchState<Scalar>& s, BatchArray<Scalar>& out,
                                std::optional<Scalar> link_damping_weight = std::nullopt) const;
  // (nq) q_out = q (+) v dt on the configuration manifold; (nv) its inverse.
  void integrate(const BatchArray<Scalar>& q, const BatchArray<Scalar>& v, Scalar dt, BatchArray<Scalar>& q_out) const;
  void difference(const BatchArray<Scalar>& q0, const BatchArray<Scalar>& q1, BatchArray<Scalar>& v_out) const;

 private:
  // Runs f(block, workspace) for every block, in parallel.
  template <class F>
  void for_each_block(int blocks, F&& f) const;
  // field: the BatchState field the array is (its name joins the message), or nullptr for an output
  void check(const BatchArray<Scalar>& array, int copies, int size, const char* what,
             const char* field = nullptr) const;
  void check(const BatchState<Scalar>& s, const char* what) const;

  const Model* model_;
  KernelModel<Scalar> km_;
  mutable tbb::enumerable_thread_specific<Workspace<L>> workspaces_;
};

extern template class BatchDynamics<float>;
extern template class BatchDynamics<double>;
extern template class BatchDynamics<lane::simd<float>>;
extern template class BatchDynamics<lane::simd<double>>;

}  // namespace lockstep
