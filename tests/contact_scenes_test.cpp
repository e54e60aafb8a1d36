// Contact scenes from the contact issue: the stiff finger pressing a box
// against a wall (PhysX's "Articulation Drive Stability" case) with both
// solvers, and anymal_b and a1 standing under a PD stance controller on flat
// and tilted ground.
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

namespace lockstep::test {
namespace {

// A fixed-base finger in the horizontal plane: proximal and distal joints
// about -z, links along +y (0.10 m and 0.08 m, 50 g each), a 1 cm sphere at
// the tip. A positive proximal angle swings the tip towards +x.
ArticulationSpec finger_spec() {
  ArticulationSpec spec;
  spec.name = "finger";
  spec.root_pose.translation() = Eigen::Vector3d(0.24, -0.18, 0.02);
  LinkSpec base;
  base.name = "finger_base";
  spec.links.push_back(base);
  auto rod = [](const std::string& name, const std::string& parent, double length, double offset) {
    LinkSpec link = joint_link(name, parent, JointType::Revolute, -Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, offset, 0));
    link.inertial.mass = 0.05;
    link.inertial.origin.translation() = Eigen::Vector3d(0, 0.5 * length, 0);
    const double i = 0.05 * length * length / 12;
    link.inertial.inertia = Eigen::Vector3d(i, 1e-6, i).asDiagonal();
    return link;
  };
  spec.links.push_back(rod("proximal", "finger_base", 0.10, 0.0));
  LinkSpec distal = rod("distal", "proximal", 0.08, 0.10);
  distal.joint.limited = true;  // the joint limit at 0.5 rad the contact pushes it against
  distal.joint.lower = -0.5;
  distal.joint.upper = 0.5;
  distal.shapes.push_back(sphere_at(0.01, Eigen::Vector3d(0, 0.08, 0)));
  spec.links.push_back(distal);
  return spec;
}

struct FingerResult {
  bool held = false;
  double worst_limit = 0, worst_penetration = 0, fastest_box = 0;
  int steps_not_pinned = 0;  // steps without force both from the tip and from the wall on the box
};

// The finger's proximal drive (kp 100 N m/rad: the target is reached
// within one 1/60 s step without the box, kp h^2 / I = 28) targets 1.0 rad;
// the tip starts touching the 50 g box (at 0.056 rad) and pushes it against
// the wall; the distal joint folds to its limit -0.5 rad. After 1 s and for
// the next 10 s: limit violation < 1e-3 rad, penetration < 1 mm, box speed
// < 1e-3 m/s, and at every step the box pinned: pressed both by the tip and
// by the wall. (Started 1 cm short of the box, the tip hits it at 10 m/s in
// the first step and knocks it out from the wall; the box then rests
// elsewhere and the criteria above hold without the box being pressed at
// all, which is how this test once passed with PGS at 64 iterations.)
// `wall_sunk`: how far the wall's bottom lies below the ground (0: in the
// ground plane, with the box's bottom). `substeps`: StepOptions::substeps,
// the whole pipeline's runs per step (not TGS's substeps, its iterations).
FingerResult finger_on_box(SolverType solver, int iterations, Precision precision, double wall_sunk, int substeps) {
  ModelBuilder builder;
  builder.add_articulation(finger_spec());
  builder.add_articulation(free_shape_spec("box", ShapeType::Box, Eigen::Vector3d::Constant(0.02), 0.05));
  const Model model = builder.finalize();
  StepOptions o;
  o.dt = 1.0 / 60.0;
  o.solver = solver;
  o.iterations = iterations;
  o.substeps = substeps;
  o.precision = precision;
  o.contacts.ground = true;
  StaticBox wall;
  wall.pose.translation() = Eigen::Vector3d(0.35, 0, 0.1 - 0.5 * wall_sunk);  // face at x = 0.30, top at 0.2
  wall.half_extents = Eigen::Vector3d(0.05, 0.2, 0.1 + 0.5 * wall_sunk);
  o.contacts.boxes.push_back(wall);
  std::vector<DofSettings> dofs = default_dof_settings(model);
  const int proximal = model.dof_index("proximal_joint"), distal = model.dof_index("distal_joint");
  dofs[proximal].drive_stiffness = 100.0;
  dofs[proximal].drive_damping = 1.0;
  Simulator sim(model, 1, o, dofs);
  Eigen::VectorXd q = model.neutral_configuration();
  const int box = model.joint_index("box_root");
  q.segment<3>(model.body_q_offset[box]) = Eigen::Vector3d(0.28, 0, 0.02);  // on the ground, against the wall
  // the tip (radius 1 cm, 0.18 m from the proximal axis at x = 0.24) touches the box's face x = 0.26
  q[model.body_q_offset[model.dof_body[proximal]]] = std::asin(0.01 / 0.18);
  sim.set_state(0, q, Eigen::VectorXd::Zero(model.nv));
  Eigen::VectorXd target = model.neutral_configuration();
  target[model.body_q_offset[model.dof_body[proximal]]] = 1.0;
  sim.set_drive_target(0, target, Eigen::VectorXd::Zero(model.nv));
  const int distal_q = model.body_q_offset[model.dof_body[distal]];
  const int box_v = model.body_dof_offset[box];
  const int box_body = box, tip_body = model.dof_body[distal];
  FingerResult r;
  for (int i = 0; i < 11 * 60; ++i) {
    sim.step();
    if (i < 60) continue;
    r.worst_limit = std::max(r.worst_limit, -0.5 - sim.q(0)[distal_q]);
    bool pushed = false, walled = false;  // the tip and the wall press on the box
    for (const Contact& c : sim.contacts(0)) {
      r.worst_penetration = std::max(r.worst_penetration, -c.separation);
      const bool on_box = c.body_a == box_body || c.body_b == box_body, pressing = c.force.norm() > 0;
      pushed = pushed || (on_box && pressing && (c.body_a == tip_body || c.body_b == tip_body));
      walled = walled || (on_box && pressing && (c.shape_a == static_box_shape(0) || c.shape_b == static_box_shape(0)));
    }
    r.steps_not_pinned += !(pushed && walled);
    r.fastest_box = std::max(r.fastest_box, sim.v(0).segment<3>(box_v).norm());
  }
  r.held = r.worst_limit < 1e-3 && r.worst_penetration < 1e-3 && r.fastest_box < 1e-3 && r.steps_not_pinned == 0 &&
           sim.fault(0) == Fault::None;
  return r;
}

// The fewest iterations (of 4, 8, ..., 4096) that hold the finger case,
// printed for docs/contacts.md.
int finger_iterations(SolverType solver, Precision precision, FingerResult& last, double wall_sunk, int substeps) {
  for (int iterations = 4; iterations <= 4096; iterations *= 2) {
    last = finger_on_box(solver, iterations, precision, wall_sunk, substeps);
    if (last.held) return iterations;
  }
  return 0;
}

void expect_finger_held(SolverType solver, Precision precision, double wall_sunk = 0.0, int substeps = 1) {
  FingerResult last;
  const int needed = finger_iterations(solver, precision, last, wall_sunk, substeps);
  std::cout << "[finger] " << solver_name(solver) << " " << precision_name(precision) << " wall sunk " << wall_sunk << " m, "
            << substeps << " substep(s): "
            << (needed ? std::to_string(needed) + " iterations" : std::string("not held at 4096")) << "\n";
  EXPECT_GT(needed, 0) << solver_name(solver) << " " << precision_name(precision) << ": limit " << last.worst_limit
                       << " rad, penetration " << last.worst_penetration << " m, box " << last.fastest_box << " m/s, "
                       << last.steps_not_pinned << " steps with the box not pinned";
}

// Measured: PGS holds it with 1024 iterations in double against the wall
// whose bottom lies in the ground plane, and with 4096 in float and against
// the wall sunk 1 cm into the ground (double and float); TGS holds it in
// double against the coplanar wall with 128. Each step's rows have a slow mode (the tip pushing the box into the
// wall with the distal joint on its limit, which only the drive-heavy
// proximal joint gives way to: eigenvalue 0.55 against diagonals of 80),
// of which Gauss-Seidel removes little per sweep; PGS moves the positions
// with its last sweep's velocities, so enough sweeps hold the scene
// (docs/contacts.md, "Open problems").
TEST(ContactScenes, StiffFingerHoldsTheBoxAgainstTheWallWithPgs) { expect_finger_held(SolverType::PGS, Precision::Double); }
TEST(ContactScenes, StiffFingerHoldsTheBoxAgainstTheWallWithPgsInFloat) {
  expect_finger_held(SolverType::PGS, Precision::Float);
}
TEST(ContactScenes, StiffFingerHoldsTheBoxAgainstASunkWallWithPgs) {
  expect_finger_held(SolverType::PGS, Precision::Double, 0.01);
}
TEST(ContactScenes, StiffFingerHoldsTheBoxAgainstASunkWallWithPgsInFloat) {
  expect_finger_held(SolverType::PGS, Precision::Float, 0.01);
}
TEST(ContactScenes, StiffFingerHoldsTheBoxAgainstTheWallWithTgs) { expect_finger_held(SolverType::TGS, Precision::Double); }

// PhysX's remedy for this scene (its "Articulation Drive Stability"): a
// drive that does not reach its target within one solver step. With the
// 1/60 s step run as 32 pipeline substeps, the drive's implicit inertia kp h^2
// falls from 0.028 to 2.7e-5 kg m^2, well below the proximal joint's own
// 1.2e-3 (the mass matrix's diagonal), and the slow mode is gone: PGS holds
// the finger in both precisions against both walls with 4 to 64 iterations
// per substep (16 and 32 from this start; 4 to 64 from the box moved 3, -4
// and 7.1 mm along the wall), 128 to 2048 sweeps per 1/60 s in all (and 32
// runs of the dynamics and contact detection), against 1024 to 4096 in one
// step. TGS needs more of them: at 32 it does not hold the finger against
// the coplanar wall (box 1.7e-3 m/s in double, 6e-3 in float, at 256
// iterations); at 64, 96, 128 and 256 it holds it in every case tried (96: 8
// to 256 iterations over the four starts).
//
// describe_plan names the finger's drive as stiff in one pipeline run
// (kp h^2 / M_kk 23.7 at the start) and not in 32 (a 1024th of it).
TEST(ContactScenes, TheFingersPlanNamesItsStiffDriveInOneStepOnly) {
  for (const int substeps : {1, 32}) {
    StepOptions o;
    o.dt = 1.0 / 60.0;
    o.substeps = substeps;
    ModelBuilder builder;
    builder.add_articulation(finger_spec());
    const Model model = builder.finalize();
    std::vector<DofSettings> dofs = default_dof_settings(model);
    dofs[model.dof_index("proximal_joint")].drive_stiffness = 100.0;
    const std::string text = Simulator(model, 1, o, dofs).describe_plan();
    const bool named =
        text.find("stiff drives: 1 DOF(s) close half or more of their position error in one step") != std::string::npos;
    EXPECT_EQ(named, substeps == 1) << text;
  }
}

// One test per solver and precision, so that ctest runs them side by side.
TEST(ContactScenes, StiffFingerHoldsTheBoxWithPgsInThirtyTwoSubsteps) {
  for (const double wall_sunk : {0.0, 0.01}) expect_finger_held(SolverType::PGS, Precision::Double, wall_sunk, 32);
}
TEST(ContactScenes, StiffFingerHoldsTheBoxWithPgsInThirtyTwoSubstepsInFloat) {
  for (const double wall_sunk : {0.0, 0.01}) expect_finger_held(SolverType::PGS, Precision::Float, wall_sunk, 32);
}
TEST(ContactScenes, StiffFingerHoldsTheBoxWithTgsInNinetySixSubsteps) {
  for (const double wall_sunk : {0.0, 0.01}) expect_finger_held(SolverType::TGS, Precision::Double, wall_sunk, 96);
}
TEST(ContactScenes, StiffFingerHoldsTheBoxWithTgsInNinetySixSubstepsInFloat) {
  for (const double wall_sunk : {0.0, 0.01}) expect_finger_held(SolverType::TGS, Precision::Float, wall_sunk, 96);
}

// Known to fail (docs/contacts.md, "Open problems"), in one pipeline run
// per step: TGS in float against either wall, up to 4096 iterations (TGS's
// substeps); against the sunk wall in double, TGS holds it at 4096 iterations
// but at none of 4 to 2048, nor at 8192. TGS
// moves the positions by the mean of its substeps' velocities. When the
// warm start misses (a wall point of the box vanishes, or the box's
// statically indeterminate loads move between the wall and the ground),
// the slow mode's error in the first substeps stays in that mean: in
// double against the coplanar wall the distal joint then passes its limit
// by about 60 rad / substeps (0.118 rad at 512, 0.056 at 1024, 0.028 at
// 2048). Run with --gtest_also_run_disabled_tests.
TEST(ContactScenes, DISABLED_StiffFingerHoldsTheBoxAgainstTheWallWithTgsInFloat) {
  expect_finger_held(SolverType::TGS, Precision::Float);
}
TEST(ContactScenes, DISABLED_StiffFingerHoldsTheBoxAgainstASunkWallWithTgs) {
  expect_finger_held(SolverType::TGS, Precision::Double, 0.01);
  expect_finger_held(SolverType::TGS, Precision::Float, 0.01);
}

// A quadruped floating over the ground, its joints held in the stance by
// PD drives (kp 300 N m/rad, kd 8 N m s/rad), dropped from 5 cm above the
// height where its feet touch; on a plane tilted by `tilt` about y.
struct Standing {
  double settled = 0, worst = 0;  // height along the normal at 2 s; largest departure from it over 10 s more
  std::string other;              // a shape besides the feet that touched, if any
  int fewest_contacts = 99;
};

Standing stand(const std::string& name, double tilt, Precision precision, SolverType solver) {
  UrdfOptions floating;
  floating.floating_base = true;
  const Model model = load_urdf(shared_model_path(name), floating);
  StepOptions o;
  o.precision = precision;
  o.solver = solver;
  o.contacts.ground = true;
  o.contacts.ground_normal = Incline(tilt).normal;
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 6; k < model.nv; ++k) dofs[k].drive_stiffness = 300, dofs[k].drive_damping = 8;
  Simulator sim(model, 1, o, dofs);
  const Eigen::VectorXd target = stance(model);
  Eigen::VectorXd q = target;
  q[2] += 0.05 + 0.35 * std::tan(tilt);  // 5 cm, and clear of the slope under the farthest foot
  sim.set_state(0, q, Eigen::VectorXd::Zero(model.nv));
  sim.set_drive_target(0, target, Eigen::VectorXd::Zero(model.nv));
  const Eigen::Vector3d n = o.contacts.ground_normal;
  Standing r;
  for (int i = 0; i < 6000; ++i) {
    sim.step();
    const double height = n.dot(sim.q(0).head<3>());
    if (i == 999) r.settled = height;
    if (i >= 1000) {
      r.worst = std::max(r.worst, std::abs(height - r.settled));
      const std::vector<Contact> contacts = sim.contacts(0);
      r.fewest_contacts = std::min<int>(r.fewest_contacts, static_cast<int>(contacts.size()));
      for (const Contact& c : contacts)
        if (c.force.norm() > 0 && model.shapes[c.shape_b].type != ShapeType::Sphere)
          r.other = describe_shape(model, c.shape_b);
    }
  }
  return r;
}

// anymal_b and a1 settle standing on their four feet and stay within 1 cm
// of their standing height for 10 s, on flat ground and on a 10 degree
// slope (friction 1 > tan 10 deg: they do not slide).
TEST(ContactScenes, QuadrupedsStandUnderPd) {
  for (const std::string name : {"anymal_b", "a1"})
    for (double degrees : {0.0, 10.0})
      for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
        const Standing r = stand(name, degrees * kPi / 180, Precision::Float, solver);
        const std::string what = name + " on " + std::to_string(static_cast<int>(degrees)) + " deg, " +
                                 solver_name(solver);
        EXPECT_GT(r.settled, 0.15) << what << ": it did not stand";
        EXPECT_LT(r.worst, 0.01) << what;
        EXPECT_EQ(r.other, "") << what << ": something besides the feet touched";
        EXPECT_GE(r.fewest_contacts, 4) << what;
        std::cout << "[stand] " << what << ": height " << r.settled << " m, worst departure " << r.worst << " m\n";
      }
}

}  // namespace
}  // namespace lockstep::test
