// What ABA's leaves-to-root pass hands from each body to its parent: the
// body's articulated inertia and bias force, both moved into the parent's
// coordinates. Where they wait is KernelModel::body_handoff: in the pass's
// carry when the parent is the next body visited (every link of a chain: no
// per-body slot, the values stay hot), in the parent's sum in the workspace
// otherwise (only branch points have one).
#pragma once

#include "kernels/kernel_model.hpp"

namespace lockstep {

template <class L>
struct SubtreeCarry {
  Inertia6<L> inertia;
  Vec6<L> force;
};

// Adds what body b's children handed over to its inertia I and force f.
template <class L>
LOCKSTEP_INLINE void add_children(const KernelModel<lane::scalar_t<L>>& km, int b, const Workspace<L>& ws,
                                  const SubtreeCarry<L>& carry, Inertia6<L>& I, Vec6<L>& f) {
  if (km.body_takes_carry[b]) {
    spatial::add_to(I, carry.inertia);
    f = spatial::add(f, carry.force);
  }
  if (km.body_takes_sum[b]) {
    spatial::add_to(I, ws.inertia[b]);
    f = spatial::add(f, ws.force[b]);
  }
}

// I and f moved by X into the parent's coordinates and written or added to
// I_out, f_out.
template <spatial::Write mode, class L>
LOCKSTEP_INLINE void subtree_to_parent(const Transform<L>& X, const Inertia6<L>& I, const Vec6<L>& f,
                                       Inertia6<L>& I_out, Vec6<L>& f_out) {
  spatial::inertia_to_parent<mode>(X, I, I_out);
  const Vec6<L> f_parent = spatial::force_to_parent(X, f);
  for (int k = 0; k < 6; ++k) spatial::write<mode>(f_out.e[k], f_parent.e[k]);
}

// Hands body b's inertia I and force f (body coordinates) to its parent, in
// the parent's coordinates. Nothing for a root. Each case names its
// destination, so the compiler knows which memory each store goes to.
template <class L>
LOCKSTEP_INLINE void hand_to_parent(const KernelModel<lane::scalar_t<L>>& km, int b, Workspace<L>& ws,
                                    SubtreeCarry<L>& carry, const Inertia6<L>& I, const Vec6<L>& f) {
  using spatial::Write;
  const Transform<L>& X = ws.local[b];
  const int parent = km.body_parent[b];
  switch (km.body_handoff[b]) {
    case Handoff::Carry: subtree_to_parent<Write::Set>(X, I, f, carry.inertia, carry.force); break;
    case Handoff::Store: subtree_to_parent<Write::Set>(X, I, f, ws.inertia[parent], ws.force[parent]); break;
    case Handoff::Add: subtree_to_parent<Write::Add>(X, I, f, ws.inertia[parent], ws.force[parent]); break;
    case Handoff::Root: break;
  }
}

}  // namespace lockstep
