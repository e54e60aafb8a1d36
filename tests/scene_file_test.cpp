// Scene files (io/scene_file.hpp): every key lands in its field, defaults,
// the JSON round trip, the bundled scenes, and each kind of bad input.
#include "io/scene_file.hpp"

#include "batch/copy_dynamics.hpp"
#include "batch/simulator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

#ifndef LOCKSTEP_MODELS_DIR
#define LOCKSTEP_MODELS_DIR "models"
#endif
#ifndef LOCKSTEP_SHARED_MODELS_DIR
#define LOCKSTEP_SHARED_MODELS_DIR "../shared/models"
#endif

namespace lockstep {
namespace {

namespace fs = std::filesystem;

const std::string kModelsDir = LOCKSTEP_MODELS_DIR;
const std::string kQuadruped = kModelsDir + "/quadruped.urdf";
const std::string kDataDir = kModelsDir + "/../tests/data";

// ---- comparing, bit for bit

std::uint64_t bits(double x) {
  std::uint64_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}

#define EXPECT_BITS(a, b) EXPECT_EQ(bits(a), bits(b)) << #a " = " << (a) << ", " #b " = " << (b)

void expect_bits(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, const std::string& what) {
  ASSERT_EQ(a.rows(), b.rows()) << what;
  ASSERT_EQ(a.cols(), b.cols()) << what;
  for (Eigen::Index i = 0; i < a.size(); ++i) EXPECT_EQ(bits(a.data()[i]), bits(b.data()[i])) << what << " entry " << i;
}

void expect_same_surface(const ShapeContact& a, const ShapeContact& b) {
  EXPECT_BITS(a.friction, b.friction);
  EXPECT_BITS(a.restitution, b.restitution);
  EXPECT_EQ(a.layers, b.layers);
  EXPECT_EQ(a.collides_with, b.collides_with);
}

void expect_same_contacts(const ContactSettings& a, const ContactSettings& b) {
  EXPECT_EQ(a.ground, b.ground);
  EXPECT_BITS(a.ground_height, b.ground_height);
  expect_bits(a.ground_normal, b.ground_normal, "ground_normal");
  expect_same_surface(a.ground_contact, b.ground_contact);
  ASSERT_EQ(a.boxes.size(), b.boxes.size());
  for (std::size_t i = 0; i < a.boxes.size(); ++i) {
    expect_bits(a.boxes[i].pose.matrix(), b.boxes[i].pose.matrix(), "box pose");
    expect_bits(a.boxes[i].half_extents, b.boxes[i].half_extents, "box half extents");
    expect_same_surface(a.boxes[i].contact, b.boxes[i].contact);
  }
  ASSERT_EQ(a.shapes.size(), b.shapes.size());
  for (std::size_t i = 0; i < a.shapes.size(); ++i) expect_same_surface(a.shapes[i], b.shapes[i]);
  EXPECT_EQ(a.self_collision, b.self_collision);
  EXPECT_EQ(a.enabled_pairs, b.enabled_pairs);
  EXPECT_EQ(a.disabled_pairs, b.disabled_pairs);
  EXPECT_EQ(a.capacity, b.capacity);
  EXPECT_BITS(a.margin, b.margin);
  EXPECT_BITS(a.speculative_speed, b.speculative_speed);
  EXPECT_BITS(a.stiffness, b.stiffness);
  EXPECT_BITS(a.damping, b.damping);
  EXPECT_BITS(a.bounce_threshold, b.bounce_threshold);
  EXPECT_BITS(a.max_depenetration_speed, b.max_depenetration_speed);
  EXPECT_BITS(a.torsional_friction, b.torsional_friction);
}

void expect_same_step(const StepOptions& a, const StepOptions& b) {
  EXPECT_BITS(a.dt, b.dt);
  EXPECT_EQ(a.substeps, b.substeps);
  EXPECT_EQ(a.solver, b.solver);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.integrator, b.integrator);
  EXPECT_EQ(a.precision, b.precision);
  EXPECT_EQ(a.lanes, b.lanes);
  EXPECT_BITS(a.error_reduction, b.error_reduction);
  EXPECT_BITS(a.warm_start, b.warm_start);
  EXPECT_EQ(a.implicit_gyroscopic, b.implicit_gyroscopic);
  EXPECT_EQ(a.reset_on_fault, b.reset_on_fault);
  EXPECT_EQ(a.record_applied_torque, b.record_applied_torque);
  EXPECT_EQ(a.record_motion, b.record_motion);
  EXPECT_EQ(a.stages, b.stages);
  expect_same_contacts(a.contacts, b.contacts);
}

void expect_same_dof(const DofSettings& a, const DofSettings& b, const std::string& dof) {
  SCOPED_TRACE(dof);
  EXPECT_BITS(a.drive_stiffness, b.drive_stiffness);
  EXPECT_BITS(a.drive_damping, b.drive_damping);
  EXPECT_EQ(a.drive_type, b.drive_type);
  EXPECT_BITS(a.max_force, b.max_force);
  EXPECT_BITS(a.damping, b.damping);
  EXPECT_BITS(a.spring_stiffness, b.spring_stiffness);
  EXPECT_BITS(a.spring_rest, b.spring_rest);
  EXPECT_BITS(a.friction, b.friction);
  EXPECT_EQ(a.friction_model, b.friction_model);
  EXPECT_BITS(a.stiction_extra, b.stiction_extra);
  EXPECT_BITS(a.falloff_velocity, b.falloff_velocity);
  EXPECT_BITS(a.stribeck_velocity, b.stribeck_velocity);
  EXPECT_BITS(a.lower, b.lower);
  EXPECT_BITS(a.upper, b.upper);
  EXPECT_BITS(a.limit_stiffness, b.limit_stiffness);
  EXPECT_BITS(a.limit_damping, b.limit_damping);
  EXPECT_BITS(a.velocity_limit, b.velocity_limit);
}

void expect_same_randomization(const Randomization& a, const Randomization& b) {
  EXPECT_EQ(a.randomize_ground_friction, b.randomize_ground_friction);
  for (const RandomizationField& f : randomization_fields()) {
    SCOPED_TRACE(f.name);
    EXPECT_BITS((a.*f.range).low, (b.*f.range).low);
    EXPECT_BITS((a.*f.range).high, (b.*f.range).high);
  }
}

// Everything but the paths.
void expect_same_scene(const Scene& a, const Scene& b) {
  EXPECT_EQ(a.floating_base, b.floating_base);
  EXPECT_EQ(a.model.nq, b.model.nq);
  expect_bits(a.model.gravity, b.model.gravity, "gravity");
  EXPECT_EQ(a.model.body_gravity, b.model.body_gravity);
  ASSERT_EQ(a.env.step.actuators.size(), b.env.step.actuators.size());
  for (std::size_t i = 0; i < a.env.step.actuators.size(); ++i) {
    const Actuator &x = a.env.step.actuators[i], &y = b.env.step.actuators[i];
    EXPECT_EQ(std::tie(x.name, x.dof, x.gear, x.couplings, x.torque_constant, x.bus_voltage, x.resistance,
                       x.velocity_constant, x.peak_torque, x.enforce_operating_region),
              std::tie(y.name, y.dof, y.gear, y.couplings, y.torque_constant, y.bus_voltage, y.resistance,
                       y.velocity_constant, y.peak_torque, y.enforce_operating_region))
        << "actuator " << i;
  }
  ASSERT_EQ(a.model.fixed_tendons.size(), b.model.fixed_tendons.size());
  for (std::size_t i = 0; i < a.model.fixed_tendons.size(); ++i) {
    const FixedTendon &x = a.model.fixed_tendons[i], &y = b.model.fixed_tendons[i];
    EXPECT_EQ(x.name, y.name) << "fixed tendon " << i;
    ASSERT_EQ(x.joints.size(), y.joints.size()) << "fixed tendon " << i;
    for (std::size_t j = 0; j < x.joints.size(); ++j) {
      EXPECT_EQ(x.joints[j].dof, y.joints[j].dof) << "fixed tendon " << i << ", joint " << j;
      EXPECT_BITS(x.joints[j].coefficient, y.joints[j].coefficient);
    }
    for (const auto field : {&FixedTendon::stiffness, &FixedTendon::damping, &FixedTendon::rest_length,
                             &FixedTendon::offset, &FixedTendon::lower_limit, &FixedTendon::upper_limit,
                             &FixedTendon::limit_stiffness})
      EXPECT_BITS(x.*field, y.*field);
  }
  expect_same_step(a.env.step, b.env.step);
  ASSERT_EQ(a.env.dofs.size(), b.env.dofs.size());
  for (std::size_t k = 0; k < a.env.dofs.size(); ++k)
    expect_same_dof(a.env.dofs[k], b.env.dofs[k], a.model.dof_name[k]);
  EXPECT_EQ(a.env.action_mode, b.env.action_mode);
  EXPECT_EQ(a.env.control_steps, b.env.control_steps);
  EXPECT_EQ(a.env.episode_steps, b.env.episode_steps);
  EXPECT_EQ(a.env.auto_reset, b.env.auto_reset);
  EXPECT_EQ(a.env.seed, b.env.seed);
  expect_same_randomization(a.env.randomization, b.env.randomization);
  expect_bits(a.env.initial_q, b.env.initial_q, "initial_q");
  expect_bits(a.env.initial_v, b.env.initial_v, "initial_v");
  expect_bits(a.env.drive_target_q, b.env.drive_target_q, "drive_target_q");
}

// ---- scene files in a temporary folder

std::string json_string(const std::string& s) { return "\"" + s + "\""; }

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Randomisation ranges that differ per field: [0.5 + 0.1 i, 0.7 + 0.1 i].
std::string all_randomization_ranges() {
  std::string text;
  for (std::size_t i = 0; i < randomization_fields().size(); ++i)
    text += std::string(i ? ", " : "") + json_string(randomization_fields()[i].name) + ": [" +
            std::to_string(0.5 + 0.1 * i) + ", " + std::to_string(0.7 + 0.1 * i) + "]";
  return "{" + text + "}";
}

// Every key of the format, none at its default.
std::string full_scene(const std::string& model) {
  return R"({
  "model": )" + json_string(model) + R"(,
  "floating_base": true,
  "gravity": [0.1, 0, -9.7],
  "links_without_gravity": ["FL_shank", "base"],
  "fixed_tendons": [
    {"name": "front knees", "joints": {"FL_knee": 1, "FR_knee": -0.5}, "stiffness": 30, "damping": 0.5, "rest_length": 0.1,
     "offset": -0.05, "limits": [null, 0.4], "limit_stiffness": 200},
    {"name": "hind hip", "joints": {"HL_hip_flex": 2}, "limits": [-0.3, 0.2]}
  ],
  "initial_state": {
    "q": {"quadruped_root": [0.1, 0.2, 0.4, 0, 0, 0, 1], "FL_knee": -1.1, "HR_hip_flex": 0.3},
    "qd": {"quadruped_root": [0.1, 0, 0, 0, 0, 0.2], "FL_knee": 0.3}
  },
  "drive_targets": {"FL_knee": -1.3, "HR_hip_flex": 0.5},
  "ground": {"height": 0.05, "normal": [0, 0, 2], "friction": 0.7, "restitution": 0.1, "layers": 2, "collides_with": 3},
  "boxes": [
    {"size": [1, 2, 0.2], "position": [2, 0, 0.1], "rpy": [0, 0, 0.3], "friction": 0.9, "restitution": 0.2},
    {"size": [0.5, 0.5, 0.5], "rotation": [[0, -1, 0], [1, 0, 0], [0, 0, 1]], "layers": 4, "collides_with": 5}
  ],
  "contacts": {
    "enabled": true, "self_collision": true, "capacity": 24, "margin": 0.02, "speculative_speed": 0.25, "stiffness": 1e5, "damping": 300,
    "bounce_threshold": 0.3, "max_depenetration_speed": 0.5, "torsional_friction": 0.01,
    "links": {"FL_foot": {"friction": 1.2, "restitution": 0.05}, "base": {"layers": 6}},
    "enabled_pairs": [["FL_foot", "FR_foot"]],
    "disabled_pairs": [["base", "FL_thigh"], ["base", "HL_thigh"]]
  },
  "drives": {
    "default": {"kp": 50, "kd": 1.5, "type": "acceleration"},
    "joints": {"FL_knee": {"kp": 80, "kd": 2, "max_force": 40, "type": "force"}, "FR_knee": {"max_force": null}}
  },
  "joint_dynamics": {"default": {"damping": 0.1, "friction": 0}, "joints": {"HL_knee": {"friction": 0.3}}},
  "actuators": [
    {"name": "knee", "joint": "FL_knee", "gear": 9, "couplings": {"FL_hip_flex": 0.5, "FL_hip_abad": -0.25}, "torque_constant": 0.12,
     "bus_voltage": 48, "resistance": 0.3, "velocity_constant": 8, "peak_torque": 3.5, "enforce_operating_region": false},
    {"name": "hip", "joint": "HR_hip_flex", "torque_constant": 0.1, "bus_voltage": 24, "resistance": 1, "velocity_constant": 10, "peak_torque": null}
  ],
  "step": {
    "dt": 0.001, "substeps": 2, "solver": "tgs", "iterations": 8, "integrator": "trapezoid", "precision": "double",
    "lanes": "scalar", "error_reduction": 0.3, "warm_start": 0.5, "implicit_gyroscopic": false,
    "reset_on_fault": true, "record_applied_torque": true, "record_motion": true
  },
  "env": {"action_mode": "position_target", "control_steps": 4, "episode_steps": 1000, "auto_reset": false, "seed": 7},
  "randomization": )" + all_randomization_ranges() + R"(
})";
}

class SceneFile : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::replace(test.begin(), test.end(), '/', '_');  // parameterised tests
    dir_ = fs::temp_directory_path() / ("lockstep_scene_test_" + std::to_string(::getpid()) + "_" + test);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& text) const {
    const fs::path path = dir_ / name;
    fs::create_directories(path.parent_path());
    std::ofstream(path) << text;
    return path.string();
  }

  // The error load_scene gives for `text`, or "(no error)".
  std::string error_of(const std::string& text) const {
    try {
      load_scene(write("bad.json", text));
    } catch (const SceneError& e) {
      return e.what();
    }
    return "(no error)";
  }

  fs::path dir_;
};

int dof(const Model& model, const std::string& joint) { return model.body_dof_offset[model.joint_index(joint)]; }

// ---- every key, defaults

TEST_F(SceneFile, EveryKeyLandsInItsField) {
  const Scene s = load_scene(write("full.json", full_scene(fs::absolute(kQuadruped).string())));
  const Model& m = s.model;
  const VecEnvOptions& e = s.env;
  EXPECT_EQ(s.source, (dir_ / "full.json").string());
  EXPECT_EQ(s.model_path, fs::absolute(kQuadruped).lexically_normal().string());
  EXPECT_TRUE(s.floating_base);
  ASSERT_EQ(m.body_joint[0], JointType::Free);
  EXPECT_EQ(m.gravity, Eigen::Vector3d(0.1, 0, -9.7));
  for (int b = 0; b < m.nbody; ++b) {
    const std::string& link = m.frame_name[m.body_frame[b]];
    EXPECT_EQ(m.body_gravity[b], link == "FL_shank" || link == "base" ? 0 : 1) << link;
  }
  // fixed tendons: in order, joints by name in the file's order, the
  // defaults where not given
  ASSERT_EQ(m.fixed_tendons.size(), 2u);
  const FixedTendon& knees = m.fixed_tendons[0];
  EXPECT_EQ(knees.name, "front knees");
  ASSERT_EQ(knees.joints.size(), 2u);
  EXPECT_EQ(knees.joints[0].dof, dof(m, "FL_knee"));
  EXPECT_EQ(knees.joints[0].coefficient, 1);
  EXPECT_EQ(knees.joints[1].dof, dof(m, "FR_knee"));
  EXPECT_EQ(knees.joints[1].coefficient, -0.5);
  EXPECT_EQ(std::tie(knees.stiffness, knees.damping, knees.rest_length, knees.offset, knees.upper_limit,
                     knees.limit_stiffness),
            std::make_tuple(30.0, 0.5, 0.1, -0.05, 0.4, 200.0));
  EXPECT_EQ(knees.lower_limit, -Model::kInfinity);
  const FixedTendon& hind = m.fixed_tendons[1];
  ASSERT_EQ(hind.joints.size(), 1u);
  EXPECT_EQ(hind.joints[0].dof, dof(m, "HL_hip_flex"));
  EXPECT_EQ(std::tie(hind.stiffness, hind.damping, hind.rest_length, hind.offset, hind.lower_limit, hind.upper_limit,
                     hind.limit_stiffness),
            std::make_tuple(0.0, 0.0, 0.0, 0.0, -0.3, 0.2, 0.0));
  // actuators: in order, joints by name, the defaults where not given
  ASSERT_EQ(e.step.actuators.size(), 2u);
  const Actuator& knee = e.step.actuators[0];
  EXPECT_EQ(knee.name, "knee");
  EXPECT_EQ(knee.dof, dof(m, "FL_knee"));
  EXPECT_EQ(knee.gear, 9);
  EXPECT_EQ(knee.couplings,
            (std::vector<std::pair<int, double>>{{dof(m, "FL_hip_flex"), 0.5}, {dof(m, "FL_hip_abad"), -0.25}}));
  EXPECT_EQ(std::tie(knee.torque_constant, knee.bus_voltage, knee.resistance, knee.velocity_constant, knee.peak_torque),
            std::make_tuple(0.12, 48.0, 0.3, 8.0, 3.5));
  EXPECT_FALSE(knee.enforce_operating_region);
  const Actuator& hip = e.step.actuators[1];
  EXPECT_EQ(hip.gear, 1);
  EXPECT_TRUE(hip.couplings.empty());
  EXPECT_EQ(hip.peak_torque, Model::kInfinity);
  EXPECT_TRUE(hip.enforce_operating_region);

  // initial state: given joints set, the others neutral, at rest
  Eigen::VectorXd q0 = m.neutral_configuration();
  q0.head<7>() << 0.1, 0.2, 0.4, 0, 0, 0, 1;
  q0[m.body_q_offset[m.joint_index("FL_knee")]] = -1.1;
  q0[m.body_q_offset[m.joint_index("HR_hip_flex")]] = 0.3;
  EXPECT_EQ(e.initial_q, q0);
  Eigen::VectorXd v0 = Eigen::VectorXd::Zero(m.nv);
  v0[0] = 0.1;
  v0[5] = 0.2;
  v0[dof(m, "FL_knee")] = 0.3;
  EXPECT_EQ(e.initial_v, v0);
  // drive targets: given joints set, the others neutral
  Eigen::VectorXd targets = m.neutral_configuration();
  targets[m.body_q_offset[m.joint_index("FL_knee")]] = -1.3;
  targets[m.body_q_offset[m.joint_index("HR_hip_flex")]] = 0.5;
  EXPECT_EQ(e.drive_target_q, targets);

  // ground and boxes
  const ContactSettings& c = e.step.contacts;
  EXPECT_TRUE(c.ground);
  EXPECT_EQ(c.ground_height, 0.05);
  EXPECT_EQ(c.ground_normal, Eigen::Vector3d(0, 0, 1));  // normalised
  EXPECT_EQ(c.ground_contact.friction, 0.7);
  EXPECT_EQ(c.ground_contact.restitution, 0.1);
  EXPECT_EQ(c.ground_contact.layers, 2u);
  EXPECT_EQ(c.ground_contact.collides_with, 3u);
  ASSERT_EQ(c.boxes.size(), 2u);
  EXPECT_EQ(c.boxes[0].half_extents, Eigen::Vector3d(0.5, 1, 0.1));
  EXPECT_EQ(c.boxes[0].pose.translation(), Eigen::Vector3d(2, 0, 0.1));
  EXPECT_TRUE(c.boxes[0].pose.linear().isApprox(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix()));
  EXPECT_EQ(c.boxes[0].contact.friction, 0.9);
  EXPECT_EQ(c.boxes[0].contact.restitution, 0.2);
  EXPECT_EQ(c.boxes[1].half_extents, Eigen::Vector3d::Constant(0.25));
  EXPECT_TRUE(c.boxes[1].pose.translation().isZero());
  Eigen::Matrix3d quarter_turn;
  quarter_turn << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  EXPECT_EQ(c.boxes[1].pose.linear(), quarter_turn);
  EXPECT_EQ(c.boxes[1].contact.friction, 1.0);
  EXPECT_EQ(c.boxes[1].contact.layers, 4u);
  EXPECT_EQ(c.boxes[1].contact.collides_with, 5u);

  // contact parameters, per-link surfaces, filters
  EXPECT_EQ(e.step.stages[static_cast<int>(Stage::Contacts)], StageMode::Auto);
  EXPECT_EQ(c.self_collision, std::vector<bool>{true});
  EXPECT_EQ(c.capacity, 24);
  EXPECT_EQ(c.margin, 0.02);
  EXPECT_EQ(c.speculative_speed, 0.25);
  EXPECT_EQ(c.stiffness, 1e5);
  EXPECT_EQ(c.damping, 300);
  EXPECT_EQ(c.bounce_threshold, 0.3);
  EXPECT_EQ(c.max_depenetration_speed, 0.5);
  EXPECT_EQ(c.torsional_friction, 0.01);
  ASSERT_EQ(c.shapes.size(), m.shapes.size());
  for (std::size_t i = 0; i < m.shapes.size(); ++i) {
    const std::string& link = m.frame_name[m.shapes[i].frame];
    SCOPED_TRACE(link);
    EXPECT_EQ(c.shapes[i].friction, link == "FL_foot" ? 1.2 : 1.0);
    EXPECT_EQ(c.shapes[i].restitution, link == "FL_foot" ? 0.05 : 0.0);
    EXPECT_EQ(c.shapes[i].layers, link == "base" ? 6u : 1u);
  }
  using Pairs = std::vector<std::pair<std::string, std::string>>;
  EXPECT_EQ(c.enabled_pairs, (Pairs{{"FL_foot", "FR_foot"}}));
  EXPECT_EQ(c.disabled_pairs, (Pairs{{"base", "FL_thigh"}, {"base", "HL_thigh"}}));

  // drives and joint dynamics: default on every non-root DOF, then by joint
  const std::vector<DofSettings> defaults = default_dof_settings(m);
  ASSERT_EQ(e.dofs.size(), static_cast<std::size_t>(m.nv));
  for (int k = 0; k < m.nv; ++k) {
    const DofSettings& d = e.dofs[k];
    const std::string& name = m.dof_name[k];
    SCOPED_TRACE(name);
    if (k < 6) {  // the floating root keeps the model's defaults
      expect_same_dof(d, defaults[k], name);
      continue;
    }
    EXPECT_EQ(d.drive_stiffness, name == "FL_knee" ? 80 : 50);
    EXPECT_EQ(d.drive_damping, name == "FL_knee" ? 2 : 1.5);
    EXPECT_EQ(d.drive_type, name == "FL_knee" ? DriveType::Force : DriveType::Acceleration);
    EXPECT_EQ(d.max_force, name == "FL_knee" ? 40 : name == "FR_knee" ? Model::kInfinity : defaults[k].max_force);
    EXPECT_EQ(d.damping, 0.1);
    EXPECT_EQ(d.friction, name == "HL_knee" ? 0.3 : 0.0);
    EXPECT_EQ(d.lower, defaults[k].lower);  // the URDF's limits are kept
    EXPECT_EQ(d.velocity_limit, defaults[k].velocity_limit);
  }

  // step and environment
  EXPECT_EQ(e.step.dt, 0.001);
  EXPECT_EQ(e.step.substeps, 2);
  EXPECT_EQ(e.step.solver, SolverType::TGS);
  EXPECT_EQ(e.step.iterations, 8);
  EXPECT_EQ(e.step.integrator, Integrator::Trapezoid);
  EXPECT_EQ(e.step.precision, Precision::Double);
  EXPECT_EQ(e.step.lanes, Lanes::Scalar);
  EXPECT_EQ(e.step.error_reduction, 0.3);
  EXPECT_EQ(e.step.warm_start, 0.5);
  EXPECT_FALSE(e.step.implicit_gyroscopic);
  EXPECT_TRUE(e.step.reset_on_fault);
  EXPECT_TRUE(e.step.record_applied_torque);
  EXPECT_TRUE(e.step.record_motion);
  EXPECT_EQ(e.action_mode, ActionMode::PositionTarget);
  EXPECT_EQ(e.control_steps, 4);
  EXPECT_EQ(e.episode_steps, 1000);
  EXPECT_FALSE(e.auto_reset);
  EXPECT_EQ(e.seed, 7u);

  // every randomisation range by its name
  EXPECT_TRUE(e.randomization.randomize_ground_friction);
  for (std::size_t i = 0; i < randomization_fields().size(); ++i) {
    const UniformRange& r = e.randomization.*randomization_fields()[i].range;
    EXPECT_EQ(r.low, std::stod(std::to_string(0.5 + 0.1 * i))) << randomization_fields()[i].name;
    EXPECT_EQ(r.high, std::stod(std::to_string(0.7 + 0.1 * i))) << randomization_fields()[i].name;
  }
}

TEST_F(SceneFile, AbsentKeysKeepTheDefaults) {
  write("quadruped.urdf", read_text(kQuadruped));
  const Scene s = load_scene(write("minimal.json", R"({"model": "quadruped.urdf"})"));
  const Scene bare = scene_from_urdf(kQuadruped, false, false);
  EXPECT_EQ(s.model_path, (dir_ / "quadruped.urdf").string());
  EXPECT_FALSE(s.floating_base);
  EXPECT_EQ(s.model.nv, 12);
  EXPECT_EQ(s.model.gravity, Model().gravity);
  EXPECT_TRUE(s.warnings.empty());
  const VecEnvOptions defaults;
  EXPECT_EQ(s.env.initial_q.size(), 0);  // the neutral configuration at rest
  EXPECT_EQ(s.env.initial_v.size(), 0);
  EXPECT_FALSE(s.env.step.contacts.ground);
  EXPECT_TRUE(s.env.step.contacts.shapes.empty());
  EXPECT_TRUE(s.env.randomization.is_identity());
  EXPECT_EQ(s.env.action_mode, defaults.action_mode);
  EXPECT_EQ(s.env.control_steps, defaults.control_steps);
  EXPECT_EQ(s.env.episode_steps, defaults.episode_steps);
  EXPECT_EQ(s.env.auto_reset, defaults.auto_reset);
  EXPECT_EQ(s.env.seed, defaults.seed);
  // the same options as the bare URDF: StepOptions{} and default_dof_settings
  expect_same_step(s.env.step, defaults.step);
  expect_same_scene(s, bare);
}

TEST_F(SceneFile, ModelPathIsRelativeToTheSceneFile) {
  write("robots/quadruped.urdf", read_text(kQuadruped));
  const Scene s = load_scene(write("scenes/deep/s.json", R"({"model": "../../robots/./quadruped.urdf"})"));
  EXPECT_EQ(s.model_path, (dir_ / "robots" / "quadruped.urdf").string());
  EXPECT_EQ(s.model.nv, 12);
}

TEST_F(SceneFile, BareUrdfHasNoGroundUnlessAsked) {
  const Scene plain = scene_from_urdf(kQuadruped, true, false);
  EXPECT_EQ(plain.source, kQuadruped);
  EXPECT_EQ(plain.model_path, kQuadruped);
  EXPECT_TRUE(plain.floating_base);
  EXPECT_EQ(plain.model.nv, 18);
  EXPECT_FALSE(plain.env.step.contacts.ground);
  ASSERT_EQ(plain.env.dofs.size(), 18u);
  const std::vector<DofSettings> defaults = default_dof_settings(plain.model);
  for (int k = 0; k < 18; ++k) expect_same_dof(plain.env.dofs[k], defaults[k], plain.model.dof_name[k]);

  const Scene grounded = scene_from_urdf(kQuadruped, false, true);
  const ContactSettings c = grounded.env.step.contacts;
  EXPECT_TRUE(c.ground);
  EXPECT_EQ(c.ground_height, 0.0);
  EXPECT_EQ(c.ground_normal, Eigen::Vector3d::UnitZ());
  EXPECT_EQ(c.ground_contact.friction, ShapeContact().friction);
  EXPECT_EQ(grounded.env.step.stages[static_cast<int>(Stage::Contacts)], StageMode::Auto);
}

// A joint position outside its limits (degrees where radians are meant,
// say) is a warning naming the key; positions within limits give none.
TEST_F(SceneFile, PositionsOutsideTheJointLimitsAreWarnedAbout) {
  const std::string model = json_string(fs::absolute(kQuadruped).string());
  const Scene bad = load_scene(write("degrees.json", "{\"model\": " + model +
                                                        R"(, "initial_state": {"q": {"FL_knee": -90, "FR_knee": -1.6}},)"
                                                        R"( "drive_targets": {"HL_knee": 45}})"));
  ASSERT_EQ(bad.value_warnings.size(), 2u);
  EXPECT_NE(bad.value_warnings[0].find("degrees.json: initial_state.q.FL_knee: -90 lies outside the joint's limits "
                                       "[-2.7, -0.3] (radians)"),
            std::string::npos)
      << bad.value_warnings[0];
  EXPECT_NE(bad.value_warnings[1].find("drive_targets.HL_knee: 45 lies outside"), std::string::npos)
      << bad.value_warnings[1];
  EXPECT_EQ(bad.env.initial_q[bad.model.body_q_offset[bad.model.joint_index("FL_knee")]], -90) << "kept as written";
  const Scene good = load_scene(write("radians.json", "{\"model\": " + model +
                                                         R"(, "initial_state": {"q": {"FL_knee": -1.6}}})"));
  EXPECT_TRUE(good.value_warnings.empty());
}

TEST_F(SceneFile, LoadSceneOrUrdfPicksByExtensionAndOverridesOnlyWhenTrue) {
  const std::string model = json_string(fs::absolute(kQuadruped).string());
  const std::string fixed = write("fixed.json", "{\"model\": " + model + "}");
  const std::string grounded =
      write("grounded.json", "{\"model\": " + model + ", \"floating_base\": true, \"ground\": {\"height\": 0.3}}");

  const Scene urdf = load_scene_or_urdf(kQuadruped, true, true);
  EXPECT_EQ(urdf.source, kQuadruped);
  EXPECT_TRUE(urdf.floating_base);
  EXPECT_TRUE(urdf.env.step.contacts.ground);

  EXPECT_FALSE(load_scene_or_urdf(fixed, false, false).floating_base);
  EXPECT_FALSE(load_scene_or_urdf(fixed, false, false).env.step.contacts.ground);
  const Scene overridden = load_scene_or_urdf(fixed, true, true);
  EXPECT_EQ(overridden.source, fixed);
  EXPECT_TRUE(overridden.floating_base);
  EXPECT_EQ(overridden.model.body_joint[0], JointType::Free);
  EXPECT_TRUE(overridden.env.step.contacts.ground);
  EXPECT_EQ(overridden.env.step.contacts.ground_height, 0.0);

  // false never overrides the file; true keeps the file's own ground
  const Scene kept = load_scene_or_urdf(grounded, false, true);
  EXPECT_TRUE(kept.floating_base);
  EXPECT_EQ(kept.env.step.contacts.ground_height, 0.3);
}

TEST_F(SceneFile, DisableContactsForcesTheStageOff) {
  Scene s = load_scene(kModelsDir + "/quadruped_scene.json");
  disable_contacts(s);
  EXPECT_EQ(s.env.step.stages[static_cast<int>(Stage::Contacts)], StageMode::Off);
  EXPECT_TRUE(s.env.step.contacts.ground);  // kept, but not simulated
  const Scene back = load_scene(write("back.json", scene_to_json(s)));
  EXPECT_EQ(back.env.step.stages[static_cast<int>(Stage::Contacts)], StageMode::Off);
  const Scene off = load_scene(write("off.json", "{\"model\": " + json_string(fs::absolute(kQuadruped).string()) +
                                                     ", \"contacts\": {\"enabled\": false}}"));
  EXPECT_EQ(off.env.step.stages[static_cast<int>(Stage::Contacts)], StageMode::Off);
}

// ---- the JSON round trip

TEST_F(SceneFile, ToJsonReadsBackToTheSameScene) {
  const Scene first = load_scene(write("full.json", full_scene(fs::absolute(kQuadruped).string())));
  const std::string text = scene_to_json(first);
  const Scene second = load_scene(write("written/elsewhere.json", text));
  expect_same_scene(first, second);
  EXPECT_EQ(second.model_path, first.model_path);
  EXPECT_EQ(scene_to_json(second), text);
  EXPECT_NE(text.find("\"model\": " + json_string(fs::absolute(kQuadruped).lexically_normal().string())),
            std::string::npos);
}

TEST_F(SceneFile, ToJsonKeepsEveryBitOfAProgrammaticScene) {
  Scene s = scene_from_urdf(kQuadruped, true, true);
  const Model& m = s.model;
  VecEnvOptions& e = s.env;
  // values without a short decimal form, a tilted normal, a rotated box
  e.step.dt = 1.0 / 300.0;
  e.step.contacts.ground_normal = Eigen::Vector3d(0.1, -0.2, 1.0).normalized();
  e.step.contacts.ground_contact.friction = 2.0 / 3.0;
  StaticBox box;
  box.pose = Eigen::Translation3d(0.1, 1.0 / 7.0, -0.3) * Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized());
  box.half_extents = Eigen::Vector3d(0.1, 1e-3, std::sqrt(2.0));
  e.step.contacts.boxes.push_back(box);
  e.dofs[dof(m, "FL_knee")].drive_stiffness = std::acos(-1.0);
  e.dofs[dof(m, "FL_knee")].max_force = Model::kInfinity;
  e.dofs[dof(m, "HR_hip_abad")].damping = 1e-300;
  e.seed = 18446744073709551557u;  // from 2^53 on: written as a string
  e.randomization.com_offset = {-1.0 / 3.0, 1.0 / 3.0};
  e.initial_q = m.neutral_configuration();
  e.initial_q.head<3>() << 0.1, 0.2, 1.0 / 3.0;
  e.initial_q[m.body_q_offset[m.joint_index("FR_knee")]] = -std::exp(0.1);
  e.initial_v = Eigen::VectorXd::LinSpaced(m.nv, -1.0 / 3.0, 1.0 / 7.0);

  const Scene back = load_scene(write("s.json", scene_to_json(s)));
  expect_same_scene(s, back);
}

// VecEnvOptions may set initial_q alone: the velocity is written as rest.
TEST_F(SceneFile, ToJsonWritesAMissingInitialVelocityAsRest) {
  Scene s = scene_from_urdf(kQuadruped, false, false);
  s.env.initial_q = Eigen::VectorXd::Constant(s.model.nq, -0.5);
  const Scene back = load_scene(write("s.json", scene_to_json(s)));
  EXPECT_EQ(back.env.initial_q, s.env.initial_q);
  EXPECT_EQ(back.env.initial_v, Eigen::VectorXd::Zero(s.model.nv));
}

// The seeds on either side of 2^53 (a number below it, a string from it on)
// read back as written.
TEST_F(SceneFile, SeedsAroundTwoToThe53RoundTrip) {
  Scene s = scene_from_urdf(kQuadruped, false, false);
  for (std::uint64_t seed : {(std::uint64_t{1} << 53) - 1, std::uint64_t{1} << 53, (std::uint64_t{1} << 53) + 1}) {
    s.env.seed = seed;
    EXPECT_EQ(load_scene(write("s.json", scene_to_json(s))).env.seed, seed);
  }
}

TEST_F(SceneFile, ToJsonRefusesWhatTheFormatCannotHold) {
  const Scene base = scene_from_urdf(kQuadruped, true, false);
  const int knee = dof(base.model, "FL_knee");
  Scene spring = base;
  spring.env.dofs[knee].spring_stiffness = 3;
  EXPECT_THROW(scene_to_json(spring), std::invalid_argument);
  Scene root_drive = base;
  root_drive.env.dofs[0].damping = 1;
  EXPECT_THROW(scene_to_json(root_drive), std::invalid_argument);
  Scene forced = base;
  forced.env.step.force(Stage::Drives, StageMode::On);
  EXPECT_THROW(scene_to_json(forced), std::invalid_argument);
  Scene wrong_size = base;
  wrong_size.env.initial_q = Eigen::VectorXd::Zero(3);
  EXPECT_THROW(scene_to_json(wrong_size), std::invalid_argument);
}

// ---- the bundled scenes

// The lowest point of every shape of the model in configuration q: sphere,
// capsule, box and cylinder exactly.
double lowest_point(const Model& model, const Eigen::VectorXd& q) {
  const std::vector<Eigen::Isometry3d> bodies = CopyDynamics(model).body_poses(q);
  double lowest = Model::kInfinity;
  for (const Shape& s : model.shapes) {
    const Eigen::Isometry3d pose = (s.body >= 0 ? bodies[s.body] : Eigen::Isometry3d::Identity()) * s.pose;
    const double z = pose.translation().z();
    const Eigen::Vector3d up = pose.linear().row(2).transpose();  // world z in the shape's axes
    double depth = 0;  // how far the shape reaches below its centre
    switch (s.type) {
      case ShapeType::Sphere: depth = s.size.x(); break;
      case ShapeType::Capsule: depth = s.size.x() + s.size.y() * std::abs(up.z()); break;
      case ShapeType::Box: depth = s.size.cwiseProduct(up.cwiseAbs()).sum(); break;
      case ShapeType::Cylinder:
        depth = s.size.y() * std::abs(up.z()) + s.size.x() * std::sqrt(std::max(0.0, 1 - up.z() * up.z()));
        break;
      case ShapeType::Mesh: continue;
    }
    lowest = std::min(lowest, z - depth);
  }
  return lowest;
}

// With a ground, a bare URDF with a floating base starts with its lowest
// shape on the ground (neutral pose), not inside it.
TEST(SceneFileBundled, AFloatingUrdfOnTheGroundStartsTouchingIt) {
  for (const std::string& path : {kQuadruped, std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/anymal_b.urdf",
                                  std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/talos_reduced.urdf"}) {
    const Scene s = scene_from_urdf(path, true, true);
    ASSERT_EQ(s.env.initial_q.size(), s.model.nq) << path;
    EXPECT_GT(s.env.initial_q[2], 0.1) << path;
    EXPECT_NEAR(lowest_point(s.model, s.env.initial_q), 0.0, 1e-12) << path;
    Eigen::VectorXd neutral = s.model.neutral_configuration();
    neutral[2] = s.env.initial_q[2];
    EXPECT_EQ(s.env.initial_q, neutral) << path << ": only the root's height moves";
    EXPECT_EQ(scene_from_urdf(path, true, false).env.initial_q.size(), 0) << "no ground: neutral, as before";
  }
}

// An initial state that starts a shape more than 1 cm inside the ground
// is a warning naming the shape and the depth: a fixed base at the
// plane's height, or a floating root a scene file leaves at z = 0.
TEST_F(SceneFile, AStartInsideTheGroundIsWarnedAbout) {
  auto expect_warning = [](const Scene& s, const std::string& hint) {
    const std::optional<std::string> warning = ground_start_warning(s);
    ASSERT_TRUE(warning) << s.source;
    const std::string& w = *warning;
    EXPECT_EQ(w.find(s.source + ": the initial state puts "), 0u) << w;
    EXPECT_NE(w.find("(sphere, shape "), std::string::npos) << w;  // the bundled quadruped's feet
    EXPECT_NE(w.find(" m inside the ground; its contacts will push it out at up to 1 m/s"), std::string::npos) << w;
    EXPECT_NE(w.find(hint), std::string::npos) << w;
    EXPECT_TRUE(s.value_warnings.empty()) << "not a value the file gave";
  };
  Scene fixed = scene_from_urdf(kQuadruped, false, true);
  expect_warning(fixed, "(the base is fixed: with a floating base");
  // derived from the scene as it is: none without contacts
  disable_contacts(fixed);
  EXPECT_FALSE(ground_start_warning(fixed));
  const std::string model = json_string(fs::absolute(kQuadruped).string());
  Scene at_zero = load_scene(write("at_zero.json", "{\"model\": " + model + R"(, "floating_base": true, "ground": {}})"));
  expect_warning(at_zero, "(initial_state.q sets the root's height)");
  // lifted to where it touches: none
  at_zero.env.initial_q = at_zero.model.neutral_configuration();
  at_zero.env.initial_q[2] = *resting_root_height(at_zero.model, at_zero.env.initial_q);
  EXPECT_FALSE(ground_start_warning(at_zero));
  // standing on the ground, or no ground: nothing to say
  EXPECT_FALSE(ground_start_warning(scene_from_urdf(kQuadruped, true, true)));
  EXPECT_FALSE(ground_start_warning(scene_from_urdf(kQuadruped, false, false)));
  EXPECT_FALSE(ground_start_warning(load_scene(kModelsDir + "/quadruped_scene.json")));
}

TEST(SceneFileBundled, QuadrupedStartsStandingJustAboveTheGround) {
  const Scene s = load_scene(kModelsDir + "/quadruped_scene.json");
  EXPECT_TRUE(s.floating_base);
  EXPECT_TRUE(s.warnings.empty());
  const VecEnvOptions& e = s.env;
  EXPECT_TRUE(e.step.contacts.ground);
  EXPECT_EQ(e.step.contacts.ground_height, 0.0);
  EXPECT_EQ(e.step.contacts.ground_contact.friction, 0.8);
  EXPECT_EQ(e.step.dt, 0.002);
  EXPECT_EQ(e.action_mode, ActionMode::PositionTarget);
  EXPECT_EQ(e.control_steps, 4);
  EXPECT_EQ(e.episode_steps, 500);
  EXPECT_EQ(e.randomization.mass_scale.low, 0.9);
  EXPECT_EQ(e.randomization.mass_scale.high, 1.1);
  EXPECT_TRUE(e.randomization.randomize_ground_friction);
  EXPECT_EQ(e.randomization.joint_position_noise.high, 0.05);
  for (int k = 6; k < s.model.nv; ++k) EXPECT_GT(e.dofs[k].drive_stiffness, 0) << s.model.dof_name[k];

  const double clearance = lowest_point(s.model, e.initial_q);
  EXPECT_GE(clearance, 0.002);
  EXPECT_LE(clearance, 0.005);
  // the lowest points are the four feet
  for (const char* foot : {"FL_foot", "FR_foot", "HL_foot", "HR_foot"}) {
    const Eigen::Isometry3d pose = CopyDynamics(s.model).frame_poses(e.initial_q)[s.model.frame_index(foot)];
    EXPECT_NEAR(pose.translation().z() - 0.025, clearance, 1e-12) << foot;
  }
}

// Holding its initial pose as drive target, the quadruped lands on its feet
// and stands still within 2 s: the base about 1 cm lower, joints within
// 0.05 rad of the pose.
TEST(SceneFileBundled, QuadrupedStandsOnItsDrives) {
  const Scene s = load_scene(kModelsDir + "/quadruped_scene.json");
  Simulator sim(s.model, 1, s.env.step, s.env.dofs);
  sim.set_state_all(s.env.initial_q, s.env.initial_v);
  sim.set_drive_target(0, s.env.initial_q, Eigen::VectorXd::Zero(s.model.nv));
  sim.step(1000);  // 2 s
  ASSERT_EQ(sim.fault(0), Fault::None);
  const Eigen::VectorXd q = sim.q(0);
  EXPECT_NEAR(q[2], s.env.initial_q[2], 0.015);
  EXPECT_LT((q.tail(12) - s.env.initial_q.tail(12)).cwiseAbs().maxCoeff(), 0.05);
  EXPECT_LT(sim.v(0).norm(), 1e-3);
}

TEST(SceneFileBundled, AnymalExampleStartsJustAboveTheGround) {
  if (!fs::exists(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/anymal_b.urdf")) GTEST_SKIP() << "no shared models";
  const Scene s = load_scene(kDataDir + "/scene_anymal_b.json");
  EXPECT_TRUE(s.floating_base);
  EXPECT_EQ(fs::path(s.model_path).filename(), "anymal_b.urdf");
  const double clearance = lowest_point(s.model, s.env.initial_q);
  EXPECT_GE(clearance, 0.002);
  EXPECT_LE(clearance, 0.005);
}

// The JSON examples of docs/scenes.md: the two bundled scenes verbatim, and
// the one with every key loads (its model path made absolute).
TEST_F(SceneFile, DocumentedExamplesAreTheFilesAndLoad) {
  const std::string doc = read_text(kModelsDir + "/../docs/scenes.md");
  std::vector<std::string> blocks;
  for (std::size_t at = doc.find("```json\n"); at != std::string::npos; at = doc.find("```json\n", at)) {
    at += 8;
    blocks.push_back(doc.substr(at, doc.find("```", at) - at));
  }
  ASSERT_EQ(blocks.size(), 3u);
  EXPECT_EQ(blocks[0], read_text(kModelsDir + "/quadruped_scene.json"));
  EXPECT_EQ(blocks[1], read_text(kDataDir + "/scene_anymal_b.json"));
  std::string every_key = blocks[2];
  const std::string relative = "\"../models/quadruped.urdf\"";
  ASSERT_NE(every_key.find(relative), std::string::npos);
  every_key.replace(every_key.find(relative), relative.size(), json_string(fs::absolute(kQuadruped).string()));
  const Scene s = load_scene(write("every_key.json", every_key));
  EXPECT_EQ(s.env.dofs[dof(s.model, "FL_knee")].max_force, 40);
  EXPECT_EQ(s.env.step.contacts.boxes.size(), 2u);
}

// ---- bad input: each names the file and the key path

struct BadScene {
  const char* name;
  std::string members;                   // after "model": the quadruped's path, floating base
  std::vector<std::string> pieces;       // each must appear in the message
};

std::ostream& operator<<(std::ostream& out, const BadScene& c) { return out << c.name; }

class SceneFileErrors : public SceneFile, public ::testing::WithParamInterface<BadScene> {};

TEST_P(SceneFileErrors, NameFileAndKey) {
  const std::string text = "{\"model\": " + json_string(fs::absolute(kQuadruped).string()) +
                           ", \"floating_base\": true" + GetParam().members + "}";
  const std::string message = error_of(text);
  EXPECT_NE(message.find("bad.json"), std::string::npos) << message;
  for (const std::string& piece : GetParam().pieces)
    EXPECT_NE(message.find(piece), std::string::npos) << "message '" << message << "' lacks '" << piece << "'";
}

INSTANTIATE_TEST_SUITE_P(
    SceneFile, SceneFileErrors,
    ::testing::Values(
        BadScene{"unknown_top_key", R"(, "modle": 1)",
                 {"bad.json: modle: unknown key (did you mean \"model\"?) (expected one of: model,"}},
        BadScene{"unknown_key_far_from_any", R"(, "zzzzzz": 1)", {"zzzzzz: unknown key (expected one of: model,"}},
        BadScene{"unknown_nested_key", R"(, "contacts": {"margn": 0.1})",
                 {"contacts.margn: unknown key (did you mean \"margin\"?)"}},
        BadScene{"unknown_step_key", R"(, "step": {"solverr": "pgs"})", {"step.solverr: unknown key"}},
        BadScene{"wrong_type", R"(, "step": {"dt": "fast"})", {"step.dt: expected a number, got string"}},
        BadScene{"wrong_type_bool", R"(, "env": {"auto_reset": 1})", {"env.auto_reset: expected true or false"}},
        BadScene{"wrong_section_type", R"(, "ground": true)", {"ground: expected an object, got boolean"}},
        BadScene{"not_finite", R"(, "ground": {"friction": NaN})", {"ground.friction: value is not finite"}},
        BadScene{"not_finite_in_array", R"(, "gravity": [0, 0, -Infinity])", {"gravity[2]: value is not finite"}},
        BadScene{"negative_dt", R"(, "step": {"dt": -0.002})", {"step.dt: must be > 0, got -0.002"}},
        BadScene{"zero_substeps", R"(, "step": {"substeps": 0})", {"step.substeps: must lie in [1, "}},
        BadScene{"fractional_iterations", R"(, "step": {"iterations": 2.5})", {"step.iterations: expected an integer"}},
        BadScene{"unknown_solver", R"(, "step": {"solver": "jacobi"})",
                 {"step.solver: unknown value \"jacobi\" (expected one of: \"pgs\", \"tgs\")"}},
        BadScene{"unknown_integrator", R"(, "step": {"integrator": "euler"})", {"step.integrator: unknown value"}},
        BadScene{"misspelled_solver", R"(, "step": {"solver": "TGS"})",
                 {"step.solver: unknown value \"TGS\" (did you mean \"tgs\"?)"}},
        BadScene{"unknown_action_mode", R"(, "env": {"action_mode": "velocity"})", {"env.action_mode: unknown value"}},
        BadScene{"negative_episode_steps", R"(, "env": {"episode_steps": -1})", {"env.episode_steps: must lie in [0,"}},
        BadScene{"negative_seed", R"(, "env": {"seed": -1})", {"env.seed: must lie in [0,"}},
        BadScene{"bad_seed_string", R"(, "env": {"seed": "12x"})", {"env.seed: expected an integer in [0, 2^64)"}},
        // 2^53 + 1 as a number reads as 2^53: it was loaded as another seed
        BadScene{"rounded_seed", R"(, "env": {"seed": 9007199254740993})", {"env.seed: a seed from 2^53 on must be"}},
        BadScene{"drive_unknown_joint", R"(, "drives": {"joints": {"knee": {"kp": 1}}})",
                 {"drives.joints.knee: unknown joint \"knee\""}},
        BadScene{"drive_misspelled_joint", R"(, "drives": {"joints": {"fl_knie": {"kp": 1}}})",
                 {"drives.joints.fl_knie: unknown joint \"fl_knie\" (did you mean \"FL_knee\"?)"}},
        BadScene{"drive_fixed_joint", R"(, "drives": {"joints": {"FL_foot_fixed": {"kp": 1}}})",
                 {"drives.joints.FL_foot_fixed: joint \"FL_foot_fixed\" is fixed"}},
        BadScene{"drive_floating_root", R"(, "drives": {"joints": {"quadruped_root": {"kp": 1}}})",
                 {"drives.joints.quadruped_root: joint \"quadruped_root\" is the floating base"}},
        BadScene{"drive_negative_gain", R"(, "drives": {"default": {"kd": -1}})", {"drives.default.kd: must be >= 0"}},
        BadScene{"drive_zero_max_force", R"(, "drives": {"joints": {"FL_knee": {"max_force": 0}}})",
                 {"drives.joints.FL_knee.max_force: must be > 0"}},
        BadScene{"drive_unknown_type", R"(, "drives": {"default": {"type": "velocity"}})",
                 {"drives.default.type: unknown value \"velocity\""}},
        BadScene{"drive_unknown_key", R"(, "drives": {"default": {"stiffness": 1}})",
                 {"drives.default.stiffness: unknown key (expected one of: kp, kd, max_force, type)"}},
        BadScene{"dynamics_unknown_joint", R"(, "joint_dynamics": {"joints": {"elbow": {"damping": 1}}})",
                 {"joint_dynamics.joints.elbow: unknown joint"}},
        BadScene{"state_unknown_joint", R"(, "initial_state": {"q": {"knee": 0.1}})",
                 {"bad.json: initial_state.q.knee: unknown joint \"knee\""}},
        BadScene{"state_wrong_size", R"(, "initial_state": {"q": {"quadruped_root": [0, 0, 1]}})",
                 {"initial_state.q.quadruped_root: expected an array of 7 numbers"}},
        BadScene{"state_velocity_wrong_type", R"(, "initial_state": {"qd": {"FL_knee": [1]}})",
                 {"bad.json: initial_state.qd.FL_knee: expected a number, got array"}},
        BadScene{"state_tau", R"(, "initial_state": {"tau": {}})", {"initial_state.tau: unknown key"}},
        BadScene{"target_unknown_joint", R"(, "drive_targets": {"knee": 0.1})",
                 {"bad.json: drive_targets.knee: unknown joint \"knee\""}},
        BadScene{"randomization_low_above_high", R"(, "randomization": {"mass_scale": [1.1, 0.9]})",
                 {"bad.json: randomization.mass_scale: low"}},
        BadScene{"randomization_unknown_field", R"(, "randomization": {"mass": [1, 1]})",
                 {"randomization.mass: unknown key"}},
        BadScene{"randomization_not_a_pair", R"(, "randomization": {"com_offset": [0.1]})",
                 {"randomization.com_offset: expected an array of 2 numbers, got 1 entries"}},
        BadScene{"randomization_zero_mass", R"(, "randomization": {"mass_scale": [0, 1]})",
                 {"randomization.mass_scale: low must be > 0"}},
        BadScene{"ground_friction_without_ground", R"(, "randomization": {"ground_friction": [0.5, 1]})",
                 {"randomization.ground_friction: the scene has no ground"}},
        BadScene{"zero_ground_normal", R"(, "ground": {"normal": [0, 0, 0]})", {"ground.normal: the normal must not"}},
        BadScene{"restitution_above_one", R"(, "ground": {"restitution": 1.5})",
                 {"ground.restitution: must lie in [0, 1]"}},
        BadScene{"layers_out_of_range", R"(, "ground": {"layers": 4294967296})", {"ground.layers: must lie in [0, "}},
        BadScene{"zero_capacity", R"(, "contacts": {"capacity": 0})", {"contacts.capacity: must lie in [1, "}},
        BadScene{"huge_capacity", R"(, "contacts": {"capacity": 100000})", {"contacts.capacity: must lie in [1, 256]"}},
        BadScene{"box_negative_size", R"(, "boxes": [{"size": [1, -1, 1]}])", {"boxes[0].size[1]: must be > 0"}},
        BadScene{"box_rpy_and_rotation",
                 R"(, "boxes": [{}, {"rpy": [0, 0, 0], "rotation": [[1,0,0],[0,1,0],[0,0,1]]}])",
                 {"boxes[1].rotation: give \"rpy\" or \"rotation\", not both"}},
        BadScene{"box_not_a_rotation", R"(, "boxes": [{"rotation": [[1,0,0],[0,1,0],[0,0,-1]]}])",
                 {"boxes[0].rotation: not a rotation matrix"}},
        BadScene{"gravity_not_an_array", R"(, "links_without_gravity": "base")",
                 {"links_without_gravity: expected an array of link names, got string"}},
        BadScene{"gravity_unknown_link", R"(, "links_without_gravity": ["base", "FL_shnak"])",
                 {"links_without_gravity[1]: unknown link \"FL_shnak\" (did you mean \"FL_shank\"?)"}},
        BadScene{"gravity_fused_link", R"(, "links_without_gravity": ["FL_foot"])",
                 {"links_without_gravity[0]: link \"FL_foot\" is fixed to link \"FL_shank\" and moves with it as one "
                  "body; name \"FL_shank\""}},
        BadScene{"gravity_link_twice", R"(, "links_without_gravity": ["FL_shank", "FL_shank"])",
                 {"links_without_gravity[1]: link \"FL_shank\" is listed twice"}},
        BadScene{"actuators_not_an_array", R"(, "actuators": {})", {"actuators: expected an array of actuators"}},
        BadScene{"tendon_missing_joints", R"(, "fixed_tendons": [{"name": "t"}])",
                 {"fixed_tendons[0]: missing key \"joints\""}},
        BadScene{"tendon_no_joints", R"(, "fixed_tendons": [{"name": "t", "joints": {}}])",
                 {"fixed_tendons[0].joints: must name at least one joint"}},
        BadScene{"tendon_unknown_joint", R"(, "fixed_tendons": [{"name": "t", "joints": {"FL_knie": 1}}])",
                 {"fixed_tendons[0].joints.FL_knie: unknown joint \"FL_knie\" (did you mean \"FL_knee\"?)"}},
        BadScene{"tendon_floating_root", R"(, "fixed_tendons": [{"name": "t", "joints": {"quadruped_root[0]": 1}}])",
                 {"fixed_tendons[0].joints.quadruped_root[0]: \"quadruped_root[0]\" is a DOF of a free joint: a tendon spans"}},
        BadScene{"tendon_zero_coefficient", R"(, "fixed_tendons": [{"name": "t", "joints": {"FL_knee": 0}}])",
                 {"fixed_tendons[0].joints.FL_knee: the coefficient must not be zero"}},
        BadScene{"tendon_negative_stiffness",
                 R"(, "fixed_tendons": [{"name": "t", "joints": {"FL_knee": 1}, "stiffness": -1}])",
                 {"fixed_tendons[0].stiffness: must be >= 0"}},
        BadScene{"tendon_reversed_limits",
                 R"(, "fixed_tendons": [{"name": "t", "joints": {"FL_knee": 1}, "limits": [0.5, 0.1]}])",
                 {"fixed_tendons[0].limits: the lower limit lies above the upper"}},
        BadScene{"tendon_one_limit", R"(, "fixed_tendons": [{"name": "t", "joints": {"FL_knee": 1}, "limits": [0.5]}])",
                 {"fixed_tendons[0].limits: expected 2 values, got 1"}},
        BadScene{"tendon_same_name",
                 R"(, "fixed_tendons": [{"name": "t", "joints": {"FL_knee": 1}}, {"name": "t", "joints": {"FR_knee": 1}}])",
                 {"fixed_tendons[1].name: \"t\" names another fixed tendon"}},
        BadScene{"actuator_missing_key",
                 R"(, "actuators": [{"name": "m", "joint": "FL_knee", "bus_voltage": 1, "resistance": 1, "velocity_constant": 1}])",
                 {"actuators[0]: missing key \"torque_constant\""}},
        BadScene{"actuator_unknown_joint",
                 R"(, "actuators": [{"name": "m", "joint": "FL_kne", "torque_constant": 1, "bus_voltage": 1, "resistance": 1, "velocity_constant": 1}])",
                 {"actuators[0].joint: unknown joint \"FL_kne\" (did you mean \"FL_knee\"?)"}},
        BadScene{"actuator_on_the_base",
                 R"(, "actuators": [{"name": "m", "joint": "quadruped_root[2]", "torque_constant": 1, "bus_voltage": 1, "resistance": 1, "velocity_constant": 1}])",
                 {"actuators[0].joint: joint \"quadruped_root[2]\" is the floating base"}},
        BadScene{"actuator_coupled_to_itself",
                 R"(, "actuators": [{"name": "m", "joint": "FL_knee", "couplings": {"FL_knee": 1}, "torque_constant": 1, "bus_voltage": 1, "resistance": 1, "velocity_constant": 1}])",
                 {"actuators[0].couplings.FL_knee: the driven joint itself"}},
        BadScene{"actuator_negative_constant",
                 R"(, "actuators": [{"name": "m", "joint": "FL_knee", "torque_constant": 1, "bus_voltage": -48, "resistance": 1, "velocity_constant": 1}])",
                 {"actuators[0].bus_voltage: must be > 0, got -48"}},
        BadScene{"actuator_names_twice",
                 R"(, "actuators": [{"name": "m", "joint": "FL_knee", "torque_constant": 1, "bus_voltage": 1, "resistance": 1, "velocity_constant": 1},
                                    {"name": "m", "joint": "FR_knee", "torque_constant": 1, "bus_voltage": 1, "resistance": 1, "velocity_constant": 1}])",
                 {"actuators[1].name: \"m\" names another actuator"}},
        BadScene{"unknown_link", R"(, "contacts": {"links": {"paw": {"friction": 1}}})",
                 {"contacts.links.paw: unknown link \"paw\""}},
        BadScene{"misspelled_link", R"(, "contacts": {"links": {"FL_shnak": {"friction": 1}}})",
                 {"contacts.links.FL_shnak: unknown link \"FL_shnak\" (did you mean \"FL_shank\"?)"}},
        BadScene{"pair_unknown_link", R"(, "contacts": {"disabled_pairs": [["base", "toe"]]})",
                 {"contacts.disabled_pairs[0][1]: unknown link \"toe\""}},
        BadScene{"duplicate_key", R"(, "ground": {}, "ground": {})", {"bad.json:1:", "duplicate key \"ground\""}}),
    [](const ::testing::TestParamInfo<BadScene>& test) { return std::string(test.param.name); });

TEST_F(SceneFile, SyntaxErrorNamesFileLineAndColumn) {
  const std::string message = error_of("{\n  \"model\": \"x.urdf\",\n  \"step\": {\"dt\": 0.002,}\n}");
  EXPECT_NE(message.find("bad.json:3:"), std::string::npos) << message;
}

TEST_F(SceneFile, ModelIsRequiredAndMustLoad) {
  EXPECT_NE(error_of(R"({"floating_base": true})").find("bad.json: \"model\" is missing"), std::string::npos);
  EXPECT_NE(error_of(R"({"model": 3})").find("bad.json: model: expected a string, got number"), std::string::npos);
  EXPECT_NE(error_of("[]").find("bad.json: expected an object, got array"), std::string::npos);

  // a missing model file: both files named, the model's path resolved
  const std::string missing = error_of(R"({"model": "robots/none.urdf"})");
  EXPECT_NE(missing.find("bad.json: model: "), std::string::npos) << missing;
  EXPECT_NE(missing.find((dir_ / "robots" / "none.urdf").string()), std::string::npos) << missing;

  // a model that is not a URDF (here another scene file)
  write("other.json", R"({"model": "x.urdf"})");
  const std::string not_urdf = error_of(R"({"model": "other.json"})");
  EXPECT_NE(not_urdf.find("bad.json: model: "), std::string::npos) << not_urdf;
  EXPECT_NE(not_urdf.find((dir_ / "other.json").string()), std::string::npos) << not_urdf;
}

TEST_F(SceneFile, ErrorsInFixtureFilesNameTheirKeys) {
  const auto message = [](const std::string& file) {
    try {
      load_scene(kDataDir + "/" + file);
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(message("scene_unknown_key.json").find("scene_unknown_key.json: contacts.frcition: unknown key"),
            std::string::npos);
  EXPECT_NE(message("scene_syntax_error.json").find("scene_syntax_error.json:4:"), std::string::npos);
}

}  // namespace
}  // namespace lockstep
