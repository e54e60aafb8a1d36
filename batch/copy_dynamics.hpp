// Dynamics of one environment copy at a time, for tools, tests and users who
// want answers for a single state. It runs the same kernels as the batch, on
// the scalar reference lane, in the chosen precision; inputs and outputs are
// double Eigen vectors in low-level order. Threads may share one object:
// each call works on its own copy of the inputs.
//
// Shapes: q (nq), v (nv), tau (nv), link_wrench (nbody x 6, each row a world-
// frame [force; torque about the body's COM]); matrices nv x nv.
#pragma once

#include "batch/precision.hpp"
#include "layout/model.hpp"

#include <memory>
#include <vector>

namespace lockstep {

class CopyDynamics {
 public:
  // Keeps a reference to the model, which must outlive it.
  explicit CopyDynamics(const Model& model, Precision precision = Precision::Double);
  explicit CopyDynamics(Model&&, Precision = Precision::Double) = delete;
  ~CopyDynamics();
  CopyDynamics(CopyDynamics&&) noexcept;
  CopyDynamics& operator=(CopyDynamics&&) noexcept;

  const Model& model() const { return *model_; }
  Precision precision() const { return precision_; }

  // World pose of every frame (URDF link), indexed like model.frame_name.
  std::vector<Eigen::Isometry3d> frame_poses(const Eigen::VectorXd& q) const;
  // World pose of every body, indexed like model.body_parent.
  std::vector<Eigen::Isometry3d> body_poses(const Eigen::VectorXd& q) const;
  // (6 x nframe) spatial velocity of every frame, world axes: column f is
  // [v; w], v the velocity of frame f's origin, w its angular velocity.
  Eigen::MatrixXd frame_velocities(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;
  // (6 x nframe) column f is [a; alpha], world axes: the classical
  // acceleration of frame f's origin and its angular acceleration during
  // the motion qacc (without gravity).
  Eigen::MatrixXd frame_accelerations(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                      const Eigen::VectorXd& qacc) const;

  Eigen::MatrixXd mass_matrix(const Eigen::VectorXd& q) const;                 // CRBA, armature included
  Eigen::MatrixXd inverse_mass_matrix(const Eigen::VectorXd& q) const;
  Eigen::VectorXd bias_force(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;  // Coriolis + centrifugal + gravity
  Eigen::VectorXd coriolis_force(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;
  Eigen::VectorXd gravity_force(const Eigen::VectorXd& q) const;               // holds the model still against gravity
  Eigen::VectorXd external_force(const Eigen::VectorXd& q, const Eigen::MatrixXd& link_wrench) const;  // sum J^T F
  // RNEA: tau = M a + bias - external_force.
  Eigen::VectorXd inverse_dynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& v, const Eigen::VectorXd& a,
                                   const Eigen::MatrixXd* link_wrench = nullptr) const;
  // ABA: a = M^-1 (tau - bias + external_force).
  Eigen::VectorXd forward_dynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& v, const Eigen::VectorXd& tau,
                                   const Eigen::MatrixXd* link_wrench = nullptr) const;
  double kinetic_energy(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;
  double potential_energy(const Eigen::VectorXd& q) const;
  // Linear momentum, world axes: the sum over all bodies of m v_com.
  Eigen::Vector3d linear_momentum(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;
  // (6 nbody x nv) rows [v_com; w] of every body, world axes (PhysX's dense Jacobian).
  Eigen::MatrixXd com_jacobian(const Eigen::VectorXd& q) const;
  // (6 x nv) rows [v; w], world axes, of the point at `offset` in frame `frame`.
  Eigen::MatrixXd point_jacobian(const Eigen::VectorXd& q, int frame, const Eigen::Vector3d& offset) const;
  // (nbody x 6) force and torque each joint transmits to its child under tau,
  // world axes, torque about the joint origin.
  Eigen::MatrixXd incoming_joint_forces(const Eigen::VectorXd& q, const Eigen::VectorXd& v, const Eigen::VectorXd& tau,
                                        const Eigen::MatrixXd* link_wrench = nullptr) const;
  // The same during the motion qacc (RNEA's per-body forces).
  Eigen::MatrixXd transmitted_joint_forces(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                           const Eigen::VectorXd& qacc,
                                           const Eigen::MatrixXd* link_wrench = nullptr) const;
  // q (+) v dt on the configuration manifold, and its inverse.
  Eigen::VectorXd integrate(const Eigen::VectorXd& q, const Eigen::VectorXd& v, double dt) const;
  Eigen::VectorXd difference(const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const;

 private:
  struct Impl;
  struct Inputs;  // the inputs of one call; those not given are zero
  template <class Method>
  Eigen::VectorXd evaluate(const Inputs& in, Method&& method, int size) const;
  const Model* model_;
  Precision precision_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lockstep
