// Linear momentum over one block.
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"

namespace lockstep {

// The linear momentum of every body's subtree, in the body's own
// coordinates, into ws.momentum: the body's m (v + w x c), the mass times
// the velocity of its COM (v, w: its spatial velocity in its coordinates, c:
// its COM), plus each child's subtree momentum turned by the child's
// rotation R in its parent. A root's entry, turned by its own R, is its
// articulation's momentum in world axes (root_momentum). Needs ws.local;
// computes ws.velocity from v. No world poses: one rotation per body.
template <class L>
void subtree_momentum(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* inertia,
                      const lane::scalar_t<L>* v, Workspace<L>& ws) {
  std::vector<Vec3<L>>& out = ws.momentum;
  body_velocities<L>(km, v, ws);
  for (int b = 0; b < km.nbody; ++b) {
    const BodyInertia<L> I = load_body_inertia<L>(inertia, b);
    const Vec6<L>& vb = ws.velocity[b];
    const Vec3<L> w = {vb.e[3], vb.e[4], vb.e[5]};
    out[b] = spatial::scale(I.mass, spatial::add(Vec3<L>{vb.e[0], vb.e[1], vb.e[2]}, spatial::cross(w, I.com)));
  }
  for (int b = km.nbody - 1; b >= 0; --b) {
    const int parent = km.body_parent[b];
    if (parent >= 0) out[parent] = spatial::add(out[parent], spatial::rotate(ws.local[b].R, out[b]));
  }
}

// The momentum of root body `root`'s articulation in world axes, after
// subtree_momentum.
template <class L>
Vec3<L> root_momentum(const Workspace<L>& ws, int root) {
  return spatial::rotate(ws.local[root].R, ws.momentum[root]);
}

}  // namespace lockstep
