// lockstep against an independent implementation: MuJoCo (2.2) reads the
// same URDF with its own reader, fuses the links on fixed joints with its own
// fusestatic lumping and computes the dynamics with its own CRBA and RNE. On
// real robots, fixed and floating base, at q = 0 at rest and at seeded random
// states, the two agree on every link's world pose, the mass matrix, the bias
// force (Coriolis, centrifugal and gravity), the gravity force and the forward
// dynamics. MuJoCo's passive forces (joint damping), constraints (limits,
// friction loss) and contacts are off: CopyDynamics has none of them.
//
// The models: ur5, solo12, simple_humanoid and finger_edu, the shared models
// whose URDF inertias MuJoCo takes as written. On the others MuJoCo computes
// something else by design: its compiler rewrites (balanceinertia) the
// inertias that violate the triangle inequality A + B >= C, which anymal_b,
// talos_reduced and allegro_right_hand have and lockstep keeps with a
// warning; and it stores each body's inertia as principal moments and axes
// from mju_eig3, accurate to ~1e-7 only, where panda, a1 and double_pendulum
// have full inertia tensors (their M then differs by up to 3e-8 of its
// largest entry). Here balanceinertia is off: MuJoCo refuses an inertia it
// would rebalance rather than rebalance it.
//
// Coordinates. Joints are matched by URDF name, links by name where MuJoCo
// keeps a body (fusestatic removes the links on fixed joints; lockstep's
// bodies are the same). A floating base's q is [x y z qw qx qy qz] in both.
// Its velocity is not: lockstep's is the body-frame twist [v_body; w_body],
// MuJoCo's free-joint qvel is [v_world; w_body], so v_mj = T v with
// T = blockdiag(R, I, 1, ...) (and the permutation between the two DOF
// orders), R the base's rotation. T is orthogonal and, with power
// tau . v invariant, tau_mj = T tau; differentiating v_mj = T v gives
// a_mj = T a + Tdot v with Tdot v = [R (w_body x v_body); 0]. Substituting
// into M_mj a_mj + b_mj = tau_mj and multiplying by T^T:
//   M = T^T M_mj T,  b = T^T (b_mj + M_mj Tdot v),  a = T^T (a_mj - Tdot v).
//
// Tolerances. Both sides are exact algorithms in double on trees of up to 35
// DOFs, differing in the order of their operations: poses agree to 1e-12 m
// and 1e-12 in each rotation-matrix entry, and M, the bias and the gravity
// force to 1e-12 of their largest entry (measured: 1.3e-15 at most). The
// forward dynamics solves with M and so may lose up to cond(M) * eps more
// (cond(M) is up to 2e4 here, on the floating bases: 4e-12): 1e-10 of its
// largest entry (measured: 1.2e-13 on ur5's floating base, 6e-15 at most on
// the others). A change of 1e-11 in one link's mass fails it (where that
// link is among the heavy ones), as does a change of 1e-10 in the velocity
// given to the bias. The test prints what it measured ("[ measured ]").
#include "test_support.hpp"

#include <mujoco/mujoco.h>
#include <tinyxml2.h>

#include <algorithm>
#include <iostream>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace lockstep {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;
using tinyxml2::XMLElement;

constexpr double kPoseTolerance = 1e-12;     // m, and per rotation-matrix entry
constexpr double kTermTolerance = 1e-12;     // of the largest entry: M, bias, gravity
constexpr double kForwardTolerance = 1e-10;  // of the largest entry: qacc
constexpr int kRandomStates = 7;             // besides q = 0 at rest

// The floating base as MuJoCo's URDF reader makes one (it welds the root link
// to the world otherwise): a floating joint from a link "world" to the root.
// A root link that is "world" itself (ur5) floats on its one joint from the
// world instead, as lockstep floats it.
void float_root(XMLElement* robot, const std::string& root) {
  if (root == "world") {
    for (XMLElement* joint = robot->FirstChildElement("joint"); joint; joint = joint->NextSiblingElement("joint"))
      if (std::string(joint->FirstChildElement("parent")->Attribute("link")) == "world")
        joint->SetAttribute("type", "floating");
    return;
  }
  robot->InsertNewChildElement("link")->SetAttribute("name", "world");
  XMLElement* joint = robot->InsertNewChildElement("joint");
  joint->SetAttribute("name", "mujoco_root");
  joint->SetAttribute("type", "floating");
  joint->InsertNewChildElement("parent")->SetAttribute("link", "world");
  joint->InsertNewChildElement("child")->SetAttribute("link", root.c_str());
}

// The URDF at `path` as MuJoCo is to read it: without visual and collision
// elements (no mesh files to find, and no geoms to give a link without an
// <inertial> a mass), links on fixed joints fused, inertias as written, and
// on a floating joint when `floating_root` names the root link.
std::string urdf_for_mujoco(const std::string& path, const std::string& floating_root) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(path.c_str()) != tinyxml2::XML_SUCCESS) throw std::runtime_error(path + ": " + doc.ErrorStr());
  XMLElement* robot = doc.FirstChildElement("robot");
  for (XMLElement* link = robot->FirstChildElement("link"); link; link = link->NextSiblingElement("link"))
    for (const char* tag : {"visual", "collision"})
      while (XMLElement* child = link->FirstChildElement(tag)) link->DeleteChild(child);
  XMLElement* compiler = robot->InsertNewChildElement("mujoco")->InsertNewChildElement("compiler");
  compiler->SetAttribute("fusestatic", "true");
  compiler->SetAttribute("balanceinertia", "false");
  if (!floating_root.empty()) float_root(robot, floating_root);
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  return printer.CStr();
}

struct MujocoDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
  void operator()(mjData* d) const { mj_deleteData(d); }
};

// Loads `urdf` from memory (a file MuJoCo reads would be written somewhere).
std::unique_ptr<mjModel, MujocoDeleter> load_mujoco(const std::string& urdf) {
  const char* name = "crosscheck.urdf";
  auto vfs = std::make_unique<mjVFS>();  // about 2 MB: off the stack
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), name, static_cast<int>(urdf.size())) != 0)
    throw std::runtime_error("MuJoCo: no room for the URDF in memory");
  std::copy(urdf.begin(), urdf.end(), static_cast<char*>(vfs->filedata[mj_findFileVFS(vfs.get(), name)]));
  char error[1000] = "";
  std::unique_ptr<mjModel, MujocoDeleter> m(mj_loadXML(name, vfs.get(), error, sizeof error));
  mj_deleteVFS(vfs.get());
  EXPECT_STREQ(error, "") << "MuJoCo's message on loading";
  return m;
}

// MuJoCo's warnings fail the test (instead of going to stdout and to
// MUJOCO_LOG.TXT in the working directory).
void fail_on_warning(const char* message) { ADD_FAILURE() << "MuJoCo warns: " << message; }

// Where lockstep's coordinates sit in MuJoCo's qpos and qvel.
struct CoordinateMap {
  std::vector<int> qpos;  // by lockstep q index
  std::vector<int> dof;   // by lockstep DOF
};

CoordinateMap map_coordinates(const Model& model, const mjModel* m) {
  CoordinateMap map{std::vector<int>(model.nq, -1), std::vector<int>(model.nv, -1)};
  for (int b = 0; b < model.nbody; ++b) {
    const JointType type = model.body_joint[b];
    // MuJoCo's one free joint is its first
    const int j = type == JointType::Free ? 0 : mj_name2id(m, mjOBJ_JOINT, model.joint_name[b].c_str());
    if (j < 0) throw std::runtime_error("MuJoCo has no joint " + model.joint_name[b]);
    for (int k = 0; k < joint_nq(type); ++k) map.qpos[model.body_q_offset[b] + k] = m->jnt_qposadr[j] + k;
    for (int k = 0; k < joint_nv(type); ++k) map.dof[model.body_dof_offset[b] + k] = m->jnt_dofadr[j] + k;
  }
  return map;
}

// MuJoCo's velocity T v and its rate Tdot v (the header comment has both).
struct VelocityMap {
  MatrixXd T;
  VectorXd Tdot_v;
};

VelocityMap velocity_map(const Model& model, const CoordinateMap& map, const VectorXd& q, const VectorXd& v) {
  VelocityMap t{MatrixXd::Zero(model.nv, model.nv), VectorXd::Zero(model.nv)};
  for (int d = 0; d < model.nv; ++d) t.T(map.dof[d], d) = 1.0;
  for (int b = 0; b < model.nbody; ++b) {
    if (model.body_joint[b] != JointType::Free) continue;
    const int o = model.body_q_offset[b], d = model.body_dof_offset[b];
    const Eigen::Matrix3d R = Eigen::Quaterniond(q[o + 3], q[o + 4], q[o + 5], q[o + 6]).toRotationMatrix();
    t.T.block<3, 3>(map.dof[d], d) = R;
    t.Tdot_v.segment<3>(map.dof[d]) = R * v.segment<3>(d + 3).cross(v.segment<3>(d));
  }
  return t;
}

double relative_difference(const MatrixXd& lockstep, const MatrixXd& mujoco) {
  return (lockstep - mujoco).cwiseAbs().maxCoeff() / mujoco.cwiseAbs().maxCoeff();
}

// The largest differences over the states, one per quantity.
struct Differences {
  double position = 0.0, rotation = 0.0;                            // of the link poses
  double mass_matrix = 0.0, bias = 0.0, gravity = 0.0, qacc = 0.0;  // relative
};

class SameAsMujoco : public test::ModelCaseTest {
 protected:
  void SetUp() override {
    test::ModelCaseTest::SetUp();
    previous_warning_ = std::exchange(mju_user_warning, fail_on_warning);
    const std::string root = model_.frame_name[model_.body_frame[0]];  // parent-first: body 0 is the root
    m_ = load_mujoco(urdf_for_mujoco(test::shared_model_path(GetParam().name), GetParam().floating_base ? root : ""));
    ASSERT_TRUE(m_);
    ASSERT_EQ(m_->nq, model_.nq);
    ASSERT_EQ(m_->nv, model_.nv);
    ASSERT_EQ(m_->jnt_type[0] == mjJNT_FREE, GetParam().floating_base);
    m_->opt.disableflags |= mjDSBL_PASSIVE | mjDSBL_CONSTRAINT | mjDSBL_CONTACT;
    d_.reset(mj_makeData(m_.get()));
    map_ = map_coordinates(model_, m_.get());
  }
  void TearDown() override { mju_user_warning = previous_warning_; }

  // Puts lockstep's state into MuJoCo's data and runs mj_forward.
  void forward(const VectorXd& q, const VectorXd& v_mj, const VectorXd& tau_mj) {
    for (int i = 0; i < model_.nq; ++i) d_->qpos[map_.qpos[i]] = q[i];
    Eigen::Map<VectorXd>(d_->qvel, model_.nv) = v_mj;
    Eigen::Map<VectorXd>(d_->qfrc_applied, model_.nv) = tau_mj;
    mj_forward(m_.get(), d_.get());
  }

  MatrixXd mujoco_mass_matrix() const {
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> M(model_.nv, model_.nv);
    mj_fullM(m_.get(), M.data(), d_->qM);
    return M;
  }

  // Positions and rotations of every link MuJoCo keeps a body for.
  void compare_poses(const VectorXd& q, Differences& worst) const {
    const std::vector<Eigen::Isometry3d> poses = dyn_->frame_poses(q);
    int matched = 0;
    for (std::size_t f = 0; f < poses.size(); ++f) {
      const int id = mj_name2id(m_.get(), mjOBJ_BODY, model_.frame_name[f].c_str());
      if (id <= 0) continue;  // fused away, or MuJoCo's world
      ++matched;
      const Eigen::Map<const Eigen::Vector3d> position(d_->xpos + 3 * id);
      const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> rotation(d_->xmat + 9 * id);
      worst.position = std::max(worst.position, (poses[f].translation() - position).cwiseAbs().maxCoeff());
      worst.rotation = std::max(worst.rotation, (poses[f].linear() - rotation).cwiseAbs().maxCoeff());
    }
    EXPECT_EQ(matched, m_->nbody - 1) << "every MuJoCo body but the world is a lockstep link";
  }

  std::unique_ptr<mjModel, MujocoDeleter> m_;
  std::unique_ptr<mjData, MujocoDeleter> d_;
  CoordinateMap map_;
  void (*previous_warning_)(const char*) = nullptr;
};

TEST_P(SameAsMujoco, PosesAndDynamics) {
  std::mt19937 rng(2024);
  Differences worst;
  for (int state = 0; state <= kRandomStates; ++state) {
    const bool at_rest = state == 0;
    const VectorXd q = at_rest ? model_.neutral_configuration() : test::random_configuration(model_, rng);
    const VectorXd v = at_rest ? VectorXd::Zero(model_.nv) : test::random_vector(model_.nv, rng);
    const VectorXd tau = test::random_vector(model_.nv, rng, 5.0);
    const VelocityMap t = velocity_map(model_, map_, q, v);

    forward(q, t.T * v, t.T * tau);
    compare_poses(q, worst);
    const MatrixXd M_mj = mujoco_mass_matrix();
    const VectorXd bias_mj = t.T.transpose() * (Eigen::Map<VectorXd>(d_->qfrc_bias, model_.nv) + M_mj * t.Tdot_v);
    const VectorXd qacc_mj = t.T.transpose() * (Eigen::Map<VectorXd>(d_->qacc, model_.nv) - t.Tdot_v);
    const MatrixXd M = dyn_->mass_matrix(q);
    worst.mass_matrix = std::max(worst.mass_matrix, relative_difference(M, t.T.transpose() * M_mj * t.T));
    worst.bias = std::max(worst.bias, relative_difference(dyn_->bias_force(q, v), bias_mj));
    worst.qacc = std::max(worst.qacc, relative_difference(dyn_->forward_dynamics(q, v, tau), qacc_mj));

    forward(q, VectorXd::Zero(model_.nv), VectorXd::Zero(model_.nv));
    const VectorXd gravity_mj = t.T.transpose() * Eigen::Map<VectorXd>(d_->qfrc_bias, model_.nv);
    worst.gravity = std::max(worst.gravity, relative_difference(dyn_->gravity_force(q), gravity_mj));
  }
  std::cout << "[ measured ] " << test::case_name(GetParam()) << " against MuJoCo " << mj_versionString()
            << ": link positions " << worst.position << " m, rotations " << worst.rotation
            << "; relative: M " << worst.mass_matrix << ", bias " << worst.bias << ", gravity " << worst.gravity
            << ", qacc " << worst.qacc << "\n";
  EXPECT_LE(worst.position, kPoseTolerance);
  EXPECT_LE(worst.rotation, kPoseTolerance);
  EXPECT_LE(worst.mass_matrix, kTermTolerance);
  EXPECT_LE(worst.bias, kTermTolerance);
  EXPECT_LE(worst.gravity, kTermTolerance);
  EXPECT_LE(worst.qacc, kForwardTolerance);
}

std::vector<test::ModelCase> crosschecked_cases() {
  std::vector<test::ModelCase> cases;
  for (const char* name : {"ur5", "solo12", "simple_humanoid", "finger_edu"})
    for (bool floating_base : {false, true}) cases.push_back({name, floating_base});
  return cases;
}

INSTANTIATE_TEST_SUITE_P(MujocoCrossCheck, SameAsMujoco, ::testing::ValuesIn(crosschecked_cases()),
                         [](const auto& info) { return test::case_name(info.param); });

}  // namespace
}  // namespace lockstep
