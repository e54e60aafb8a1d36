// Shared helpers of the kernel tests: the real robot models, random states.
#pragma once

#include "batch/copy_dynamics.hpp"
#include "io/urdf_import.hpp"
#include "layout/model_builder.hpp"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <unistd.h>

#include <ostream>
#include <random>
#include <string>
#include <vector>

#ifndef LOCKSTEP_SHARED_MODELS_DIR
#define LOCKSTEP_SHARED_MODELS_DIR "../shared/models"
#endif

// Expects `statement` to throw a ModelError whose message contains each of the given pieces.
#define EXPECT_MODEL_ERROR(statement, ...)                                         \
  do {                                                                             \
    try {                                                                          \
      statement;                                                                   \
      ADD_FAILURE() << "no ModelError from " #statement;                           \
    } catch (const ::lockstep::ModelError& e) {                                    \
      for (const char* piece : {__VA_ARGS__})                                      \
        EXPECT_NE(std::string(e.what()).find(piece), std::string::npos)            \
            << "message '" << e.what() << "' lacks '" << piece << "'";             \
    }                                                                              \
  } while (0)

// Expects `statement` to throw `Error` with a message containing `piece`.
#define EXPECT_THROW_WITH(statement, Error, piece)                                           \
  do {                                                                                       \
    try {                                                                                    \
      statement;                                                                             \
      ADD_FAILURE() << "no " #Error " from " #statement;                                     \
    } catch (const Error& e) {                                                               \
      EXPECT_NE(std::string(e.what()).find(piece), std::string::npos)                        \
          << "message '" << e.what() << "' lacks '" << (piece) << "'";                       \
    }                                                                                        \
  } while (0)

namespace lockstep::test {

// A link on a joint named <name>_joint (no joint for a root), its joint frame
// at `origin` in the parent link; the inertial is the caller's to fill in.
inline LinkSpec joint_link(const std::string& name, const std::string& parent, JointType type,
                           const Eigen::Vector3d& axis, const Eigen::Vector3d& origin) {
  LinkSpec l;
  l.name = name;
  l.parent = parent;
  l.joint.name = parent.empty() ? "" : name + "_joint";
  l.joint.type = type;
  l.joint.axis = axis;
  l.joint.origin.translation() = origin;
  return l;
}

// joint_link with a body: `mass` at an offset COM, with a full inertia
// (one product of inertia nonzero), for the dynamics tests' small trees.
inline LinkSpec massive_link(const std::string& name, const std::string& parent, JointType type,
                             const Eigen::Vector3d& axis, double mass,
                             const Eigen::Vector3d& origin = Eigen::Vector3d::Zero()) {
  LinkSpec l = joint_link(name, parent, type, axis, origin);
  l.inertial.mass = mass;
  l.inertial.origin.translation() = Eigen::Vector3d(0.05, 0.1, -0.2);
  l.inertial.inertia = mass * Eigen::Vector3d(0.03, 0.04, 0.05).asDiagonal();
  l.inertial.inertia(0, 1) = l.inertial.inertia(1, 0) = 0.002 * mass;
  return l;
}


inline const std::vector<std::string>& shared_model_names() {
  static const std::vector<std::string> names = {"ur5",          "panda",          "double_pendulum", "anymal_b",
                                                 "a1",           "solo12",         "talos_reduced",   "simple_humanoid",
                                                 "allegro_right_hand", "finger_edu"};
  return names;
}

inline std::string shared_model_path(const std::string& name) {
  return std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/" + name + ".urdf";
}

inline Model load_shared_model(const std::string& name, bool floating_base) {
  UrdfOptions options;
  options.floating_base = floating_base;
  return load_urdf(shared_model_path(name), options);
}

// A tree with Spherical joints (three DOFs in one body) between revolutes
// and a prismatic joint, on two branches: the shared models have none.
inline Model spherical_tree(bool floating_base) {
  ArticulationSpec a;
  a.name = "tree";
  a.floating_base = floating_base;
  a.links.push_back(massive_link("torso", "", JointType::Fixed, Eigen::Vector3d::UnitZ(), 5.0));
  a.links.push_back(massive_link("hip", "torso", JointType::Revolute, Eigen::Vector3d::UnitX(), 1.0,
                                 Eigen::Vector3d(0.1, 0, 0)));
  a.links.push_back(massive_link("ball", "hip", JointType::Spherical, Eigen::Vector3d::UnitZ(), 0.8,
                                 Eigen::Vector3d(0, 0, -0.3)));
  a.links.push_back(massive_link("foot", "ball", JointType::Revolute, Eigen::Vector3d(0.3, 1, 0.2), 0.3,
                                 Eigen::Vector3d(0, 0, -0.3)));
  a.links.push_back(massive_link("shoulder", "torso", JointType::Spherical, Eigen::Vector3d::UnitZ(), 0.6,
                                 Eigen::Vector3d(-0.1, 0, 0.2)));
  a.links.push_back(massive_link("hand", "shoulder", JointType::Prismatic, Eigen::Vector3d::UnitY(), 0.2,
                                 Eigen::Vector3d(0, 0.3, 0)));
  ModelBuilder builder;
  builder.add_articulation(a);
  return builder.finalize();
}

// A model case: name and base type, printable for parameterised tests. The
// name is a shared model's, or "spherical_tree" (above).
struct ModelCase {
  std::string name;
  bool floating_base;
};
inline std::vector<ModelCase> all_model_cases() {
  std::vector<ModelCase> cases;
  for (const std::string& name : shared_model_names()) {
    cases.push_back({name, false});
    cases.push_back({name, true});
  }
  cases.push_back({"spherical_tree", false});
  cases.push_back({"spherical_tree", true});
  return cases;
}
inline Model load_model_case(const ModelCase& c) {
  return c.name == "spherical_tree" ? spherical_tree(c.floating_base) : load_shared_model(c.name, c.floating_base);
}
inline std::string case_name(const ModelCase& c) { return c.name + (c.floating_base ? "_floating" : "_fixed"); }
inline void PrintTo(const ModelCase& c, std::ostream* os) { *os << case_name(c); }
inline std::vector<ModelCase> fixed_model_cases() {
  std::vector<ModelCase> cases;
  for (const std::string& name : shared_model_names()) cases.push_back({name, false});
  return cases;
}

// A random configuration: joint angles in [-1.5, 1.5] rad (inside the
// limits where the joint has them), prismatic joints inside their limits,
// random unit quaternions, the base within a metre of the origin.
inline Eigen::VectorXd random_configuration(const Model& model, std::mt19937& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::VectorXd q = model.neutral_configuration();
  for (int b = 0; b < model.nbody; ++b) {
    const int o = model.body_q_offset[b];
    const int d = model.body_dof_offset[b];
    switch (model.body_joint[b]) {
      case JointType::Revolute:
      case JointType::Prismatic: {
        double lo = std::max(model.dof_lower[d], -1.5), hi = std::min(model.dof_upper[d], 1.5);
        if (lo > hi) lo = hi = 0.5 * (model.dof_lower[d] + model.dof_upper[d]);
        q[o] = lo + (hi - lo) * 0.5 * (unit(rng) + 1.0);
        break;
      }
      case JointType::Free:
        for (int k = 0; k < 3; ++k) q[o + k] = unit(rng);
        [[fallthrough]];
      case JointType::Spherical: {
        const int r = model.body_joint[b] == JointType::Free ? o + 3 : o;
        Eigen::Vector4d quat(unit(rng), unit(rng), unit(rng), unit(rng));
        q.segment<4>(r) = quat.normalized();
        break;
      }
      case JointType::Fixed:
        break;
    }
  }
  return q;
}

inline Eigen::VectorXd random_vector(int n, std::mt19937& rng, double scale = 1.0) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::VectorXd v(n);
  for (int k = 0; k < n; ++k) v[k] = scale * unit(rng);
  return v;
}

// A test over one model case, with the model and its one-copy dynamics in double.
class ModelCaseTest : public ::testing::TestWithParam<ModelCase> {
 protected:
  void SetUp() override {
    model_ = load_model_case(GetParam());
    dyn_ = std::make_unique<CopyDynamics>(model_, Precision::Double);
  }
  Model model_;
  std::unique_ptr<CopyDynamics> dyn_;
};

// Link damping's generalized matrix sum_b J_b^T D_b J_b at q, from the
// bodies' [v_com; w] Jacobians (world axes) and D_b = diag(c_lin m 1,
// c_ang R I_c R^T) about each COM: what the kernels' -D v is in joint space.
inline Eigen::MatrixXd link_damping_matrix(const Model& model, const Eigen::VectorXd& q) {
  const CopyDynamics dyn(model, Precision::Double);
  const Eigen::MatrixXd J = dyn.com_jacobian(q);
  const std::vector<Eigen::Isometry3d> poses = dyn.body_poses(q);
  Eigen::MatrixXd matrix = Eigen::MatrixXd::Zero(model.nv, model.nv);
  for (int b = 0; b < model.nbody; ++b) {
    const Eigen::Matrix3d R = poses[b].linear();
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(6, 6);
    D.topLeftCorner<3, 3>() = model.body_linear_damping[b] * model.body_mass[b] * Eigen::Matrix3d::Identity();
    D.bottomRightCorner<3, 3>() = model.body_angular_damping[b] * R * model.body_inertia[b] * R.transpose();
    matrix += J.middleRows(6 * b, 6).transpose() * D * J.middleRows(6 * b, 6);
  }
  return matrix;
}

// A test with a folder of its own for the files it writes (scenes, URDFs),
// removed after it: dir_ is unique to the process and the test.
class SceneFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           ("lockstep_" + std::string(info->test_suite_name()) + "_" + std::to_string(::getpid()) + "_" + info->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  // Writes `text` to scene.json in dir_; returns its path.
  std::string write(const std::string& text) {
    const std::string path = (dir_ / "scene.json").string();
    std::ofstream(path) << text;
    return path;
  }
  std::filesystem::path dir_;
};

}  // namespace lockstep::test
