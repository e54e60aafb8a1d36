// Forward kinematics over one block: joint transforms (with the joint
// sin/cos), world poses of bodies and frames.
#pragma once

#include "kernels/kernel_model.hpp"

#include <tuple>
#include <utility>

namespace lockstep {

// Rotation of a quaternion (w, x, y, z) of any non-zero norm, as if normalised:
// R = 1 + s [w [u]x + [u]x^2] with u = (x, y, z), s = 2 / |q|^2.
template <class L>
inline Mat3<L> quaternion_rotation(const L& w, const L& x, const L& y, const L& z) {
  const L norm2 = lane::fmadd(z, z, lane::fmadd(y, y, lane::fmadd(x, x, w * w)));
  const L s = L(lane::scalar_t<L>(2)) / norm2;
  const L xs = x * s, ys = y * s, zs = z * s;
  const L wx = w * xs, wy = w * ys, wz = w * zs;
  const L xx = x * xs, xy = x * ys, xz = x * zs;
  const L yy = y * ys, yz = y * zs, zz = z * zs;
  const L one(lane::scalar_t<L>(1));
  return {{one - (yy + zz), xy - wz, xz + wy,
           xy + wz, one - (xx + zz), yz - wx,
           xz - wy, yz + wx, one - (xx + yy)}};
}

template <class L>
inline Transform<L> broadcast_transform(const lane::scalar_t<L>* X) {
  Transform<L> t;
  for (int k = 0; k < 9; ++k) t.R.m[k] = L(X[k]);
  t.p = {L(X[9]), L(X[10]), L(X[11])};
  return t;
}

// The pose of every body in its parent body's coordinates:
// placement * joint motion (RBDA Table 4.1, with every axis along z).
template <class L>
void joint_transforms(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* q, Workspace<L>& ws) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int b = 0; b < km.nbody; ++b) {
    const lane::scalar_t<L>* P = &km.body_placement[12 * b];
    const lane::scalar_t<L>* qb = q + km.body_q_offset[b] * W;
    Transform<L>& X = ws.local[b];
    switch (km.body_joint[b]) {
      case JointType::Revolute: {
        // R = P.R Rz(q): columns (c P0 + s P1, -s P0 + c P1, P2).
        L s, c;
        lane::sincos(lane::load<L>(qb), s, c);
        for (int r = 0; r < 3; ++r) {
          const L p0(P[3 * r]), p1(P[3 * r + 1]);
          X.R(r, 0) = lane::fmadd(s, p1, c * p0);
          X.R(r, 1) = lane::fnmadd(s, p0, c * p1);
          X.R(r, 2) = L(P[3 * r + 2]);
        }
        X.p = {L(P[9]), L(P[10]), L(P[11])};
        break;
      }
      case JointType::Prismatic: {
        const L d = lane::load<L>(qb);
        for (int k = 0; k < 9; ++k) X.R.m[k] = L(P[k]);
        X.p = {lane::fmadd(d, L(P[2]), L(P[9])), lane::fmadd(d, L(P[5]), L(P[10])), lane::fmadd(d, L(P[8]), L(P[11]))};
        break;
      }
      case JointType::Spherical: {
        const Mat3<L> Rq = quaternion_rotation(lane::load<L>(qb), lane::load<L>(qb + W), lane::load<L>(qb + 2 * W),
                                               lane::load<L>(qb + 3 * W));
        X.R = spatial::mul(broadcast_transform<L>(P).R, Rq);
        X.p = {L(P[9]), L(P[10]), L(P[11])};
        break;
      }
      case JointType::Free:
        // q = [position; quaternion], the world pose of the body.
        X.R = quaternion_rotation(lane::load<L>(qb + 3 * W), lane::load<L>(qb + 4 * W), lane::load<L>(qb + 5 * W),
                                  lane::load<L>(qb + 6 * W));
        X.p = {lane::load<L>(qb), lane::load<L>(qb + W), lane::load<L>(qb + 2 * W)};
        break;
      case JointType::Fixed:
        X = broadcast_transform<L>(P);
        break;
    }
  }
}

// World pose of every body from the joint transforms.
template <class L>
void world_transforms(const KernelModel<lane::scalar_t<L>>& km, Workspace<L>& ws) {
  for (int b = 0; b < km.nbody; ++b) {
    const int parent = km.body_parent[b];
    ws.world[b] = parent < 0 ? ws.local[b] : spatial::compose(ws.world[parent], ws.local[b]);
  }
}

// World pose of every frame: body pose times the frame's fixed placement.
// frame_out: (nframe x 12) [field][lane], R row-major then p.
template <class L>
void frame_transforms(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws, lane::scalar_t<L>* frame_out) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int f = 0; f < km.nframe; ++f) {
    const Transform<L> placement = broadcast_transform<L>(&km.frame_placement[12 * f]);
    const int body = km.frame_body[f];
    const Transform<L> X = body < 0 ? placement : spatial::compose(ws.world[body], placement);
    lane::scalar_t<L>* out = frame_out + 12 * f * W;
    for (int k = 0; k < 9; ++k) lane::store(X.R.m[k], out + k * W);
    lane::store(X.p.x, out + 9 * W);
    lane::store(X.p.y, out + 10 * W);
    lane::store(X.p.z, out + 11 * W);
  }
}

// Spatial velocity of every body in its own coordinates, v_i = X v_parent + S qd
// (RBDA eq. 5.7). v == nullptr means all joints at rest.
template <class L>
void body_velocities(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* v, Workspace<L>& ws) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int b = 0; b < km.nbody; ++b) {
    const int parent = km.body_parent[b];
    Vec6<L> out;
    if (parent < 0)
      for (int k = 0; k < 6; ++k) out.e[k] = L(0);
    else
      out = spatial::motion_to_child(ws.local[b], ws.velocity[parent]);
    if (v)
      with_motion_axes(km.body_joint[b], [&](auto S) {
        for (int k = 0; k < S.count; ++k)
          out.e[S.index[k]] = out.e[S.index[k]] + lane::load<L>(v + (km.body_dof_offset[b] + k) * W);
      });
    ws.velocity[b] = out;
  }
}

// Six values per frame into frame_out, [linear; angular]: f(body, p) for a
// frame on a moving body (p: the frame's origin in the body's coordinates)
// returns the pair in world axes; a frame on the world gets zeros.
template <class L, class F>
void write_frame_vectors(const KernelModel<lane::scalar_t<L>>& km, lane::scalar_t<L>* frame_out, F&& f) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  for (int frame = 0; frame < km.nframe; ++frame) {
    const int body = km.frame_body[frame];
    Vec3<L> linear = {L(T(0)), L(T(0)), L(T(0))}, angular = linear;
    if (body >= 0) {
      const T* placement = &km.frame_placement[12 * frame];
      std::tie(linear, angular) = f(body, Vec3<L>{L(placement[9]), L(placement[10]), L(placement[11])});
    }
    const L e[6] = {linear.x, linear.y, linear.z, angular.x, angular.y, angular.z};
    for (int k = 0; k < 6; ++k) lane::store(e[k], frame_out + (6 * frame + k) * W);
  }
}

// Spatial velocity of every frame (URDF link), world axes, 6 values per
// frame: [v; w], v the velocity of the frame's origin and w the angular
// velocity (the rows of point_jacobian at the origin: the same as
// point_jacobian(frame, 0) qd). With the body's velocity (w_b, v_b) in its
// own coordinates and the frame's origin at p_f there,
// v = R_b (v_b + w_b x p_f), w = R_b w_b. Needs ws.world and ws.velocity.
template <class L>
void frame_velocities(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws,
                      lane::scalar_t<L>* frame_out) {
  write_frame_vectors<L>(km, frame_out, [&](int body, const Vec3<L>& p) {
    const Vec3<L> w = ws.velocity[body].ang();
    const Vec3<L> v = spatial::add(ws.velocity[body].lin(), spatial::cross(w, p));
    return std::pair{spatial::rotate(ws.world[body].R, v), spatial::rotate(ws.world[body].R, w)};
  });
}

// Classical acceleration of every frame's origin and its angular
// acceleration, world axes, 6 values per frame: [a; alpha] (PhysX's link
// acceleration, there at the COM). With the body's spatial acceleration
// (alpha_b, a_b) and velocity (w_b, v_b) in its own coordinates, the
// origin's classical acceleration is a_b + w_b x v_b (RBDA section 2.11),
// and the frame's origin at p_f moves with
// a = R_b (a_b + w_b x v_b + alpha_b x p_f + w_b x (w_b x p_f)),
// alpha = R_b alpha_b. Needs ws.world, and ws.velocity and ws.accel as
// RNEA's forward pass leaves them run without gravity.
template <class L>
void frame_accelerations(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws,
                         lane::scalar_t<L>* frame_out) {
  write_frame_vectors<L>(km, frame_out, [&](int body, const Vec3<L>& p) {
    const Vec3<L> w = ws.velocity[body].ang(), v = ws.velocity[body].lin();
    const Vec3<L> alpha = ws.accel[body].ang();
    const Vec3<L> origin = spatial::add(ws.accel[body].lin(), spatial::cross(w, v));
    const Vec3<L> turn = spatial::add(spatial::cross(alpha, p), spatial::cross(w, spatial::cross(w, p)));
    return std::pair{spatial::rotate(ws.world[body].R, spatial::add(origin, turn)),
                     spatial::rotate(ws.world[body].R, alpha)};
  });
}

}  // namespace lockstep
