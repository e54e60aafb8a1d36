// Kinetic and potential energy over one block.
#pragma once

#include "kernels/body_terms.hpp"
#include "kernels/kinematics.hpp"

namespace lockstep {

// T = 1/2 sum_i v_i^T I_i v_i (body coordinates) + 1/2 sum_k armature_k
// qdot_k^2: 1/2 qdot^T M qdot with M as crba gives it, rotor inertia
// included. Needs ws.local.
template <class L>
L kinetic_energy(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, Workspace<L>& ws) {
  constexpr std::size_t W = lane::width_v<L>;
  body_velocities<L>(km, in.v, ws);
  L energy(0);
  for (int b = 0; b < km.nbody; ++b) {
    const Vec6<L>& v = ws.velocity[b];
    const Vec6<L> h = rigid_mul(load_body_inertia<L>(in.inertia, b), v);
    for (int k = 0; k < 6; ++k) energy = lane::fmadd(v.e[k], h.e[k], energy);
  }
  for (int k = 0; k < km.nv; ++k) {
    const L qdot = lane::load<L>(in.v + k * W);
    energy = lane::fmadd(L(km.dof_armature[k]) * qdot, qdot, energy);
  }
  return L(lane::scalar_t<L>(0.5)) * energy;
}

// V = -sum_i m_i g . x_com,i over the bodies gravity acts on (zero at the
// world origin). Needs ws.world.
template <class L>
L potential_energy(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in, const Workspace<L>& ws) {
  constexpr std::size_t W = lane::width_v<L>;
  if (!in.gravity) return L(0);
  const Vec3<L> g = {lane::load<L>(in.gravity), lane::load<L>(in.gravity + W), lane::load<L>(in.gravity + 2 * W)};
  L energy(0);
  for (int b = 0; b < km.nbody; ++b) {
    if (!km.body_gravity[b]) continue;
    const BodyInertia<L> I = load_body_inertia<L>(in.inertia, b);
    const Vec3<L> com = spatial::add(ws.world[b].p, spatial::rotate(ws.world[b].R, I.com));
    energy = lane::fnmadd(I.mass, spatial::dot(g, com), energy);
  }
  return energy;
}

}  // namespace lockstep
