// What the kernels read of a Model, flattened into arrays of the working
// precision T, plus the per-block inputs and the per-block scratch.
#pragma once

#include "kernels/spatial.hpp"
#include "layout/model.hpp"

#include <vector>

namespace lockstep {

// Per-copy inertial parameters of one body, as laid out in the batch:
// mass, COM (x y z) in the body frame, rotational inertia about the COM
// (xx yy zz xy xz yz) in body axes.
inline constexpr int kInertiaParams = 10;
inline constexpr int kInertiaMass = 0;
inline constexpr int kInertiaCom = 1;
inline constexpr int kInertiaRot = 4;

// A rigid transform as the kernels store it (broadcast_transform reads it):
// R row-major, then p; 12 values from out.
template <class T>
void flatten_transform(const Eigen::Isometry3d& X, T* out) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out[3 * r + c] = static_cast<T>(X.linear()(r, c));
  for (int k = 0; k < 3; ++k) out[9 + k] = static_cast<T>(X.translation()[k]);
}

// How a leaves-to-root pass (ABA's articulated inertias and bias forces;
// kernels/subtree.hpp) hands a body's subtree share to its parent: the
// parent is the next body visited (Carry: kept in the pass's local carry,
// never stored per body), or the parent's sum of its other children in the
// workspace, which the first of them visited starts (Store) and the rest
// add to (Add). Root: none.
enum class Handoff : std::uint8_t { Root, Carry, Store, Add };

template <class T>
struct KernelModel {
  int nbody = 0, nq = 0, nv = 0, nframe = 0;
  std::vector<int> body_parent;       // (nbody)
  std::vector<JointType> body_joint;  // (nbody)
  std::vector<int> body_q_offset;     // (nbody)
  std::vector<int> body_dof_offset;   // (nbody)
  std::vector<T> body_placement;      // (nbody x 12): R row-major (9), p (3); joint frame in parent body
  std::vector<int> dof_parent;        // (nv)
  // DOF k's ancestors (its dof_parent chain, nearest first) are
  // dof_ancestors[dof_ancestor_begin[k], dof_ancestor_begin[k + 1]): the
  // factor's loops read them as a list, not by chasing the chain
  std::vector<int> dof_ancestor_begin;  // (nv + 1)
  std::vector<int> dof_ancestors;
  std::vector<T> dof_armature;        // (nv)
  std::vector<int> frame_body;        // (nframe), -1: world
  std::vector<T> frame_placement;     // (nframe x 12), in the body frame (or the world)
  std::vector<T> default_inertia;     // (nbody x kInertiaParams), the model's values
  std::vector<std::uint8_t> body_gravity;  // (nbody) Model::body_gravity
  // Some body has gravity switched off: the kernels that take gravity then
  // need ws.world (body_weight), as they do for wrenches.
  bool gravity_switched_off = false;
  // Model::body_linear_damping and body_angular_damping (kernels/body_terms.hpp,
  // link_damping_inertia); body_damped: either is nonzero
  std::vector<T> body_linear_damping, body_angular_damping;  // (nbody)
  std::vector<std::uint8_t> body_damped;                     // (nbody)
  bool link_damping = false;                                 // some body is damped
  // Whether RNEA and ABA read ws.world: with wrenches, or with gravity where
  // some body has it switched off or, with the step's implicit link damping
  // (BlockInputs::link_damping_weight not 0), is damped.
  bool needs_world(bool wrenches, bool gravity = true, bool damping = false) const {
    return wrenches || (gravity && (gravity_switched_off || (damping && link_damping)));
  }
  std::vector<Handoff> body_handoff;           // (nbody) see Handoff
  std::vector<std::uint8_t> body_takes_carry;  // (nbody) the next body visited hands over by Carry
  std::vector<std::uint8_t> body_takes_sum;    // (nbody) some child hands over by Store / Add

  explicit KernelModel(const Model& model);
};

// The spatial axes a joint frees, as indices into [v; w] of the child body
// frame: every motion subspace S is a set of unit columns. MotionAxes<J>
// has them at compile time (kernels that keep a body's 6x6 blocks in
// registers need every index known), joint_axes at run time.
template <JointType J>
struct MotionAxes;
template <>
struct MotionAxes<JointType::Revolute> {
  static constexpr int count = 1;
  static constexpr int index[6] = {5};
};
template <>
struct MotionAxes<JointType::Prismatic> {
  static constexpr int count = 1;
  static constexpr int index[6] = {2};
};
template <>
struct MotionAxes<JointType::Spherical> {
  static constexpr int count = 3;
  static constexpr int index[6] = {3, 4, 5};
};
template <>
struct MotionAxes<JointType::Free> {
  static constexpr int count = 6;
  static constexpr int index[6] = {0, 1, 2, 3, 4, 5};
};

// Calls f(MotionAxes<J>{}) for the joint type of a moving joint (bodies'
// inbound joints are never Fixed: fixed joints are fused).
template <class F>
inline void with_motion_axes(JointType type, F&& f) {
  switch (type) {
    case JointType::Revolute: f(MotionAxes<JointType::Revolute>{}); break;
    case JointType::Prismatic: f(MotionAxes<JointType::Prismatic>{}); break;
    case JointType::Spherical: f(MotionAxes<JointType::Spherical>{}); break;
    case JointType::Free: f(MotionAxes<JointType::Free>{}); break;
    case JointType::Fixed: break;
  }
}

inline int joint_axes(JointType type, int axes[6]) {
  int n = 0;
  with_motion_axes(type, [&](auto S) {
    n = S.count;
    for (int k = 0; k < n; ++k) axes[k] = S.index[k];
  });
  return n;
}

// Inputs of a kernel for one block: arrays laid out [field][lane], width
// lanes per field. A null pointer means "all zero" (no gravity, no wrench...).
template <class T>
struct BlockInputs {
  const T* q = nullptr;        // (nq)
  const T* v = nullptr;        // (nv)
  const T* qacc = nullptr;     // (nv) joint accelerations (inverse dynamics)
  const T* tau = nullptr;      // (nv) joint forces (forward dynamics)
  const T* wrench = nullptr;   // (nbody x 6) world [force; torque about the body COM]
  const T* inertia = nullptr;  // (nbody x kInertiaParams); required
  const T* gravity = nullptr;  // (3) world gravity vector
  // Link damping (kernels/body_terms.hpp), which only the simulation step
  // applies: its force is taken at v + link_damping_weight a (0: explicit)
  bool link_damping = false;
  T link_damping_weight = 0;
};

// Scratch for one block, sized for a model once; kernels never allocate.
template <class L>
struct Workspace {
  std::vector<Transform<L>> local;    // (nbody) body in parent-body coordinates
  std::vector<Transform<L>> world;    // (nbody) body in world coordinates
  std::vector<Vec6<L>> velocity;      // (nbody) spatial velocity, body coordinates
  std::vector<Vec6<L>> accel;         // (nbody) spatial acceleration, body coordinates
  std::vector<Vec6<L>> force;         // (nbody) RNEA force / ABA: sum of children's bias forces (Handoff)
  std::vector<Inertia6<L>> inertia;   // (nbody) CRBA composite / ABA: sum of children's articulated inertias
  std::vector<L> joint_U;             // (nv x 6) U = IA S, one 6-column per DOF
  std::vector<L> joint_Dinv;          // (sum over bodies of ndof^2) D^-1 (1-DOF joints) or the L D L^T factor of D = S^T IA S + armature + w
  std::vector<int> joint_Dinv_offset; // (nbody)
  std::vector<L> gyroscopic;          // like joint_Dinv: h G of Free bodies (see aba.hpp)
  std::vector<L> joint_u;             // (nv) u = tau - S^T pA
  std::vector<L> matrix;              // (nv x nv) mass matrix / factorisation
  std::vector<L> vector;              // (nv) temporary
  std::vector<Vec3<L>> momentum;      // (nbody) linear momentum of each body's subtree, body axes

  template <class T>
  explicit Workspace(const KernelModel<T>& km);
};

template <class L>
template <class T>
Workspace<L>::Workspace(const KernelModel<T>& km)
    : local(km.nbody), world(km.nbody), velocity(km.nbody), accel(km.nbody),
      force(km.nbody), inertia(km.nbody), joint_U(6 * km.nv), joint_Dinv_offset(km.nbody), joint_u(km.nv),
      matrix(km.nv * km.nv), vector(km.nv), momentum(km.nbody) {
  int offset = 0;
  for (int b = 0; b < km.nbody; ++b) {
    joint_Dinv_offset[b] = offset;
    const int n = joint_nv(km.body_joint[b]);
    offset += n * n;
  }
  joint_Dinv.resize(offset);
  gyroscopic.resize(offset);
}

}  // namespace lockstep
