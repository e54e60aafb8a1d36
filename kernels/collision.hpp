// Narrowphase collision geometry over lanes: for one pair of shapes (one
// pose per lane), a fixed number of contact candidates, each a signed
// separation along a unit normal at a world point. The caller keeps the
// candidates whose separation is below its margin.
//
// Shapes (sizes as layout/model.hpp's Shape::size):
//   plane     {x : n.x = d}, n unit, solid on the side -n;
//   sphere    radius r about the frame origin;
//   capsule   radius r about the segment from -l to +l along the frame's z;
//   cylinder  radius r, half length l along z (against a plane only; the
//             pair list treats it as a capsule elsewhere);
//   box       half extents (hx, hy, hz) along the frame's axes.
// Poses are Transform<L>: the shape's axes are the columns of R, its origin
// p, in world coordinates.
//
// A candidate of the pair (A, B) (A first in the function's name):
//   normal      unit, world, from A towards B: B moves along +normal to separate;
//   separation  signed distance of the surfaces along the normal (< 0: overlap);
//   point       world, midway between the two surface points.
// A candidate that does not exist in a lane has separation +inf, normal
// (0, 0, 1) and point 0, so every field stays finite.
//
// Branch-free: every lane runs the same instructions and chooses with
// lane::select, and every formula is written once on L, so SIMD lanes give
// the scalar reference's bits. Degenerate directions (coincident centres,
// parallel axes) fall back to a fixed axis by select: no NaN.
#pragma once

#include "kernels/spatial.hpp"

#include <limits>

namespace lockstep {

template <class L>
struct ContactCandidate {
  L separation;    // < 0: penetration; +inf: no candidate in this lane
  Vec3<L> normal;  // unit, world, from A towards B
  Vec3<L> point;   // world, midway between the two surface points
};

// Candidates each function writes (a compile-time count per pair kind).
inline constexpr int kPlaneSphereCandidates = 1;
inline constexpr int kPlaneCapsuleCandidates = 2;
inline constexpr int kPlaneBoxCandidates = 8;
inline constexpr int kPlaneCylinderCandidates = 4;
inline constexpr int kSphereSphereCandidates = 1;
inline constexpr int kSphereCapsuleCandidates = 1;
inline constexpr int kSphereBoxCandidates = 1;
inline constexpr int kCapsuleCapsuleCandidates = 2;
inline constexpr int kCapsuleBoxCandidates = 3;
inline constexpr int kBoxBoxCandidates = 24;

namespace collision_detail {

// Thresholds by precision.
//   tiny       a length below it is zero: its direction is undefined.
//   parallel   capsule-capsule, capsule-box along an edge: axes with
//              sin(angle) below it are parallel.
//   edge_axis  box-box: edge pairs with |ea x eb| below it give no axis.
//   relative   box-box: tie and clipping tolerances, times the box sizes;
//              ball pairs: centres closer than it times ra + rb coincide.
//   duplicate  capsule points closer than this times the half lengths
//              along the axis count as one.
template <class T>
struct Tolerances;
template <>
struct Tolerances<double> {
  static constexpr double tiny = 1e-100, parallel = 1e-3, edge_axis = 1e-6, relative = 1e-9, duplicate = 1e-3;
};
template <>
struct Tolerances<float> {
  static constexpr float tiny = 1e-15f, parallel = 1e-3f, edge_axis = 1e-3f, relative = 1e-5f, duplicate = 1e-3f;
};

template <class L>
inline L k(double x) { return L(static_cast<lane::scalar_t<L>>(x)); }
template <class L>
inline L infinity() { return L(std::numeric_limits<lane::scalar_t<L>>::infinity()); }
template <class L>
inline L tiny() { return k<L>(Tolerances<lane::scalar_t<L>>::tiny); }

template <class L>
inline Vec3<L> select(const lane::mask_t<L>& m, const Vec3<L>& a, const Vec3<L>& b) {
  return {lane::select(m, a.x, b.x), lane::select(m, a.y, b.y), lane::select(m, a.z, b.z)};
}
template <class L>
inline ContactCandidate<L> select(const lane::mask_t<L>& m, const ContactCandidate<L>& a,
                                  const ContactCandidate<L>& b) {
  return {lane::select(m, a.separation, b.separation), select(m, a.normal, b.normal), select(m, a.point, b.point)};
}
// +1 for x >= 0 (and -0), -1 below.
template <class L>
inline L unit_sign(const L& x) { return lane::select(x < k<L>(0), k<L>(-1), k<L>(1)); }
template <class L>
inline Vec3<L> negated(const Vec3<L>& v) { return {-v.x, -v.y, -v.z}; }
template <class L>
inline Vec3<L> column(const Mat3<L>& R, int c) { return {R(0, c), R(1, c), R(2, c)}; }
// p + s u, fused per component.
template <class L>
inline Vec3<L> axpy(const L& s, const Vec3<L>& u, const Vec3<L>& p) {
  return {lane::fmadd(s, u.x, p.x), lane::fmadd(s, u.y, p.y), lane::fmadd(s, u.z, p.z)};
}
template <class L>
inline Vec3<L> midpoint(const Vec3<L>& a, const Vec3<L>& b) { return spatial::scale(k<L>(0.5), spatial::add(a, b)); }

// v / |v| with |v| in `length`; `fallback` where |v| <= threshold.
template <class L>
inline Vec3<L> normalize_or(const Vec3<L>& v, const Vec3<L>& fallback, L& length, const L& threshold = tiny<L>()) {
  length = lane::sqrt(spatial::dot(v, v));
  const auto ok = length > threshold;
  const L inv = k<L>(1) / lane::select(ok, length, k<L>(1));
  return select(ok, spatial::scale(inv, v), fallback);
}

// A candidate that exists where `exists` holds, and is the finite
// placeholder (+inf, (0,0,1), 0) elsewhere.
template <class L>
inline ContactCandidate<L> only_where(const lane::mask_t<L>& exists, const ContactCandidate<L>& c) {
  const L zero = k<L>(0);
  return select(exists, c, ContactCandidate<L>{infinity<L>(), {zero, zero, k<L>(1)}, {zero, zero, zero}});
}

// The contact of a ball (centre a, radius ra) of shape A with a surface at
// separation sep along the unit normal n (from A): the ball's surface point
// a + ra n and the other surface point a + (ra + sep) n have the midpoint
// a + (ra + sep/2) n.
template <class L>
inline Vec3<L> ball_point(const Vec3<L>& a, const L& ra, const Vec3<L>& n, const L& sep) {
  return axpy(lane::fmadd(k<L>(0.5), sep, ra), n, a);
}

// Two balls (a, ra) and (b, rb): n = (b - a)/|b - a|, separation
// |b - a| - ra - rb. Where the centres coincide (|b - a| <= relative
// (ra + rb), which also catches centres apart only by rounding, whose
// direction is noise) the normal is `fallback`.
template <class L>
inline ContactCandidate<L> ball_ball(const Vec3<L>& a, const L& ra, const Vec3<L>& b, const L& rb,
                                     const Vec3<L>& fallback) {
  L dist;
  const L threshold = lane::max(k<L>(Tolerances<lane::scalar_t<L>>::relative) * (ra + rb), tiny<L>());
  const Vec3<L> n = normalize_or(spatial::sub(b, a), fallback, dist, threshold);
  const L sep = dist - ra - rb;
  return {sep, n, ball_point(a, ra, n, sep)};
}

// A ball (x, radius) against the plane {y : n.y = d}: separation n.x - d - radius
// along n; the point is midway between the ball's lowest point x - radius n
// and its projection on the plane: x - (radius + sep/2) n.
template <class L>
inline ContactCandidate<L> plane_ball(const Vec3<L>& n, const L& d, const Vec3<L>& x, const L& radius) {
  const L sep = spatial::dot(n, x) - d - radius;
  return {sep, n, axpy(-lane::fmadd(k<L>(0.5), sep, radius), n, x)};
}

// The parameter s in [-l, l] of the point of the segment c + s u (u unit)
// closest to x: the projection u.(x - c), clamped.
template <class L>
inline L closest_on_segment(const Vec3<L>& c, const Vec3<L>& u, const L& l, const Vec3<L>& x) {
  return lane::clamp(spatial::dot(u, spatial::sub(x, c)), -l, l);
}

// Closest points of the segments P(s) = p + s u, |s| <= lp and
// Q(t) = q + t v, |t| <= lq (u, v unit). With r = p - q, b = u.v, c = u.r,
// f = v.r, the lines' closest points satisfy s - b t = -c, t - b s = f, so
// s = (b f - c) / (1 - b^2), and 1 - b^2 = |u x v|^2. Clamping then follows
// Ericson (Real-Time Collision Detection, 5.1.9): s clamped, t the best
// for that s (clamped), s the best for that t (clamped); exact for the
// convex quadratic, including parallel segments (where s is arbitrary:
// the division by max(|u x v|^2, tiny^2) only has to stay finite).
template <class L>
inline void closest_segment_segment(const Vec3<L>& p, const Vec3<L>& u, const L& lp, const Vec3<L>& q,
                                    const Vec3<L>& v, const L& lq, L& s, L& t) {
  const Vec3<L> r = spatial::sub(p, q);
  const L b = spatial::dot(u, v), c = spatial::dot(u, r), f = spatial::dot(v, r);
  const Vec3<L> w = spatial::cross(u, v);
  const L denom = lane::max(spatial::dot(w, w), tiny<L>() * tiny<L>());
  const L s0 = lane::clamp(lane::fnmadd(k<L>(1), c, b * f) / denom, -lp, lp);
  t = lane::clamp(lane::fmadd(s0, b, f), -lq, lq);
  s = lane::clamp(lane::fnmadd(k<L>(1), c, t * b), -lp, lp);
}

// Signed distance of the box-frame point q from the box |x_i| <= h_i, with
// the outward unit normal at the closest surface point (box frame).
// Outside: the clamped point c = clamp(q, -h, h), distance |q - c|, normal
// (q - c)/|q - c|. Inside (or on the surface): the face of least
// penetration h_i - |q_i| (first axis on ties), distance -(h_i - |q_i|),
// normal sign(q_i) e_i (+1 at q_i = 0).
template <class L>
struct BoxPoint {
  L distance;
  Vec3<L> normal;
};
template <class L>
inline BoxPoint<L> box_point_local(const Vec3<L>& h, const Vec3<L>& q) {
  const Vec3<L> c = {lane::clamp(q.x, -h.x, h.x), lane::clamp(q.y, -h.y, h.y), lane::clamp(q.z, -h.z, h.z)};
  L dist;
  const Vec3<L> zero = {k<L>(0), k<L>(0), k<L>(0)};
  const Vec3<L> n_out = normalize_or(spatial::sub(q, c), zero, dist);
  const auto outside = dist > tiny<L>();
  const L pen_x = h.x - lane::abs(q.x), pen_y = h.y - lane::abs(q.y), pen_z = h.z - lane::abs(q.z);
  const auto y_less = pen_y < pen_x;
  const L pen_xy = lane::select(y_less, pen_y, pen_x);
  const auto z_least = pen_z < pen_xy;
  const auto y_least = y_less && !z_least;
  const auto x_least = !y_less && !z_least;
  const L pen = lane::select(z_least, pen_z, pen_xy);
  const Vec3<L> n_in = {lane::select(x_least, unit_sign(q.x), k<L>(0)), lane::select(y_least, unit_sign(q.y), k<L>(0)),
                        lane::select(z_least, unit_sign(q.z), k<L>(0))};
  return {lane::select(outside, dist, -pen), select(outside, n_out, n_in)};
}

// sign(g) g^2 for the signed distance g of box_point_local, without its
// square root and division: the same order, for comparisons.
template <class L>
inline L box_distance_order(const Vec3<L>& h, const Vec3<L>& q) {
  const Vec3<L> c = {lane::clamp(q.x, -h.x, h.x), lane::clamp(q.y, -h.y, h.y), lane::clamp(q.z, -h.z, h.z)};
  const Vec3<L> d = spatial::sub(q, c);
  const L d2 = spatial::dot(d, d);
  const L pen = lane::min(lane::min(h.x - lane::abs(q.x), h.y - lane::abs(q.y)), h.z - lane::abs(q.z));
  return lane::select(d2 > tiny<L>() * tiny<L>(), d2, -(pen * pen));
}

}  // namespace collision_detail

// --- plane pairs (A: the plane {x : n.x = d}) ----------------------------

// Sphere (centre c = X.p, radius r): separation n.c - d - r, normal n,
// point c - (r + separation/2) n.
template <class L>
void collide_plane_sphere(const Vec3<L>& n, const L& d, const Transform<L>& X, const L& r,
                          ContactCandidate<L>* out) {
  out[0] = collision_detail::plane_ball(n, d, X.p, r);
}

// Capsule: the two end balls p -+ l z (z = R's third column), each as a sphere.
template <class L>
void collide_plane_capsule(const Vec3<L>& n, const L& d, const Transform<L>& X, const L& r, const L& l,
                           ContactCandidate<L>* out) {
  using namespace collision_detail;
  const Vec3<L> z = column(X.R, 2);
  out[0] = plane_ball(n, d, axpy(-l, z, X.p), r);
  out[1] = plane_ball(n, d, axpy(l, z, X.p), r);
}

// Box: each corner v = p + R (+-hx, +-hy, +-hz) (index bits 0, 1, 2 set:
// +hx, +hy, +hz): separation n.v - d, normal n, point v - (separation/2) n,
// midway between the corner and its projection on the plane.
template <class L>
void collide_plane_box(const Vec3<L>& n, const L& d, const Transform<L>& X, const L& hx, const L& hy,
                       const L& hz, ContactCandidate<L>* out) {
  using namespace collision_detail;
  for (int i = 0; i < 8; ++i) {
    const Vec3<L> corner = {i & 1 ? hx : -hx, i & 2 ? hy : -hy, i & 4 ? hz : -hz};
    out[i] = plane_ball(n, d, spatial::add(X.p, spatial::rotate(X.R, corner)), k<L>(0));
  }
}

// Cylinder (MuJoCo's choice of points). With a the axis (R's third column),
// the rim direction of deepest descent is v = normalize((n x a) x a) (the
// component of -n perpendicular to a, as cross products so that it stays
// perpendicular to a however short); where a is parallel to n it is
// undefined and v is R's first column instead. The deeper cap is the one
// at s l a with s = -1 where n.a > 0, else +1. Candidates, each a
// point x of the surface with separation n.x - d:
//   0: the deeper cap's rim point  p + s l a + r v,
//   1: the other cap's rim point   p - s l a + r v,
//   2, 3: the deeper cap's rim at +-120 degrees from candidate 0:
//         p + s l a + r (-v/2 +- (sqrt(3)/2) (a x v)).
// Upright on the plane: 0, 2, 3 are three rim points 120 degrees apart;
// lying on its side: 0 and 1 are the two ends of the line of contact.
template <class L>
void collide_plane_cylinder(const Vec3<L>& n, const L& d, const Transform<L>& X, const L& r, const L& l,
                            ContactCandidate<L>* out) {
  using namespace collision_detail;
  const Vec3<L> a = column(X.R, 2);
  const L na = spatial::dot(n, a);
  L length;
  const Vec3<L> v = normalize_or(spatial::cross(spatial::cross(n, a), a), column(X.R, 0), length);
  const Vec3<L> w = spatial::cross(a, v);
  const L s = lane::select(na > k<L>(0), k<L>(-1), k<L>(1));
  const Vec3<L> deep_cap = axpy(s * l, a, X.p), other_cap = axpy(-(s * l), a, X.p);
  const L zero = k<L>(0);
  out[0] = plane_ball(n, d, axpy(r, v, deep_cap), zero);
  out[1] = plane_ball(n, d, axpy(r, v, other_cap), zero);
  const L along_v = k<L>(-0.5) * r, along_w = k<L>(0.86602540378443864676) * r;  // r cos 120, r sin 120
  const Vec3<L> rim = axpy(along_v, v, deep_cap);
  out[2] = plane_ball(n, d, axpy(along_w, w, rim), zero);
  out[3] = plane_ball(n, d, axpy(-along_w, w, rim), zero);
}

// --- sphere and capsule pairs ---------------------------------------------

// Spheres (centres a, b): normal (b - a)/|b - a|, separation
// |b - a| - ra - rb; coincident centres take the normal +z.
template <class L>
void collide_sphere_sphere(const Transform<L>& A, const L& ra, const Transform<L>& B, const L& rb,
                           ContactCandidate<L>* out) {
  using namespace collision_detail;
  out[0] = ball_ball(A.p, ra, B.p, rb, Vec3<L>{k<L>(0), k<L>(0), k<L>(1)});
}

// Sphere (centre a) and capsule (segment pb + t zb, |t| <= lb): the sphere
// against the ball at the segment point closest to a,
// t = clamp(zb.(a - pb), -lb, lb). A centre on the segment takes the
// capsule's x axis (perpendicular to its segment) as the normal.
template <class L>
void collide_sphere_capsule(const Transform<L>& A, const L& ra, const Transform<L>& B, const L& rb, const L& lb,
                            ContactCandidate<L>* out) {
  using namespace collision_detail;
  const Vec3<L> zb = column(B.R, 2);
  const L t = closest_on_segment(B.p, zb, lb, A.p);
  out[0] = ball_ball(A.p, ra, axpy(t, zb, B.p), rb, column(B.R, 0));
}

// Capsules (segments pa + s za, |s| <= la and pb + t zb, |t| <= lb):
//   candidate 0: the balls at the segments' closest points
//                (closest_segment_segment);
//   candidate 1: +inf,
// except where the axes are parallel (|za x zb| < parallel) and B's
// segment, projected on A's axis, overlaps A's in an interval
// [lo, hi] = [-la, la] n [c - lb|b|, c + lb|b|] (c = za.(pb - pa),
// b = za.zb) longer than duplicate (la + lb): then the candidates are the
// balls at the two ends of the overlap, s = lo and s = hi, each against the
// closest point of B's segment, so that a capsule lying along another rests
// on two points. (For axes at a small angle the distance at the ends may
// exceed the least one, by less than parallel * (hi - lo).)
// Segments that touch (closest points coincide) take as the normal their
// common perpendicular za x zb, or A's x axis where they are parallel,
// turned to point from A's centre towards B's.
template <class L>
void collide_capsule_capsule(const Transform<L>& A, const L& ra, const L& la, const Transform<L>& B, const L& rb,
                             const L& lb, ContactCandidate<L>* out) {
  using namespace collision_detail;
  using T = lane::scalar_t<L>;
  const Vec3<L> za = column(A.R, 2), zb = column(B.R, 2), xa = column(A.R, 0);
  const Vec3<L> ab = spatial::sub(B.p, A.p);
  const Vec3<L> w = spatial::cross(za, zb);
  const auto parallel = spatial::dot(w, w) < k<L>(Tolerances<T>::parallel * Tolerances<T>::parallel);
  L length;
  Vec3<L> fallback = select(parallel, xa, normalize_or(w, xa, length));
  fallback = spatial::scale(unit_sign(spatial::dot(fallback, ab)), fallback);

  auto at = [&](const L& s, const L& t) { return ball_ball(axpy(s, za, A.p), ra, axpy(t, zb, B.p), rb, fallback); };
  auto on_b = [&](const L& s) { return closest_on_segment(B.p, zb, lb, axpy(s, za, A.p)); };

  L s, t;
  closest_segment_segment(A.p, za, la, B.p, zb, lb, s, t);
  const ContactCandidate<L> closest = at(s, t);

  const L centre = spatial::dot(za, ab), reach = lb * lane::abs(spatial::dot(za, zb));
  const L lo = lane::max(-la, centre - reach), hi = lane::min(la, centre + reach);
  const auto two = parallel && (hi - lo > k<L>(Tolerances<T>::duplicate) * (la + lb));
  const L lo_c = lane::clamp(lo, -la, la), hi_c = lane::clamp(hi, -la, la);  // finite in every lane
  out[0] = select(two, at(lo_c, on_b(lo_c)), closest);
  out[1] = only_where(two, at(hi_c, on_b(hi_c)));
}

// --- box pairs ------------------------------------------------------------

// Sphere (centre a) and box B: with q = R_B^T (a - p_B) and the box's
// signed distance and outward normal m at q (box_point_local, so also
// inside: the face of least penetration), normal -R_B m (from the sphere
// into the box), separation distance - ra.
template <class L>
void collide_sphere_box(const Transform<L>& A, const L& ra, const Transform<L>& B, const L& hx, const L& hy,
                        const L& hz, ContactCandidate<L>* out) {
  using namespace collision_detail;
  const BoxPoint<L> bp = box_point_local(Vec3<L>{hx, hy, hz}, spatial::rotate_back(B.R, spatial::sub(A.p, B.p)));
  const Vec3<L> n = negated(spatial::rotate(B.R, bp.normal));
  const L sep = bp.distance - ra;
  out[0] = {sep, n, ball_point(A.p, ra, n, sep)};
}

// Capsule A (segment S(s) = pa + s za, |s| <= la) and box B. In B's frame
// the segment is q(s) = c + s a and g(s) = signed distance of q(s) from the
// box (box_point_local), a convex function of s. Three candidates, each the
// capsule's ball at a segment point S(s) against the box as a sphere (so
// each separation is exact for its point: g(s) - ra):
//   0: s* = argmin g over the segment, exactly: outside the box g is least
//      at an end or at the segment's closest point to one of the 12 edges
//      (if the closest box point is on a face, g is linear there and is
//      least where that face region ends: at an end or an edge); inside,
//      g = max_i(|q_i| - h_i) is piecewise linear with its minimum at an
//      end or a kink: q_i = 0 (3) or |q_i| - h_i = |q_j| - h_j (12). g is
//      compared at all 29 parameters (as sign(g) g^2); the first least wins.
//   1, 2: the ends [lo, hi] of the part of the segment over the box face
//      whose normal is nearest candidate 0's (axis k: |q_i(s)| <= h_i for
//      i != k), so that a capsule lying on a face rests on two points
//      (hanging over the face's edges: the points above the edges).
// Duplicates are dropped (+inf): an end within duplicate la of s*, and
// candidate 0 itself where it lies strictly inside (lo, hi) with g > 0
// (there the face distance is linear in s, so s* ties with the ends).
// Where the segment itself passes through the box the normal is that of
// its deepest point, which need not be the shortest way out.
template <class L>
void collide_capsule_box(const Transform<L>& A, const L& ra, const L& la, const Transform<L>& B, const L& hx,
                         const L& hy, const L& hz, ContactCandidate<L>* out) {
  using namespace collision_detail;
  using T = lane::scalar_t<L>;
  const Vec3<L> h = {hx, hy, hz};
  const L hs[3] = {hx, hy, hz};
  const Vec3<L> za = column(A.R, 2);
  const Vec3<L> c = spatial::rotate_back(B.R, spatial::sub(A.p, B.p));
  const Vec3<L> a = spatial::rotate_back(B.R, za);
  const L cs[3] = {c.x, c.y, c.z}, as[3] = {a.x, a.y, a.z};
  const L zero = k<L>(0), one = k<L>(1);

  L best_s = -la;
  L best_g = box_distance_order(h, axpy(best_s, a, c));
  auto consider = [&](const L& s_any) {
    const L s = lane::clamp(s_any, -la, la);
    const L g = box_distance_order(h, axpy(s, a, c));
    const auto less = g < best_g;
    best_g = lane::select(less, g, best_g);
    best_s = lane::select(less, s, best_s);
  };
  // num / den, or 0 where den is (nearly) 0: any parameter is harmless to try.
  auto ratio = [&](const L& num, const L& den) {
    const auto ok = lane::abs(den) > tiny<L>();
    return lane::select(ok, num / lane::select(ok, den, one), zero);
  };
  consider(la);
  for (int e = 0; e < 3; ++e) {  // the 12 edges, 4 along each axis e
    const int e1 = (e + 1) % 3, e2 = (e + 2) % 3;
    L dir[3] = {zero, zero, zero};
    dir[e] = one;
    for (int corner = 0; corner < 4; ++corner) {
      L mid[3];
      mid[e] = zero;
      mid[e1] = corner & 1 ? hs[e1] : -hs[e1];
      mid[e2] = corner & 2 ? hs[e2] : -hs[e2];
      L s, t;
      closest_segment_segment(c, a, la, Vec3<L>{mid[0], mid[1], mid[2]}, Vec3<L>{dir[0], dir[1], dir[2]}, hs[e], s, t);
      consider(s);
    }
  }
  for (int i = 0; i < 3; ++i) consider(ratio(-cs[i], as[i]));  // q_i = 0
  for (int i = 0; i < 3; ++i)  // sigma_i q_i - h_i = sigma_j q_j - h_j
    for (int j = i + 1; j < 3; ++j)
      for (int signs = 0; signs < 4; ++signs) {
        const L ci = signs & 1 ? cs[i] : -cs[i], ai = signs & 1 ? as[i] : -as[i];
        const L cj = signs & 2 ? cs[j] : -cs[j], aj = signs & 2 ? as[j] : -as[j];
        consider(ratio((hs[i] - hs[j]) - ci + cj, ai - aj));
      }

  // The capsule's ball at S(s) against the box.
  auto contact_at = [&](const L& s) -> ContactCandidate<L> {
    const BoxPoint<L> bp = box_point_local(h, axpy(s, a, c));
    const Vec3<L> n = negated(spatial::rotate(B.R, bp.normal));
    const L sep = bp.distance - ra;
    return {sep, n, ball_point(axpy(s, za, A.p), ra, n, sep)};
  };

  // The face nearest candidate 0's normal, and the segment's part over it;
  // where candidate 0's nearest box point is on an edge (the segment's
  // point outside the box's slabs along two axes), the segment's part
  // along that edge: a capsule lying along an edge (in a groove between
  // two boxes) touches it along a line, and took one point at an end,
  // which moved to the other end every step as it rocked.
  const Vec3<L> best = axpy(best_s, a, c);
  const Vec3<L> m = box_point_local(h, best).normal;
  const L m0 = lane::abs(m.x), m1 = lane::abs(m.y), m2 = lane::abs(m.z);
  const auto face_y = m1 > m0, face_z = m2 > lane::max(m0, m1);
  const lane::mask_t<L> face[3] = {!face_y && !face_z, face_y && !face_z, face_z};
  const lane::mask_t<L> outside[3] = {lane::abs(best.x) > hs[0], lane::abs(best.y) > hs[1], lane::abs(best.z) > hs[2]};
  const auto on_edge = (outside[0] && outside[1] && !outside[2]) || (outside[0] && !outside[1] && outside[2]) ||
                       (!outside[0] && outside[1] && outside[2]);
  L lo = -la, hi = la;
  for (int i = 0; i < 3; ++i) {  // s with |c_i + s a_i| <= h_i, on the face's two axes or the edge's one
    const auto moving = lane::abs(as[i]) > tiny<L>();
    const L inv = one / lane::select(moving, as[i], one);
    const L s1 = (-hs[i] - cs[i]) * inv, s2 = (hs[i] - cs[i]) * inv;
    const auto within = lane::abs(cs[i]) <= hs[i];
    const L lo_i = lane::select(moving, lane::min(s1, s2), lane::select(within, -infinity<L>(), infinity<L>()));
    const L hi_i = lane::select(moving, lane::max(s1, s2), lane::select(within, infinity<L>(), -infinity<L>()));
    const auto constrained = (on_edge && !outside[i]) || (!on_edge && !face[i]);
    lo = lane::select(constrained, lane::max(lo, lo_i), lo);
    hi = lane::select(constrained, lane::min(hi, hi_i), hi);
  }
  const auto over_face = lo <= hi;
  const L lo_c = lane::clamp(lo, -la, la), hi_c = lane::clamp(hi, -la, la);
  const L dup = k<L>(Tolerances<T>::duplicate) * la;
  // Over a face the distance is linear in s, least at an end of the part
  // (candidate 0 then repeats one of the two); along an edge it is too
  // where the segment is parallel to the edge (sin(angle) below
  // `parallel`: the ends then stand for the line, and a third point
  // between them came and went with the capsule's slightest turn), and
  // otherwise least between the ends, where candidate 0 stays.
  L edge_sin2 = zero;  // sin^2 of the angle between the segment and the edge
  for (int i = 0; i < 3; ++i) edge_sin2 = edge_sin2 + lane::select(outside[i], as[i] * as[i], zero);
  const auto linear = !on_edge || edge_sin2 < k<L>(Tolerances<T>::parallel * Tolerances<T>::parallel);
  const auto inside_interval = over_face && linear && (best_s > lo_c + dup) && (best_s < hi_c - dup);
  out[0] = only_where(!(inside_interval && (best_g > zero)), contact_at(best_s));
  out[1] = only_where(over_face && (lane::abs(lo_c - best_s) > dup), contact_at(lo_c));
  out[2] = only_where(over_face && (lane::abs(hi_c - best_s) > dup) && (hi_c - lo_c > dup), contact_at(hi_c));
}

// Boxes A and B (centres pa, pb, unit axes ua_i, ub_j: the columns of R,
// half extents ea_i, eb_j), t = pb - pa.
//
// Axis: the separating-axis test over the 15 axes u (ua_i, ub_j, and
// ua_i x ub_j normalised, skipped where |ua_i x ub_j| < edge_axis) with the
// separation |t.u| - sum_i ea_i |ua_i.u| - sum_j eb_j |ub_j.u|. Its largest
// value over the axes is the depth of penetration (when < 0: exact for
// convex polyhedra) or a lower bound of the distance (when > 0). Ties go
// to A's faces, then B's (which must win by relative size), and an edge
// axis must beat the best face by 5 % of its magnitude plus relative size:
// resting faces stay faces. The normal is the axis turned along t.
//
// Face axis: the face whose axis won is the reference face (on the box
// "ref", normal n_ref towards the other box, "inc"), and inc's face most
// opposed to n_ref is the incident face. Their contact region is the
// incident face clipped to the prism over the reference face; its vertices
// are (a) incident vertices inside the reference face, (b) reference
// vertices inside the incident face (projected along n_ref), (c) crossings
// of incident edges with the reference face's sides. All of them are
// candidates (4 + 4 + 16 = 24), valid where they are such vertices, with a
// tolerance of relative * size so that vertices shared by the outlines
// count once: (a) inside or up to it outside; (b) inside by more than it;
// (c) the edge's ends more than it either side of the side's line, and
// the crossing on the side or up to it beyond the side's ends. (So a
// reference vertex on an incident edge is a crossing, an incident vertex
// on a reference side an incident vertex, coinciding vertices an incident
// vertex.) Each lies on the incident face; its separation is its height
// above the reference plane along n_ref, its point halfway down to that
// plane.
// A small box resting on a big one: its 4 bottom corners (a, or b when the
// small box is the reference); equal boxes turned 45 degrees: the 8
// corners of the octagon (c).
//
// Edge axis ua_i x ub_j: candidate 0 instead, the others +inf: the closest
// points of A's edge along ua_i farthest along n and B's edge along ub_j
// farthest along -n, with the test's separation, at their midpoint.
//
// Limits: for boxes apart the separations are heights along the chosen
// axis: the least is the separating-axis test's, a lower bound of the
// distance (exact where faces face each other), carried by the lowest
// incident vertex even where it lies outside the reference face; the other
// face candidates exist only where the faces overlap seen along n_ref.
// Overlapping, the least separation is minus the depth of penetration, or
// deeper by up to 5 % of its own depth (1/0.95 - 1 = 5.3 % of the true
// one) where a face axis was kept over an edge axis.
template <class L>
void collide_box_box(const Transform<L>& A, const L& ax, const L& ay, const L& az, const Transform<L>& B,
                     const L& bx, const L& by, const L& bz, ContactCandidate<L>* out) {
  using namespace collision_detail;
  using T = lane::scalar_t<L>;
  const Vec3<L> ua[3] = {column(A.R, 0), column(A.R, 1), column(A.R, 2)};
  const Vec3<L> ub[3] = {column(B.R, 0), column(B.R, 1), column(B.R, 2)};
  const L ea[3] = {ax, ay, az}, eb[3] = {bx, by, bz};
  const Vec3<L> t = spatial::sub(B.p, A.p);
  const L zero = k<L>(0), one = k<L>(1);
  const L tol = k<L>(Tolerances<T>::relative) * (((ax + ay) + az) + ((bx + by) + bz));

  auto separation_along = [&](const Vec3<L>& u) {
    L reach = zero;
    for (int i = 0; i < 3; ++i) reach = lane::fmadd(ea[i], lane::abs(spatial::dot(ua[i], u)), reach);
    for (int j = 0; j < 3; ++j) reach = lane::fmadd(eb[j], lane::abs(spatial::dot(ub[j], u)), reach);
    return lane::abs(spatial::dot(t, u)) - reach;
  };

  // The separating-axis test; axis numbers: A's faces 0-2, B's 3-5, edges 6 + 3 i + j.
  L best = separation_along(ua[0]), axis = zero;
  Vec3<L> dir = ua[0];
  for (int f = 1; f < 6; ++f) {
    const Vec3<L>& u = f < 3 ? ua[f] : ub[f - 3];
    const L s = separation_along(u);
    const auto better = f < 3 ? s > best : s > best + tol;
    best = lane::select(better, s, best);
    axis = lane::select(better, k<L>(f), axis);
    dir = select(better, u, dir);
  }
  L edge_best = -infinity<L>(), edge_axis = zero;
  Vec3<L> edge_dir = dir;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      L length;
      const Vec3<L> u = normalize_or(spatial::cross(ua[i], ub[j]), ua[i], length);
      const L s = lane::select(length > k<L>(Tolerances<T>::edge_axis), separation_along(u), -infinity<L>());
      const auto better = s > edge_best;
      edge_best = lane::select(better, s, edge_best);
      edge_axis = lane::select(better, k<L>(6 + 3 * i + j), edge_axis);
      edge_dir = select(better, u, edge_dir);
    }
  const auto is_edge = edge_best > best + lane::fmadd(k<L>(0.05), lane::abs(best), tol);
  best = lane::select(is_edge, edge_best, best);
  axis = lane::select(is_edge, edge_axis, axis);
  dir = select(is_edge, edge_dir, dir);
  const Vec3<L> n = spatial::scale(unit_sign(spatial::dot(t, dir)), dir);  // from A to B
  const auto is_face = !is_edge;

  // Face axis: reference and incident boxes.
  const auto b_ref = (axis > k<L>(2.5)) && (axis < k<L>(5.5));
  Vec3<L> ur[3], ui[3];
  L er[3], ei[3];
  for (int c = 0; c < 3; ++c) {
    ur[c] = select(b_ref, ub[c], ua[c]);
    ui[c] = select(b_ref, ua[c], ub[c]);
    er[c] = lane::select(b_ref, eb[c], ea[c]);
    ei[c] = lane::select(b_ref, ea[c], eb[c]);
  }
  const Vec3<L> p_ref = select(b_ref, B.p, A.p), p_inc = select(b_ref, A.p, B.p);
  const Vec3<L> n_ref = select(b_ref, negated(n), n);
  // Reference face: axis kr, tangents (kr + 1) % 3 and (kr + 2) % 3.
  const L kr = lane::select(b_ref, axis - k<L>(3), axis);
  const auto r0 = kr == zero, r1 = kr == one;
  const Vec3<L> t1 = select(r0, ur[1], select(r1, ur[2], ur[0])), t2 = select(r0, ur[2], select(r1, ur[0], ur[1]));
  const L e1 = lane::select(r0, er[1], lane::select(r1, er[2], er[0]));
  const L e2 = lane::select(r0, er[2], lane::select(r1, er[0], er[1]));
  const L e_n = lane::select(r0, er[0], lane::select(r1, er[1], er[2]));
  const Vec3<L> c_ref = axpy(e_n, n_ref, p_ref);
  // Incident face: inc's axis most parallel to n_ref, outward normal m against n_ref.
  const L d0 = lane::abs(spatial::dot(ui[0], n_ref)), d1 = lane::abs(spatial::dot(ui[1], n_ref)),
          d2 = lane::abs(spatial::dot(ui[2], n_ref));
  const auto i1 = d1 > d0, i2 = d2 > lane::max(d0, d1);
  const auto q0 = !i1 && !i2, q1 = i1 && !i2;
  const Vec3<L> uk = select(q0, ui[0], select(q1, ui[1], ui[2]));
  const Vec3<L> m = spatial::scale(-unit_sign(spatial::dot(uk, n_ref)), uk);
  const Vec3<L> w1 = select(q0, ui[1], select(q1, ui[2], ui[0])), w2 = select(q0, ui[2], select(q1, ui[0], ui[1]));
  const L f1 = lane::select(q0, ei[1], lane::select(q1, ei[2], ei[0]));
  const L f2 = lane::select(q0, ei[2], lane::select(q1, ei[0], ei[1]));
  const L f_n = lane::select(q0, ei[0], lane::select(q1, ei[1], ei[2]));
  const Vec3<L> c_inc = axpy(f_n, m, p_inc);
  const L clip = k<L>(Tolerances<T>::relative) * (((e1 + e2) + f1) + f2);
  const L half = k<L>(0.5);
  const int s1[4] = {1, -1, -1, 1}, s2[4] = {1, 1, -1, -1};  // corners in order around the face

  // (a) Incident vertices: coordinates x1, x2 in the reference face, height hgt above it.
  Vec3<L> V[4];
  L x1[4], x2[4], hgt[4];
  for (int v = 0; v < 4; ++v) {
    V[v] = axpy(s2[v] > 0 ? f2 : -f2, w2, axpy(s1[v] > 0 ? f1 : -f1, w1, c_inc));
    const Vec3<L> rel = spatial::sub(V[v], c_ref);
    x1[v] = spatial::dot(rel, t1);
    x2[v] = spatial::dot(rel, t2);
    hgt[v] = spatial::dot(rel, n_ref);
  }
  // Apart, the lowest vertex is kept even outside the face: its height is
  // the test's separation, a lower bound of the boxes' distance, where the
  // points over the face alone can all lie farther than the distance (a
  // corner hanging past the face's edge), and a fast box passed into it.
  const L lowest = lane::min(lane::min(hgt[0], hgt[1]), lane::min(hgt[2], hgt[3]));
  for (int v = 0; v < 4; ++v) {
    const auto inside = (lane::abs(x1[v]) <= e1 + clip) && (lane::abs(x2[v]) <= e2 + clip);
    const auto kept = is_face && (inside || ((best > zero) && (hgt[v] <= lowest)));
    out[v] = only_where(kept, ContactCandidate<L>{hgt[v], n, axpy(-(half * hgt[v]), n_ref, V[v])});
  }
  // (b) Reference vertices, moved along n_ref onto the incident plane m.(y - c_inc) = 0.
  const L mn = spatial::dot(m, n_ref);  // |mn| >= 1/sqrt(3)
  for (int v = 0; v < 4; ++v) {
    const Vec3<L> R = axpy(s2[v] > 0 ? e2 : -e2, t2, axpy(s1[v] > 0 ? e1 : -e1, t1, c_ref));
    const L lift = spatial::dot(m, spatial::sub(c_inc, R)) / mn;
    const Vec3<L> rel = spatial::sub(axpy(lift, n_ref, R), c_inc);
    const auto inside = is_face && (lane::abs(spatial::dot(rel, w1)) < f1 - clip) &&
                        (lane::abs(spatial::dot(rel, w2)) < f2 - clip);
    out[4 + v] = only_where(inside, ContactCandidate<L>{lift, n, axpy(half * lift, n_ref, R)});
  }
  // (c) Incident edge V[v] -> V[v + 1] crossing a side x_a = bound of the reference face.
  for (int v = 0; v < 4; ++v) {
    const int w = (v + 1) % 4;
    for (int side = 0; side < 4; ++side) {
      const bool first = side < 2;  // sides x1 = +-e1, then x2 = +-e2
      const L bound = side % 2 == 0 ? (first ? e1 : e2) : -(first ? e1 : e2);
      const L P = (first ? x1[v] : x2[v]) - bound, Q = (first ? x1[w] : x2[w]) - bound;
      const auto crosses = ((P < -clip) && (Q > clip)) || ((P > clip) && (Q < -clip));
      const L tau = P / lane::select(crosses, P - Q, one);
      const L o_v = first ? x2[v] : x1[v], o_w = first ? x2[w] : x1[w], e_o = first ? e2 : e1;
      const L other = lane::fmadd(tau, o_w - o_v, o_v);
      const auto inside = is_face && crosses && (lane::abs(other) <= e_o + clip);
      const Vec3<L> X = axpy(tau, spatial::sub(V[w], V[v]), V[v]);
      const L sep = lane::fmadd(tau, hgt[w] - hgt[v], hgt[v]);
      out[8 + 4 * v + side] = only_where(inside, ContactCandidate<L>{sep, n, axpy(-(half * sep), n_ref, X)});
    }
  }

  // Edge axis 6 + 3 i + j: A's edge along ua_i, B's along ub_j.
  lane::mask_t<L> on_a[3], on_b[3];
  for (int i = 0; i < 3; ++i) {
    on_a[i] = (axis > k<L>(5.5 + 3 * i)) && (axis < k<L>(8.5 + 3 * i));
    on_b[i] = (axis == k<L>(6 + i)) || (axis == k<L>(9 + i)) || (axis == k<L>(12 + i));
  }
  const Vec3<L> da = select(on_a[0], ua[0], select(on_a[1], ua[1], ua[2]));
  const Vec3<L> db = select(on_b[0], ub[0], select(on_b[1], ub[1], ub[2]));
  const L la = lane::select(on_a[0], ea[0], lane::select(on_a[1], ea[1], ea[2]));
  const L lb = lane::select(on_b[0], eb[0], lane::select(on_b[1], eb[1], eb[2]));
  Vec3<L> ca = A.p, cb = B.p;  // the edges' midpoints: A's support along n, B's along -n
  for (int c = 0; c < 3; ++c) {
    ca = axpy(lane::select(on_a[c], zero, unit_sign(spatial::dot(ua[c], n)) * ea[c]), ua[c], ca);
    cb = axpy(lane::select(on_b[c], zero, -(unit_sign(spatial::dot(ub[c], n)) * eb[c])), ub[c], cb);
  }
  L s, u;
  closest_segment_segment(ca, da, la, cb, db, lb, s, u);
  const ContactCandidate<L> edge = {best, n, midpoint(axpy(s, da, ca), axpy(u, db, cb))};
  out[0] = select(is_edge, edge, out[0]);
}

}  // namespace lockstep
