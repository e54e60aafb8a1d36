// URDF import: a URDF robot becomes one ArticulationSpec (then a Model).
//
// What is read: links with their inertials (rotated inertia axes included),
// joints (revolute, continuous = unlimited revolute, prismatic, fixed) with
// origin, axis, limits (position, velocity, effort), dynamics (damping,
// friction) and mimic tags, collision geometry (box, sphere, cylinder,
// `<capsule radius length>` and meshes, fitted with boxes), and Gazebo's
// per-link gravity switch (`<gazebo reference="link"><gravity>false</gravity>`
// or `<turnGravityOff>true</turnGravityOff>`: LinkSpec::gravity). Visual
// elements, the rest of the gazebo tags, transmission/sensor tags and
// `<calibration>`/`<safety_controller>` are ignored.
//
// Conventions:
// - The URDF is fixed-base unless UrdfOptions::floating_base; a floating
//   root's Free joint is named after the articulation ("<prefix><robot>_root").
// - Links are listed depth-first from the root, children in the order their
//   joints appear in the file; that is the Model's low-level order.
// - name_prefix is prepended to the robot (articulation), link and joint
//   names, so that one file can be added several times to a scene.
// - Meshes: relative paths are resolved against the URDF's folder,
//   `package://pkg/rest` by searching upward from it for a folder `pkg`.
//   A missing mesh file is a warning naming link and file, and only that
//   collision element is skipped. A mesh file that is there becomes the box
//   bounding its scaled vertices (io/mesh_bounds.hpp, docs/contacts.md), with
//   a warning giving the box; one that cannot be read is skipped with a
//   warning giving the reason.
// - Limits written as placeholders are read as "no limit", with a warning
//   naming the joint: lower == upper == 0 on a revolute/prismatic joint
//   (position), and velocity="0" or effort="0".
//
// Errors are ModelError naming the file (and line and element where known):
// malformed XML, no root or several roots, cycles (also a cycle disjoint from
// a valid tree), a link with two parents, joints naming missing links,
// non-finite, unparsable or out-of-range numbers, unsupported joint types
// (planar, floating), and everything ModelBuilder rejects.
#pragma once

#include "layout/model_builder.hpp"

#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace lockstep {

struct UrdfOptions {
  bool floating_base = false;
  std::string name_prefix;
  Eigen::Isometry3d root_pose = Eigen::Isometry3d::Identity();
};

// Reads `path`; warnings (meshes missing, unreadable or fitted with boxes,
// placeholder limits) are appended to `warnings` when given.
ArticulationSpec urdf_articulation_from_file(const std::string& path, const UrdfOptions& options = {},
                                             std::vector<std::string>* warnings = nullptr);

// `source_name` is used in messages; its folder is the base for relative mesh paths.
ArticulationSpec urdf_articulation_from_string(const std::string& xml, const std::string& source_name,
                                               const UrdfOptions& options = {},
                                               std::vector<std::string>* warnings = nullptr);

// Imports `path` into `builder`; returns the articulation index. The
// importer's warnings go to the builder's warning list.
int add_urdf(ModelBuilder& builder, const std::string& path, const UrdfOptions& options = {});

// One URDF as a whole model. `warnings` receives the importer's and builder's warnings.
Model load_urdf(const std::string& path, const UrdfOptions& options = {}, const BuildOptions& build = {},
                std::vector<std::string>* warnings = nullptr);

}  // namespace lockstep
