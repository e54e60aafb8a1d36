// The configuration manifold: q has a quaternion (w, x, y, z) for every Free
// and Spherical joint, so positions are integrated by the exponential map and
// compared by its logarithm, never by adding to the quaternion.
#pragma once

#include "kernels/kinematics.hpp"

namespace lockstep {

template <class L>
struct Quaternion {
  L w, x, y, z;
};

template <class L>
inline Quaternion<L> quaternion_multiply(const Quaternion<L>& a, const Quaternion<L>& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

// exp of the rotation vector phi as a unit quaternion: (cos h, sin(h)/h phi/2),
// h = |phi|/2. sin(h)/h by its Taylor series below h = 1e-2 (float) or
// 1e-4 (double), where the series error is below the working precision.
template <class L>
inline Quaternion<L> quaternion_exp(const Vec3<L>& phi) {
  using T = lane::scalar_t<L>;
  const L h2 = T(0.25) * spatial::dot(phi, phi);
  const L h = lane::sqrt(h2);
  L s, c;
  lane::sincos(h, s, c);
  const T small = std::is_same_v<T, float> ? T(1e-2) : T(1e-4);
  const L sinc_series = lane::fmadd(h2, lane::fmadd(h2, L(T(1.0 / 120.0)), L(T(-1.0 / 6.0))), L(T(1)));
  const L sinc = lane::select(h < L(small), sinc_series, s / lane::max(h, L(small)));
  const L k = T(0.5) * sinc;
  return {c, k * phi.x, k * phi.y, k * phi.z};
}

// Rotation vector of a quaternion of any non-zero norm (the shorter way
// round), as of the quaternion normalised.
template <class L>
inline Vec3<L> quaternion_log(const Quaternion<L>& q) {
  using T = lane::scalar_t<L>;
  const L sign = lane::select(q.w < L(T(0)), L(T(-1)), L(T(1)));
  const Vec3<L> u = {sign * q.x, sign * q.y, sign * q.z};
  const L n = lane::sqrt(spatial::dot(u, u));
  const L half_angle = lane::atan2(n, sign * q.w);
  // The rotation vector is 2 h u / n with n = |q| sin(h); for small h that
  // is (2 / |q|) (h / sin h) u ~ (2 / |q|) (1 + h^2/6) u.
  const T small = std::is_same_v<T, float> ? T(1e-2) : T(1e-4);
  const L norm = lane::sqrt(lane::fmadd(q.w, q.w, n * n));
  const L series = T(2) * lane::fmadd(half_angle * half_angle, L(T(1.0 / 6.0)), L(T(1))) / norm;
  const L direct = T(2) * half_angle / lane::max(n, L(std::numeric_limits<T>::min()));
  const L ratio = lane::select(half_angle < L(small), series, direct);
  return spatial::scale(ratio, u);
}

template <class L>
inline Quaternion<L> load_quaternion(const lane::scalar_t<L>* q) {
  constexpr std::size_t W = lane::width_v<L>;
  return {lane::load<L>(q), lane::load<L>(q + W), lane::load<L>(q + 2 * W), lane::load<L>(q + 3 * W)};
}

// Three consecutive fields of a [field][lane] array.
template <class L>
inline Vec3<L> load_vec3(const lane::scalar_t<L>* p) {
  constexpr std::size_t W = lane::width_v<L>;
  return {lane::load<L>(p), lane::load<L>(p + W), lane::load<L>(p + 2 * W)};
}

template <class L>
inline void store_vec3(const Vec3<L>& a, lane::scalar_t<L>* p) {
  constexpr std::size_t W = lane::width_v<L>;
  lane::store(a.x, p);
  lane::store(a.y, p + W);
  lane::store(a.z, p + 2 * W);
}

template <class L>
inline void store_normalized(const Quaternion<L>& q, lane::scalar_t<L>* out) {
  constexpr std::size_t W = lane::width_v<L>;
  const L inv = L(lane::scalar_t<L>(1)) / lane::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  lane::store(q.w * inv, out);
  lane::store(q.x * inv, out + W);
  lane::store(q.y * inv, out + 2 * W);
  lane::store(q.z * inv, out + 3 * W);
}

// q_out = q (+) v dt: 1-DOF joints add, a Spherical joint turns its quaternion
// by exp(w dt) on the right (w in the body frame), a Free joint moves by
// R v_lin dt (R at q) and turns likewise. Quaternions are renormalised. q_out
// may be q.
template <class L>
void integrate(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* q, const lane::scalar_t<L>* v,
               lane::scalar_t<L> dt, lane::scalar_t<L>* q_out) {
  constexpr std::size_t W = lane::width_v<L>;
  const L h(dt);
  for (int b = 0; b < km.nbody; ++b) {
    const lane::scalar_t<L>* qb = q + km.body_q_offset[b] * W;
    const lane::scalar_t<L>* vb = v + km.body_dof_offset[b] * W;
    lane::scalar_t<L>* ob = q_out + km.body_q_offset[b] * W;
    switch (km.body_joint[b]) {
      case JointType::Revolute:
      case JointType::Prismatic:
        lane::store(lane::fmadd(lane::load<L>(vb), h, lane::load<L>(qb)), ob);
        break;
      case JointType::Spherical: {
        const Vec3<L> w = {lane::load<L>(vb) * h, lane::load<L>(vb + W) * h, lane::load<L>(vb + 2 * W) * h};
        store_normalized(quaternion_multiply(load_quaternion<L>(qb), quaternion_exp(w)), ob);
        break;
      }
      case JointType::Free: {
        const Quaternion<L> rot = load_quaternion<L>(qb + 3 * W);
        const Mat3<L> R = quaternion_rotation(rot.w, rot.x, rot.y, rot.z);
        const Vec3<L> dp = spatial::rotate(R, Vec3<L>{lane::load<L>(vb) * h, lane::load<L>(vb + W) * h,
                                                      lane::load<L>(vb + 2 * W) * h});
        const Vec3<L> w = {lane::load<L>(vb + 3 * W) * h, lane::load<L>(vb + 4 * W) * h, lane::load<L>(vb + 5 * W) * h};
        const Quaternion<L> turned = quaternion_multiply(rot, quaternion_exp(w));
        for (int k = 0; k < 3; ++k) {
          const L e = k == 0 ? dp.x : k == 1 ? dp.y : dp.z;
          lane::store(lane::load<L>(qb + k * W) + e, ob + k * W);
        }
        store_normalized(turned, ob + 3 * W);
        break;
      }
      case JointType::Fixed:
        break;
    }
  }
}

// A Free joint's velocity is (v, w) in its body frame: the linear velocity
// of the body origin turns with the body. The step integrates it in the frame
// the body has at the start of the step, where it changes only by the
// origin's classical acceleration a + w x v (a: the body-coordinate
// derivative that ABA gives), so a body without force keeps its world
// velocity and a world force adds h F / m, both to round-off:
//   u = v0 + h (a + w x v)   (add_frame_turn_rate on v0 + h a)
// with w x v taken as ABA took the velocity-product force w x p of the
// body's linear rows: at v0, or linearised about v0 with weight g (the
// implicit gyroscopic force, gyroscopic_jacobian), w0 x v0 + g (dw x v0 +
// w0 x dv), dv = h a. The solver rows (Jacobian and impulses at q0) act on u,
// positions move by R0 u h, and the new state's velocity is D^T u with
// D = exp(h w) the body's turn in the step (turn_free_linear, ToEnd).
// Impulses therefore keep momentum through the turn, and a spinning ball
// flies straight.

// x's Free-joint linear parts += scale (w x v + g h (alpha x v + w x a)),
// with (v, w) from v and (a, alpha) from a; g h = weight_h. With
// TurnPart::Implicit only the implicit gyroscopic part, scale g h (...).
enum class TurnPart { Whole, Implicit };
template <class L>
void add_frame_turn_rate(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* v,
                         const lane::scalar_t<L>* a, lane::scalar_t<L> weight_h, lane::scalar_t<L> scale,
                         lane::scalar_t<L>* x, TurnPart part = TurnPart::Whole) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int b = 0; b < km.nbody; ++b) {
    if (km.body_joint[b] != JointType::Free) continue;
    const int o = km.body_dof_offset[b] * W;
    const Vec3<L> lin = load_vec3<L>(v + o), w = load_vec3<L>(v + o + 3 * W);
    const Vec3<L> dlin = load_vec3<L>(a + o), dw = load_vec3<L>(a + o + 3 * W);
    const Vec3<L> change = spatial::add(spatial::cross(dw, lin), spatial::cross(w, dlin));
    const Vec3<L> implicit = spatial::scale(L(weight_h), change);
    const Vec3<L> rate = part == TurnPart::Whole ? spatial::add(spatial::cross(w, lin), implicit) : implicit;
    store_vec3(spatial::add(load_vec3<L>(x + o), spatial::scale(L(scale), rate)), x + o);
  }
}

// The body turns by D = exp(step w) in integrate(q, velocity, step), w the
// angular part of velocity. A vector x in body coordinates at one end of
// that turn is the same world vector as D x (ToStart) or D^T x (ToEnd) at
// the other; only the Free joints' linear parts are turned.
enum class Turn { ToStart, ToEnd };

template <class L>
void turn_free_linear(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* velocity,
                      lane::scalar_t<L> step, lane::scalar_t<L>* x, Turn turn) {
  constexpr std::size_t W = lane::width_v<L>;
  const L h(step);
  for (int b = 0; b < km.nbody; ++b) {
    if (km.body_joint[b] != JointType::Free) continue;
    const int o = km.body_dof_offset[b] * W;
    const Quaternion<L> d = quaternion_exp(spatial::scale(h, load_vec3<L>(velocity + o + 3 * W)));
    const Mat3<L> D = quaternion_rotation(d.w, d.x, d.y, d.z);
    const Vec3<L> in = load_vec3<L>(x + o);
    store_vec3(turn == Turn::ToStart ? spatial::rotate(D, in) : spatial::rotate_back(D, in), x + o);
  }
}

// The slope of a turn's coordinates u at q0 exp(u): a Spherical or Free
// joint at a stage reached by u = step w_p (w_p: the angular part of
// `previous`, as integrate(q0, previous, step) turned it) that turns at the
// body-frame angular velocity w moves u at J_r(u)^-1 w = w + (u x w) / 2 +
// u x (u x w) / 12 + O(|u|^4 |w|), J_r the right Jacobian of SO(3): RK4's
// stages added up in u (Munthe-Kaas's RKMK; Iserles et al., Acta Numerica
// 2000, sec. 4.3; the series kept to u^2 keeps order 4). x holds the
// stages' angular velocities and gets their slopes; other DOFs unchanged.
template <class L>
void turn_rate_at_start(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* previous,
                        lane::scalar_t<L> step, lane::scalar_t<L>* x) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const L h(step), half(T(0.5)), twelfth(T(1) / T(12));
  for (int b = 0; b < km.nbody; ++b) {
    const JointType type = km.body_joint[b];
    if (type != JointType::Spherical && type != JointType::Free) continue;
    const int o = (km.body_dof_offset[b] + (type == JointType::Free ? 3 : 0)) * W;
    const Vec3<L> u = spatial::scale(h, load_vec3<L>(previous + o)), w = load_vec3<L>(x + o);
    const Vec3<L> uw = spatial::cross(u, w);
    store_vec3(spatial::add(w, spatial::add(spatial::scale(half, uw), spatial::scale(twelfth, spatial::cross(u, uw)))),
               x + o);
  }
}

// v_out such that integrate(q0, v_out, 1) = q1 (up to round-off): the
// inverse of integrate on the manifold.
template <class L>
void difference(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* q0, const lane::scalar_t<L>* q1,
                lane::scalar_t<L>* v_out) {
  constexpr std::size_t W = lane::width_v<L>;
  for (int b = 0; b < km.nbody; ++b) {
    const int qo = km.body_q_offset[b] * W, vo = km.body_dof_offset[b] * W;
    switch (km.body_joint[b]) {
      case JointType::Revolute:
      case JointType::Prismatic:
        lane::store(lane::load<L>(q1 + qo) - lane::load<L>(q0 + qo), v_out + vo);
        break;
      case JointType::Spherical:
      case JointType::Free: {
        const int rot = km.body_joint[b] == JointType::Free ? 3 : 0;
        const int ang = km.body_joint[b] == JointType::Free ? 3 : 0;
        const Quaternion<L> a = load_quaternion<L>(q0 + qo + rot * W);
        const Quaternion<L> c = load_quaternion<L>(q1 + qo + rot * W);
        const Vec3<L> w = quaternion_log(quaternion_multiply(Quaternion<L>{a.w, -a.x, -a.y, -a.z}, c));
        lane::store(w.x, v_out + vo + ang * W);
        lane::store(w.y, v_out + vo + (ang + 1) * W);
        lane::store(w.z, v_out + vo + (ang + 2) * W);
        if (km.body_joint[b] == JointType::Free) {
          const Mat3<L> R = quaternion_rotation(a.w, a.x, a.y, a.z);
          const Vec3<L> dp = {lane::load<L>(q1 + qo) - lane::load<L>(q0 + qo),
                              lane::load<L>(q1 + qo + W) - lane::load<L>(q0 + qo + W),
                              lane::load<L>(q1 + qo + 2 * W) - lane::load<L>(q0 + qo + 2 * W)};
          const Vec3<L> local = spatial::rotate_back(R, dp);
          lane::store(local.x, v_out + vo);
          lane::store(local.y, v_out + vo + W);
          lane::store(local.z, v_out + vo + 2 * W);
        }
        break;
      }
      case JointType::Fixed:
        break;
    }
  }
}

}  // namespace lockstep
