// Recursive Newton-Euler inverse dynamics over one block (RBDA Table 5.1):
// tau = M(q) qacc + C(q, v) v + g(q) - sum_i J_i^T F_i, M with the joints'
// armature on its diagonal as in CRBA and ABA (and, with the step's link
// damping, its force at v + w a: kernels/body_terms.hpp).
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"

namespace lockstep {

// Needs ws.local (joint_transforms) and, with a wrench, ws.world. Leaves in
// ws.force[i] the spatial force the parent transmits to body i through its
// joint, in body i coordinates about its origin. tau_out: (nv) per lane, or
// nullptr when only those forces are wanted.
//
// The forward pass computes the velocities itself rather than calling
// body_velocities: fused with the accelerations they stay in registers, and
// RNEA measured 30 % slower (anymal_b, float) with the separate helper.
template <class L>
void rnea(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, Workspace<L>& ws,
          lane::scalar_t<L>* tau_out) {
  constexpr std::size_t W = lane::width_v<L>;
  const Vec6<L> a0 = world_acceleration<L>(in.gravity);
  // forward pass: velocities, accelerations, net body forces
  for (int b = 0; b < km.nbody; ++b) {
    const int parent = km.body_parent[b];
    int axes[6];
    const int n = joint_axes(km.body_joint[b], axes);
    Vec6<L> vJ, aJ;
    for (int k = 0; k < 6; ++k) vJ.e[k] = aJ.e[k] = L(0);
    for (int k = 0; k < n; ++k) {
      const int dof = km.body_dof_offset[b] + k;
      if (in.v) vJ.e[axes[k]] = lane::load<L>(in.v + dof * W);
      if (in.qacc) aJ.e[axes[k]] = lane::load<L>(in.qacc + dof * W);
    }
    const Transform<L>& X = ws.local[b];
    Vec6<L> v, a;
    if (parent < 0) {
      v = vJ;
      a = spatial::add(spatial::motion_to_child(X, a0), aJ);
    } else {
      v = spatial::add(spatial::motion_to_child(X, ws.velocity[parent]), vJ);
      a = spatial::add(spatial::add(spatial::motion_to_child(X, ws.accel[parent]), aJ), spatial::motion_cross(v, vJ));
    }
    ws.velocity[b] = v;
    ws.accel[b] = a;
    const BodyInertia<L> I = load_body_inertia<L>(in.inertia, b);
    // f = I a + v x* I v - f_ext
    Vec6<L> f = spatial::add(rigid_mul(I, a), spatial::force_cross(v, rigid_mul(I, v)));
    subtract_applied_forces<L>(km, in, b, ws.world[b], I, f);
    if (damps_body(km, in, b)) {  // + D (v + w a), in the kernels' a' (body_terms.hpp)
      const Vec6<L> damped = link_damping_velocity<L>(in, ws.world[b], v);
      const Vec6<L> rate = spatial::add(damped, spatial::scale(L(in.link_damping_weight), a));
      f = spatial::add(f, rigid_mul(link_damping_inertia<L>(km, b, I, lane::scalar_t<L>(1)), rate));
    }
    ws.force[b] = f;
  }
  // backward pass: project on the joint axes, pass the rest to the parent
  for (int b = km.nbody - 1; b >= 0; --b) {
    int axes[6];
    const int n = joint_axes(km.body_joint[b], axes);
    if (tau_out)
      for (int k = 0; k < n; ++k) {
        const int dof = km.body_dof_offset[b] + k;
        L tau = ws.force[b].e[axes[k]];
        // the rotor's own inertia acts on the DOF only; the bodies never see it
        if (in.qacc) tau = lane::fmadd(L(km.dof_armature[dof]), lane::load<L>(in.qacc + dof * W), tau);
        lane::store(tau, tau_out + dof * W);
      }
    const int parent = km.body_parent[b];
    if (parent >= 0) ws.force[parent] = spatial::add(ws.force[parent], spatial::force_to_parent(ws.local[b], ws.force[b]));
  }
}

}  // namespace lockstep
