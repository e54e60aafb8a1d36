// Every bundled robot whose collision geometry loads whole, floating,
// dropped 5 cm onto the ground with its drives holding the benchmark's
// pose (tools/step_scene.hpp): it lands without sinking in and comes to
// rest, with either solver in either precision. The other bundled robots
// lack their collision meshes (their links have no shapes), so nothing of
// them meets the ground.
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>
#include <optional>

namespace lockstep::test {
namespace {

struct Drop {
  double deepest = 0;     // most negative separation of a pushing contact after the first 0.5 s [m]
  double last_speed = 0;  // largest |qd| over the last 0.1 s [m/s or rad/s]
  int faulted_steps = 0;
  int fewest_contacts = 1 << 30;  // over the last 0.1 s
};

Drop drop(const Model& model, Precision precision, SolverType solver) {
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  StepOptions o;
  o.precision = precision;
  o.solver = solver;
  o.contacts.ground = true;
  Simulator sim(model, 1, o, scene.dofs);
  Eigen::VectorXd q = scene.q0;
  q[2] += 0.05;  // the root's height: the lowest shape 5 cm above the ground
  sim.set_state(0, q, Eigen::VectorXd::Zero(model.nv));
  sim.set_drive_target(0, scene.q_target, Eigen::VectorXd::Zero(model.nv));
  Drop r;
  const int steps = 1500, last = steps - 50;  // 3 s at dt 2 ms
  for (int i = 0; i < steps; ++i) {
    sim.step();
    r.faulted_steps += sim.fault(0) != Fault::None;
    const std::vector<Contact> contacts = sim.contacts(0);
    if (i >= 250)
      for (const Contact& c : contacts)
        if (c.force.norm() > 0) r.deepest = std::min(r.deepest, c.separation);
    if (i >= last) {
      r.last_speed = std::max(r.last_speed, sim.v(0).cwiseAbs().maxCoeff());
      r.fewest_contacts = std::min(r.fewest_contacts, static_cast<int>(contacts.size()));
    }
  }
  return r;
}

// The model, floating, when every collision element of its URDF became a
// shape and there are some; nullopt otherwise.
std::optional<Model> with_whole_collision_geometry(const std::string& name) {
  UrdfOptions floating;
  floating.floating_base = true;
  std::vector<std::string> warnings;
  Model model = load_urdf(shared_model_path(name), floating, {}, &warnings);
  const bool skipped = std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
    return w.find("collision geometry skipped") != std::string::npos;
  });
  if (skipped || model.shapes.empty()) return std::nullopt;
  return model;
}

// Bounds: 1 mm of penetration and 1e-3 m/s (rad/s) of motion, those of the
// contact issue's resting sphere. Measured (2026-11-26, AMD EPYC): the
// deepest contact 1.5e-7 m (anymal_b), 1.1e-7 (a1), 4.9e-6 (the hand, its
// fingertips pressed by stiff drives); the largest |qd| at 3 s 7.3e-5.
TEST(GroundDrop, EveryRobotWithItsCollisionGeometryLandsAndComesToRest) {
  std::vector<std::string> dropped;
  for (const std::string& name : shared_model_names()) {
    const std::optional<Model> model = with_whole_collision_geometry(name);
    if (!model) continue;
    dropped.push_back(name);
    for (SolverType solver : {SolverType::PGS, SolverType::TGS})
      for (Precision precision : {Precision::Float, Precision::Double}) {
        const Drop r = drop(*model, precision, solver);
        const std::string what = name + ", " + solver_name(solver) + ", " + precision_name(precision);
        EXPECT_EQ(r.faulted_steps, 0) << what;
        EXPECT_GT(r.deepest, -1e-3) << what;
        EXPECT_LT(r.last_speed, 1e-3) << what;
        EXPECT_GE(r.fewest_contacts, 3) << what << ": it does not rest on the ground";
        std::cout << "[drop] " << what << ": deepest " << r.deepest << " m, largest |qd| at 3 s " << r.last_speed
                  << ", contacts " << r.fewest_contacts << "\n";
      }
  }
  // the bundled models whose collision geometry is whole: the quadrupeds
  // with sphere feet, and the hand with its boxes and spheres
  EXPECT_EQ(dropped, (std::vector<std::string>{"anymal_b", "a1", "allegro_right_hand"}));
}

// anymal_b standing on a box stands as on the ground: on its feet, at the
// ground's sag. Its shank cylinders reach into its foot spheres; against a
// box they are the capsules inside them (ordered_pair in
// batch/contact_pairs.cpp). As capsules as long as the cylinders they stuck
// out 5.4 mm below the feet: the robot was kicked up 0.069 m/s in the first
// step and stood on its shanks, its height depending on the step size.
// Measured after 2 s: 0.490719 m above the surface on the box and on the
// ground alike (float and double), the feet alone pushing. Asserted: the
// heights within 1e-4 m of each other, only foot spheres pushing, and no
// upward kick (|vz| after the first step below 0.02 m/s).
TEST(GroundDrop, AQuadrupedOnABoxStandsOnItsFeetAsOnTheGround) {
  const Model model = load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  for (const Precision precision : {Precision::Float, Precision::Double}) {
    double height[2];
    for (const bool box : {false, true}) {
      StepOptions o;
      o.precision = precision;
      o.contacts.ground = true;
      Eigen::VectorXd q = scene.q0;
      if (box) {  // a 10 cm box under the robot, its top where the ground was, 10 cm lower
        StaticBox step;
        step.pose.translation() = Eigen::Vector3d(0, 0, 0.05);
        step.half_extents = Eigen::Vector3d(0.5, 0.5, 0.05);
        o.contacts.boxes.push_back(step);
        q[2] += 0.1;
      }
      Simulator sim(model, 1, o, scene.dofs);
      sim.set_state(0, q, Eigen::VectorXd::Zero(model.nv));
      sim.set_drive_target(0, q, Eigen::VectorXd::Zero(model.nv));
      sim.step();
      const std::string what = std::string(precision_name(precision)) + (box ? " on the box" : " on the ground");
      EXPECT_LT(std::abs(sim.v(0)[2]), 0.02) << what;
      sim.step(999);
      EXPECT_EQ(sim.fault(0), Fault::None) << what;
      height[box] = sim.q(0)[2] - (box ? 0.1 : 0.0);
      for (const Contact& c : sim.contacts(0)) {
        const int shape = c.shape_a >= 0 ? c.shape_a : c.shape_b;  // the robot's (the box sorts after a sphere)
        if (c.force.norm() > 0)
          EXPECT_EQ(model.shapes[shape].type, ShapeType::Sphere)
              << what << ": shape " << shape << " of " << model.frame_name[model.shapes[shape].frame] << " pushes";
      }
    }
    EXPECT_NEAR(height[1], height[0], 1e-4) << precision_name(precision);
  }
}

}  // namespace
}  // namespace lockstep::test
