// The narrowphase kernels (kernels/collision.hpp): analytic cases with known
// separation, normal and point; the SIMD lanes against the scalar reference
// bit for bit; and, on random poses, the separation against independent
// brute-force distances and the normal as a direction that separates.
//
// Tolerances of the analytic cases: 1e-12 in double and 5e-6 in float, on
// separations, normals and points of size about 1 (a handful of roundings
// of O(1) quantities: about 1e-15 and 1e-6).
#include "kernels/collision.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <vector>

namespace lockstep {
namespace {

using V3 = Eigen::Vector3d;
using M3 = Eigen::Matrix3d;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.14159265358979323846;

template <class T>
double tol() { return std::is_same_v<T, double> ? 1e-12 : 5e-6; }

template <class T>
Vec3<T> v3(const V3& v) { return {T(v.x()), T(v.y()), T(v.z())}; }
template <class T>
V3 eig(const Vec3<T>& v) { return V3(double(v.x), double(v.y), double(v.z)); }
template <class T>
Transform<T> pose(const M3& R, const V3& p) {
  Transform<T> X;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) X.R(r, c) = T(R(r, c));
  X.p = v3<T>(p);
  return X;
}
M3 rot(const V3& axis, double angle) { return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix(); }

// A fixed "generic" rotation and shift applied to whole scenes: results
// rotate with them.
const M3 kG = rot(V3(1, -2, 0.5), 0.7);
const V3 kShift(0.3, -0.2, 0.1);

template <class T>
void expect_candidate(const ContactCandidate<T>& c, double sep, const V3& n, const V3& p, const std::string& what) {
  const double t = tol<T>();
  EXPECT_NEAR(double(c.separation), sep, t) << what;
  EXPECT_LT((eig(c.normal) - n).norm(), t) << what << " normal " << eig(c.normal).transpose();
  EXPECT_LT((eig(c.point) - p).norm(), t) << what << " point " << eig(c.point).transpose();
}
template <class T>
void expect_absent(const ContactCandidate<T>& c, const std::string& what) {
  EXPECT_EQ(double(c.separation), kInf) << what;
  EXPECT_EQ(eig(c.normal), V3(0, 0, 1)) << what;
  EXPECT_EQ(eig(c.point), V3(0, 0, 0)) << what;
}
template <class T>
std::vector<int> existing(const ContactCandidate<T>* c, int n) {
  std::vector<int> out;
  for (int i = 0; i < n; ++i)
    if (std::isfinite(double(c[i].separation))) out.push_back(i);
  return out;
}

// --- analytic cases ---------------------------------------------------------

template <class T>
void plane_sphere_cases() {
  const V3 n = V3(1, 2, 2) / 3, tangent = V3(2, 1, -2) / 3;
  const double d = 0.7, r = 0.3;
  for (double height : {0.5, 0.0, -0.1}) {  // of the sphere's lowest point above the tilted plane
    const V3 c = n * (d + r + height) + 1.3 * tangent;
    ContactCandidate<T> out[kPlaneSphereCandidates];
    collide_plane_sphere<T>(v3<T>(n), T(d), pose<T>(M3::Identity(), c), T(r), out);
    expect_candidate(out[0], height, n, c - n * (r + height / 2), "plane-sphere");
  }
}
TEST(Collision, PlaneSphere) { plane_sphere_cases<double>(); plane_sphere_cases<float>(); }

template <class T>
void plane_capsule_cases() {
  const V3 n = kG * V3(0, 0, 1);
  const double d = n.dot(kShift) + 0.2, r = 0.1, l = 0.4;
  // Lying on the plane (axis along x), 0.01 deep: both end balls touch.
  {
    const V3 c(1, 2, 0.2 + r - 0.01);
    ContactCandidate<T> out[kPlaneCapsuleCandidates];
    collide_plane_capsule<T>(v3<T>(n), T(d), pose<T>(kG * rot(V3::UnitY(), kPi / 2), kG * c + kShift), T(r), T(l),
                             out);
    // R's z axis is world x after the turn about y: end 0 at -l x.
    expect_candidate(out[0], -0.01, n, kG * V3(1 - l, 2, 0.2 - 0.005) + kShift, "lying end 0");
    expect_candidate(out[1], -0.01, n, kG * V3(1 + l, 2, 0.2 - 0.005) + kShift, "lying end 1");
  }
  // Tilted by 0.3 rad from the horizontal: the ends at heights z -+ l sin 0.3.
  {
    const V3 c(0, 0, 0.5);
    ContactCandidate<T> out[kPlaneCapsuleCandidates];
    const M3 R = rot(V3::UnitY(), kPi / 2 - 0.3);  // z axis (cos 0.3, 0, sin 0.3)
    collide_plane_capsule<T>(v3<T>(n), T(d), pose<T>(kG * R, kG * c + kShift), T(r), T(l), out);
    const V3 z = R.col(2);
    const double h0 = 0.5 - l * std::sin(0.3) - 0.2 - r, h1 = 0.5 + l * std::sin(0.3) - 0.2 - r;
    expect_candidate(out[0], h0, n, kG * (c - l * z - V3(0, 0, r + h0 / 2)) + kShift, "tilted end 0");
    expect_candidate(out[1], h1, n, kG * (c + l * z - V3(0, 0, r + h1 / 2)) + kShift, "tilted end 1");
  }
}
TEST(Collision, PlaneCapsule) { plane_capsule_cases<double>(); plane_capsule_cases<float>(); }

template <class T>
void plane_box_cases() {
  // A box turned 0.4 about z, 0.01 into the plane z = 0; then the whole scene
  // turned by kG and shifted: 4 corners at -0.01, 4 at 2 hz - 0.01.
  const V3 n = kG * V3(0, 0, 1);
  const double d = n.dot(kShift);
  const V3 h(0.3, 0.2, 0.1);
  const M3 R = rot(V3::UnitZ(), 0.4);
  const V3 c(0.5, -0.4, h.z() - 0.01);
  ContactCandidate<T> out[kPlaneBoxCandidates];
  collide_plane_box<T>(v3<T>(n), T(d), pose<T>(kG * R, kG * c + kShift), T(h.x()), T(h.y()), T(h.z()), out);
  for (int i = 0; i < 8; ++i) {
    const V3 local((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
    const V3 corner = c + R * local;
    const double sep = corner.z();
    EXPECT_NEAR(sep, (i & 4) ? 2 * h.z() - 0.01 : -0.01, 1e-15);
    expect_candidate(out[i], sep, n, kG * (corner - V3(0, 0, sep / 2)) + kShift, "corner " + std::to_string(i));
  }
  // Balanced on an edge (turned 45 degrees about x): two corners touch.
  const M3 R2 = rot(V3::UnitX(), kPi / 4);
  const double reach = (h.y() + h.z()) / std::sqrt(2.0);
  collide_plane_box<T>(v3<T>(n), T(d), pose<T>(kG * R2, kG * V3(0, 0, reach) + kShift), T(h.x()), T(h.y()),
                       T(h.z()), out);
  int touching = 0;
  for (int i = 0; i < 8; ++i) touching += std::abs(double(out[i].separation)) < tol<T>();
  EXPECT_EQ(touching, 2);
}
TEST(Collision, PlaneBox) { plane_box_cases<double>(); plane_box_cases<float>(); }

template <class T>
void plane_cylinder_cases() {
  const V3 n = kG * V3(0, 0, 1);
  const double d = n.dot(kShift), r = 0.2, l = 0.3;
  ContactCandidate<T> out[kPlaneCylinderCandidates];
  // Upright, 0.01 deep: candidates 0, 2, 3 on the bottom rim 120 degrees
  // apart (an equilateral triangle of side r sqrt 3), 1 on the top rim.
  {
    collide_plane_cylinder<T>(v3<T>(n), T(d), pose<T>(kG, kG * V3(0.1, 0.2, l - 0.01) + kShift), T(r), T(l), out);
    for (int i : {0, 2, 3}) {
      EXPECT_NEAR(double(out[i].separation), -0.01, tol<T>());
      const V3 local = kG.transpose() * (eig(out[i].point) - kShift);
      EXPECT_NEAR(local.z(), -0.005, tol<T>());
      EXPECT_NEAR(std::hypot(local.x() - 0.1, local.y() - 0.2), r, tol<T>());
    }
    EXPECT_NEAR(double(out[1].separation), 2 * l - 0.01, tol<T>());
    EXPECT_NEAR((eig(out[0].point) - eig(out[2].point)).norm(), r * std::sqrt(3.0), tol<T>());
    EXPECT_NEAR((eig(out[2].point) - eig(out[3].point)).norm(), r * std::sqrt(3.0), tol<T>());
    for (int i = 0; i < 4; ++i) EXPECT_LT((eig(out[i].normal) - n).norm(), tol<T>());
  }
  // Lying on its side (axis along y), 0.02 deep: 0 and 1 at the two ends of
  // the line of contact, 2 and 3 at height 1.5 r.
  {
    collide_plane_cylinder<T>(v3<T>(n), T(d), pose<T>(kG * rot(V3::UnitX(), kPi / 2), kG * V3(0, 0, r - 0.02) + kShift),
                              T(r), T(l), out);
    // The axis (R's z) is world -y; which cap counts as the deeper one
    // depends on the rounding of n.a = 0.
    const bool minus_first = (kG.transpose() * (eig(out[0].point) - kShift)).y() < 0;
    expect_candidate(out[minus_first ? 0 : 1], -0.02, n, kG * V3(0, -l, -0.01) + kShift, "lying, cap -y");
    expect_candidate(out[minus_first ? 1 : 0], -0.02, n, kG * V3(0, l, -0.01) + kShift, "lying, cap +y");
    EXPECT_NEAR(double(out[2].separation), 1.5 * r - 0.02, tol<T>());
    EXPECT_NEAR(double(out[3].separation), 1.5 * r - 0.02, tol<T>());
  }
  // Tilted by 0.5 rad from upright: the lowest rim point at
  // z - l cos 0.5 - r sin 0.5, the upper cap's lowest at z + l cos - r sin.
  {
    const double z = 0.4, th = 0.5;
    const M3 R = rot(V3::UnitX(), th);
    collide_plane_cylinder<T>(v3<T>(n), T(d), pose<T>(kG * R, kG * V3(0, 0, z) + kShift), T(r), T(l), out);
    const double s0 = z - l * std::cos(th) - r * std::sin(th), s1 = z + l * std::cos(th) - r * std::sin(th);
    // The rim's lowest direction: the part of -z perpendicular to the axis a.
    const V3 a = R.col(2), v = (a * a.z() - V3::UnitZ()).normalized();
    expect_candidate(out[0], s0, n, kG * (-l * a + r * v - V3(0, 0, s0 / 2) + V3(0, 0, z)) + kShift, "tilted 0");
    expect_candidate(out[1], s1, n, kG * (l * a + r * v - V3(0, 0, s1 / 2) + V3(0, 0, z)) + kShift, "tilted 1");
  }
  // Axis exactly along n (n x a = 0): the rim direction falls back to R's
  // x axis; the bottom rim points touch, no NaN.
  collide_plane_cylinder<T>(v3<T>(V3(0, 0, 1)), T(0), pose<T>(M3::Identity(), V3(0, 0, l)), T(r), T(l), out);
  expect_candidate(out[0], 0.0, V3(0, 0, 1), V3(r, 0, 0), "upright exactly, 0");
  expect_candidate(out[1], 2 * l, V3(0, 0, 1), V3(r, 0, l), "upright exactly, 1");
  expect_candidate(out[2], 0.0, V3(0, 0, 1), V3(-r / 2, r * std::sqrt(0.75), 0), "upright exactly, 2");
  expect_candidate(out[3], 0.0, V3(0, 0, 1), V3(-r / 2, -r * std::sqrt(0.75), 0), "upright exactly, 3");
}
TEST(Collision, PlaneCylinder) { plane_cylinder_cases<double>(); plane_cylinder_cases<float>(); }

template <class T>
void sphere_sphere_cases() {
  ContactCandidate<T> out[kSphereSphereCandidates];
  const V3 a = kShift, b = kShift + kG * V3(3, 4, 0), n = kG * V3(0.6, 0.8, 0);
  collide_sphere_sphere<T>(pose<T>(kG, a), T(1), pose<T>(M3::Identity(), b), T(2), out);
  expect_candidate(out[0], 2.0, n, a + 2.0 * n, "apart");
  collide_sphere_sphere<T>(pose<T>(kG, a), T(3), pose<T>(M3::Identity(), b), T(2.5), out);
  expect_candidate(out[0], -0.5, n, a + 2.75 * n, "overlapping");
  collide_sphere_sphere<T>(pose<T>(kG, a), T(0.5), pose<T>(M3::Identity(), a), T(0.25), out);
  expect_candidate(out[0], -0.75, V3(0, 0, 1), a + 0.125 * V3(0, 0, 1), "coincident: the fixed axis z");
}
TEST(Collision, SphereSphere) { sphere_sphere_cases<double>(); sphere_sphere_cases<float>(); }

template <class T>
void sphere_capsule_cases() {
  ContactCandidate<T> out[kSphereCapsuleCandidates];
  const Transform<T> cap = pose<T>(kG, kShift);  // capsule along kG z, l = 1, r = 0.2
  auto world = [](const V3& x) { return V3(kG * x + kShift); };
  // Beside the segment: distance 0.7 from the point 0.4 along the axis.
  collide_sphere_capsule<T>(pose<T>(M3::Identity(), world(V3(0.7, 0, 0.4))), T(0.3), cap, T(0.2), T(1), out);
  expect_candidate(out[0], 0.2, kG * V3(-1, 0, 0), world(V3(0.7 - 0.3 - 0.1, 0, 0.4)), "beside");
  // Beyond the end: distance 0.5 from the end point (0, 0, 1).
  collide_sphere_capsule<T>(pose<T>(M3::Identity(), world(V3(0, 0.3, 1.4))), T(0.3), cap, T(0.2), T(1), out);
  expect_candidate(out[0], 0.0, kG * V3(0, -0.6, -0.8), world(V3(0, 0.3, 1.4) + 0.3 * V3(0, -0.6, -0.8)), "end");
  // On the axis: the capsule's x axis, depth ra + rb.
  collide_sphere_capsule<T>(pose<T>(M3::Identity(), world(V3(0, 0, 0.5))), T(0.3), cap, T(0.2), T(1), out);
  expect_candidate(out[0], -0.5, kG.col(0), world(V3(0.05, 0, 0.5)), "on the axis");
}
TEST(Collision, SphereCapsule) { sphere_capsule_cases<double>(); sphere_capsule_cases<float>(); }

template <class T>
void capsule_capsule_cases() {
  ContactCandidate<T> out[kCapsuleCapsuleCandidates];
  auto world = [](const V3& x) { return V3(kG * x + kShift); };
  const M3 along_x = kG * rot(V3::UnitY(), kPi / 2), along_y = kG * rot(V3::UnitX(), -kPi / 2);
  const V3 up = kG * V3(0, 0, 1);
  // Crossed at right angles, 0.25 apart: one point, the second absent.
  collide_capsule_capsule<T>(pose<T>(along_x, world(V3(0, 0, 0))), T(0.1), T(1), pose<T>(along_y, world(V3(0.2, 0.3, 0.25))),
                             T(0.1), T(1), out);
  expect_candidate(out[0], 0.05, up, world(V3(0.2, 0, 0.125)), "crossed");
  expect_absent(out[1], "crossed, second");
  // Parallel, B (l = 0.5) lying on A (l = 1) 0.01 deep, overlapping over x in
  // [0.3, 1]: the two ends of the overlap.
  collide_capsule_capsule<T>(pose<T>(along_x, world(V3(0, 0, 0))), T(0.1), T(1), pose<T>(along_x, world(V3(0.8, 0, 0.19))),
                             T(0.1), T(0.5), out);
  expect_candidate(out[0], -0.01, up, world(V3(0.3, 0, 0.095)), "parallel lo");
  expect_candidate(out[1], -0.01, up, world(V3(1.0, 0, 0.095)), "parallel hi");
  // Antiparallel: the same two points.
  collide_capsule_capsule<T>(pose<T>(along_x, world(V3(0, 0, 0))), T(0.1), T(1),
                             pose<T>(kG * rot(V3::UnitY(), -kPi / 2), world(V3(0.8, 0, 0.19))), T(0.1), T(0.5), out);
  expect_candidate(out[0], -0.01, up, world(V3(0.3, 0, 0.095)), "antiparallel lo");
  expect_candidate(out[1], -0.01, up, world(V3(1.0, 0, 0.095)), "antiparallel hi");
  // Collinear end to end, gap 0.5 between the segments: one point.
  collide_capsule_capsule<T>(pose<T>(along_x, world(V3(0, 0, 0))), T(0.1), T(1), pose<T>(along_x, world(V3(2.5, 0, 0))),
                             T(0.1), T(1), out);
  expect_candidate(out[0], 0.3, kG * V3(1, 0, 0), world(V3(1.25, 0, 0)), "end to end");
  expect_absent(out[1], "end to end, second");
  // Coaxial and overlapping (segments coincide in part): finite unit normals.
  collide_capsule_capsule<T>(pose<T>(along_x, world(V3(0, 0, 0))), T(0.1), T(1), pose<T>(along_x, world(V3(0.5, 0, 0))),
                             T(0.1), T(1), out);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(double(out[i].separation), -0.2, tol<T>());
    EXPECT_NEAR(eig(out[i].normal).norm(), 1.0, tol<T>());
  }
  // Crossing axes that intersect: the common perpendicular as the normal.
  collide_capsule_capsule<T>(pose<T>(along_x, world(V3(0, 0, 0))), T(0.1), T(1), pose<T>(along_y, world(V3(0.2, 0.3, 0))),
                             T(0.1), T(1), out);
  EXPECT_NEAR(double(out[0].separation), -0.2, tol<T>());
  EXPECT_NEAR(std::abs(eig(out[0].normal).dot(up)), 1.0, tol<T>());
}
TEST(Collision, CapsuleCapsule) { capsule_capsule_cases<double>(); capsule_capsule_cases<float>(); }

template <class T>
void sphere_box_cases() {
  ContactCandidate<T> out[kSphereBoxCandidates];
  const V3 h(0.5, 0.4, 0.3);
  const Transform<T> box = pose<T>(kG, kShift);
  auto world = [](const V3& x) { return V3(kG * x + kShift); };
  auto run = [&](const V3& local, double r) {
    collide_sphere_box<T>(pose<T>(M3::Identity(), world(local)), T(r), box, T(h.x()), T(h.y()), T(h.z()), out);
  };
  run(V3(0.1, 0.2, 0.45), 0.1);  // above the top face
  expect_candidate(out[0], 0.05, kG * V3(0, 0, -1), world(V3(0.1, 0.2, 0.325)), "face");
  run(V3(0.6, 0.0, 0.4), 0.1);  // beside the edge x = 0.5, z = 0.3
  const V3 ne = V3(-1, 0, -1).normalized();
  expect_candidate(out[0], std::sqrt(0.02) - 0.1, kG * ne,
                   world(V3(0.6, 0, 0.4) + ne * (0.1 + (std::sqrt(0.02) - 0.1) / 2)), "edge");
  run(V3(0.8, 0.6, 0.5), 0.5);  // off the corner (0.5, 0.4, 0.3)
  const V3 nc = -V3(0.3, 0.2, 0.2).normalized();
  const double dc = std::sqrt(0.17);
  expect_candidate(out[0], dc - 0.5, kG * nc, world(V3(0.8, 0.6, 0.5) + nc * (0.5 + (dc - 0.5) / 2)), "corner");
  run(V3(0.1, 0.3, -0.05), 0.1);  // centre inside, nearest the face +y (0.1 in)
  expect_candidate(out[0], -0.2, kG * V3(0, -1, 0), world(V3(0.1, 0.3 - 0.1 + 0.1, -0.05)), "inside");
  run(V3(0, 0, 0), 0.1);  // at the centre: the face of least penetration, z
  expect_candidate(out[0], -0.4, kG * V3(0, 0, -1), world(V3(0, 0, -0.1 + 0.2)), "centre");
}
TEST(Collision, SphereBox) { sphere_box_cases<double>(); sphere_box_cases<float>(); }

// The existing candidates, ordered along the direction u.
template <class T>
std::vector<ContactCandidate<T>> existing_along(const ContactCandidate<T>* c, int n, const V3& u) {
  std::vector<ContactCandidate<T>> on;
  for (int i : existing(c, n)) on.push_back(c[i]);
  std::sort(on.begin(), on.end(), [&](const ContactCandidate<T>& a, const ContactCandidate<T>& b) {
    return eig(a.point).dot(u) < eig(b.point).dot(u);
  });
  return on;
}

template <class T>
void capsule_box_cases() {
  ContactCandidate<T> out[kCapsuleBoxCandidates];
  auto world = [](const V3& x) { return V3(kG * x + kShift); };
  const M3 along_x = kG * rot(V3::UnitY(), kPi / 2);
  const V3 down = kG * V3(0, 0, -1);
  // Lying flat on the top face (box 1 x 0.5 x 0.2), 0.005 deep: exactly two
  // points, at the ends.
  {
    const V3 h(1, 0.5, 0.2);
    collide_capsule_box<T>(pose<T>(along_x, world(V3(0.2, 0.1, 0.295))), T(0.1), T(0.4), pose<T>(kG, kShift), T(h.x()),
                           T(h.y()), T(h.z()), out);
    const auto on = existing_along(out, kCapsuleBoxCandidates, kG * V3::UnitX());
    ASSERT_EQ(on.size(), 2u);
    expect_candidate(on[0], -0.005, down, world(V3(-0.2, 0.1, 0.1975)), "lying, end -x");
    expect_candidate(on[1], -0.005, down, world(V3(0.6, 0.1, 0.1975)), "lying, end +x");
  }
  // Longer than the box (l = 1.5 over hx = 1): the points above the edges x = +-1.
  {
    const V3 h(1, 0.5, 0.2);
    collide_capsule_box<T>(pose<T>(along_x, world(V3(0, 0.1, 0.295))), T(0.1), T(1.5), pose<T>(kG, kShift), T(h.x()),
                           T(h.y()), T(h.z()), out);
    const auto on = existing_along(out, kCapsuleBoxCandidates, kG * V3::UnitX());
    ASSERT_EQ(on.size(), 2u);
    expect_candidate(on[0], -0.005, down, world(V3(-1, 0.1, 0.1975)), "overhanging, edge -x");
    expect_candidate(on[1], -0.005, down, world(V3(1, 0.1, 0.1975)), "overhanging, edge +x");
  }
  // Across the edge x = z = 0.5 of a cube, tilted 0.3 rad down over it: the
  // axis passes 0.12 from the edge along perp = (sin, 0, cos), the closest
  // point is the edge, separation 0.12 - r.
  {
    const double th = 0.3, D = 0.12, r = 0.1;
    const V3 u(std::cos(th), 0, -std::sin(th)), perp(std::sin(th), 0, std::cos(th)), E(0.5, 0, 0.5);
    const M3 R = rot(V3::UnitY(), kPi / 2 + th);  // z axis = u
    ASSERT_LT((R.col(2) - u).norm(), 1e-15);
    collide_capsule_box<T>(pose<T>(kG * R, world(E + D * perp - 0.1 * u)), T(r), T(0.6), pose<T>(kG, kShift), T(0.5),
                           T(0.5), T(0.5), out);
    int least = 0;
    for (int i = 1; i < kCapsuleBoxCandidates; ++i)
      if (out[i].separation < out[least].separation) least = i;
    expect_candidate(out[least], D - r, kG * -perp, world(E + perp * ((D - r) / 2)), "across the edge");
  }
  // Along the edge x = 1, z = 0.5 of a box (1 x 1 x 0.5), just touching it
  // from outside both faces: a line contact, two points at the capsule's
  // ends (it once got one, at whichever end tied first).
  {
    const V3 h(1, 1, 0.5), n = V3(-1, 0, -1).normalized();
    const M3 along_y = kG * rot(V3::UnitX(), -kPi / 2);
    const double r = 0.1, gap = 0.002;
    collide_capsule_box<T>(pose<T>(along_y, world(V3(1, 0, 0.5) - (r + gap) * n)), T(r), T(0.5), pose<T>(kG, kShift),
                           T(h.x()), T(h.y()), T(h.z()), out);
    const auto on = existing_along(out, kCapsuleBoxCandidates, kG * V3::UnitY());
    ASSERT_EQ(on.size(), 2u);
    expect_candidate(on[0], gap, kG * n, world(V3(1, -0.5, 0.5) - n * (gap / 2)), "along the edge, end -y");
    expect_candidate(on[1], gap, kG * n, world(V3(1, 0.5, 0.5) - n * (gap / 2)), "along the edge, end +y");
  }
  // Upright on the top face, 0.01 deep: the bottom end only; the top end is
  // the other candidate over the face, 2 l higher.
  {
    collide_capsule_box<T>(pose<T>(kG, world(V3(0.1, 0, 0.5 + 0.1 + 0.3 - 0.01))), T(0.1), T(0.3), pose<T>(kG, kShift),
                           T(0.5), T(0.5), T(0.5), out);
    const auto on = existing_along(out, kCapsuleBoxCandidates, kG * V3::UnitZ());
    ASSERT_EQ(on.size(), 2u);
    expect_candidate(on[0], -0.01, down, world(V3(0.1, 0, 0.495)), "upright bottom");
    EXPECT_NEAR(double(on[1].separation), 0.6 - 0.01, tol<T>());
  }
}
TEST(Collision, CapsuleBox) { capsule_box_cases<double>(); capsule_box_cases<float>(); }

// The existing candidates of a box pair, sorted by point (x, then y, then z in the scene's frame).
template <class T>
std::vector<ContactCandidate<T>> box_box_existing(const M3& Ra, const V3& pa, const V3& ha, const M3& Rb, const V3& pb,
                                                  const V3& hb) {
  ContactCandidate<T> out[kBoxBoxCandidates];
  collide_box_box<T>(pose<T>(kG * Ra, kG * pa + kShift), T(ha.x()), T(ha.y()), T(ha.z()),
                     pose<T>(kG * Rb, kG * pb + kShift), T(hb.x()), T(hb.y()), T(hb.z()), out);
  std::vector<ContactCandidate<T>> on;
  for (int i : existing(out, kBoxBoxCandidates)) on.push_back(out[i]);
  std::sort(on.begin(), on.end(), [](const ContactCandidate<T>& a, const ContactCandidate<T>& b) {
    // Coordinates rounded to 1e-4, so that float rounding does not reorder equal ones.
    auto key = [](const ContactCandidate<T>& c) {
      const V3 x = kG.transpose() * eig(c.point) * 1e4;
      return std::make_tuple(std::lround(x.x()), std::lround(x.y()), std::lround(x.z()));
    };
    return key(a) < key(b);
  });
  return on;
}

template <class T>
void box_box_cases() {
  const M3 I = M3::Identity();
  auto world = [](const V3& x) { return V3(kG * x + kShift); };
  const V3 up = kG * V3(0, 0, 1);
  // A small box (turned 0.3 about z) resting 0.001 deep on a big one: its
  // four bottom corners, normal the big box's face normal; either order.
  {
    const V3 hs(0.2, 0.1, 0.05), hbig(1, 1, 0.2), ps(0.1, -0.2, 0.2 + 0.05 - 0.001);
    const M3 Rs = rot(V3::UnitZ(), 0.3);
    for (bool big_first : {true, false}) {
      const auto on = big_first ? box_box_existing<T>(I, V3::Zero(), hbig, Rs, ps, hs)
                                : box_box_existing<T>(Rs, ps, hs, I, V3::Zero(), hbig);
      ASSERT_EQ(on.size(), 4u) << "big first " << big_first;
      std::vector<V3> corners;
      for (int i = 0; i < 4; ++i) corners.push_back(ps + Rs * V3((i & 1) ? hs.x() : -hs.x(), (i & 2) ? hs.y() : -hs.y(), -hs.z()));
      std::sort(corners.begin(), corners.end(), [](const V3& a, const V3& b) { return a.x() < b.x(); });
      for (int i = 0; i < 4; ++i)
        expect_candidate(on[i], -0.001, big_first ? up : V3(-up), world(corners[i] + V3(0, 0, 0.0005)),
                         "small on big, corner " + std::to_string(i));
    }
  }
  // Equal cubes stacked, 0.002 deep: aligned, the 4 corners once each;
  // shifted by 0.1 in x, the 4 corners of the overlap.
  {
    const V3 h(0.3, 0.3, 0.3);
    for (double shift : {0.0, 0.1}) {
      const auto on = box_box_existing<T>(I, V3::Zero(), h, I, V3(shift, 0, 0.6 - 0.002), h);
      ASSERT_EQ(on.size(), 4u) << "shift " << shift;
      const V3 expect[4] = {V3(-0.3 + shift, -0.3, 0.299), V3(-0.3 + shift, 0.3, 0.299), V3(0.3, -0.3, 0.299),
                            V3(0.3, 0.3, 0.299)};
      for (int i = 0; i < 4; ++i)
        expect_candidate(on[i], -0.002, up, world(expect[i]), "stacked, shift " + std::to_string(shift));
    }
  }
  // Equal cubes stacked, the upper turned 45 degrees about z: the octagon's
  // 8 corners (edge crossings), each on both squares' outlines.
  {
    const V3 h(0.3, 0.3, 0.3);
    const auto on = box_box_existing<T>(I, V3::Zero(), h, rot(V3::UnitZ(), kPi / 4), V3(0, 0, 0.6 - 0.002), h);
    ASSERT_EQ(on.size(), 8u);
    for (const auto& c : on) {
      EXPECT_NEAR(double(c.separation), -0.002, tol<T>());
      EXPECT_LT((eig(c.normal) - up).norm(), tol<T>());
      const V3 x = kG.transpose() * (eig(c.point) - kShift);
      EXPECT_NEAR(x.z(), 0.299, tol<T>());
      EXPECT_NEAR(std::max(std::abs(x.x()), std::abs(x.y())), 0.3, tol<T>());  // on the lower square's outline
      EXPECT_NEAR(std::max(std::abs(x.x() + x.y()), std::abs(x.x() - x.y())) / std::sqrt(2.0), 0.3, tol<T>());
    }
  }
  // A cube on one corner (its diagonal vertical) 0.003 into a big flat box:
  // one point at the corner.
  {
    const V3 h(0.2, 0.2, 0.2), hbig(1, 1, 0.1);
    const M3 R = Eigen::Quaterniond::FromTwoVectors(V3(1, 1, 1), V3(0, 0, 1)).toRotationMatrix();
    const double z = 0.1 + 0.2 * std::sqrt(3.0) - 0.003;
    ContactCandidate<T> out[kBoxBoxCandidates];
    collide_box_box<T>(pose<T>(kG, kShift), T(hbig.x()), T(hbig.y()), T(hbig.z()), pose<T>(kG * R, world(V3(0.3, 0.1, z))),
                       T(h.x()), T(h.y()), T(h.z()), out);
    int deep = 0, least = 0;
    for (int i = 0; i < kBoxBoxCandidates; ++i) {
      deep += out[i].separation < T(0.05);
      if (out[i].separation < out[least].separation) least = i;
    }
    EXPECT_EQ(deep, 1);
    expect_candidate(out[least], -0.003, up, world(V3(0.3, 0.1, 0.1 - 0.0015)), "vertex on face");
  }
  // Two long boxes crossed like a '+', each turned 45 degrees about its
  // length so that an edge meets an edge, 0.001 deep: one point, normal the
  // edges' cross product x x y = z.
  {
    const V3 ha(1, 0.1, 0.1), hb(0.1, 1, 0.1);
    const double reach = 0.1 * std::sqrt(2.0);
    ContactCandidate<T> out[kBoxBoxCandidates];
    collide_box_box<T>(pose<T>(kG * rot(V3::UnitX(), kPi / 4), kShift), T(ha.x()), T(ha.y()), T(ha.z()),
                       pose<T>(kG * rot(V3::UnitY(), kPi / 4), world(V3(0.05, -0.1, 2 * reach - 0.001))), T(hb.x()),
                       T(hb.y()), T(hb.z()), out);
    const std::vector<int> on = existing(out, kBoxBoxCandidates);
    ASSERT_EQ(on.size(), 1u);
    expect_candidate(out[on[0]], -0.001, up, world(V3(0.05, 0, reach - 0.0005)), "crossed edges");
  }
  // The same boxes crossed flat (faces meeting): the 4 corners of the
  // overlap x in [-0.05, 0.15], y in [-0.1, 0.1] (edge crossings).
  {
    const auto on = box_box_existing<T>(I, V3::Zero(), V3(1, 0.1, 0.1), I, V3(0.05, -0.1, 0.2 - 0.001), V3(0.1, 1, 0.1));
    ASSERT_EQ(on.size(), 4u);
    const V3 expect[4] = {V3(-0.05, -0.1, 0.0995), V3(-0.05, 0.1, 0.0995), V3(0.15, -0.1, 0.0995),
                          V3(0.15, 0.1, 0.0995)};
    for (int i = 0; i < 4; ++i) expect_candidate(on[i], -0.001, up, world(expect[i]), "crossed flat");
  }
}
TEST(Collision, BoxBox) { box_box_cases<double>(); box_box_cases<float>(); }

// --- random configurations ------------------------------------------------

// Every shape size and pose a pair function reads, as one flat record of T
// (so that it packs into lanes field by field).
template <class T>
struct Scene {
  Transform<T> A, B;
  Vec3<T> n;
  T d;
  T ra, la, rb, lb;
  Vec3<T> ha, hb;
};
template <class T>
constexpr int kSceneFields = sizeof(Scene<T>) / sizeof(T);
static_assert(sizeof(Scene<double>) == 38 * sizeof(double), "Scene is a flat record");
static_assert(sizeof(ContactCandidate<double>) == 7 * sizeof(double), "ContactCandidate is a flat record");

enum Kind { kPlaneSphere, kPlaneCapsule, kPlaneBox, kPlaneCylinder, kSphereSphere, kSphereCapsule, kCapsuleCapsule,
            kSphereBox, kCapsuleBox, kBoxBox, kKinds };
const char* const kKindName[kKinds] = {"plane-sphere", "plane-capsule", "plane-box", "plane-cylinder",
                                       "sphere-sphere", "sphere-capsule", "capsule-capsule", "sphere-box",
                                       "capsule-box", "box-box"};
const int kKindCount[kKinds] = {kPlaneSphereCandidates, kPlaneCapsuleCandidates, kPlaneBoxCandidates,
                                kPlaneCylinderCandidates, kSphereSphereCandidates, kSphereCapsuleCandidates,
                                kCapsuleCapsuleCandidates, kSphereBoxCandidates, kCapsuleBoxCandidates,
                                kBoxBoxCandidates};
constexpr int kMaxCandidates = kBoxBoxCandidates;

template <class L>
void collide(Kind kind, const Scene<L>& s, ContactCandidate<L>* out) {
  switch (kind) {
    case kPlaneSphere: collide_plane_sphere<L>(s.n, s.d, s.B, s.rb, out); break;
    case kPlaneCapsule: collide_plane_capsule<L>(s.n, s.d, s.B, s.rb, s.lb, out); break;
    case kPlaneBox: collide_plane_box<L>(s.n, s.d, s.B, s.hb.x, s.hb.y, s.hb.z, out); break;
    case kPlaneCylinder: collide_plane_cylinder<L>(s.n, s.d, s.B, s.rb, s.lb, out); break;
    case kSphereSphere: collide_sphere_sphere<L>(s.A, s.ra, s.B, s.rb, out); break;
    case kSphereCapsule: collide_sphere_capsule<L>(s.A, s.ra, s.B, s.rb, s.lb, out); break;
    case kCapsuleCapsule: collide_capsule_capsule<L>(s.A, s.ra, s.la, s.B, s.rb, s.lb, out); break;
    case kSphereBox: collide_sphere_box<L>(s.A, s.ra, s.B, s.hb.x, s.hb.y, s.hb.z, out); break;
    case kCapsuleBox: collide_capsule_box<L>(s.A, s.ra, s.la, s.B, s.hb.x, s.hb.y, s.hb.z, out); break;
    case kBoxBox: collide_box_box<L>(s.A, s.ha.x, s.ha.y, s.ha.z, s.B, s.hb.x, s.hb.y, s.hb.z, out); break;
    default: break;
  }
}

M3 random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> g;
  return Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
}

// A random scene in double: sizes about 0.05 to 1, B in a random direction
// from A at up to 0.6 times the sum of their reaches (radius, half length
// and half diagonal of either shape: so separated,
// touching and overlapping pairs all occur), and in about half the scenes
// a special arrangement: equal or opposite orientations, coincident
// centres, B on A's axis, capsules side by side, the plane normal along B's
// axis, spheres touching, boxes stacked face on face (touching, or 1e-3
// deep and shifted sideways).
Scene<double> random_scene(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  Scene<double> s;
  const M3 Ra = random_rotation(rng);
  M3 Rb = random_rotation(rng);
  const V3 pa = V3(u(rng), u(rng), u(rng)) * 2 - V3::Ones();
  s.ra = 0.05 + 0.45 * u(rng);
  s.rb = 0.05 + 0.45 * u(rng);
  s.la = u(rng);
  s.lb = u(rng);
  const V3 ha = V3(u(rng), u(rng), u(rng)) * 0.95 + V3::Constant(0.05);
  const V3 hb = V3(u(rng), u(rng), u(rng)) * 0.95 + V3::Constant(0.05);
  const double reach = s.ra + s.la + ha.norm() + s.rb + s.lb + hb.norm();
  V3 dir = random_rotation(rng).col(0);
  V3 pb = pa + dir * reach * 0.6 * u(rng);
  const int degenerate = std::uniform_int_distribution<int>(0, 17)(rng);
  switch (degenerate) {
    case 0: Rb = Ra; break;                                                  // parallel axes, aligned boxes
    case 1: Rb = Ra * rot(V3::UnitX(), kPi); break;                          // antiparallel
    case 2: pb = pa; break;                                                  // coincident centres
    case 3: pb = pa + Ra.col(2) * (2 * u(rng) - 1) * s.la; break;            // B's centre on A's axis
    case 4: Rb = Ra; pb = pa + Ra.col(0) * (s.ra + s.rb) * 0.9 + Ra.col(2) * u(rng); break;  // capsules side by side
    case 7: pb = pa + dir * (s.ra + s.rb); break;                             // spheres touching
    case 8: Rb = Ra; pb = pa + Ra.col(2) * (ha.z() + hb.z()); break;          // boxes stacked, touching
    case 9:
      Rb = Ra * rot(V3::UnitZ(), 0.3 * u(rng));
      pb = pa + Ra.col(2) * (ha.z() + hb.z() - 1e-3) + Ra.col(0) * (u(rng) - 0.5) * ha.x();
      break;
    default: break;
  }
  s.A = pose<double>(Ra, pa);
  s.B = pose<double>(Rb, pb);
  s.ha = v3<double>(ha);
  s.hb = v3<double>(hb);
  V3 n = random_rotation(rng).col(2);
  if (degenerate == 5) n = Rb.col(2);
  if (degenerate == 6) n = -Rb.col(2);
  s.n = v3<double>(n);
  s.d = n.dot(pb) - (s.rb + s.lb + hb.norm()) * (2 * u(rng) - 0.5);
  return s;
}
template <class T>
Scene<T> cast_scene(const Scene<double>& s) {
  Scene<T> out;
  const double* from = reinterpret_cast<const double*>(&s);
  T* to = reinterpret_cast<T*>(&out);
  for (int f = 0; f < kSceneFields<double>; ++f) to[f] = T(from[f]);
  return out;
}

// SIMD lanes against the scalar reference, bit for bit, for every pair
// function over random scenes (one per lane); in every other batch each
// scene is first moved to touch (B by -separation along the normal of its
// least candidate in double), so that touching pairs are compared too.
// Also: every field finite but absent separations (+inf), normals unit.
template <class T>
void check_lanes(int batches) {
  using S = lane::simd<T>;
  constexpr int W = int(S::size);
  static_assert(sizeof(Scene<S>) == kSceneFields<T> * sizeof(S), "Scene<simd> is a flat record");
  std::mt19937 rng(11);
  int compared = 0;
  for (int batch = 0; batch < batches; ++batch) {
    Scene<double> drawn[W];
    for (int i = 0; i < W; ++i) drawn[i] = random_scene(rng);
    for (int kind = 0; kind < kKinds; ++kind) {
      Scene<T> scenes[W];
      for (int i = 0; i < W; ++i) {
        Scene<double> scene = drawn[i];
        if (batch % 2 == 1) {
          ContactCandidate<double> out[kMaxCandidates];
          collide<double>(Kind(kind), scene, out);
          int best = 0;
          for (int c = 1; c < kKindCount[kind]; ++c)
            if (out[c].separation < out[best].separation) best = c;
          if (std::isfinite(out[best].separation))
            scene.B.p = v3<double>(eig(scene.B.p) - eig(out[best].normal) * out[best].separation);
        }
        scenes[i] = cast_scene<T>(scene);
      }
      Scene<S> packed;
      alignas(64) T buffer[W];
      for (int f = 0; f < kSceneFields<T>; ++f) {
        for (int i = 0; i < W; ++i) buffer[i] = reinterpret_cast<const T*>(&scenes[i])[f];
        reinterpret_cast<S*>(&packed)[f] = S::load_aligned(buffer);
      }
      ContactCandidate<S> wide[kMaxCandidates];
      collide<S>(Kind(kind), packed, wide);
      for (int i = 0; i < W; ++i) {
        ContactCandidate<T> one[kMaxCandidates];
        collide<T>(Kind(kind), scenes[i], one);
        for (int c = 0; c < kKindCount[kind]; ++c)
          for (int f = 0; f < 7; ++f) {
            reinterpret_cast<const S*>(&wide[c])[f].store_aligned(buffer);
            const T scalar = reinterpret_cast<const T*>(&one[c])[f];
            ASSERT_EQ(std::memcmp(&buffer[i], &scalar, sizeof(T)), 0)
                << kKindName[kind] << " batch " << batch << " lane " << i << " candidate " << c << " field " << f
                << ": SIMD " << buffer[i] << ", scalar " << scalar;
            ++compared;
          }
        for (int c = 0; c < kKindCount[kind]; ++c) {
          ASSERT_TRUE(eig(one[c].normal).allFinite() && eig(one[c].point).allFinite()) << kKindName[kind];
          ASSERT_FALSE(std::isnan(one[c].separation)) << kKindName[kind];
          ASSERT_NEAR(eig(one[c].normal).norm(), 1.0, (std::is_same_v<T, double> ? 1e-12 : 1e-5)) << kKindName[kind];
        }
      }
    }
  }
  EXPECT_EQ(compared, batches * W * 7 * (1 + 2 + 8 + 4 + 1 + 1 + 2 + 1 + 3 + 24));
}
TEST(Collision, SimdLanesMatchScalarDouble) { check_lanes<double>(40); }
TEST(Collision, SimdLanesMatchScalarFloat) { check_lanes<float>(20); }

// --- independent references (double) ------------------------------------

// The least of a convex function on [lo, hi]: a grid, then golden-section
// search around the best grid point.
double convex_min(const std::function<double(double)>& f, double lo, double hi) {
  if (hi - lo < 1e-15) return f(lo);
  const int grid = 64;
  int best = 0;
  double best_f = kInf;
  for (int i = 0; i <= grid; ++i) {
    const double v = f(lo + (hi - lo) * i / grid);
    if (v < best_f) best_f = v, best = i;
  }
  double a = lo + (hi - lo) * std::max(best - 1, 0) / grid, b = lo + (hi - lo) * std::min(best + 1, grid) / grid;
  const double g = (std::sqrt(5.0) - 1) / 2;
  double x1 = b - g * (b - a), x2 = a + g * (b - a), f1 = f(x1), f2 = f(x2);
  for (int it = 0; it < 100; ++it) {
    if (f1 < f2) b = x2, x2 = x1, f2 = f1, x1 = b - g * (b - a), f1 = f(x1);
    else a = x1, x1 = x2, f1 = f2, x2 = a + g * (b - a), f2 = f(x2);
  }
  return std::min({best_f, f1, f2});
}
double point_segment(const V3& x, const V3& c, const V3& u, double l) {
  return (x - (c + std::clamp(u.dot(x - c), -l, l) * u)).norm();
}
// Signed distance of a world point from a box (negative inside).
double point_box(const V3& x, const M3& R, const V3& p, const V3& h) {
  const V3 q = R.transpose() * (x - p);
  const V3 outside = (q.cwiseAbs() - h).cwiseMax(0.0);
  const double inside = std::min((q.cwiseAbs() - h).maxCoeff(), 0.0);
  return outside.norm() + inside;
}
// The boxes' largest gap over the 15 separating axes: > 0 exactly when
// they are disjoint; when < 0, minus their depth of penetration.
double box_gap(const M3& Ra, const V3& pa, const V3& ha, const M3& Rb, const V3& pb, const V3& hb) {
  std::vector<V3> axes;
  for (int i = 0; i < 3; ++i) axes.push_back(Ra.col(i)), axes.push_back(Rb.col(i));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const V3 w = Ra.col(i).cross(Rb.col(j));
      if (w.norm() > 1e-6) axes.push_back(w.normalized());
    }
  double gap = -kInf;
  for (const V3& u : axes) {
    const double ra = (Ra.transpose() * u).cwiseAbs().dot(ha), rb = (Rb.transpose() * u).cwiseAbs().dot(hb);
    gap = std::max(gap, std::abs(u.dot(pb - pa)) - ra - rb);
  }
  return gap;
}

M3 mat(const Transform<double>& X) {
  M3 R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = X.R(r, c);
  return R;
}

// The signed distance of the shapes of a scene by brute force, for every
// kind but box-box: the plane's distance from the corners or from the rim
// (720 samples a cap, then golden-section search about the least),
// otherwise the
// distance of the cores (point or segment, without radius) minimised over
// the segment by convex_min, less the radii. `core` receives the distance
// of the cores (for the plane: of the shape's reference point).
double brute_distance(Kind kind, const Scene<double>& s, double& core) {
  const M3 Ra = mat(s.A), Rb = mat(s.B);
  const V3 pa = eig(s.A.p), pb = eig(s.B.p), n = eig(s.n), hb = eig(s.hb);
  const V3 za = Ra.col(2), zb = Rb.col(2);
  auto segment_b = [&](const V3& x) { return point_segment(x, pb, zb, s.lb); };
  core = 1;
  switch (kind) {
    case kPlaneSphere: return n.dot(pb) - s.d - s.rb;
    case kPlaneCapsule: return convex_min([&](double t) { return n.dot(pb + t * zb) - s.d; }, -s.lb, s.lb) - s.rb;
    case kPlaneBox: {
      double least = kInf;
      for (int i = 0; i < 8; ++i)
        least = std::min(least, n.dot(pb + Rb * V3((i & 1) ? hb.x() : -hb.x(), (i & 2) ? hb.y() : -hb.y(),
                                                     (i & 4) ? hb.z() : -hb.z())) - s.d);
      return least;
    }
    case kPlaneCylinder: {
      double least = kInf;
      for (int cap = -1; cap <= 1; cap += 2) {
        auto height = [&](double th) {
          return n.dot(pb + cap * s.lb * zb + s.rb * (std::cos(th) * Rb.col(0) + std::sin(th) * Rb.col(1))) - s.d;
        };
        const int samples = 720;
        int best = 0;
        for (int i = 1; i < samples; ++i)
          if (height(2 * kPi * i / samples) < height(2 * kPi * best / samples)) best = i;
        const double step = 2 * kPi / samples;  // the height is a sinusoid: convex within a step of its least
        least = std::min(least, convex_min(height, step * (best - 1), step * (best + 1)));
      }
      return least;
    }
    case kSphereSphere: core = (pb - pa).norm(); return core - s.ra - s.rb;
    case kSphereCapsule: core = segment_b(pa); return core - s.ra - s.rb;
    case kCapsuleCapsule:
      core = convex_min([&](double t) { return segment_b(pa + t * za); }, -s.la, s.la);
      return core - s.ra - s.rb;
    case kSphereBox: core = point_box(pa, Rb, pb, hb); return core - s.ra;
    case kCapsuleBox:
      core = convex_min([&](double t) { return point_box(pa + t * za, Rb, pb, hb); }, -s.la, s.la);
      return core - s.ra;
    default: return std::nan("");
  }
}

// Random scenes, every kind but box-box:
//   the least separation over the candidates equals the brute-force signed
//   distance (1e-9: the golden-section search and the rim sampling), also
//   where the shapes overlap (a sphere centre inside a box: its depth);
//   moving B by n (1e-3 - separation) along the least candidate's normal
//   leaves the shapes 1e-3 apart (1e-9), and moving it by -separation
//   makes the kernel report 0 (1e-9): for every pair but a capsule whose
//   segment enters the box (whose normal is that of its deepest point).
TEST(Collision, RandomScenesAgreeWithBruteForce) {
  std::mt19937 rng(5);
  int checked_distance = 0, checked_move = 0;
  for (int scene = 0; scene < 400; ++scene) {
    const Scene<double> s = random_scene(rng);
    for (int kind = 0; kind < kBoxBox; ++kind) {
      const std::string what = std::string(kKindName[kind]) + " scene " + std::to_string(scene);
      auto least = [&](const Scene<double>& t) {
        ContactCandidate<double> out[kMaxCandidates];
        collide<double>(Kind(kind), t, out);
        int best = 0;
        for (int c = 1; c < kKindCount[kind]; ++c)
          if (out[c].separation < out[best].separation) best = c;
        return out[best];
      };
      const ContactCandidate<double> c = least(s);
      ASSERT_TRUE(std::isfinite(c.separation)) << what;
      double core = 0;
      const double brute = brute_distance(Kind(kind), s, core);
      EXPECT_NEAR(c.separation, brute, 1e-9) << what;
      ++checked_distance;
      if (kind == kCapsuleBox && core <= 1e-9) continue;
      auto moved_by = [&](double distance) {
        Scene<double> t = s;
        t.B.p = v3<double>(eig(s.B.p) + eig(c.normal) * distance);
        return t;
      };
      double moved_core = 0;
      EXPECT_NEAR(brute_distance(Kind(kind), moved_by(1e-3 - c.separation), moved_core), 1e-3, 1e-9)
          << what << ": moved along the normal";
      EXPECT_NEAR(least(moved_by(-c.separation)).separation, 0.0, 1e-9) << what << ": moved to touch";
      ++checked_move;
    }
  }
  EXPECT_GE(checked_distance, 3600);
  EXPECT_GE(checked_move, 3000);
}

// Box pairs on random poses that overlap (by the separating-axis test,
// largest gap g < 0 over the axes: -g is the depth of penetration): the
// least candidate separation is g (1e-9), or deeper by at most 5 % of
// itself (the kernel keeps a face axis unless an edge axis is better by 5 %
// of the face's depth, plus 1e-9 times the sizes); moving B
// by n (1e-3 - separation) along its normal separates the boxes, by 1e-3
// where the separation was g.
TEST(Collision, RandomBoxPairsSeparateAlongTheNormal) {
  std::mt19937 rng(9);
  int overlapping = 0, exact_depth = 0;
  for (int scene = 0; scene < 600; ++scene) {
    const Scene<double> s = random_scene(rng);
    const M3 Ra = mat(s.A), Rb = mat(s.B);
    const double gap = box_gap(Ra, eig(s.A.p), eig(s.ha), Rb, eig(s.B.p), eig(s.hb));
    if (gap >= 0) continue;
    ++overlapping;
    ContactCandidate<double> out[kBoxBoxCandidates];
    collide<double>(kBoxBox, s, out);
    int best = 0;
    for (int c = 1; c < kBoxBoxCandidates; ++c)
      if (out[c].separation < out[best].separation) best = c;
    const std::string what = "scene " + std::to_string(scene);
    const double sep = out[best].separation;
    EXPECT_LE(sep, gap + 1e-9) << what;
    EXPECT_GE(0.95 * sep, gap - 1e-8) << what;
    const bool exact = std::abs(sep - gap) <= 1e-9;
    exact_depth += exact;
    const V3 moved = eig(s.B.p) + eig(out[best].normal) * (1e-3 - sep);
    const double moved_gap = box_gap(Ra, eig(s.A.p), eig(s.ha), Rb, moved, eig(s.hb));
    EXPECT_GT(moved_gap, 0.0) << what;
    if (exact) {
      EXPECT_NEAR(moved_gap, 1e-3, 1e-9) << what;
    }
  }
  EXPECT_GT(overlapping, 100);
  EXPECT_GT(exact_depth, overlapping * 8 / 10);
}

// The distance of two boxes apart: the least over the corners of each to
// the other box and over the pairs of their edges (convex polyhedra meet
// vertex to face or edge to edge).
double box_distance(const M3& Ra, const V3& pa, const V3& ha, const M3& Rb, const V3& pb, const V3& hb) {
  double least = kInf;
  for (int i = 0; i < 8; ++i) {
    const V3 corner((i & 1) ? 1 : -1, (i & 2) ? 1 : -1, (i & 4) ? 1 : -1);
    least = std::min(least, point_box(pa + Ra * corner.cwiseProduct(ha), Rb, pb, hb));
    least = std::min(least, point_box(pb + Rb * corner.cwiseProduct(hb), Ra, pa, ha));
  }
  auto edges = [](const M3& R, const V3& p, const V3& h, auto&& each) {  // each(centre, unit direction, half length)
    for (int k = 0; k < 3; ++k)
      for (int s = 0; s < 4; ++s) {
        const int i = (k + 1) % 3, j = (k + 2) % 3;
        each(p + R.col(i) * ((s & 1) ? h[i] : -h[i]) + R.col(j) * ((s & 2) ? h[j] : -h[j]), V3(R.col(k)), h[k]);
      }
  };
  edges(Ra, pa, ha, [&](const V3& ca, const V3& ua, double la) {
    edges(Rb, pb, hb, [&](const V3& cb, const V3& ub, double lb) {
      least = std::min(least, convex_min([&](double t) { return point_segment(ca + t * ua, cb, ub, lb); }, -la, la));
    });
  });
  return least;
}

// Box pairs apart: the least candidate separation is a lower bound of the
// distance (1e-9), near the separating-axis test's gap. Before, only the
// points over the reference face were candidates, and a corner hanging
// past the face's edge left all of them farther than the distance: for
// the pose below 0.0156 against a distance of 0.0101, at worst 0.112
// against 0.0108, and a box moving at 3 m/s sank 17 mm into another.
template <class T>
void apart_boxes_separation_is_a_lower_bound() {
  const double tolerance = std::is_same_v<T, double> ? 1e-9 : 2e-6;
  const M3 I = M3::Identity();
  const V3 big(0.5, 0.5, 0.5), small(0.1, 0.1, 0.1);
  for (const auto& [quaternion, position] :
       {std::pair{Eigen::Quaterniond(-0.483468, 0.624369, -0.511727, -0.338463), V3(0.566019, 0.056575, 0.657819)},
        std::pair{Eigen::Quaterniond(0.221337, 0.684375, -0.230019, -0.655539), V3(0.598119, -0.099289, 0.654253)}}) {
    const M3 R = quaternion.normalized().toRotationMatrix();
    const double distance = box_distance(I, V3::Zero(), big, R, position, small);
    const auto on = box_box_existing<T>(I, V3::Zero(), big, R, position, small);
    ASSERT_FALSE(on.empty());
    double least = kInf;
    for (const auto& c : on) least = std::min(least, double(c.separation));
    EXPECT_LE(least, distance + tolerance) << "distance " << distance;
    EXPECT_GT(least, 0.0);
  }
}

TEST(Collision, ApartBoxesSeparationIsALowerBoundOfTheDistance) {
  apart_boxes_separation_is_a_lower_bound<double>();
  apart_boxes_separation_is_a_lower_bound<float>();
  std::mt19937 rng(13);
  int apart = 0;
  for (int scene = 0; scene < 600; ++scene) {
    const Scene<double> s = random_scene(rng);
    const M3 Ra = mat(s.A), Rb = mat(s.B);
    const double gap = box_gap(Ra, eig(s.A.p), eig(s.ha), Rb, eig(s.B.p), eig(s.hb));
    if (gap <= 0) continue;
    ++apart;
    ContactCandidate<double> out[kBoxBoxCandidates];
    collide<double>(kBoxBox, s, out);
    double least = kInf;
    for (const auto& c : out) least = std::min(least, c.separation);
    const double distance = box_distance(Ra, eig(s.A.p), eig(s.ha), Rb, eig(s.B.p), eig(s.hb));
    const std::string what = "scene " + std::to_string(scene) + ", distance " + std::to_string(distance);
    EXPECT_LE(least, distance + 1e-9) << what;
    EXPECT_GE(least, 0.95 * gap - 1e-9) << what;  // the test's gap, or a face's within 5 % of an edge's
  }
  EXPECT_GT(apart, 100);
}

}  // namespace
}  // namespace lockstep
