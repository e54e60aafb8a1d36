// Articulated-body forward dynamics over one block (RBDA Table 7.1), with the
// joint armature added to D = S^T IA S:
//   qacc = (M + diag(armature))^-1 (tau - bias + sum_i J_i^T F_i).
// A joint-terms policy may replace tau and add an implicit diagonal w to D
// per DOF (the simulation step's implicit drives, damping and springs):
//   qacc = (M + diag(armature + w))^-1 (tau - bias + sum_i J_i^T F_i).
// With the step's link damping (BlockInputs::link_damping) M also holds
// w J_b^T D_b J_b per damped body b and the bias its force at v + w [R^T g; 0]
// (kernels/body_terms.hpp).
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"
#include "kernels/subtree.hpp"

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

// Joint rate qd of DOF k of a body's joint; in.v == nullptr: at rest.
template <class L>
inline L joint_rate(const lane::scalar_t<L>* v, int dof) {
  return v ? lane::load<L>(v + dof * lane::width_v<L>) : L(lane::scalar_t<L>(0));
}

// The velocity-product acceleration c = v x (S qd) of a body with velocity v
// (RBDA eq. 5.7, S constant in body coordinates), from the nonzero entries
// of S qd only: a revolute joint's c = qd (v_y, -v_x, 0, w_y, -w_x, 0).
template <class S, class L>
LOCKSTEP_INLINE Vec6<L> joint_bias_accel(const Vec6<L>& v, const L* qd) {
  using T = lane::scalar_t<L>;
  const L zero(T(0));
  if constexpr (S::count == 1 && S::index[0] == 5) {
    return {{v.e[1] * qd[0], -(v.e[0] * qd[0]), zero, v.e[4] * qd[0], -(v.e[3] * qd[0]), zero}};
  } else if constexpr (S::count == 1 && S::index[0] == 2) {
    return {{v.e[4] * qd[0], -(v.e[3] * qd[0]), zero, zero, zero, zero}};
  } else {
    Vec6<L> vJ;
    for (int k = 0; k < 6; ++k) vJ.e[k] = zero;
    for (int k = 0; k < S::count; ++k) vJ.e[S::index[k]] = qd[k];
    return spatial::motion_cross(v, vJ);
  }
}

// Pass 2 for body b, whose children are done (RBDA Table 7.1): its
// articulated inertia IA and bias force pA (the rigid body's, plus what its
// children handed over), then U = IA S, D = S^T U + armature (+ w from the
// joint terms), u = tau - S^T pA for pass 3, and Ia, pa handed to the parent.
// The joint's axes are compile-time constants (S), so IA's entries stay in
// registers; the rigid inertia is built here, not stored by an earlier pass.
// Inlined into the pass's loop: as a called function it was 5-20 % slower
// (A/B in one process on ur5, anymal_b and talos_reduced, float and double).
template <class S, class L, class JointTerms>
LOCKSTEP_INLINE void aba_backward_body(const KernelModel<lane::scalar_t<L>>& km,
                                       const BlockInputs<lane::scalar_t<L>>& in, int b, JointTerms& terms,
                                       Workspace<L>& ws, SubtreeCarry<L>& carry) {
  using T = lane::scalar_t<L>;
  constexpr int N = S::count;
  const int dof0 = km.body_dof_offset[b];
  const BodyInertia<L> I = load_body_inertia<L>(in.inertia, b);
  const Vec6<L> v = ws.velocity[b];
  Inertia6<L> IA = rigid_inertia(I);
  if constexpr (N == 6)
    if (terms.implicit_gyroscopic_step() != 0)
      gyroscopic_jacobian(IA, v, terms.implicit_gyroscopic_step(), &ws.gyroscopic[ws.joint_Dinv_offset[b]]);
  Vec6<L> pA = spatial::force_cross(v, rigid_mul(I, v));
  subtract_applied_forces<L>(km, in, b, ws.world[b], I, pA);
  if (damps_body(km, in, b)) {
    const Vec6<L> damped = link_damping_velocity<L>(in, ws.world[b], v);
    pA = spatial::add(pA, rigid_mul(link_damping_inertia<L>(km, b, I, T(1)), damped));
    if (in.link_damping_weight != 0)
      spatial::add_to(IA, rigid_inertia(link_damping_inertia<L>(km, b, I, in.link_damping_weight)));
  }
  add_children(km, b, ws, carry, IA, pA);
  L U[6 * N];  // column k at U + 6k
  for (int k = 0; k < N; ++k)
    for (int r = 0; r < 6; ++r) U[6 * k + r] = spatial::at(IA, r, S::index[k]);
  for (int k = 0; k < 6 * N; ++k) ws.joint_U[6 * dof0 + k] = U[k];
  L D[N * N];
  for (int k = 0; k < N; ++k)
    for (int l = 0; l < N; ++l) D[k * N + l] = U[6 * l + S::index[k]];
  L u[N];
  for (int k = 0; k < N; ++k) {
    L& Dkk = D[k * N + k];
    Dkk = Dkk + L(km.dof_armature[dof0 + k]);
    L tau_k;
    Dkk = Dkk + terms.apply(dof0 + k, Dkk, tau_k);
    u[k] = tau_k - pA.e[S::index[k]];
    ws.joint_u[dof0 + k] = u[k];
  }
  // D^-1 for one DOF; D's L D L^T factor for a Spherical joint; for a Free
  // root, the LU factor of D plus its implicit gyroscopic Jacobian h G (not
  // symmetric).
  L F[N * N];
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
  for (int k = 0; k < N * N; ++k) ws.joint_Dinv[ws.joint_Dinv_offset[b] + k] = F[k];
  if (km.body_handoff[b] == Handoff::Root) return;
  // Ia = IA - U D^-1 U^T;  pa = pA + Ia c + U D^-1 u   (RBDA eq. 7.42-7.43).
  // Row r of U D^-1 solves D x = (row r of U), D being symmetric.
  L UDinv[6 * N];
  for (int r = 0; r < 6; ++r) {
    for (int l = 0; l < N; ++l) UDinv[r * N + l] = U[6 * l + r];
    if constexpr (N == 1) UDinv[r] = UDinv[r] * F[0];
    else ldlt_solve(N, F, &UDinv[r * N]);
  }
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c) {
      L& e = spatial::at(IA, r, c);
      for (int k = 0; k < N; ++k) e = lane::fnmadd(UDinv[r * N + k], U[6 * k + c], e);
    }
  L qd[N];
  for (int k = 0; k < N; ++k) qd[k] = joint_rate<L>(in.v, dof0 + k);
  Vec6<L> pa = spatial::add(pA, spatial::mul(IA, joint_bias_accel<S>(v, qd)));
  for (int r = 0; r < 6; ++r)
    for (int k = 0; k < N; ++k) pa.e[r] = lane::fmadd(UDinv[r * N + k], u[k], pa.e[r]);
  hand_to_parent(km, b, ws, carry, IA, pa);
}

// Pass 3 for body b: a' = X a_parent + c, qacc = D^-1 (u - U^T a'),
// a = a' + S qacc.
template <class S, class L>
inline void aba_forward_body(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* v, int b,
                             const Vec6<L>& a0, Workspace<L>& ws, lane::scalar_t<L>* qacc_out) {
  constexpr std::size_t W = lane::width_v<L>;
  constexpr int N = S::count;
  const int dof0 = km.body_dof_offset[b];
  const int parent = km.body_parent[b];
  Vec6<L> a;
  if (parent < 0) {
    a = spatial::motion_to_child(ws.local[b], a0);  // c = v x (S qd) = 0 when v = S qd
  } else {
    L qd[N];
    for (int k = 0; k < N; ++k) qd[k] = joint_rate<L>(v, dof0 + k);
    a = spatial::add(spatial::motion_to_child(ws.local[b], ws.accel[parent]), joint_bias_accel<S>(ws.velocity[b], qd));
  }
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
    a.e[S::index[k]] = a.e[S::index[k]] + qdd[k];
  }
  ws.accel[b] = a;
}

// Needs ws.local (joint_transforms) and, with a wrench, ws.world.
// qacc_out: (nv) per lane. in.tau is ignored: the policy gives the torques.
template <class L, class JointTerms>
void aba_with(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, JointTerms& terms,
              Workspace<L>& ws, lane::scalar_t<L>* qacc_out) {
  // pass 1: velocities
  body_velocities<L>(km, in.v, ws);
  // pass 2 (leaves to roots): articulated inertias and bias forces, each
  // body's share handed to its parent through the carry (kernels/subtree.hpp)
  SubtreeCarry<L> carry;
  for (int b = km.nbody - 1; b >= 0; --b)
    with_motion_axes(km.body_joint[b],
                     [&](auto S) { aba_backward_body<decltype(S)>(km, in, b, terms, ws, carry); });
  // pass 3 (roots to leaves): accelerations
  const Vec6<L> a0 = world_acceleration<L>(in.gravity);
  for (int b = 0; b < km.nbody; ++b)
    with_motion_axes(km.body_joint[b],
                     [&](auto S) { aba_forward_body<decltype(S)>(km, in.v, b, a0, ws, qacc_out); });
}

// ABA with the joint forces in.tau.
template <class L>
void aba(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, Workspace<L>& ws,
         lane::scalar_t<L>* qacc_out) {
  InputTorques<L> terms{in.tau};
  aba_with<L>(km, in, terms, ws, qacc_out);
}

}  // namespace lockstep
