// Drives so stiff that one (sub)step closes most of their error. Alone
// an implicit drive stays stable at any gain, but held against a joint limit
// or a contact by such a drive, a mechanism's rows have a slow mode that
// Gauss-Seidel removes only over many iterations (PhysX's "Articulation
// Drive Stability"; docs/contacts.md, the stiff finger). The remedy is the
// one PhysX gives: lower gains, or a shorter step (StepOptions::substeps).
#pragma once

#include "batch/step_options.hpp"
#include "layout/model.hpp"

#include <string>
#include <vector>

namespace lockstep {

struct StiffDrive {
  int dof = -1;
  // kp h^2 / M_kk (force drives) or kp h^2 (acceleration drives): the
  // implicit drive's inertia against the joint's own. Above 1, one step
  // closes more than half of the position error of the joint alone.
  double ratio = 0.0;
};

// The driven DOFs whose ratio is at least 1 at configuration q for the
// (sub)step h, the stiffest first. M_kk is the mass matrix's diagonal at q,
// armature included.
std::vector<StiffDrive> stiff_drives(const Model& model, const std::vector<DofSettings>& dofs,
                                     const Eigen::VectorXd& q, double h);

// One line, without indent or newline, for Simulator::describe_plan and the
// command-line tool's warnings; empty when no drive is stiff.
std::string describe_stiff_drives(const Model& model, const std::vector<StiffDrive>& stiff, int substeps);

}  // namespace lockstep
