// Steps N copies of a robot (floating base, no contacts) whose joint drives
// hold a pose in the middle of the joints' ranges, each copy with its own
// random offsets, and prints how far the copies are from their targets
// (the URDF's joint friction leaves a small error) and how many faulted.
//
//   hold_pose MODEL.urdf [COPIES]
#include "batch/simulator.hpp"
#include "io/urdf_import.hpp"

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <random>

int main(int argc, char** argv) {
  if (argc < 2 || argc > 3) {
    std::cerr << "usage: hold_pose MODEL.urdf [COPIES]\n";
    return 2;
  }
  lockstep::UrdfOptions urdf;
  urdf.floating_base = true;
  lockstep::Model model;
  try {
    model = lockstep::load_urdf(argv[1], urdf);
  } catch (const std::exception& e) {  // lockstep::ModelError names the file and element
    std::cerr << e.what() << "\n";
    return 2;
  }
  const int copies = argc == 3 ? std::atoi(argv[2]) : 1024;

  // Drives on every joint but the floating base's; everything else (effort,
  // velocity and position limits, damping, friction) from the URDF.
  std::vector<lockstep::DofSettings> dofs = lockstep::default_dof_settings(model);
  for (int k = 0; k < model.nv; ++k) {
    if (model.body_joint[model.dof_body[k]] == lockstep::JointType::Free) continue;
    dofs[k].drive_stiffness = 200.0;  // N m/rad
    dofs[k].drive_damping = 5.0;      // N m s/rad
  }
  lockstep::StepOptions options;  // dt 2 ms, PGS, semi-implicit Euler, float SIMD lanes
  lockstep::Simulator sim(model, copies, options, dofs);
  std::cout << sim.describe_plan();

  std::mt19937 rng(1);
  std::uniform_real_distribution<double> offset(-0.2, 0.2);
  std::vector<Eigen::VectorXd> targets;
  for (int c = 0; c < copies; ++c) {
    Eigen::VectorXd target = model.neutral_configuration();
    for (int b = 0; b < model.nbody; ++b) {
      if (model.body_joint[b] != lockstep::JointType::Revolute) continue;
      // the middle of the joint's range (0 when unlimited), give or take 0.2 rad
      const int k = model.body_dof_offset[b];
      const double middle = std::isfinite(dofs[k].lower + dofs[k].upper) ? 0.5 * (dofs[k].lower + dofs[k].upper) : 0.0;
      target[model.body_q_offset[b]] = middle + offset(rng);
    }
    sim.set_drive_target(c, target, Eigen::VectorXd::Zero(model.nv));
    targets.push_back(target);
  }
  sim.set_gravity(0, Eigen::Vector3d::Zero());  // copy 0 floats without gravity, the others fall freely

  sim.step(500);  // 1 s
  double worst = 0;
  for (int c = 0; c < copies; ++c) {
    const Eigen::VectorXd q = sim.q(c);
    for (int b = 0; b < model.nbody; ++b)
      if (model.body_joint[b] == lockstep::JointType::Revolute) {
        const int i = model.body_q_offset[b];
        worst = std::max(worst, std::abs(q[i] - targets[c][i]));
      }
  }
  std::cout << copies << " copies after " << sim.time() << " s: largest joint error " << worst << " rad, "
            << sim.fault_count() << " faulted, " << sim.bytes_per_copy() << " bytes per copy\n";
  return sim.fault_count() == 0 ? 0 : 1;
}
