// The candidate shape pairs of a scene: every pair of shapes that may touch
// after filtering (docs/contacts.md, "Which shapes touch"), each with its
// narrowphase kind, its bodies, the shapes' poses and sizes, and its
// combined friction and restitution. Built once per Simulator; internal to
// batch/.
#pragma once

#include "batch/contact_settings.hpp"
#include "kernels/pair_kind.hpp"
#include "layout/model.hpp"

#include <string>
#include <vector>

namespace lockstep {

const char* pair_kind_name(PairKind kind);
int pair_candidates(PairKind kind);  // contact points the narrowphase of a kind proposes

inline constexpr int kGroundShape = -1;  // shape index of the ground plane
inline int static_box_shape(int box) { return -2 - box; }  // shape index of ContactSettings::boxes[box]

// One side of a pair.
struct PairSide {
  int shape = kGroundShape;  // Model::shapes index, kGroundShape, or static_box_shape(i)
  int body = -1;             // moving body, -1 for the world
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // shape frame in the body frame (world if static)
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // Shape::size convention
  double bound_radius = 0;   // a sphere about the shape's origin holding it
};

struct ContactPair {
  PairKind kind;
  PairSide a, b;
  double friction = 0, restitution = 0;  // combined; for the ground, the shape's own (the ground's is per copy)
  int first_candidate = 0;  // numbering of the pair's points across the scene (warm start identity)
};

struct ContactPairs {
  std::vector<ContactPair> pairs;
  int candidates = 0;  // total narrowphase points
  std::vector<int> candidate_pair;  // (candidates) the pair each candidate number belongs to
  std::vector<std::string> notes;  // shapes left out and why (meshes), named pairs that cannot touch
};

// Throws std::invalid_argument for a named pair that names no link.
ContactPairs build_contact_pairs(const Model& model, const ContactSettings& settings);

// "LF_FOOT (sphere 0)", "ground", "static box 2": for messages and reports.
std::string describe_shape(const Model& model, int shape);

}  // namespace lockstep
