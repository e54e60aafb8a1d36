// Contacts over one block: the narrowphase of every candidate pair, the
// points compacted per lane into a fixed number of contact slots, and each
// slot's solver rows (docs/contacts.md):
//   normal   n . (v_B - v_A) at the point, lambda >= 0; the separation e
//            is its error: speculative -e/h while apart, a share of the
//            penetration per step when rigid (a positional row: TGS
//            advances e through its substeps), the spring-damper law when
//            compliant; restitution lifts the target to the bounce speed;
//   friction t1 and t2, a cone pair |lambda_t| <= mu lambda_n;
//   torsion  n . (w_B - w_A), |lambda| <= torsional * lambda_n (optional).
// A slot holds, per lane, the lane's c-th contact; lanes with fewer contacts
// leave it empty (zero Jacobian, impulse box [0, 0]), so no lane's result
// depends on another's.
#pragma once

#include "kernels/collision.hpp"
#include "kernels/crba.hpp"
#include "kernels/jacobian.hpp"
#include "kernels/joint_rows.hpp"
#include "kernels/pair_kind.hpp"

#include <algorithm>
#include <limits>
#include <vector>

namespace lockstep {

// One candidate pair in the kernels' precision.
template <class T>
struct ContactPairSpec {
  PairKind kind;
  bool ground = false;     // A is the copy's ground plane
  int body_a = -1, body_b = -1;  // -1: fixed in the world
  T pose_a[12], pose_b[12];  // shape frame in the body frame (world if fixed), flatten_transform's layout
  T size_a[3], size_b[3];    // Shape::size convention
  T radius_a = 0, radius_b = 0;  // bounding spheres about the shape origins
  T reach_a = 0, reach_b = 0;    // |shape origin| + radius, on the body: a point's distance from the body origin
  T friction = 0, restitution = 0;  // combined (for the ground: B's own friction)
  int first_candidate = 0, candidates = 0;
  std::vector<int> dofs;  // the DOFs that move body A or body B, ascending
};

template <class T>
struct ContactParams {
  int capacity = 16;        // slots per copy
  int rows_per_contact = 3; // 3, or 4 with torsional friction
  T margin = 0, speculative_speed = 0;  // contacts exist below margin + speculative_speed h
  T stiffness = 0, damping = 0;  // N/m, N s/m; stiffness 0: rigid
  T bounce_threshold = 0;
  T max_depenetration_speed = 0;  // the ceiling of a normal row's target
  T torsional = 0;
  T error_reduction = 0;
};

// The contacts of one block.
template <class L>
struct ContactScratch {
  using T = lane::scalar_t<L>;
  int capacity, k, nv;
  int slots = 0;  // slots in use in this block: at least the most contacts of any lane, at most capacity
  L count;        // per lane: contact points found this step (above capacity: overflow)
  std::vector<ContactCandidate<L>> candidates;  // of one pair
  std::vector<L> linear_speed, angular_speed;   // (nbody) |v| of the body origin and |w|, free motion
  std::vector<L> candidate_J;                   // (k x nv) rows of one point
  // per slot; body_a and body_b: the point's pair's bodies (-1: the world)
  std::vector<L> id, separation, mu, restitution, body_a, body_b;
  std::vector<Vec3<L>> point, normal;
  std::vector<unsigned char> moves;  // (capacity x nv) 1: the DOF moves a body of some lane's point in the slot
  std::vector<int> support;          // (capacity x nv) those DOFs, ascending (closed under dof_parent)
  std::vector<int> support_size;     // (capacity)
  std::vector<int> common;           // (nv) DOFs two slots share
  // (capacity x k x nv) rows: normal, t1, t2[, torsion]. With Mt =
  // L^T Dg L (ltdl_factor), contact_delassus turns J into Y = L^-T J^T in
  // place (nothing reads J after the rows' free velocities) and sets
  // Z = Dg^-1 Y, both on the slot's support only (Z's other entries are
  // stale); X = Mt^-1 J^T = L^-1 Z, dense, only where the joint rows'
  // coupling needs it.
  std::vector<L> J, Z, X;
  std::vector<L> inv_dg;   // (nv) 1 / Dg
  std::vector<L> dv;       // (nv) Mt^-1 J^T x of some impulses x
  std::vector<L> warm;  // (capacity x k) last step's impulses of the same points

  ContactScratch(int capacity_, int k_, int nv_, int nbody, int max_candidates)
      : capacity(capacity_), k(k_), nv(nv_), count(T(0)), candidates(max_candidates), candidate_J(k_ * nv_),
        id(capacity_), separation(capacity_), mu(capacity_), restitution(capacity_), body_a(capacity_),
        body_b(capacity_), point(capacity_),
        normal(capacity_), moves(capacity_ * nv_), support(capacity_ * nv_), support_size(capacity_), common(nv_),
        J(capacity_ * k_ * nv_), Z(J.size()), X(J.size()), inv_dg(nv_), dv(nv_), warm(capacity_ * k_) {
    linear_speed.resize(nbody);
    angular_speed.resize(nbody);
  }
};

// The per-copy arrays of a block that contacts read and write, [field][lane].
template <class T>
struct ContactArrays {
  const T* ground;           // (4) plane normal xyz and offset d: the plane n . x = d
  const T* ground_friction;  // (1)
  T* id;          // (capacity) candidate number of each slot's point, -1 when empty
  T* impulse;     // (capacity x k) the solver's impulses: normal, t1, t2[, torsion]
  T* point;       // (capacity x 3) world, at the start of the step
  T* normal;      // (capacity x 3) world, from A to B
  T* separation;  // (capacity)
  T* count;       // (1) contacts kept (at most capacity)
  T* dropped;     // (1) contacts found beyond capacity this step (its largest pipeline run's)
  T* overflow_steps;  // (1) steps with dropped contacts, since the last reset
};

// Two unit tangents completing the normal n to a right-handed frame
// (n, t1, t2): t1 from the world axis x, or y where n is within 55 degrees
// of x, so that the frame is the same for the same normal in every lane and
// every step (friction's warm start needs that).
template <class L>
inline void tangent_frame(const Vec3<L>& n, Vec3<L>& t1, Vec3<L>& t2) {
  using T = lane::scalar_t<L>;
  const auto use_y = lane::abs(n.x) > L(T(0.57735));
  const L ax = lane::select(use_y, L(T(0)), L(T(1))), ay = lane::select(use_y, L(T(1)), L(T(0)));
  const L an = ax * n.x + ay * n.y;
  const Vec3<L> t = {ax - an * n.x, ay - an * n.y, -(an * n.z)};
  t1 = spatial::scale(L(T(1)) / lane::sqrt(spatial::dot(t, t)), t);
  t2 = spatial::cross(n, t1);
}

namespace contact_detail {

// A shape's world pose: its body's world transform times its pose on the body.
template <class L>
Transform<L> shape_pose(const Workspace<L>& ws, int body, const lane::scalar_t<L>* pose) {
  const Transform<L> local = broadcast_transform<L>(pose);
  return body < 0 ? local : spatial::compose(ws.world[body], local);
}

// The narrowphase of one pair into out[0, pair.candidates).
template <class L>
void collide(const ContactPairSpec<lane::scalar_t<L>>& pair, const Vec3<L>& plane_n, const L& plane_d,
             const Transform<L>& A, const Transform<L>& B, ContactCandidate<L>* out) {
  const L a[3] = {L(pair.size_a[0]), L(pair.size_a[1]), L(pair.size_a[2])};
  const L b[3] = {L(pair.size_b[0]), L(pair.size_b[1]), L(pair.size_b[2])};
  switch (pair.kind) {
    case PairKind::PlaneSphere: collide_plane_sphere<L>(plane_n, plane_d, B, b[0], out); break;
    case PairKind::PlaneCapsule: collide_plane_capsule<L>(plane_n, plane_d, B, b[0], b[1], out); break;
    case PairKind::PlaneBox: collide_plane_box<L>(plane_n, plane_d, B, b[0], b[1], b[2], out); break;
    case PairKind::PlaneCylinder: collide_plane_cylinder<L>(plane_n, plane_d, B, b[0], b[1], out); break;
    case PairKind::SphereSphere: collide_sphere_sphere<L>(A, a[0], B, b[0], out); break;
    case PairKind::SphereCapsule: collide_sphere_capsule<L>(A, a[0], B, b[0], b[1], out); break;
    case PairKind::SphereBox: collide_sphere_box<L>(A, a[0], B, b[0], b[1], b[2], out); break;
    case PairKind::CapsuleCapsule: collide_capsule_capsule<L>(A, a[0], a[1], B, b[0], b[1], out); break;
    case PairKind::CapsuleBox: collide_capsule_box<L>(A, a[0], a[1], B, b[0], b[1], b[2], out); break;
    case PairKind::BoxBox: collide_box_box<L>(A, a[0], a[1], a[2], B, b[0], b[1], b[2], out); break;
  }
}

// Rows (k x nv) of the relative motion of B against A at the world point x:
// n, t1, t2 along the linear velocity, then n along the angular velocity.
template <class L>
void contact_jacobian(const KernelModel<lane::scalar_t<L>>& km, const Workspace<L>& ws, int body_a, int body_b,
                      const Vec3<L>& x, const Vec3<L> (&dirs)[3], int k, L* out) {
  using T = lane::scalar_t<L>;
  const int nv = km.nv;
  for (int i = 0; i < k * nv; ++i) out[i] = L(T(0));
  auto add = [&](int body, bool minus) {
    for_each_point_column<L>(km, ws, body, x, [&](int col, const Vec3<L>& v, const Vec3<L>& w) {
      for (int r = 0; r < k; ++r) {
        const L e = r < 3 ? spatial::dot(dirs[r], v) : spatial::dot(dirs[0], w);
        out[r * nv + col] = minus ? out[r * nv + col] - e : out[r * nv + col] + e;
      }
    });
  };
  if (body_b >= 0) add(body_b, false);
  if (body_a >= 0) add(body_a, true);
}

template <class L>
L dot_n(const L* a, const L* b, int n) {
  L sum = a[0] * b[0];
  for (int i = 1; i < n; ++i) sum = lane::fmadd(a[i], b[i], sum);
  return sum;
}

}  // namespace contact_detail

// Finds the block's contacts: every pair's points closer than the margin
// plus the distance the two shapes may close within the step h at the free
// velocity u (a bound from their bodies' speeds, so that a fast body meets
// the row before it passes through: speculative contact), each with its
// rows' Jacobian, put into the lane's next free slot. A lane takes a
// pair's points only where the pair's bounding spheres are within that
// distance; a pair no lane takes is skipped, and so is a point no lane
// has. Needs ws.local and ws.world at the step's q; overwrites ws.velocity.
template <class L>
void detect_contacts(const KernelModel<lane::scalar_t<L>>& km, const std::vector<ContactPairSpec<lane::scalar_t<L>>>& pairs,
                     const ContactParams<lane::scalar_t<L>>& p, const lane::scalar_t<L>* u, lane::scalar_t<L> h,
                     Workspace<L>& ws, const ContactArrays<lane::scalar_t<L>>& arrays, ContactScratch<L>& s) {
  using T = lane::scalar_t<L>;
  using namespace contact_detail;
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv, k = s.k;
  const L zero(T(0)), one(T(1)), margin(p.margin + p.speculative_speed * h);
  const Vec3<L> plane_n = {lane::load<L>(arrays.ground), lane::load<L>(arrays.ground + W),
                           lane::load<L>(arrays.ground + 2 * W)};
  const L plane_d = lane::load<L>(arrays.ground + 3 * W);
  const L ground_friction = lane::load<L>(arrays.ground_friction);
  body_velocities<L>(km, u, ws);
  for (int b = 0; b < km.nbody; ++b) {
    const Vec3<L> v = ws.velocity[b].lin(), w = ws.velocity[b].ang();
    s.linear_speed[b] = lane::sqrt(spatial::dot(v, v));
    s.angular_speed[b] = lane::sqrt(spatial::dot(w, w));
  }
  auto travel = [&](int body, T reach) {  // how far a point of the shape may move in h
    return body < 0 ? zero : L(h) * lane::fmadd(s.angular_speed[body], L(reach), s.linear_speed[body]);
  };
  s.count = zero;
  s.slots = 0;
  auto origin = [&](int body) { return body < 0 ? Vec3<L>{zero, zero, zero} : ws.world[body].p; };
  for (const ContactPairSpec<T>& pair : pairs) {
    const L reach = margin + travel(pair.body_b, pair.reach_b) + (pair.ground ? zero : travel(pair.body_a, pair.reach_a));
    // first the bodies' origins, each with its shape's reach, before the
    // shapes' poses: most pairs of a robot are far apart. `near`: the lanes
    // where neither bound rules the pair out. Only those take its points: a
    // narrowphase's separation may be a lower bound of the distance (box
    // against box), so a lane must not take a point its own bounds reject
    // because another lane of the block kept the pair.
    lane::mask_t<L> near;
    if (pair.ground) {
      near = !(spatial::dot(plane_n, origin(pair.body_b)) - plane_d - L(pair.reach_b) > reach);
    } else {
      const Vec3<L> d = spatial::sub(origin(pair.body_b), origin(pair.body_a));
      const L apart = L(pair.reach_a + pair.reach_b) + reach;
      near = !(spatial::dot(d, d) > apart * apart);
    }
    if (!lane::any<L>(near)) continue;
    const Transform<L> B = shape_pose<L>(ws, pair.body_b, pair.pose_b);
    Transform<L> pose_a;
    const Transform<L>* A = &B;  // the ground's narrowphase reads the plane, not A
    if (pair.ground) {
      near = near && !(spatial::dot(plane_n, B.p) - plane_d - L(pair.radius_b) > reach);
    } else {
      pose_a = shape_pose<L>(ws, pair.body_a, pair.pose_a);
      A = &pose_a;
      const Vec3<L> d = spatial::sub(B.p, A->p);
      const L apart = L(pair.radius_a + pair.radius_b) + reach;
      near = near && !(spatial::dot(d, d) > apart * apart);
    }
    if (!lane::any<L>(near)) continue;
    collide<L>(pair, plane_n, plane_d, *A, B, s.candidates.data());
    const L mu = pair.ground ? L(T(0.5)) * (L(pair.friction) + ground_friction) : L(pair.friction);
    for (int c = 0; c < pair.candidates; ++c) {
      const ContactCandidate<L>& point = s.candidates[c];
      const auto active = near && point.separation < reach;
      if (lane::all<L>(!active)) continue;
      Vec3<L> dirs[3];
      dirs[0] = point.normal;
      tangent_frame(point.normal, dirs[1], dirs[2]);
      contact_jacobian<L>(km, ws, pair.ground ? -1 : pair.body_a, pair.body_b, point.point, dirs, k,
                          s.candidate_J.data());
      if (s.slots < s.capacity) {  // a slot no lane has used yet this step
        const int fresh = s.slots;
        s.id[fresh] = L(T(-1));
        s.separation[fresh] = s.mu[fresh] = s.restitution[fresh] = zero;
        s.body_a[fresh] = s.body_b[fresh] = L(T(-1));
        s.point[fresh] = s.normal[fresh] = {zero, zero, zero};
        for (int i = 0; i < k * nv; ++i) s.J[fresh * k * nv + i] = zero;
        for (int j = 0; j < nv; ++j) s.moves[fresh * nv + j] = 0;
        ++s.slots;
      }
      const L id(static_cast<T>(pair.first_candidate + c));
      // the point into `slot` in the lanes `here`; `taken`: the slot held
      // another point there, whose J may reach other DOFs (a lane's slot
      // otherwise starts the step empty, its J zero outside the DOFs of
      // the point's pair)
      auto write = [&](int slot, const lane::mask_t<L>& here, bool taken) {
        for (int j : pair.dofs) s.moves[slot * nv + j] = 1;
        s.id[slot] = lane::select(here, id, s.id[slot]);
        s.separation[slot] = lane::select(here, point.separation, s.separation[slot]);
        s.mu[slot] = lane::select(here, mu, s.mu[slot]);
        s.restitution[slot] = lane::select(here, L(pair.restitution), s.restitution[slot]);
        s.body_a[slot] = lane::select(here, L(static_cast<T>(pair.ground ? -1 : pair.body_a)), s.body_a[slot]);
        s.body_b[slot] = lane::select(here, L(static_cast<T>(pair.body_b)), s.body_b[slot]);
        Vec3<L>& x = s.point[slot];
        x = {lane::select(here, point.point.x, x.x), lane::select(here, point.point.y, x.y),
             lane::select(here, point.point.z, x.z)};
        Vec3<L>& n = s.normal[slot];
        n = {lane::select(here, point.normal.x, n.x), lane::select(here, point.normal.y, n.y),
             lane::select(here, point.normal.z, n.z)};
        L* J = &s.J[slot * k * nv];
        if (taken)
          for (int i = 0; i < k * nv; ++i) J[i] = lane::select(here, zero, J[i]);
        const L* candidate_J = s.candidate_J.data();
        for (int i = 0; i < k; ++i)
          for (int j : pair.dofs) J[i * nv + j] = lane::select(here, candidate_J[i * nv + j], J[i * nv + j]);
      };
      for (int slot = 0; slot < s.slots; ++slot) {
        const auto here = active && (s.count == L(static_cast<T>(slot)));
        if (lane::any<L>(here)) write(slot, here, false);
      }
      // A lane whose slots are full keeps its deepest points: the point
      // takes the slot of the lane's shallowest one if it lies deeper (a
      // box flat on the ground with 2 slots for its 4 corners once kept
      // the first two found, tipped and sank).
      const auto full = active && s.count >= L(static_cast<T>(s.capacity));
      if (lane::any<L>(full)) {
        L shallowest = s.separation[0], shallowest_slot = zero;
        for (int slot = 1; slot < s.capacity; ++slot) {
          const auto above = s.separation[slot] > shallowest;
          shallowest = lane::select(above, s.separation[slot], shallowest);
          shallowest_slot = lane::select(above, L(static_cast<T>(slot)), shallowest_slot);
        }
        const auto deeper = full && point.separation < shallowest;
        if (lane::any<L>(deeper))
          for (int slot = 0; slot < s.capacity; ++slot) {
            const auto here = deeper && shallowest_slot == L(static_cast<T>(slot));
            if (lane::any<L>(here)) write(slot, here, true);
          }
      }
      s.count = s.count + lane::select(active, one, zero);
    }
  }
}

// The slots' rows into rows [0, k slots) of `rows` (the solver's block of
// contact rows), from the free velocity u (nv), and each slot's warm start: last step's impulses of
// the point with the same candidate number. h is the (sub)step; u_start
// (nv) the velocity the (sub)step started from, whose approach speed a
// bounce returns.
template <class L>
void build_contact_rows(const ContactParams<lane::scalar_t<L>>& p, const ContactArrays<lane::scalar_t<L>>& arrays,
                        const L* u, const L* u_start, lane::scalar_t<L> h, ContactScratch<L>& s,
                        RowBlock<L>& rows) {
  using T = lane::scalar_t<L>;
  using contact_detail::dot_n;
  constexpr std::size_t W = lane::width_v<L>;
  const T inf = std::numeric_limits<T>::infinity();
  const int nv = s.nv, k = s.k;
  const L zero(T(0)), inv_h(T(1) / h);
  // rigid: a share error_reduction of the penetration per step; compliant:
  // the implicit spring-damper f = -k e - c v gives the target -e k/(k h + c)
  const L rate(p.stiffness > 0 ? p.stiffness / (p.stiffness * h + p.damping) : p.error_reduction / h);
  for (int c = 0; c < s.slots; ++c) {
    const auto active = s.count > L(static_cast<T>(c));
    const L* J = &s.J[c * k * nv];
    const int r = c * k;
    const L vn = dot_n(J, u, nv);
    const L e = lane::select(active, s.separation[c], zero);
    // an impact faster than the bounce threshold, reached within the step,
    // leaves at the restitution share of its approach speed: the speed it
    // came with, not the free velocity, which holds the step's gravity too
    // (with it a ball of restitution 1 left each bounce g h faster, and
    // rose v h higher)
    const L approach = dot_n(J, u_start, nv);
    const auto bounce = active && (s.restitution[c] > zero) && (approach < L(-p.bounce_threshold)) &&
                        (lane::fmadd(L(h), vn, e) < zero);
    const L floor = lane::select(bounce, -s.restitution[c] * approach, L(-inf));
    rows.v_free[r] = vn;
    rows.error[r] = e;
    rows.rate[r] = rate;
    rows.floor[r] = floor;
    // rigid rows push out at most this fast; a compliant row's spring law
    // sets its own force, which a cap on its target would clip
    rows.ceiling[r] = L(p.stiffness > 0 ? inf : p.max_depenetration_speed);
    rows.target[r] = rows.target_hi[r] = lane::max(lane::min(positional_target(e, inv_h, rate), rows.ceiling[r]), floor);
    rows.lo[r] = zero;
    rows.hi[r] = lane::select(active, L(inf), zero);
    // a compliant row's spring-damper law is implicit over the step already
    // (the k h in its rate and compliance): TGS keeps its target through the
    // substeps, as PGS does, instead of advancing its error a second time
    rows.positional[r] = p.stiffness > 0 ? 0 : 1;
    rows.bound_row[r] = -1;
    rows.cone[r] = 0;
    for (int i = 1; i < k; ++i) {
      rows.v_free[r + i] = dot_n(J + i * nv, u, nv);
      rows.error[r + i] = rows.target[r + i] = rows.target_hi[r + i] = zero;
      rows.positional[r + i] = 0;
      rows.bound_row[r + i] = r;
      rows.mu[r + i] = i < 3 ? s.mu[c] : L(p.torsional);
      rows.cone[r + i] = i == 1;
    }
    // warm start: the same point's impulses, if some slot held it last step
    for (int i = 0; i < k; ++i) s.warm[c * k + i] = zero;
    for (int old = 0; old < s.capacity; ++old) {
      const L old_id = lane::load<L>(arrays.id + old * W);
      if (lane::all<L>(old_id < zero)) break;  // slots fill in order: none further
      const auto same = active && (old_id == s.id[c]);
      for (int i = 0; i < k; ++i)
        s.warm[c * k + i] = lane::select(same, lane::load<L>(arrays.impulse + (old * k + i) * W), s.warm[c * k + i]);
    }
  }
}

// Per lane: true where no contact row needs an impulse (the normal rows
// decide; friction and torsion lean on them).
template <class L>
lane::mask_t<L> contact_rows_at_rest(const RowBlock<L>& rows, const ContactScratch<L>& s) {
  lane::mask_t<L> rest(true);
  for (int c = 0; c < s.slots; ++c) {
    const int r = c * s.k;
    rest = rest && row_at_rest(rows.v_free[r], rows.target[r], rows.target_hi[r], rows.lo[r], rows.hi[r],
                               rows.error[r], true);
  }
  return rest;
}

// The K x K block of D between slots c1 <= c2: D_ij = Z_i . Y_j over the
// DOFs they share (common[0, shared)), every entry summed in DOF order
// from zero. The K x K sums run side by side over the shared DOFs, each
// DOF's index loaded once; within one slot only j >= i, mirrored.
template <int K, class L>
LOCKSTEP_INLINE void slot_pair_delassus(const ContactScratch<L>& s, int c1, int c2, const int* common, int shared,
                                        RowBlock<L>& rows) {
  using T = lane::scalar_t<L>;
  const int nv = s.nv, m = rows.m;
  const L* Z = &s.Z[c1 * K * nv];
  const L* Y = &s.J[c2 * K * nv];  // Y by now
  L sum[K][K];
  for (int i = 0; i < K; ++i)
    for (int j = 0; j < K; ++j) sum[i][j] = L(T(0));
  for (int t = 0; t < shared; ++t) {
    const int dof = common[t];
    L z[K], y[K];
    for (int i = 0; i < K; ++i) {
      z[i] = Z[i * nv + dof];
      y[i] = Y[i * nv + dof];
    }
    for (int i = 0; i < K; ++i)
      for (int j = 0; j < K; ++j) sum[i][j] = lane::fmadd(z[i], y[j], sum[i][j]);
  }
  for (int i = 0; i < K; ++i)
    for (int j = c1 == c2 ? i : 0; j < K; ++j) {
      const int a = c1 * K + i, b = c2 * K + j;
      rows.D[a * m + b] = rows.D[b * m + a] = sum[i][j];
    }
}

// D = J Mt^-1 J^T of the contact rows, into `rows` (their own block), with
// Mt factored in H as L^T Dg L (factor_step_mass_matrix): Y = L^-T J^T and
// Z = Dg^-1 Y per row, D_ij = Z_i . Y_j. A row's J is zero outside the DOFs that move its
// slot's bodies, and so is its Y (the L^-T pass only carries entries to
// ancestors), so each product runs over the DOFs two slots share: a foot's
// rows reach 9 of anymal_b's 18 DOFs, two feet share the base's 6. A
// compliant normal row adds its compliance 1 / (h (k h + c)) to its
// diagonal; an empty slot's rows, and rows with no mobility, get a unit
// diagonal (their impulse is 0). The coupling with a joint row r is
// J_r X_i (StepEngine::build_round).
template <class L>
void contact_delassus(const KernelModel<lane::scalar_t<L>>& km, const ContactParams<lane::scalar_t<L>>& p,
                      const lane::scalar_t<L>* H, lane::scalar_t<L> h, ContactScratch<L>& s, RowBlock<L>& rows) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = s.nv, k = s.k, m = rows.m;
  for (int j = 0; j < nv; ++j) s.inv_dg[j] = L(T(1)) / lane::load<L>(H + (j * nv + j) * W);
  for (int c = 0; c < s.slots; ++c) {
    int* support = &s.support[c * nv];
    int n = 0;
    for (int j = 0; j < nv; ++j) {  // compacted without a branch per DOF
      support[n] = j;
      n += s.moves[c * nv + j];
    }
    s.support_size[c] = n;
    // the slot's rows (3, or 4 with torsion) share their support: solved
    // together, J turning into Y
    T* Y = reinterpret_cast<T*>(&s.J[c * k * nv]);
    const int stride = nv * static_cast<int>(W);
    if (k == 3) ltdl_transpose_solve_many<3, L>(km, H, Y, stride, support, n);
    else ltdl_transpose_solve_many<4, L>(km, H, Y, stride, support, n);
    for (int i = c * k; i < (c + 1) * k; ++i)
      for (int t = 0; t < n; ++t) s.Z[i * nv + support[t]] = s.J[i * nv + support[t]] * s.inv_dg[support[t]];
  }
  for (int c1 = 0; c1 < s.slots; ++c1)
    for (int c2 = c1; c2 < s.slots; ++c2) {
      // the DOFs of c2's support that c1's moves too, compacted without a
      // branch per DOF (which of them are shared differs from pair to pair)
      const int* s2 = &s.support[c2 * nv];
      const unsigned char* in_c1 = &s.moves[c1 * nv];
      int* common = s.common.data();
      int shared = 0;
      for (int t = 0; t < s.support_size[c2]; ++t) {
        common[shared] = s2[t];
        shared += in_c1[s2[t]];
      }
      if (k == 3) slot_pair_delassus<3>(s, c1, c2, common, shared, rows);
      else slot_pair_delassus<4>(s, c1, c2, common, shared, rows);
    }
  const L compliance(p.stiffness > 0 ? T(1) / (h * (p.stiffness * h + p.damping)) : T(0));
  const L zero(T(0)), one(T(1));
  for (int c = 0; c < s.slots; ++c) {
    const auto active = s.count > L(static_cast<T>(c));
    // a row the bodies cannot move along (J = 0: a fixed-base link's point
    // moving only in the plane of the normal) takes no impulse
    const int r = c * k;
    rows.hi[r] = lane::select(rows.D[r * m + r] > zero, rows.hi[r], zero);
    for (int i = 0; i < k; ++i) {
      L& d = rows.D[(r + i) * m + r + i];
      d = lane::select(active && d > zero, i == 0 ? d + compliance : d, one);
    }
  }
}

// X_i = Mt^-1 J_i^T = L^-1 Z_i of every contact row, dense over the DOFs:
// row i's impulse changes DOF j's velocity by X_i[j] lambda_i. Needs
// contact_delassus.
template <class L>
void contact_columns(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, ContactScratch<L>& s) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = s.nv, k = s.k;
  const int stride = nv * static_cast<int>(W);
  for (int c = 0; c < s.slots; ++c) {
    const int* support = &s.support[c * nv];
    for (int i = c * k; i < (c + 1) * k; ++i) {
      L* X = &s.X[i * nv];
      for (int j = 0; j < nv; ++j) X[j] = L(T(0));
      for (int t = 0; t < s.support_size[c]; ++t) X[support[t]] = s.Z[i * nv + support[t]];
    }
    // the slot's rows (3, or 4 with torsion) through L^-1 together
    T* X = reinterpret_cast<T*>(&s.X[c * k * nv]);
    if (k == 3) ltdl_lower_solve_many<3, L>(km, H, X, stride);
    else ltdl_lower_solve_many<4, L>(km, H, X, stride);
  }
}

// s.dv = Mt^-1 J^T x = L^-1 (sum_i x_i Z_i): the velocity change of the
// contact impulses x (or the displacement of TGS's lambda_sum). Needs
// contact_delassus.
template <class L>
void contact_velocity_change(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, const L* x,
                             ContactScratch<L>& s) {
  using T = lane::scalar_t<L>;
  const int nv = s.nv, k = s.k;
  L* dv = s.dv.data();
  for (int j = 0; j < nv; ++j) dv[j] = L(T(0));
  if (s.slots == 0) return;  // L^-1 of zeros: zeros
  // per DOF, the slot's rows summed in registers in row order (the same
  // chain of multiply-adds as row after row, one load and store per DOF)
  for (int c = 0; c < s.slots; ++c) {
    const int* support = &s.support[c * nv];
    const L* Z = &s.Z[c * k * nv];
    for (int t = 0; t < s.support_size[c]; ++t) {
      const int j = support[t];
      L sum = dv[j];
      for (int i = 0; i < k; ++i) sum = lane::fmadd(x[c * k + i], Z[i * nv + j], sum);
      dv[j] = sum;
    }
  }
  ltdl_lower_solve<L>(km, H, reinterpret_cast<T*>(dv));
}

// out += Mt^-1 J^T x (contact_velocity_change).
template <class L>
void add_contact_impulses(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* H, const L* x,
                          ContactScratch<L>& s, L* out) {
  contact_velocity_change<L>(km, H, x, s);
  for (int j = 0; j < s.nv; ++j) out[j] = out[j] + s.dv[j];
}

// The slots' impulses x (k per slot; zero where `rest`) as wrenches on
// their bodies, added into sum (6 per body, [field][lane], for the bodies
// listed in `bodies`, those of some contact pair:
// [linear; angular about the world origin], world axes): n x_n + t1 x_1 +
// t2 x_2 at the point (and x_torsion about n) on body B, its opposite on
// body A. Per slot and body a select on the lanes whose point is on it: no
// lane's data steers the loop.
template <class L>
void add_contact_wrenches(const ContactScratch<L>& s, const L* x, const lane::mask_t<L>& rest,
                          const std::vector<int>& bodies, lane::scalar_t<L>* sum) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const int k = s.k;
  const L zero(T(0));
  for (int c = 0; c < s.slots; ++c) {
    const auto active = !rest && s.count > L(static_cast<T>(c));
    auto impulse = [&](int i) { return lane::select(active, x[c * k + i], zero); };
    const Vec3<L>& n = s.normal[c];
    Vec3<L> t1, t2;
    tangent_frame(n, t1, t2);
    const L xn = impulse(0), x1 = impulse(1), x2 = impulse(2);
    const Vec3<L> f = {lane::fmadd(t2.x, x2, lane::fmadd(t1.x, x1, n.x * xn)),
                       lane::fmadd(t2.y, x2, lane::fmadd(t1.y, x1, n.y * xn)),
                       lane::fmadd(t2.z, x2, lane::fmadd(t1.z, x1, n.z * xn))};
    Vec3<L> torque = spatial::cross(s.point[c], f);
    if (k > 3) {
      const L xt = impulse(3);
      torque = {lane::fmadd(n.x, xt, torque.x), lane::fmadd(n.y, xt, torque.y), lane::fmadd(n.z, xt, torque.z)};
    }
    const L w[6] = {f.x, f.y, f.z, torque.x, torque.y, torque.z};
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const L body(static_cast<T>(bodies[i]));
      const auto on_b = s.body_b[c] == body, on_a = s.body_a[c] == body;
      if (lane::all<L>(!(on_b || on_a))) continue;
      T* out = sum + 6 * bodies[i] * W;
      for (int j = 0; j < 6; ++j) {
        const L added = lane::select(on_b, w[j], zero) - lane::select(on_a, w[j], zero);
        lane::store(lane::load<L>(out + j * W) + added, out + j * W);
      }
    }
  }
}

// The slots, their impulses x (k per slot; zero where `rest`) and
// the counts into the copies' arrays. A slot whose id is -1 is empty, its
// other entries unspecified (nothing reads them): a slot no lane used this
// step is written empty only where some lane's id is not -1 yet, so that a
// copy's unused slots do not stream through memory every step. A step of
// several pipeline runs (StepOptions::substeps) reports the most contacts
// any of its runs dropped, and counts as one overflow step: first_run
// starts the step's count.
template <class L>
void store_contacts(const ContactScratch<L>& s, const L* x, const lane::mask_t<L>& rest,
                    const ContactArrays<lane::scalar_t<L>>& arrays, bool first_run) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const int k = s.k;
  const L zero(T(0)), none(T(-1)), capacity(static_cast<T>(s.capacity));
  for (int c = 0; c < s.capacity; ++c) {
    const bool used = c < s.slots;
    if (!used && lane::all<L>(lane::load<L>(arrays.id + c * W) < zero)) continue;
    const auto active = used ? s.count > L(static_cast<T>(c)) : lane::mask_t<L>(false);
    lane::store(used ? lane::select(active, s.id[c], none) : none, arrays.id + c * W);
    for (int i = 0; i < k; ++i)
      lane::store(used ? lane::select(rest, zero, x[c * k + i]) : zero, arrays.impulse + (c * k + i) * W);
    const Vec3<L> point = used ? s.point[c] : Vec3<L>{zero, zero, zero};
    const Vec3<L> normal = used ? s.normal[c] : Vec3<L>{zero, zero, zero};
    const L e[7] = {point.x, point.y, point.z, normal.x, normal.y, normal.z, used ? s.separation[c] : zero};
    for (int j = 0; j < 3; ++j) {
      lane::store(e[j], arrays.point + (c * 3 + j) * W);
      lane::store(e[3 + j], arrays.normal + (c * 3 + j) * W);
    }
    lane::store(e[6], arrays.separation + c * W);
  }
  const L dropped = lane::max(s.count - capacity, zero);
  const L dropped_before = first_run ? zero : lane::load<L>(arrays.dropped);  // by this step's earlier runs
  lane::store(lane::min(s.count, capacity), arrays.count);
  lane::store(lane::max(dropped, dropped_before), arrays.dropped);
  const L steps = lane::load<L>(arrays.overflow_steps);
  lane::store(lane::select(dropped > zero && dropped_before == zero, steps + L(T(1)), steps), arrays.overflow_steps);
}

}  // namespace lockstep
