// The numbers `lockstep dynamics` and `lockstep info --json` print are the
// library's: every field against CopyDynamics and the Model, for floating
// anymal_b at a state with its base moved, tilted and turning, legs bent,
// and torques on joints and base (docs/cli.md holds the formats).
#include "batch/copy_dynamics.hpp"
#include "io/json.hpp"
#include "test_support.hpp"
#include "tools/cli.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <unistd.h>

namespace lockstep {
namespace {

Eigen::VectorXd numbers(const json::Value& v) {
  Eigen::VectorXd out(v.array.size());
  for (std::size_t i = 0; i < v.array.size(); ++i) out[i] = v.array[i].number;
  return out;
}

const json::Value& member(const json::Value& v, const std::string& key) {
  const json::Value* m = v.find(key);
  if (!m) throw std::runtime_error("no member " + key);
  return *m;
}

// Relative to the size of what is compared: the command and this test run
// the same double kernels on a state that may differ by the ulp of the
// quaternion's normalisation.
void expect_close(const Eigen::MatrixXd& printed, const Eigen::MatrixXd& expected, const std::string& what) {
  ASSERT_EQ(printed.rows(), expected.rows()) << what;
  ASSERT_EQ(printed.cols(), expected.cols()) << what;
  EXPECT_LE((printed - expected).norm(), 1e-12 * (1.0 + expected.norm())) << what;
}

TEST(CliOutput, DynamicsPrintsTheLibrarysNumbers) {
  const std::string urdf = test::shared_model_path("anymal_b");
  const std::filesystem::path state = std::filesystem::temp_directory_path() /
                                      ("lockstep_cli_output_" + std::to_string(::getpid()) + ".json");
  const double c = std::cos(0.2), s = std::sin(0.2);
  std::ofstream(state) << std::setprecision(17) << "{\"q\": {\"anymal_root\": [0.1, -0.2, 0.55, " << c << ", 0, " << s
                       << ", 0], \"LF_HAA\": 0.1, \"RH_KFE\": -0.7},\n"
                       << " \"qd\": {\"anymal_root\": [0.3, 0, -0.1, 0.05, 0.2, -0.1], \"LF_HFE\": 1.5},\n"
                       << " \"tau\": {\"LF_KFE\": 5.0, \"anymal_root\": [1, 2, 3, 0.1, 0.2, 0.3]}}\n";
  std::ostringstream out;
  ASSERT_EQ(cli::run_dynamics({urdf, "--state", state.string(), "--floating-base"}, out), 0);
  std::filesystem::remove(state);
  const json::Value printed = json::parse(out.str());

  const Model model = test::load_shared_model("anymal_b", true);
  const CopyDynamics dynamics(model, Precision::Double);
  Eigen::VectorXd q = model.neutral_configuration(), v = Eigen::VectorXd::Zero(model.nv), tau = v;
  q.head<7>() << 0.1, -0.2, 0.55, c, 0, s, 0;
  q[model.body_q_offset[model.joint_index("LF_HAA")]] = 0.1;
  q[model.body_q_offset[model.joint_index("RH_KFE")]] = -0.7;
  v.head<6>() << 0.3, 0, -0.1, 0.05, 0.2, -0.1;
  v[model.dof_index("LF_HFE")] = 1.5;
  tau.head<6>() << 1, 2, 3, 0.1, 0.2, 0.3;
  tau[model.dof_index("LF_KFE")] = 5.0;

  const json::Value& names = member(printed, "dof_names");
  ASSERT_EQ(names.array.size(), static_cast<std::size_t>(model.nv));
  for (int k = 0; k < model.nv; ++k) EXPECT_EQ(names.array[k].string, model.dof_name[k]);
  expect_close(numbers(member(printed, "q")), q, "q");
  expect_close(numbers(member(printed, "qd")), v, "qd");
  expect_close(numbers(member(printed, "tau")), tau, "tau");
  const json::Value& rows = member(printed, "mass_matrix");
  Eigen::MatrixXd M(rows.array.size(), model.nv);
  for (std::size_t i = 0; i < rows.array.size(); ++i) M.row(i) = numbers(rows.array[i]).transpose();
  expect_close(M, dynamics.mass_matrix(q), "mass_matrix");
  expect_close(numbers(member(printed, "bias")), dynamics.bias_force(q, v), "bias");
  expect_close(numbers(member(printed, "gravity")), dynamics.gravity_force(q), "gravity");
  expect_close(numbers(member(printed, "qacc")), dynamics.forward_dynamics(q, v, tau), "qacc");
  EXPECT_NEAR(member(printed, "kinetic_energy").number, dynamics.kinetic_energy(q, v), 1e-12);
  EXPECT_NEAR(member(printed, "potential_energy").number, dynamics.potential_energy(q), 1e-12);
  const json::Value& links = member(printed, "links");
  const std::vector<Eigen::Isometry3d> poses = dynamics.frame_poses(q);
  ASSERT_EQ(links.object.size(), poses.size());
  for (std::size_t f = 0; f < poses.size(); ++f) {
    EXPECT_EQ(links.object[f].first, model.frame_name[f]);
    const json::Value& link = links.object[f].second;
    expect_close(numbers(member(link, "position")), poses[f].translation(), model.frame_name[f] + " position");
    Eigen::Matrix3d R;
    for (int i = 0; i < 3; ++i) R.row(i) = numbers(member(link, "rotation").array[i]).transpose();
    expect_close(R, poses[f].linear(), model.frame_name[f] + " rotation");
  }
}

TEST(CliOutput, InfoJsonPrintsTheModelsStructure) {
  const std::string urdf = test::shared_model_path("talos_reduced");  // fused links with mass of their own
  std::ostringstream out;
  ASSERT_EQ(cli::run_info({urdf, "--floating-base", "--json"}, out), 0);
  const json::Value printed = json::parse(out.str());
  const Model model = test::load_shared_model("talos_reduced", true);
  EXPECT_EQ(member(printed, "nbody").number, model.nbody);
  EXPECT_EQ(member(printed, "nq").number, model.nq);
  EXPECT_EQ(member(printed, "nv").number, model.nv);
  EXPECT_EQ(member(printed, "total_mass").number, model.total_mass());
  const json::Value& bodies = member(printed, "bodies");
  ASSERT_EQ(bodies.array.size(), static_cast<std::size_t>(model.nbody));
  for (int b = 0; b < model.nbody; ++b) {
    const json::Value& body = bodies.array[b];
    EXPECT_EQ(member(body, "parent").number, model.body_parent[b]);
    EXPECT_EQ(member(body, "joint").string, model.joint_name[b]);
    EXPECT_EQ(member(body, "q_offset").number, model.body_q_offset[b]);
    EXPECT_EQ(member(body, "dof_offset").number, model.body_dof_offset[b]);
    EXPECT_EQ(member(body, "mass").number, model.body_mass[b]);
    EXPECT_EQ(member(body, "gravity").boolean, model.body_gravity[b] != 0);
  }
  const json::Value& frames = member(printed, "frames");
  ASSERT_EQ(frames.array.size(), model.frame_name.size());
  double fused_mass = 0, frame_mass = 0;
  for (std::size_t f = 0; f < frames.array.size(); ++f) {
    const json::Value& frame = frames.array[f];
    EXPECT_EQ(member(frame, "name").string, model.frame_name[f]);
    EXPECT_EQ(member(frame, "body").number, model.frame_body[f]);
    EXPECT_EQ(member(frame, "parent").number, model.frame_parent[f]);
    EXPECT_EQ(member(frame, "mass").number, model.frame_mass[f]);
    if (member(frame, "fused").boolean) fused_mass += model.frame_mass[f];
    frame_mass += model.frame_mass[f];
  }
  EXPECT_GT(fused_mass, 0.0) << "talos_reduced fuses links that have mass";
  EXPECT_NEAR(frame_mass, model.total_mass(), 1e-9) << "the links' masses add up to the bodies'";
}

}  // namespace
}  // namespace lockstep
