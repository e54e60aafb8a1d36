// The force each joint transmits from the parent to its child body: RaiSim's
// force at the joint in the world frame, PhysX's link incoming joint force.
#pragma once

#include "kernels/aba.hpp"
#include "kernels/rnea.hpp"

namespace lockstep {

// out: (nbody x 6) per lane, world axes: [force; torque about the joint
// origin (the child body's origin)], during the motion in.qacc: the RNEA
// forward/backward passes' per-body forces (RBDA Table 5.1), turned to
// world axes. Needs ws.local and ws.world.
template <class L>
void transmitted_joint_forces(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in,
                              Workspace<L>& ws, lane::scalar_t<L>* out) {
  constexpr std::size_t W = lane::width_v<L>;
  rnea<L>(km, in, ws, nullptr);  // only the per-body forces are wanted
  for (int b = 0; b < km.nbody; ++b) {
    const Vec6<L>& f = ws.force[b];
    const Vec3<L> F = spatial::rotate(ws.world[b].R, f.lin());
    const Vec3<L> N = spatial::rotate(ws.world[b].R, f.ang());
    const L e[6] = {F.x, F.y, F.z, N.x, N.y, N.z};
    for (int k = 0; k < 6; ++k) lane::store(e[k], out + (6 * b + k) * W);
  }
}

// The same during the motion that in.tau produces: ABA for the
// accelerations first. scratch_qacc: (nv) per lane.
template <class L>
void incoming_joint_forces(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in,
                           Workspace<L>& ws, lane::scalar_t<L>* scratch_qacc, lane::scalar_t<L>* out) {
  aba<L>(km, in, ws, scratch_qacc);
  BlockInputs<lane::scalar_t<L>> with_qacc = in;
  with_qacc.qacc = scratch_qacc;
  transmitted_joint_forces<L>(km, with_qacc, ws, out);
}

}  // namespace lockstep
