#include "kernels/kernel_model.hpp"

namespace lockstep {

namespace {
template <class T>
void append_placement(std::vector<T>& out, const Eigen::Isometry3d& X) {
  out.resize(out.size() + 12);
  flatten_transform(X, out.data() + out.size() - 12);
}
}  // namespace

template <class T>
KernelModel<T>::KernelModel(const Model& model)
    : nbody(model.nbody), nq(model.nq), nv(model.nv), nframe(static_cast<int>(model.frame_name.size())),
      body_parent(model.body_parent), body_joint(model.body_joint), body_q_offset(model.body_q_offset),
      body_dof_offset(model.body_dof_offset), dof_parent(model.dof_parent), frame_body(model.frame_body),
      body_gravity(model.body_gravity) {
  for (std::uint8_t on : body_gravity) gravity_switched_off |= on == 0;
  for (int b = 0; b < nbody; ++b) {
    body_linear_damping.push_back(static_cast<T>(model.body_linear_damping[b]));
    body_angular_damping.push_back(static_cast<T>(model.body_angular_damping[b]));
    body_damped.push_back(model.body_linear_damping[b] != 0.0 || model.body_angular_damping[b] != 0.0);
    link_damping |= body_damped.back() != 0;
    append_placement(body_placement, model.body_placement[b]);
    const Eigen::Matrix3d& I = model.body_inertia[b];
    const double params[kInertiaParams] = {model.body_mass[b], model.body_com[b].x(), model.body_com[b].y(),
                                           model.body_com[b].z(), I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2),
                                           I(1, 2)};
    for (double p : params) default_inertia.push_back(static_cast<T>(p));
  }
  for (double a : model.dof_armature) dof_armature.push_back(static_cast<T>(a));
  dof_ancestor_begin.push_back(0);
  for (int k = 0; k < nv; ++k) {
    for (int a = dof_parent[k]; a >= 0; a = dof_parent[a]) dof_ancestors.push_back(a);
    dof_ancestor_begin.push_back(static_cast<int>(dof_ancestors.size()));
  }
  for (const Eigen::Isometry3d& X : model.frame_placement) append_placement(frame_placement, X);
  // Leaves-to-root passes visit bodies from the last to the first: a body's
  // children come before it, the child right after it (if any) last.
  body_handoff.assign(nbody, Handoff::Root);
  body_takes_carry.assign(nbody, 0);
  body_takes_sum.assign(nbody, 0);
  for (int b = nbody - 1; b >= 0; --b) {
    const int parent = body_parent[b];
    if (parent < 0) continue;
    if (parent == b - 1) {
      body_handoff[b] = Handoff::Carry;
      body_takes_carry[parent] = 1;
    } else {
      body_handoff[b] = body_takes_sum[parent] ? Handoff::Add : Handoff::Store;
      body_takes_sum[parent] = 1;
    }
  }
}

template struct KernelModel<float>;
template struct KernelModel<double>;

}  // namespace lockstep
