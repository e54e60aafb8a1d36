// Loads a URDF, prints its bodies and the joint-space mass matrix at the
// neutral configuration.
//
//   print_model MODEL.urdf [--floating-base]
#include "batch/copy_dynamics.hpp"
#include "io/urdf_import.hpp"

#include <cstring>
#include <iostream>

int main(int argc, char** argv) {
  if (argc < 2 || (argc == 3 && std::strcmp(argv[2], "--floating-base") != 0) || argc > 3) {
    std::cerr << "usage: print_model MODEL.urdf [--floating-base]\n";
    return 2;
  }
  lockstep::UrdfOptions options;
  options.floating_base = argc == 3;
  lockstep::Model model;
  try {
    model = lockstep::load_urdf(argv[1], options);
  } catch (const std::exception& e) {  // lockstep::ModelError names the file and element
    std::cerr << e.what() << "\n";
    return 2;
  }

  std::cout << model.nbody << " bodies, " << model.nv << " DOFs, " << model.total_mass() << " kg\n";
  for (int b = 0; b < model.nbody; ++b) {
    std::cout << "  " << b << " " << model.frame_name[model.body_frame[b]] << " on "
              << lockstep::joint_type_name(model.body_joint[b]) << " joint " << model.joint_name[b]
              << ", parent " << model.body_parent[b] << ", " << model.body_mass[b] << " kg\n";
  }

  // One environment copy, double precision: M(q) by the composite-rigid-body algorithm.
  const lockstep::CopyDynamics dynamics(model, lockstep::Precision::Double);
  const Eigen::MatrixXd mass_matrix = dynamics.mass_matrix(model.neutral_configuration());
  const Eigen::IOFormat format(4, 0, " ", "\n", "  ");
  std::cout << "mass matrix at the neutral configuration (" << model.nv << "x" << model.nv << "):\n"
            << mass_matrix.format(format) << "\n";
  return 0;
}
