// Every kernel, declared for the lane types the library instantiates: the
// scalar reference (float, double) and the SIMD lanes (lane::simd<float>,
// lane::simd<double>). Instantiated once in kernels_float.cpp and
// kernels_double.cpp, so users of this header do not compile the templates.
#pragma once

#include "kernels/aba.hpp"
#include "kernels/configuration.hpp"
#include "kernels/crba.hpp"
#include "kernels/energy.hpp"
#include "kernels/jacobian.hpp"
#include "kernels/joint_force.hpp"
#include "kernels/kinematics.hpp"
#include "kernels/momentum.hpp"
#include "kernels/rnea.hpp"

#define LOCKSTEP_KERNEL_TEMPLATES(EXTERN, L)                                                                         \
  EXTERN template struct Workspace<L>;                                                                               \
  EXTERN template Workspace<L>::Workspace(const KernelModel<lane::scalar_t<L>>&);                                   \
  EXTERN template void joint_transforms<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,         \
                                           Workspace<L>&);                                                            \
  EXTERN template void world_transforms<L>(const KernelModel<lane::scalar_t<L>>&, Workspace<L>&);                  \
  EXTERN template void frame_transforms<L>(const KernelModel<lane::scalar_t<L>>&, const Workspace<L>&,              \
                                           lane::scalar_t<L>*);                                                       \
  EXTERN template void body_velocities<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,          \
                                          Workspace<L>&);                                                             \
  EXTERN template void frame_velocities<L>(const KernelModel<lane::scalar_t<L>>&, const Workspace<L>&,              \
                                           lane::scalar_t<L>*);                                                       \
  EXTERN template void frame_accelerations<L>(const KernelModel<lane::scalar_t<L>>&, const Workspace<L>&,           \
                                              lane::scalar_t<L>*);                                                    \
  EXTERN template void rnea<L>(const KernelModel<lane::scalar_t<L>>&, const BlockInputs<lane::scalar_t<L>>&,        \
                               Workspace<L>&, lane::scalar_t<L>*);                                                    \
  EXTERN template void aba<L>(const KernelModel<lane::scalar_t<L>>&, const BlockInputs<lane::scalar_t<L>>&,         \
                              Workspace<L>&, lane::scalar_t<L>*);                                                     \
  EXTERN template void crba<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*, Workspace<L>&,      \
                               lane::scalar_t<L>*);                                                                   \
  EXTERN template void inverse_mass_matrix<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,      \
                                              Workspace<L>&, lane::scalar_t<L>*);                                     \
  EXTERN template L kinetic_energy<L>(const KernelModel<lane::scalar_t<L>>&, const BlockInputs<lane::scalar_t<L>>&, \
                                      Workspace<L>&);                                                                 \
  EXTERN template L potential_energy<L>(const KernelModel<lane::scalar_t<L>>&,                                      \
                                        const BlockInputs<lane::scalar_t<L>>&, const Workspace<L>&);                 \
  EXTERN template void subtree_momentum<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,        \
                                           const lane::scalar_t<L>*, Workspace<L>&);                                 \
  EXTERN template Vec3<L> root_momentum<L>(const Workspace<L>&, int);                                                \
  EXTERN template void point_jacobian<L>(const KernelModel<lane::scalar_t<L>>&, const Workspace<L>&, int,           \
                                         const Vec3<L>&, lane::scalar_t<L>*);                                         \
  EXTERN template void com_jacobian<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,             \
                                       const Workspace<L>&, lane::scalar_t<L>*);                                      \
  EXTERN template void transmitted_joint_forces<L>(const KernelModel<lane::scalar_t<L>>&,                           \
                                                   const BlockInputs<lane::scalar_t<L>>&, Workspace<L>&,             \
                                                   lane::scalar_t<L>*);                                               \
  EXTERN template void incoming_joint_forces<L>(const KernelModel<lane::scalar_t<L>>&,                              \
                                                const BlockInputs<lane::scalar_t<L>>&, Workspace<L>&,                \
                                                lane::scalar_t<L>*, lane::scalar_t<L>*);                              \
  EXTERN template void integrate<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,                \
                                    const lane::scalar_t<L>*, lane::scalar_t<L>, lane::scalar_t<L>*);                 \
  EXTERN template void difference<L>(const KernelModel<lane::scalar_t<L>>&, const lane::scalar_t<L>*,               \
                                     const lane::scalar_t<L>*, lane::scalar_t<L>*);

namespace lockstep {
LOCKSTEP_KERNEL_TEMPLATES(extern, float)
LOCKSTEP_KERNEL_TEMPLATES(extern, lane::simd<float>)
LOCKSTEP_KERNEL_TEMPLATES(extern, double)
LOCKSTEP_KERNEL_TEMPLATES(extern, lane::simd<double>)
}  // namespace lockstep
