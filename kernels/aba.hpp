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

// L D L^T factorisation of a small symmetric positive-definite matrix
// (n x n, row-major) in place: the unit lower factor L below the diagonal,
// 1/D on the diagonal (no square roots, no pivoting: safe for SPD). About
// n^3/6 multiply-adds, against n^3 for an explicit inverse.
template <class L>
inline void ldlt_factor(int n, L* a) {
  using T = lane::scalar_t<L>;
  L d[6];
  for (int j = 0; j < n; ++j) {
    L dj = a[j * n + j];
    for (int k = 0; k < j; ++k) dj = lane::fnmadd(a[j * n + k] * a[j * n + k], d[k], dj);
    d[j] = dj;
    const L inv_d = L(T(1)) / dj;
    a[j * n + j] = inv_d;
    for (int i = j + 1; i < n; ++i) {
      L s = a[i * n + j];
      for (int k = 0; k < j; ++k) s = lane::fnmadd(a[i * n + k] * a[j * n + k], d[k], s);
      a[i * n + j] = s * inv_d;
    }
  }
}

// Solves (L D L^T) x = b in place, with the factor of ldlt_factor.
template <class L>
inline void ldlt_solve(int n, const L* f, L* x) {
  for (int i = 1; i < n; ++i)
    for (int k = 0; k < i; ++k) x[i] = lane::fnmadd(f[i * n + k], x[k], x[i]);
  for (int i = 0; i < n; ++i) x[i] = x[i] * f[i * n + i];
  for (int i = n - 2; i >= 0; --i)
    for (int k = i + 1; k < n; ++k) x[i] = lane::fnmadd(f[k * n + i], x[k], x[i]);
}

// LU factorisation without pivoting of a small matrix whose symmetric part
// is positive definite (a Free root's D plus its implicit gyroscopic
// Jacobian), in place: unit-lower multipliers below the diagonal, 1/U_kk on
// it, U above.
template <class L>
inline void lu_factor(int n, L* a) {
  using T = lane::scalar_t<L>;
  for (int k = 0; k < n; ++k) {
    const L inv = L(T(1)) / a[k * n + k];
    a[k * n + k] = inv;
    for (int i = k + 1; i < n; ++i) {
      const L f = a[i * n + k] * inv;
      a[i * n + k] = f;
      for (int j = k + 1; j < n; ++j) a[i * n + j] = lane::fnmadd(f, a[k * n + j], a[i * n + j]);
    }
  }
}

template <class L>
inline void lu_solve(int n, const L* f, L* x) {
  for (int i = 1; i < n; ++i)
    for (int k = 0; k < i; ++k) x[i] = lane::fnmadd(f[i * n + k], x[k], x[i]);
  for (int i = n - 1; i >= 0; --i) {
    for (int k = i + 1; k < n; ++k) x[i] = lane::fnmadd(f[i * n + k], x[k], x[i]);
    x[i] = x[i] * f[i * n + i];
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
  // a h, the weight of a Free body's implicit gyroscopic Jacobian (see
  // gyroscopic_jacobian); 0: explicit.
  lane::scalar_t<L> implicit_gyroscopic_step() const { return 0; }
};

// h G for a Free body: G = d(v x* I v)/dv, the Jacobian of its velocity-
// product force, column j = e_j x* (I v) + v x* (I e_j). With it the force
// is taken later in the step, f(v0 + a dv) ~ f(v0) + a G dv, and a h G
// joins the body's D (a = 1: backward Euler, as for a free rigid body in
// Catto's "Numerical Methods", GDC 2015; the simulation step passes a = 1/2,
// the implicit midpoint rule, which keeps kinetic energy): a body spinning
// near its intermediate or major axis no longer gains energy every step.
template <class L>
inline void gyroscopic_jacobian(const Inertia6<L>& I, const Vec6<L>& v, lane::scalar_t<L> h, L* hG) {
  using T = lane::scalar_t<L>;
  const Vec6<L> momentum = spatial::mul(I, v);
  for (int j = 0; j < 6; ++j) {
    Vec6<L> unit, column;
    for (int r = 0; r < 6; ++r) {
      unit.e[r] = L(T(r == j ? 1 : 0));
      column.e[r] = spatial::at(I, r, j);
    }
    const Vec6<L> g = spatial::add(spatial::force_cross(unit, momentum), spatial::force_cross(v, column));
    for (int r = 0; r < 6; ++r) hG[r * 6 + j] = L(h) * g.e[r];
  }
}

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
  // D^-1 for one DOF; D's L D L^T factor for a Spherical joint; for a Free
  // root, the LU factor of D plus its implicit gyroscopic Jacobian h G
  // (not symmetric), kept by pass 1 in ws.gyroscopic.
  L* F = &ws.joint_Dinv[ws.joint_Dinv_offset[b]];
  if constexpr (N == 1) {
    F[0] = L(T(1)) / D[0];
  } else if constexpr (N == 3) {
    for (int k = 0; k < N * N; ++k) F[k] = D[k];
    ldlt_factor(N, F);
  } else {
    const L* hG = &ws.gyroscopic[ws.joint_Dinv_offset[b]];
    for (int k = 0; k < N * N; ++k) F[k] = terms.implicit_gyroscopic_step() != 0 ? D[k] + hG[k] : D[k];
    lu_factor(N, F);
  }
  const int parent = km.body_parent[b];
  if (parent < 0) return;
  // Ia = IA - U D^-1 U^T;  pa = pA + Ia c + U D^-1 u   (RBDA eq. 7.42-7.43).
  // Row r of U D^-1 solves D x = (row r of U), D being symmetric.
  L UDinv[6 * N];
  for (int r = 0; r < 6; ++r) {
    for (int l = 0; l < N; ++l) UDinv[r * N + l] = U[6 * l + r];
    if constexpr (N == 1) UDinv[r] = UDinv[r] * F[0];
    else ldlt_solve(N, F, &UDinv[r * N]);
  }
  // IA is not needed after this pass (pass 3 reads U, D and u): update in place.
  Inertia6<L>& Ia = ws.inertia[b];
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
  const L* F = &ws.joint_Dinv[ws.joint_Dinv_offset[b]];
  L qdd[N];
  for (int k = 0; k < N; ++k) {
    L sum = ws.joint_u[dof0 + k];
    for (int r = 0; r < 6; ++r) sum = lane::fnmadd(U[6 * k + r], a.e[r], sum);
    qdd[k] = sum;
  }
  if constexpr (N == 1) qdd[0] = F[0] * qdd[0];
  else if constexpr (N == 3) ldlt_solve(N, F, qdd);
  else lu_solve(N, F, qdd);
  for (int k = 0; k < N; ++k) {
    lane::store(qdd[k], qacc_out + (dof0 + k) * W);
    a.e[axes[k]] = a.e[axes[k]] + qdd[k];
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
    if (km.body_joint[b] == JointType::Free && terms.implicit_gyroscopic_step() != 0)
      gyroscopic_jacobian(ws.inertia[b], v, terms.implicit_gyroscopic_step(), &ws.gyroscopic[ws.joint_Dinv_offset[b]]);
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
