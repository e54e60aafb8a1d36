// Per-body terms shared by the dynamics kernels: the body's inertial
// parameters for this block, its external wrench in body coordinates, and the
// world acceleration that stands in for gravity.
#pragma once

#include "kernels/kernel_model.hpp"

namespace lockstep {

template <class L>
struct BodyInertia {
  L mass;
  Vec3<L> com;
  L rot[6];  // about the COM, xx yy zz xy xz yz
};

template <class L>
inline BodyInertia<L> load_body_inertia(const lane::scalar_t<L>* inertia, int body) {
  constexpr std::size_t W = lane::width_v<L>;
  const lane::scalar_t<L>* p = inertia + kInertiaParams * body * W;
  BodyInertia<L> I;
  I.mass = lane::load<L>(p);
  I.com = {lane::load<L>(p + W), lane::load<L>(p + 2 * W), lane::load<L>(p + 3 * W)};
  for (int k = 0; k < 6; ++k) I.rot[k] = lane::load<L>(p + (kInertiaRot + k) * W);
  return I;
}

template <class L>
inline Vec6<L> rigid_mul(const BodyInertia<L>& I, const Vec6<L>& a) {
  return spatial::rigid_mul(I.mass, I.com, I.rot, a);
}

template <class L>
inline Inertia6<L> rigid_inertia(const BodyInertia<L>& I) {
  return spatial::rigid_inertia(I.mass, I.com, I.rot);
}

// The user's wrench on a body (world axes, torque about the COM) as a spatial
// force in body coordinates about the body origin: f = R^T F, n = R^T N + c x f.
template <class L>
inline Vec6<L> body_wrench(const lane::scalar_t<L>* wrench, int body, const Transform<L>& world, const Vec3<L>& com) {
  constexpr std::size_t W = lane::width_v<L>;
  const lane::scalar_t<L>* p = wrench + 6 * body * W;
  const Vec3<L> F = {lane::load<L>(p), lane::load<L>(p + W), lane::load<L>(p + 2 * W)};
  const Vec3<L> N = {lane::load<L>(p + 3 * W), lane::load<L>(p + 4 * W), lane::load<L>(p + 5 * W)};
  const Vec3<L> f = spatial::rotate_back(world.R, F);
  return spatial::make6(f, spatial::add(spatial::rotate_back(world.R, N), spatial::cross(com, f)));
}

// The weight m g of a body, acting at its COM, as a spatial force in body
// coordinates about the body origin (body_wrench's form).
template <class L>
inline Vec6<L> body_weight(const lane::scalar_t<L>* gravity, const BodyInertia<L>& I, const Transform<L>& world) {
  constexpr std::size_t W = lane::width_v<L>;
  const Vec3<L> g = {lane::load<L>(gravity), lane::load<L>(gravity + W), lane::load<L>(gravity + 2 * W)};
  const Vec3<L> f = spatial::scale(I.mass, spatial::rotate_back(world.R, g));
  return spatial::make6(f, spatial::cross(I.com, f));
}

// Takes from a body's force balance f (RNEA's I a + v x* I v, ABA's bias
// force) what acts on it from outside the tree: the user's wrench, and on a
// body whose gravity is switched off (KernelModel::body_gravity) the weight
// that a0 = [-g; 0] put into I a, so that no net gravity acts on it. Needs
// ws.world when either is there.
template <class L>
inline void subtract_applied_forces(const KernelModel<lane::scalar_t<L>>& km, const BlockInputs<lane::scalar_t<L>>& in,
                                    int b, const Transform<L>& world, const BodyInertia<L>& I, Vec6<L>& f) {
  if (in.wrench) f = spatial::sub(f, body_wrench<L>(in.wrench, b, world, I.com));
  if (in.gravity && !km.body_gravity[b]) f = spatial::add(f, body_weight<L>(in.gravity, I, world));
}

// Link damping of body b (KernelModel::body_linear_damping and
// body_angular_damping, c_lin and c_ang): the wrench -D v, where D is the
// rigid inertia with mass c_lin m and rotational inertia c_ang I_c about the
// same COM (about the COM, -c_lin m v_com and -c_ang I_c w). The step takes
// it at the end of the step, backward Euler with its weight w
// (BlockInputs::link_damping_weight): -D (v + w a), a being the body's
// spatial acceleration. The kernels' acceleration a' = a - [R^T g; 0]
// (gravity as the base's acceleration a0 = [-g; 0]), so
//   -D (v + w a) = -w D a' - D (v + w [R^T g; 0]):
// w D joins the body's inertia where it multiplies a' (ABA's IA, and so
// the factors of Mt read off it) and D (v + w [R^T g; 0]) its bias force
// (RNEA takes D (v + w (a' + [R^T g; 0])) whole). For a free
// body without gravity this is v1 = v0 / (1 + h c) per step.
// link_damping_inertia gives s D, as BodyInertia parameters.
template <class L>
inline BodyInertia<L> link_damping_inertia(const KernelModel<lane::scalar_t<L>>& km, int b, const BodyInertia<L>& I,
                                           lane::scalar_t<L> s) {
  BodyInertia<L> D;
  D.mass = L(s * km.body_linear_damping[b]) * I.mass;
  D.com = I.com;
  const L angular(s * km.body_angular_damping[b]);
  for (int k = 0; k < 6; ++k) D.rot[k] = angular * I.rot[k];
  return D;
}

// The velocity link damping acts on, but for the w a' that joins the
// inertia: v + w [R^T g; 0] (see link_damping_inertia).
template <class L>
inline Vec6<L> link_damping_velocity(const BlockInputs<lane::scalar_t<L>>& in, const Transform<L>& world,
                                     const Vec6<L>& v) {
  constexpr std::size_t W = lane::width_v<L>;
  if (!in.gravity || in.link_damping_weight == 0) return v;
  const Vec3<L> g = {lane::load<L>(in.gravity), lane::load<L>(in.gravity + W), lane::load<L>(in.gravity + 2 * W)};
  const Vec3<L> shift = spatial::scale(L(in.link_damping_weight), spatial::rotate_back(world.R, g));
  return spatial::make6(spatial::add(v.lin(), shift), v.ang());
}

// Whether body b takes link damping in these inputs.
template <class T>
inline bool damps_body(const KernelModel<T>& km, const BlockInputs<T>& in, int b) {
  return in.link_damping && km.body_damped[b];
}

// Gravity enters as a fictitious world acceleration a0 = [-g; 0] of the base
// (RBDA sec. 5.3), which also makes the bias force include gravity.
template <class L>
inline Vec6<L> world_acceleration(const lane::scalar_t<L>* gravity) {
  constexpr std::size_t W = lane::width_v<L>;
  Vec6<L> a0;
  for (int k = 0; k < 6; ++k) a0.e[k] = L(0);
  if (gravity)
    for (int k = 0; k < 3; ++k) a0.e[k] = -lane::load<L>(gravity + k * W);
  return a0;
}

}  // namespace lockstep
