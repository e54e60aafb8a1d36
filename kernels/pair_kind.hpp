// The narrowphase routine of a shape pair, A first: the plane, then spheres,
// then capsules (cylinders count as capsules except against the plane), then
// boxes. Shared by the pair list (batch/contact_pairs.hpp) and the contact
// kernels (kernels/contact_rows.hpp).
#pragma once

namespace lockstep {

enum class PairKind : unsigned char {
  PlaneSphere, PlaneCapsule, PlaneBox, PlaneCylinder,
  SphereSphere, SphereCapsule, SphereBox,
  CapsuleCapsule, CapsuleBox,
  BoxBox,
};

}  // namespace lockstep
