// Articulated-body forward dynamics over one block (RBDA Table 7.1), with the
// joint armature added to D = S^T IA S:
//   qacc = (M + diag(armature))^-1 (tau - bias + sum_i J_i^T F_i).
// A joint-terms policy may replace tau and add an implicit diagonal w to D
// per DOF (the simulation step's implicit drives, damping and springs):
//   qacc = (M + diag(armature + w))^-1 (tau - bias + sum_i J_i^T F_i).
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"

namespace lockstep {

// Inverse of a small symmetric positive-definite matrix (n x n, row-major),
// by Gauss-Jordan elimination without pivoting (safe for SPD matrices).
template <class L>
inline void spd_inverse(int n, const L* D, L* Dinv) {
  L a[36];
  for (int k = 0; k < n * n; ++k) a[k] = D[k];
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c) Dinv[r * n + c] = L(lane::scalar_t<L>(r == c ? 1 : 0));
  for (int p = 0; p < n; ++p) {
    const L inv = L(lane::scalar_t<L>(1)) / a[p * n + p];
    for (int c = 0; c < n; ++c) {
      a[p * n + c] = a[p * n + c] * inv;
      Dinv[p * n + c] = Dinv[p * n + c] * inv;
    }
    for (int r = 0; r < n; ++r) {
      if (r == p) continue;
      const L f = a[r * n + p];
      for (int c = 0; c < n; ++c) {
        a[r * n + c] = lane::fnmadd(f, a[p * n + c], a[r * n + c]);
        Dinv[r * n + c] = lane::fnmadd(f, Dinv[p * n + c], Dinv[r * n + c]);
      }
    }
  }
}

// The plain joint-terms policy: tau from the inputs (zero when absent), no
// implicit diagonal. A policy's apply(dof, D, tau) is given the DOF's
// D = S^T IA S + armature (its articulated inertia, before w) and returns w
// to add to it, setting tau.
template <class L>
struct InputTorques {
  const lane::scalar_t<L>* tau;
  L apply(int dof, const L& /*D*/, L& tau_out) const {
    using T = lane::scalar_t<L>;
    tau_out = tau ? lane::load<L>(tau + dof * lane::width_v<L>) : L(T(0));
    return L(T(0));
  }
};

// Pass 2 for body b with an N-DOF joint (N a compile-time constant so the
// small loops unroll): U = IA S, D = S^T U + armature, u = tau - S^T pA, and
// the articulated inertia and bias handed to the parent.
template <int N, class L, class JointTerms>
inline void aba_backward_joint(const KernelModel<lane::scalar_t<L>>& km, int b, const int* axes, JointTerms& terms,
                               Workspace<L>& ws) {
  using T = lane::scalar_t<L>;
  const int dof0 = km.body_dof_offset[b];
  const Inertia6<L>& IA = ws.inertia[b];
  const Vec6<L>& pA = ws.force[b];
  L* U = &ws.joint_U[6 * dof0];  // column k at U + 6k
  for (int k = 0; k < N; ++k)
    for (int r = 0; r < 6; ++r) U[6 * k + r] = spatial::at(IA, r, axes[k]);
  L D[N * N];
  for (int k = 0; k < N; ++k)
    for (int l = 0; l < N; ++l) D[k * N + l] = U[6 * l + axes[k]];
  for (int k = 0; k < N; ++k) {
    L& Dkk = D[k * N + k];
    Dkk = Dkk + L(km.dof_armature[dof0 + k]);
    L tau_k;
    Dkk = Dkk + terms.apply(dof0 + k, Dkk, tau_k);
    ws.joint_u[dof0 + k] = tau_k - pA.e[axes[k]];
  }
  L* Dinv = &ws.joint_Dinv[ws.joint_Dinv_offset[b]];
  if constexpr (N == 1) {
    Dinv[0] = L(T(1)) / D[0];
  } else {
    spd_inverse(N, D, Dinv);
  }
  const int parent = km.body_parent[b];
  if (parent < 0) return;
  // Ia = IA - U D^-1 U^T;  pa = pA + Ia c + U D^-1 u   (RBDA eq. 7.42-7.43)
  L UDinv[6 * N];
  for (int r = 0; r < 6; ++r)
    for (int l = 0; l < N; ++l) {
      L sum = U[r] * Dinv[l];
      for (int k = 1; k < N; ++k) sum = lane::fmadd(U[6 * k + r], Dinv[k * N + l], sum);
      UDinv[r * N + l] = sum;
    }
  Inertia6<L> Ia = IA;
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c) {
      L& e = spatial::at(Ia, r, c);
      for (int k = 0; k < N; ++k) e = lane::fnmadd(UDinv[r * N + k], U[6 * k + c], e);
    }
  Vec6<L> pa = spatial::add(pA, spatial::mul(Ia, ws.bias_accel[b]));
  for (int r = 0; r < 6; ++r)
    for (int k = 0; k < N; ++k) pa.e[r] = lane::fmadd(UDinv[r * N + k], ws.joint_u[dof0 + k], pa.e[r]);
  spatial::add_to(ws.inertia[parent], spatial::inertia_to_parent(ws.local[b], Ia));
  ws.force[parent] = spatial::add(ws.force[parent], spatial::force_to_parent(ws.local[b], pa));
}

// Pass 3 for body b: qacc = D^-1 (u - U^T a'), a = a' + S qacc.
template <int N, class L>
inline void aba_forward_joint(const KernelModel<lane::scalar_t<L>>& km, int b, const int* axes, const Vec6<L>& a0,
                              Workspace<L>& ws, lane::scalar_t<L>* qacc_out) {
  constexpr std::size_t W = lane::width_v<L>;
  const int dof0 = km.body_dof_offset[b];
  const int parent = km.body_parent[b];
  Vec6<L> a = spatial::add(spatial::motion_to_child(ws.local[b], parent < 0 ? a0 : ws.accel[parent]), ws.bias_accel[b]);
  const L* U = &ws.joint_U[6 * dof0];
  const L* Dinv = &ws.joint_Dinv[ws.joint_Dinv_offset[b]];
  L rhs[N];
  for (int k = 0; k < N; ++k) {
    L sum = ws.joint_u[dof0 + k];
    for (int r = 0; r < 6; ++r) sum = lane::fnmadd(U[6 * k + r], a.e[r], sum);
    rhs[k] = sum;
  }
  for (int k = 0; k < N; ++k) {
    L qdd = Dinv[k * N] * rhs[0];
    for (int l = 1; l < N; ++l) qdd = lane::fmadd(Dinv[k * N + l], rhs[l], qdd);
    lane::store(qdd, qacc_out + (dof0 + k) * W);
    a.e[axes[k]] = a.e[axes[k]] + qdd;
  }
  ws.accel[b] = a;
}

// Needs ws.local (joint_transforms) and, with a wrench, ws.world.
// qacc_out: (nv) per lane. in.tau is ignored: the policy gives the torques.
template <class L, class JointTerms>
void aba_with(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, JointTerms& terms,
              Workspace<L>& ws, lane::scalar_t<L>* qacc_out) {
  // pass 1: velocities, velocity-product accelerations, rigid inertias and bias forces
  body_velocities<L>(km, in.v, ws);
  for (int b = 0; b < km.nbody; ++b) {
    const BodyInertia<L> I = load_body_inertia<L>(in.inertia, b);
    const Vec6<L>& v = ws.velocity[b];
    ws.inertia[b] = rigid_inertia(I);
    Vec6<L> pA = spatial::force_cross(v, rigid_mul(I, v));
    if (in.wrench) pA = spatial::sub(pA, body_wrench<L>(in.wrench, b, ws.world[b], I.com));
    ws.force[b] = pA;
  }
  // pass 2 (leaves to roots): articulated inertias IA and bias forces pA
  for (int b = km.nbody - 1; b >= 0; --b) {
    int axes[6];
    switch (joint_axes(km.body_joint[b], axes)) {
      case 1: aba_backward_joint<1>(km, b, axes, terms, ws); break;
      case 3: aba_backward_joint<3>(km, b, axes, terms, ws); break;
      case 6: aba_backward_joint<6>(km, b, axes, terms, ws); break;
    }
  }
  // pass 3 (roots to leaves): accelerations
  const Vec6<L> a0 = world_acceleration<L>(in.gravity);
  for (int b = 0; b < km.nbody; ++b) {
    int axes[6];
    switch (joint_axes(km.body_joint[b], axes)) {
      case 1: aba_forward_joint<1>(km, b, axes, a0, ws, qacc_out); break;
      case 3: aba_forward_joint<3>(km, b, axes, a0, ws, qacc_out); break;
      case 6: aba_forward_joint<6>(km, b, axes, a0, ws, qacc_out); break;
    }
  }
}

// ABA with the joint forces in.tau.
template <class L>
void aba(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, Workspace<L>& ws,
         lane::scalar_t<L>* qacc_out) {
  InputTorques<L> terms{in.tau};
  aba_with<L>(km, in, terms, ws, qacc_out);
}

}  // namespace lockstep
