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

}  // namespace
}  // namespace lockstep::test
