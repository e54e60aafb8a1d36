// Dense Jacobians over one block, world axes: J v gives [linear; angular]
// velocity of a point fixed on a body.
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"

namespace lockstep {

// Calls f(column, v, w) for every DOF that moves `body`: the linear velocity
// v of the point x (world coordinates) fixed on the body and the angular
// velocity w, world axes, per unit velocity of that DOF. Column of axis k of
// an ancestor joint j: w = R_j e_k (angular axes), v = R_j e_k (linear axes)
// + w x (x - p_j). Needs ws.world.
template <class L, class F>
void for_each_point_column(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws, int body,
                           const Vec3<L>& x, F&& f) {
  for (int j = body; j >= 0; j = km.body_parent[j]) {
    int axes[6];
    const int n = joint_axes(km.body_joint[j], axes);
    const Transform<L>& X = ws.world[j];
    const Vec3<L> r = spatial::sub(x, X.p);
    for (int k = 0; k < n; ++k) {
      const int a = axes[k] % 3;
      const Vec3<L> axis = {X.R(0, a), X.R(1, a), X.R(2, a)};  // body axis in world
      const int col = km.body_dof_offset[j] + k;
      if (axes[k] < 3) f(col, axis, Vec3<L>{L(0), L(0), L(0)});
      else f(col, spatial::cross(axis, r), axis);
    }
  }
}

// Rows [v; w] (6 x nv, row-major per lane, starting at out) of the point x
// (world coordinates) moving with `body`; columns of DOFs that do not move
// the body are zero. Needs ws.world.
template <class L>
void point_jacobian(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws, int body, const Vec3<L>& x,
                    lane::scalar_t<L>* out) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  for (int k = 0; k < 6 * nv; ++k) lane::store(L(0), out + k * W);
  for_each_point_column<L>(km, ws, body, x, [&](int col, const Vec3<L>& v, const Vec3<L>& w) {
    const L e[6] = {v.x, v.y, v.z, w.x, w.y, w.z};
    for (int row = 0; row < 6; ++row) lane::store(e[row], out + (row * nv + col) * W);
  });
}

// PhysX's dense Jacobian: for every body, 6 rows [v_com; w] of its centre of
// mass, stacked in low-level order: out (6 nbody x nv). Needs ws.world.
template <class L>
void com_jacobian(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* inertia, const Workspace<L>& ws,
                  lane::scalar_t<L>* out) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int b = 0; b < km.nbody; ++b) {
    const BodyInertia<L> I = load_body_inertia<L>(inertia, b);
    const Vec3<L> com = spatial::add(ws.world[b].p, spatial::rotate(ws.world[b].R, I.com));
    point_jacobian<L>(km, ws, b, com, out + 6 * b * km.nv * W);
  }
}

}  // namespace lockstep
