#pragma once

#include <Eigen/Core>
#include <Eigen/LU>

namespace lockstep {

// A proper rotation matrix: finite, R^T R within 1e-6 of I in every entry
// and det R > 0. Poses of joints, frames, shapes, static boxes and scene
// files are checked with it and then used as written (not
// re-orthonormalised).
inline bool is_rotation(const Eigen::Matrix3d& r) {
  return r.allFinite() && (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-6 &&
         r.determinant() > 0.0;
}

}  // namespace lockstep
