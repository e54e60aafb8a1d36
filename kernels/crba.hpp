// Joint-space mass matrix by the composite-rigid-body algorithm (RBDA
// Table 6.2), and its inverse through the tree-sparse factorisation
// M = L^T D L (RBDA sec. 6.5, Tables 6.3 and 6.4).
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"

namespace lockstep {

// Carries the force columns F[0, n) of body b's DOFs (b's coordinates) up
// the tree: at each ancestor j, entry(i, l, S_i^T ^jX_b^* F_l) for each DOF
// i of j's joint (RBDA Table 6.2's inner loop). N: the columns' room, a
// compile-time 1 for a one-DOF body keeps its column in registers.
template <class L, int N, class Entry>
LOCKSTEP_INLINE void carry_columns_to_ancestors(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws, int b,
                                                Vec6<L> (&F)[N], int n, Entry&& entry) {
  for (int j = b; km.body_parent[j] >= 0;) {
    for (int l = 0; l < n; ++l) F[l] = spatial::force_to_parent(ws.local[j], F[l]);
    j = km.body_parent[j];
    int axes_j[6];
    const int nj = joint_axes(km.body_joint[j], axes_j);
    const int dofj = km.body_dof_offset[j];
    for (int k = 0; k < nj; ++k)
      for (int l = 0; l < n; ++l) entry(dofj + k, l, F[l].e[axes_j[k]]);
  }
}

// The entries of M between a DOF and itself or its tree ancestors (both
// triangles), all that ltdl_factor reads; the others are left as they were.
// Needs ws.local. M_out: (nv x nv) per lane, row-major, armature on the
// diagonal.
template <class L>
void crba_tree(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* inertia, Workspace<L>& ws,
               lane::scalar_t<L>* M_out) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  for (int b = 0; b < km.nbody; ++b) ws.inertia[b] = rigid_inertia(load_body_inertia<L>(inertia, b));
  // composite inertias, leaves to roots
  for (int b = km.nbody - 1; b >= 0; --b) {
    const int parent = km.body_parent[b];
    if (parent >= 0) spatial::inertia_to_parent<spatial::Write::Add>(ws.local[b], ws.inertia[b], ws.inertia[parent]);
  }
  auto M = [&](int r, int c) { return M_out + (r * nv + c) * W; };
  for (int b = 0; b < km.nbody; ++b) {
    int axes[6];
    const int n = joint_axes(km.body_joint[b], axes);
    const int dof0 = km.body_dof_offset[b];
    // F = Ic S, then carried to each ancestor j as ^jX_b^T F: M_jb = S_j^T F.
    Vec6<L> F[6];
    for (int k = 0; k < n; ++k)
      for (int r = 0; r < 6; ++r) F[k].e[r] = spatial::at(ws.inertia[b], r, axes[k]);
    for (int k = 0; k < n; ++k)
      for (int l = 0; l < n; ++l) {
        L m = F[l].e[axes[k]];
        if (k == l) m = m + L(km.dof_armature[dof0 + k]);
        lane::store(m, M(dof0 + k, dof0 + l));
      }
    carry_columns_to_ancestors<L>(km, ws, b, F, n, [&](int i, int l, const L& m) {
      lane::store(m, M(i, dof0 + l));
      lane::store(m, M(dof0 + l, i));
    });
  }
}

// Needs ws.local. M_out: (nv x nv) per lane, row-major, armature on the
// diagonal; entries between DOFs on different branches are zero.
template <class L>
void crba(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* inertia, Workspace<L>& ws,
          lane::scalar_t<L>* M_out) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int k = 0; k < km.nv * km.nv; ++k) lane::store(L(0), M_out + k * W);
  crba_tree<L>(km, inertia, ws, M_out);
}

// In place: M (nv x nv per lane, as crba writes it) becomes its L^T D L
// factors, L unit lower triangular in the strict lower part, D on the
// diagonal. Uses the tree sparsity through the DOFs' ancestor lists.
template <class L>
void ltdl_factor(const KernelModel<lane::scalar_t<L>>& km, lane::scalar_t<L>* H) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  auto at = [&](int r, int c) { return H + (r * nv + c) * W; };
  const int* begin = km.dof_ancestor_begin.data();
  const int* ancestors = km.dof_ancestors.data();
  for (int k = nv - 1; k >= 0; --k) {
    const L Hkk = lane::load<L>(at(k, k));
    for (int t = begin[k]; t < begin[k + 1]; ++t) {
      const int i = ancestors[t];
      const L a = lane::load<L>(at(k, i)) / Hkk;
      for (int u = t; u < begin[k + 1]; ++u) {  // j: i and its ancestors
        const int j = ancestors[u];
        lane::store(lane::fnmadd(a, lane::load<L>(at(k, j)), lane::load<L>(at(i, j))), at(i, j));
      }
      lane::store(a, at(k, i));
    }
  }
}

// The factors ltdl_factor makes of Mt = M + diag(w), read off the ABA run
// just before at the same q with the same w (ws.joint_U = IA S per DOF;
// `implicit_diagonal`: w, what the ABA's policy added to each D). The
// factorisation eliminates leaves first, and eliminating all of a body's
// descendants from Mt leaves that body's articulated inertia IA (the Schur
// complement of the subtree; RBDA ch. 7, and the innovations factorisation
// of A. Jain, "Robot and Multibody Dynamics", 2011). So when it reaches
// body b, b's rows already hold
//   its own block  S^T IA S + armature + w  (ABA's D),
//   ancestor DOF i (of body j)  U^T ^bX_j S_i,
// the transform rigid, as the DOFs in between are not eliminated yet; what
// is left is to eliminate b's own DOFs (more than one for Spherical and
// Free joints), updating b's rows only: the ancestors' entries come from
// their own IA, which already holds what eliminating b leaves. CRBA's
// composite inertias and the elimination's updates of ancestor rows are not
// needed. Overwrites H's entries on the tree pattern, as ltdl_factor does.
template <class L>
void ltdl_factor_from_aba(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws, const L* implicit_diagonal,
                          lane::scalar_t<L>* H) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  auto at = [&](int r, int c) { return H + (r * nv + c) * W; };
  const int* begin = km.dof_ancestor_begin.data();
  const int* ancestors = km.dof_ancestors.data();
  for (int b = 0; b < km.nbody; ++b) {
    int axes[6];
    const int n = joint_axes(km.body_joint[b], axes);
    const int dof0 = km.body_dof_offset[b];
    auto diagonal = [&](int k, const L& u) {  // ABA's D, rounded alike
      return u + L(km.dof_armature[dof0 + k]) + implicit_diagonal[dof0 + k];
    };
    if (n == 1) {  // nothing to eliminate inside the body: carry U / D, whose entries are L's
      const L* U = &ws.joint_U[6 * dof0];
      const L d = diagonal(0, U[axes[0]]);
      lane::store(d, at(dof0, dof0));
      const L inverse = L(T(1)) / d;
      Vec6<L> F[1];
      for (int r = 0; r < 6; ++r) F[0].e[r] = U[r] * inverse;
      carry_columns_to_ancestors<L>(km, ws, b, F, 1, [&](int i, int, const L& a) { lane::store(a, at(dof0, i)); });
      continue;
    }
    Vec6<L> F[6];
    for (int l = 0; l < n; ++l)
      for (int r = 0; r < 6; ++r) F[l].e[r] = ws.joint_U[6 * (dof0 + l) + r];
    for (int k = 0; k < n; ++k)
      for (int l = 0; l <= k; ++l)
        lane::store(k == l ? diagonal(k, F[l].e[axes[k]]) : F[l].e[axes[k]], at(dof0 + k, dof0 + l));
    carry_columns_to_ancestors<L>(km, ws, b, F, n, [&](int i, int l, const L& m) { lane::store(m, at(dof0 + l, i)); });
    for (int k = dof0 + n - 1; k >= dof0; --k) {
      const L inverse = L(T(1)) / lane::load<L>(at(k, k));
      for (int t = begin[k]; t < begin[k + 1]; ++t) {
        const int i = ancestors[t];
        const L a = lane::load<L>(at(k, i)) * inverse;
        if (i >= dof0)  // one of b's own DOFs: its row takes the elimination of k
          for (int u = t; u < begin[k + 1]; ++u) {
            const int j = ancestors[u];
            lane::store(lane::fnmadd(a, lane::load<L>(at(k, j)), lane::load<L>(at(i, j))), at(i, j));
          }
        lane::store(a, at(k, i));
      }
    }
  }
}

// Solves L x = z in place on R right-hand sides x[0], ..., x[R - 1] (nv
// per lane each), with H from ltdl_factor: the last pass of ltdl_solve,
// root to leaves. Each factor entry is loaded once for the R of them; each
// gets the bits of a solve of its own.
template <int R, class L>
void ltdl_lower_solve_many(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H,
                           lane::scalar_t<L>* const (&x)[R]) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  const int* begin = km.dof_ancestor_begin.data();
  const int* ancestors = km.dof_ancestors.data();
  for (int k = 0; k < nv; ++k) {
    L xk[R];
    for (int r = 0; r < R; ++r) xk[r] = lane::load<L>(x[r] + k * W);
    for (int t = begin[k]; t < begin[k + 1]; ++t) {
      const int i = ancestors[t];
      const L Lki = lane::load<L>(H + (k * nv + i) * W);
      for (int r = 0; r < R; ++r) xk[r] = lane::fnmadd(Lki, lane::load<L>(x[r] + i * W), xk[r]);
    }
    for (int r = 0; r < R; ++r) lane::store(xk[r], x[r] + k * W);
  }
}

// The same on R right-hand sides `stride` scalars apart from x.
template <int R, class L>
void ltdl_lower_solve_many(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H,
                           lane::scalar_t<L>* x, int stride) {
  lane::scalar_t<L>* columns[R];
  for (int r = 0; r < R; ++r) columns[r] = x + r * stride;
  ltdl_lower_solve_many<R, L>(km, H, columns);
}

template <class L>
void ltdl_lower_solve(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, lane::scalar_t<L>* x) {
  ltdl_lower_solve_many<1, L>(km, H, x, 0);
}

// ltdl_lower_solve on the right-hand sides x + which[i] stride (i < count),
// four at a time (ltdl_lower_solve_many: the same bits as one solve each).
template <class L>
void ltdl_lower_solve_columns(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H,
                              lane::scalar_t<L>* x, int stride, const int* which, int count) {
  using T = lane::scalar_t<L>;
  int i = 0;
  for (; i + 4 <= count; i += 4) {
    T* const four[4] = {x + which[i] * stride, x + which[i + 1] * stride, x + which[i + 2] * stride,
                        x + which[i + 3] * stride};
    ltdl_lower_solve_many<4, L>(km, H, four);
  }
  for (; i < count; ++i) {
    T* const one[1] = {x + which[i] * stride};
    ltdl_lower_solve_many<1, L>(km, H, one);
  }
}

// Solves L^T y = b in place on x (nv per lane), with H from ltdl_factor:
// the first pass of ltdl_solve, leaves to root. With `dofs` (n of them,
// ascending, closed under dof_parent), b is zero outside them and the pass
// touches only them (the others stay zero); without, every DOF. R right-
// hand sides at once, `stride` scalars apart: each entry of L is loaded
// once for all of them, and their updates are independent of each other
// (the same operations as R single solves, so the same bits).
template <int R, class L>
void ltdl_transpose_solve_many(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H,
                               lane::scalar_t<L>* x, int stride, const int* dofs = nullptr, int n = -1) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  if (!dofs) n = nv;
  const int* begin = km.dof_ancestor_begin.data();
  const int* ancestors = km.dof_ancestors.data();
  for (int i = n - 1; i >= 0; --i) {
    const int k = dofs ? dofs[i] : i;
    L yk[R];
    for (int r = 0; r < R; ++r) yk[r] = lane::load<L>(x + r * stride + k * W);
    for (int t = begin[k]; t < begin[k + 1]; ++t) {
      const int a = ancestors[t];
      const L Lka = lane::load<L>(H + (k * nv + a) * W);
      for (int r = 0; r < R; ++r) {
        lane::scalar_t<L>* xa = x + r * stride + a * W;
        lane::store(lane::fnmadd(Lka, yk[r], lane::load<L>(xa)), xa);
      }
    }
  }
}

template <class L>
void ltdl_transpose_solve(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, lane::scalar_t<L>* x,
                          const int* dofs = nullptr, int n = -1) {
  ltdl_transpose_solve_many<1, L>(km, H, x, 0, dofs, n);
}

// Solves D y = b in place on x (nv per lane), with H from ltdl_factor: the
// middle pass of ltdl_solve. With `dofs` (n of them), b is zero outside
// them and only they are divided (0 / D_kk is 0: the same bits).
template <class L>
void ltdl_diagonal_solve(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, lane::scalar_t<L>* x,
                         const int* dofs = nullptr, int n = -1) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  if (!dofs) n = nv;
  for (int i = 0; i < n; ++i) {
    const int k = dofs ? dofs[i] : i;
    lane::store(lane::load<L>(x + k * W) / lane::load<L>(H + (k * nv + k) * W), x + k * W);
  }
}

// Solves (L^T D L) x = b in place on x (nv per lane), with H from ltdl_factor.
template <class L>
void ltdl_solve(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, lane::scalar_t<L>* x) {
  ltdl_transpose_solve<L>(km, H, x);
  ltdl_diagonal_solve<L>(km, H, x);
  ltdl_lower_solve<L>(km, H, x);
}

// M^-1 (nv x nv per lane) from the configuration: CRBA, factorisation, and
// one solve per column. Uses ws.matrix for the factors; needs ws.local.
template <class L>
void inverse_mass_matrix(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* inertia, Workspace<L>& ws,
                         lane::scalar_t<L>* Minv_out) {
  constexpr std::size_t W = lane::width_v<L>;
  using T = lane::scalar_t<L>;
  const int nv = km.nv;
  // The factors live in the caller's output until the columns overwrite it;
  // ws.matrix holds them meanwhile.
  T* H = reinterpret_cast<T*>(ws.matrix.data());
  crba<L>(km, inertia, ws, H);
  ltdl_factor<L>(km, H);
  T* column = reinterpret_cast<T*>(ws.vector.data());
  for (int c = 0; c < nv; ++c) {
    for (int r = 0; r < nv; ++r) lane::store(L(T(r == c ? 1 : 0)), column + r * W);
    ltdl_solve<L>(km, H, column);
    for (int r = 0; r < nv; ++r) lane::store(lane::load<L>(column + r * W), Minv_out + (r * nv + c) * W);
  }
}

}  // namespace lockstep
