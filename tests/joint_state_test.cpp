#include "layout/model_builder.hpp"
#include "io/joint_state.hpp"

#include <gtest/gtest.h>

#include <random>

namespace lockstep {
namespace {

LinkSpec link(const std::string& name, const std::string& parent, const std::string& joint, JointType type) {
  LinkSpec l;
  l.name = name;
  l.parent = parent;
  l.joint.name = joint;
  l.joint.type = type;
  l.joint.axis = Eigen::Vector3d::UnitY();
  l.joint.origin.translation() = Eigen::Vector3d(0.0, 0.0, 0.3);
  l.inertial.mass = 1.0;
  l.inertial.inertia = Eigen::Matrix3d::Identity() * 0.01;
  return l;
}

// A floating base with a revolute arm, a ball joint and a fixed tip.
Model test_model() {
  ArticulationSpec spec;
  spec.name = "bot";
  spec.floating_base = true;
  spec.links = {link("base", "", "", JointType::Fixed), link("arm", "base", "elbow", JointType::Revolute),
                link("ball", "base", "shoulder", JointType::Spherical), link("tip", "arm", "tip_joint", JointType::Fixed)};
  ModelBuilder builder;
  builder.add_articulation(spec);
  return builder.finalize();
}

JointState read(const Model& model, const std::string& text) {
  return read_state(model, json::parse(text, "s.json"), "s.json");
}

std::string error_of(const Model& model, const std::string& text) {
  try {
    read(model, text);
  } catch (const StateError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(CliState, JointsNotGivenAreNeutralAndAtRest) {
  const Model model = test_model();
  const JointState s = read(model, "{}");
  EXPECT_EQ(s.q, model.neutral_configuration());
  EXPECT_TRUE(s.v.isZero());
  EXPECT_TRUE(s.tau.isZero());
  EXPECT_EQ(s.v.size(), model.nv);
}

TEST(CliState, EntriesLandAtTheirJointsOffsets) {
  const Model model = test_model();
  const std::string root = model.joint_name[0];
  EXPECT_EQ(root, "bot_root");  // the documented name of a floating base's joint
  const JointState s = read(model, R"({
    "q": {"bot_root": [1, 2, 3, 0, 1, 0, 0], "elbow": 0.5, "shoulder": [0, 0, 0, 1]},
    "qd": {"bot_root": [1, 2, 3, 4, 5, 6], "elbow": -1.5, "shoulder": [7, 8, 9]},
    "tau": {"elbow": 2.5}})");
  const int elbow = model.joint_index("elbow");
  const int shoulder = model.joint_index("shoulder");
  EXPECT_EQ(s.q.segment<7>(model.body_q_offset[0]), (Eigen::Matrix<double, 7, 1>() << 1, 2, 3, 0, 1, 0, 0).finished());
  EXPECT_EQ(s.q[model.body_q_offset[elbow]], 0.5);
  EXPECT_EQ(s.q.segment<4>(model.body_q_offset[shoulder]), Eigen::Vector4d(0, 0, 0, 1));
  EXPECT_EQ(s.v.segment<6>(model.body_dof_offset[0]), (Eigen::Matrix<double, 6, 1>() << 1, 2, 3, 4, 5, 6).finished());
  EXPECT_EQ(s.v[model.body_dof_offset[elbow]], -1.5);
  EXPECT_EQ(s.v.segment<3>(model.body_dof_offset[shoulder]), Eigen::Vector3d(7, 8, 9));
  EXPECT_EQ(s.tau[model.body_dof_offset[elbow]], 2.5);
  EXPECT_EQ(s.tau.norm(), 2.5);
}

TEST(CliState, NearlyUnitQuaternionsAreNormalised) {
  const Model model = test_model();
  const JointState s = read(model, R"({"q": {"shoulder": [0.7071, 0.7071, 0, 0]}})");
  EXPECT_NEAR(s.q.segment<4>(model.body_q_offset[model.joint_index("shoulder")]).norm(), 1.0, 1e-15);
  EXPECT_NE(error_of(model, R"({"q": {"shoulder": [0.5, 0, 0, 0]}})").find("q.shoulder: the quaternion"),
            std::string::npos);
  EXPECT_NE(error_of(model, R"({"q": {"bot_root": [0, 0, 0, 0, 0, 0, 0]}})").find("has norm 0"), std::string::npos);
  // norms whose squares overflow or underflow are still named as they are
  EXPECT_NE(error_of(model, R"({"q": {"bot_root": [0, 0, 0, 1e200, 1e200, 0, 0]}})").find("has norm 1.414213562373"),
            std::string::npos);
  EXPECT_NE(error_of(model, R"({"q": {"bot_root": [0, 0, 0, 1e-200, 0, 0, 0]}})").find("has norm 1e-200"),
            std::string::npos);
}

// What a first read normalised reads back as written: writing a state and
// reading it again keeps its bits (scene files round-trip through this).
TEST(CliState, ANormalisedQuaternionReadsBackBitForBit) {
  const Model model = test_model();
  const int at = model.body_q_offset[model.joint_index("shoulder")];
  auto as_text = [](const Eigen::Vector4d& x) {
    std::string text = R"({"q": {"shoulder": [)";
    for (int k = 0; k < 4; ++k) text += (k ? ", " : "") + json::number(x[k]);
    return text + "]}}";
  };
  std::mt19937 rng(7);
  std::normal_distribution<double> gauss;
  for (int i = 0; i < 1000; ++i) {
    Eigen::Vector4d written(gauss(rng), gauss(rng), gauss(rng), gauss(rng));
    written *= (1 + 5e-4 * std::uniform_real_distribution<double>(-1, 1)(rng)) / written.norm();  // within 1e-3 of unit
    const Eigen::Vector4d once = read(model, as_text(written)).q.segment<4>(at);
    const Eigen::Vector4d twice = read(model, as_text(once)).q.segment<4>(at);
    for (int k = 0; k < 4; ++k) ASSERT_EQ(twice[k], once[k]) << "quaternion " << i << " entry " << k;
  }
}

TEST(CliState, ErrorsNameTheKey) {
  const Model model = test_model();
  const auto expect_error = [&](const std::string& text, const std::string& part) {
    const std::string message = error_of(model, text);
    EXPECT_NE(message.find(part), std::string::npos) << "input: " << text << "\nmessage: " << message;
    EXPECT_EQ(message.rfind("s.json: ", 0), 0u) << message;
  };
  expect_error(R"({"q": {"knee": 1}})", "q.knee: unknown joint \"knee\"");
  expect_error(R"({"qd": {"tip_joint": 1}})", "qd.tip_joint: joint \"tip_joint\" is fixed");
  expect_error(R"({"q": {"elbw": 1}})", "q.elbw: unknown joint \"elbw\" (did you mean \"elbow\"?)");
  expect_error(R"({"qdd": {}})", "unknown key \"qdd\" (did you mean \"qd\"?)");
  expect_error(R"({"q": [1, 2]})", "q: expected an object keyed by joint name, got array");
  expect_error(R"([])", "expected an object");
  expect_error(R"({"q": {"elbow": [1]}})", "q.elbow: expected a number, got array");
  expect_error(R"({"tau": {"elbow": "1"}})", "tau.elbow: expected a number, got string");
  expect_error(R"({"q": {"bot_root": [0, 0, 0, 1, 0, 0]}})", "q.bot_root: expected an array of 7 numbers");
  expect_error(R"({"qd": {"bot_root": 1}})", "qd.bot_root: expected an array of 6 numbers");
  expect_error(R"({"tau": {"shoulder": [1, 2, 3, 4]}})", "tau.shoulder: expected an array of 3 numbers");
  expect_error(R"({"qd": {"shoulder": [1, null, 3]}})", "qd.shoulder[1]: expected a number, got null");
  expect_error(R"({"tau": {"elbow": NaN}})", "tau.elbow: value is not finite");
  expect_error(R"({"qd": {"bot_root": [0, 0, 0, 0, Infinity, 0]}})", "qd.bot_root[4]: value is not finite");
  expect_error(R"({"q": {"elbow": 1e400}})", "q.elbow: value is not finite");
}

}  // namespace
}  // namespace lockstep
