#include "batch/simulator.hpp"
#include "io/urdf_import.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <tinyxml2.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>

#ifndef LOCKSTEP_SHARED_MODELS_DIR
#define LOCKSTEP_SHARED_MODELS_DIR "/work/shared/models"
#endif
#ifndef LOCKSTEP_MODELS_DIR
#define LOCKSTEP_MODELS_DIR "/work/main/models"
#endif

namespace lockstep {
namespace {

namespace fs = std::filesystem;


const char* kInertial = R"(<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>)";

std::string link(const std::string& name, const std::string& body = kInertial) {
  return "<link name=\"" + name + "\">" + body + "</link>\n";
}

std::string joint(const std::string& name, const std::string& type, const std::string& parent, const std::string& child,
                  const std::string& body = "") {
  std::string limit = type == "revolute" || type == "prismatic" ? R"(<limit lower="-1" upper="1" effort="10" velocity="5"/>)" : "";
  return "<joint name=\"" + name + "\" type=\"" + type + "\"><parent link=\"" + parent + "\"/><child link=\"" + child +
         "\"/>" + limit + body + "</joint>\n";
}

std::string robot(const std::string& body) { return "<robot name=\"bot\">\n" + body + "</robot>\n"; }

ArticulationSpec parse(const std::string& xml, std::vector<std::string>* warnings = nullptr, UrdfOptions options = {}) {
  return urdf_articulation_from_string(xml, "test.urdf", options, warnings);
}

// A valid two-link chain to mutate in the error tests.
std::string chain(const std::string& joint_body = R"(<axis xyz="0 1 0"/>)", const std::string& child_body = kInertial) {
  return robot(link("base") + link("arm", child_body) + joint("shoulder", "continuous", "base", "arm", joint_body));
}

TEST(UrdfImport, ReadsJointsInertialsAndLimits) {
  const std::string xml = robot(
      link("base") +
      link("upper", R"(<inertial><origin xyz="0.1 0 -0.2" rpy="0.3 0.2 0.1"/><mass value="2.5"/>
                     <inertia ixx="0.3" ixy="0.01" ixz="0.02" iyy="0.2" iyz="0.03" izz="0.4"/></inertial>)") +
      link("lower") + link("tool", "") +
      joint("shoulder", "revolute", "base", "upper",
            R"(<origin xyz="0 0 0.5" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 -1"/>
               <dynamics damping="0.5" friction="0.25"/>)") +
      R"(<joint name="elbow" type="continuous"><parent link="upper"/><child link="lower"/><axis xyz="1 0 0"/>
           <limit effort="7" velocity="3"/><mimic joint="shoulder" multiplier="-2" offset="0.1"/></joint>)" +
      joint("tool_mount", "fixed", "lower", "tool", R"(<origin xyz="0 0 0.1"/>)"));
  std::vector<std::string> warnings;
  const ArticulationSpec spec = parse(xml, &warnings);
  EXPECT_EQ(spec.name, "bot");
  EXPECT_EQ(spec.source, "test.urdf");
  EXPECT_FALSE(spec.floating_base);
  ASSERT_EQ(spec.links.size(), 4u);
  const LinkSpec& upper = spec.links[1];
  EXPECT_EQ(upper.name, "upper");
  EXPECT_EQ(upper.parent, "base");
  EXPECT_EQ(upper.joint.type, JointType::Revolute);
  EXPECT_TRUE(upper.joint.limited);
  EXPECT_EQ(upper.joint.lower, -1.0);
  EXPECT_EQ(upper.joint.upper, 1.0);
  EXPECT_EQ(upper.joint.velocity_limit, 5.0);
  EXPECT_EQ(upper.joint.effort_limit, 10.0);
  EXPECT_EQ(upper.joint.damping, 0.5);
  EXPECT_EQ(upper.joint.friction, 0.25);
  EXPECT_EQ(upper.joint.axis, Eigen::Vector3d(0, 0, -1));
  EXPECT_TRUE(upper.joint.origin.translation().isApprox(Eigen::Vector3d(0, 0, 0.5)));
  EXPECT_TRUE(upper.joint.origin.linear().isApprox(
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix()));
  EXPECT_EQ(upper.inertial.mass, 2.5);
  EXPECT_TRUE(upper.inertial.origin.translation().isApprox(Eigen::Vector3d(0.1, 0, -0.2)));
  const Eigen::Matrix3d rpy = (Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX())).toRotationMatrix();
  EXPECT_TRUE(upper.inertial.origin.linear().isApprox(rpy, 1e-12));
  Eigen::Matrix3d inertia;
  inertia << 0.3, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.4;
  EXPECT_EQ(upper.inertial.inertia, inertia);
  const LinkSpec& lower = spec.links[2];
  EXPECT_EQ(lower.joint.type, JointType::Revolute);
  EXPECT_FALSE(lower.joint.limited);
  EXPECT_EQ(lower.joint.velocity_limit, 3.0);
  EXPECT_EQ(lower.joint.effort_limit, 7.0);
  EXPECT_EQ(lower.joint.mimic.leader_joint, "shoulder");
  EXPECT_EQ(lower.joint.mimic.multiplier, -2.0);
  EXPECT_EQ(lower.joint.mimic.offset, 0.1);
  EXPECT_EQ(spec.links[3].joint.type, JointType::Fixed);
  EXPECT_EQ(spec.links[3].inertial.mass, 0.0);
  EXPECT_TRUE(warnings.empty());

  ModelBuilder builder;
  builder.add_articulation(spec);
  const Model m = builder.finalize();
  EXPECT_EQ(m.nv, 2);
  ASSERT_EQ(m.mimics.size(), 1u);
  EXPECT_EQ(m.mimics[0].leader_dof, m.dof_index("shoulder"));
  // Rotated inertia axes end up in the body frame as R I R^T.
  const Eigen::Matrix3d r = m.frame_placement[1].linear() * rpy;
  EXPECT_TRUE(m.body_inertia[0].isApprox(r * inertia * r.transpose(), 1e-12));
  // The world-fused base is dropped; the massless tool frame is warned about.
  EXPECT_DOUBLE_EQ(m.total_mass(), 3.5);
  ASSERT_EQ(builder.warnings().size(), 1u);
  EXPECT_NE(builder.warnings()[0].find("tool"), std::string::npos);
}

// RaiSim reads a joint spring from <dynamics stiffness spring_mount>; so
// does lockstep, into the model and default_dof_settings (they had been
// dropped without a word). Without gravity a damped joint started at 0
// settles at the spring's mount.
TEST(UrdfImport, ReadsRaisimJointSprings) {
  const Model m = [] {
    ModelBuilder builder;
    builder.add_articulation(
        parse(chain(R"(<axis xyz="0 1 0"/><dynamics damping="0.5" stiffness="20" spring_mount="0.3"/>)")));
    return builder.finalize();
  }();
  ASSERT_EQ(m.nv, 1);
  EXPECT_EQ(m.dof_spring_stiffness[0], 20.0);
  EXPECT_EQ(m.dof_spring_rest[0], 0.3);
  const std::vector<DofSettings> dofs = default_dof_settings(m);
  EXPECT_EQ(dofs[0].spring_stiffness, 20.0);
  EXPECT_EQ(dofs[0].spring_rest, 0.3);
  StepOptions o;
  o.precision = Precision::Double;
  o.dt = 0.002;
  Simulator sim(m, 1, o);
  sim.set_gravity(0, Eigen::Vector3d::Zero());
  sim.step(5000);
  EXPECT_NEAR(sim.q(0)[0], 0.3, 1e-6);
}

// Gazebo's per-link gravity switch: <gravity> (SDF's bool, any case,
// whitespace around it) or the older <turnGravityOff>; a <gazebo> element
// for a joint is no error. As Gazebo lumps links fixed together, a body
// takes the switch of its first link that has one, and the links fixed to
// it follow; one switched the other way is a warning.
TEST(UrdfImport, ReadsGazebosGravitySwitch) {
  const std::string links = link("base") + link("arm") + link("hand") + link("tool") +
                            joint("shoulder", "continuous", "base", "arm", R"(<axis xyz="0 1 0"/>)") +
                            joint("wrist", "continuous", "arm", "hand", R"(<axis xyz="0 1 0"/>)") +
                            joint("flange", "fixed", "hand", "tool");
  const ArticulationSpec spec = parse(robot(links + R"(<gazebo reference="arm"><gravity>
   False </gravity></gazebo>
<gazebo reference="hand"><turnGravityOff>TRUE</turnGravityOff></gazebo>
<gazebo reference="tool"><turnGravityOff>true</turnGravityOff></gazebo>
<gazebo reference="base"><gravity>1</gravity></gazebo>
<gazebo reference="shoulder"><implicitSpringDamper>true</implicitSpringDamper></gazebo>
)"));
  std::vector<bool> gravity;
  for (const LinkSpec& l : spec.links) gravity.push_back(l.gravity);
  EXPECT_EQ(gravity, (std::vector<bool>{true, false, false, false}));
  ModelBuilder builder;
  builder.add_articulation(spec);
  EXPECT_EQ(builder.finalize().body_gravity, (std::vector<std::uint8_t>{0, 0}));
  // the tool is fixed to the hand: one body, which follows the hand's switch
  std::vector<std::string> warnings;
  const ArticulationSpec hand_off =
      parse(robot(links + R"(<gazebo reference="hand"><gravity>0</gravity></gazebo>)"), &warnings);
  EXPECT_FALSE(hand_off.links[3].gravity) << "the tool follows its body";
  EXPECT_TRUE(warnings.empty());
  const ArticulationSpec tool_on = parse(robot(links + R"(<gazebo reference="hand"><gravity>0</gravity></gazebo>
<gazebo reference="tool"><gravity>true</gravity></gazebo>)"),
                                         &warnings);
  EXPECT_FALSE(tool_on.links[3].gravity);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("link 'tool': Gazebo gravity switch (on) ignored: the link is fixed to link 'hand' and "
                             "moves with it as one body, whose gravity link 'hand' switches off"),
            std::string::npos)
      << warnings[0];
  // a fixed base's root: fixed to the world
  warnings.clear();
  parse(robot(links + R"(<gazebo reference="base"><gravity>0</gravity></gazebo>)"), &warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("link 'base': Gazebo gravity switch ignored: the link is fixed to the world"),
            std::string::npos)
      << warnings[0];
}

TEST(UrdfImportError, GazeboGravitySwitch) {
  const auto with = [](const std::string& gazebo) {
    return parse(robot(link("base") + link("arm") + joint("shoulder", "continuous", "base", "arm") + gazebo));
  };
  EXPECT_MODEL_ERROR(with(R"(<gazebo reference="arm"><gravity>off</gravity></gazebo>)"), "<gravity>",
                     "expected true, false, 1 or 0, got 'off'");
  EXPECT_MODEL_ERROR(with(R"(<gazebo reference="arm"><gravity/></gazebo>)"), "<gravity>",
                     "expected true, false, 1 or 0, got ''");
  EXPECT_MODEL_ERROR(with(R"(<gazebo reference="arm"><gravity>fal se</gravity></gazebo>)"),
                     "expected true, false, 1 or 0, got 'fal se'");
  EXPECT_MODEL_ERROR(with(R"(<gazebo reference="arm"><gravity>false</gravity><turnGravityOff>true</turnGravityOff></gazebo>)"),
                     "<turnGravityOff>: link 'arm' has its gravity switched already");
  EXPECT_MODEL_ERROR(with(R"(<gazebo reference="elbow"><gravity>false</gravity></gazebo>)"),
                     "<gazebo reference=\"elbow\"> names no link");
  EXPECT_MODEL_ERROR(with(R"(<gazebo><turnGravityOff>true</turnGravityOff></gazebo>)"),
                     "<turnGravityOff> outside a <gazebo reference=\"link\"> element");
}

TEST(UrdfImport, ChildrenInFileOrderAndOptions) {
  const std::string xml = robot(link("z_root") + link("b") + link("a") + link("c") +
                                joint("jb", "prismatic", "z_root", "b", R"(<axis xyz="0 0 1"/>)") +
                                joint("ja", "revolute", "z_root", "a") + joint("jc", "revolute", "b", "c"));
  UrdfOptions options;
  options.floating_base = true;
  options.name_prefix = "left_";
  options.root_pose.translation() = Eigen::Vector3d(0, 0, 1);
  const ArticulationSpec spec = parse(xml, nullptr, options);
  EXPECT_EQ(spec.name, "left_bot");
  EXPECT_TRUE(spec.floating_base);
  EXPECT_TRUE(spec.root_pose.isApprox(options.root_pose));
  ASSERT_EQ(spec.links.size(), 4u);
  EXPECT_EQ(spec.links[0].name, "left_z_root");
  EXPECT_EQ(spec.links[1].name, "left_b");
  EXPECT_EQ(spec.links[1].joint.name, "left_jb");
  EXPECT_EQ(spec.links[2].name, "left_c");
  EXPECT_EQ(spec.links[2].parent, "left_b");
  EXPECT_EQ(spec.links[3].name, "left_a");
  // Two copies side by side in one model.
  ModelBuilder builder;
  builder.add_articulation(spec);
  options.name_prefix = "right_";
  builder.add_articulation(parse(xml, nullptr, options));
  const Model m = builder.finalize();
  EXPECT_EQ(m.nbody, 8);
  EXPECT_EQ(m.joint_index("right_bot_root"), 4);
  EXPECT_EQ(m.body_joint[1], JointType::Prismatic);
}

TEST(UrdfImport, CollisionPrimitivesAndMeshes) {
  const fs::path dir = fs::temp_directory_path() / "lockstep_urdf_test" / "mypkg";
  fs::create_directories(dir / "urdf");
  fs::create_directories(dir / "meshes");
  // one triangle: (0, 0, 0), (1, 0, 0), (0, 1, 0.5)
  const char* stl = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0.5\nendloop\nendfacet\nendsolid x\n";
  std::ofstream(dir / "meshes" / "part.stl") << stl;
  std::ofstream(dir / "urdf" / "near.stl") << stl;
  const std::string body = std::string(kInertial) + R"(
    <collision><origin xyz="0 0 0.1" rpy="0 0 0"/><geometry><box size="0.2 0.4 0.6"/></geometry></collision>
    <collision><geometry><sphere radius="0.05"/></geometry></collision>
    <collision><geometry><cylinder radius="0.03" length="0.5"/></geometry></collision>
    <collision><geometry><capsule radius="0.02" length="0.3"/></geometry></collision>
    <collision><geometry><mesh filename="package://mypkg/meshes/part.stl" scale="2 2 2"/></geometry></collision>
    <collision><geometry><mesh filename="near.stl"/></geometry></collision>
    <collision><geometry><mesh filename="package://mypkg/meshes/missing.stl"/></geometry></collision>
    <visual><geometry><mesh filename="whatever.dae"/></geometry></visual>)";
  const fs::path file = dir / "urdf" / "robot.urdf";
  std::ofstream(file) << robot(link("base", body));
  std::vector<std::string> warnings;
  const ArticulationSpec spec = urdf_articulation_from_file(file.string(), {}, &warnings);
  const std::vector<Shape>& s = spec.links[0].shapes;
  ASSERT_EQ(s.size(), 6u);
  EXPECT_EQ(s[0].type, ShapeType::Box);
  EXPECT_EQ(s[0].size, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_TRUE(s[0].pose.translation().isApprox(Eigen::Vector3d(0, 0, 0.1)));
  EXPECT_EQ(s[1].type, ShapeType::Sphere);
  EXPECT_EQ(s[1].size.x(), 0.05);
  EXPECT_EQ(s[2].type, ShapeType::Cylinder);
  EXPECT_EQ(s[2].size, Eigen::Vector3d(0.03, 0.25, 0.0));
  EXPECT_EQ(s[3].type, ShapeType::Capsule);
  EXPECT_EQ(s[3].size, Eigen::Vector3d(0.02, 0.15, 0.0));
  // meshes whose file exists become fitted boxes (tests/mesh_fit_test.cpp), each with a warning
  EXPECT_EQ(s[4].type, ShapeType::Box);
  EXPECT_EQ(s[4].size, Eigen::Vector3d(1, 1, 0.5));
  EXPECT_TRUE(fs::equivalent(s[4].mesh_path, dir / "meshes" / "part.stl"));
  EXPECT_EQ(s[4].mesh_scale, Eigen::Vector3d(2, 2, 2));
  EXPECT_TRUE(fs::equivalent(s[5].mesh_path, dir / "urdf" / "near.stl"));
  ASSERT_EQ(warnings.size(), 3u);
  EXPECT_NE(warnings[0].find("part.stl' fitted with a box"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[1].find("near.stl' fitted with a box"), std::string::npos) << warnings[1];
  EXPECT_NE(warnings[2].find("link 'base'"), std::string::npos);
  EXPECT_NE(warnings[2].find("missing.stl"), std::string::npos);
  // the file by its bare name from its own folder: package:// searched up from there
  const fs::path cwd = fs::current_path();
  fs::current_path(dir / "urdf");
  const ArticulationSpec bare = urdf_articulation_from_file("robot.urdf");
  fs::current_path(cwd);
  ASSERT_EQ(bare.links[0].shapes.size(), 6u);
  EXPECT_TRUE(fs::equivalent(bare.links[0].shapes[4].mesh_path, dir / "meshes" / "part.stl"));
  fs::remove_all(dir.parent_path());
}

TEST(UrdfImport, PlaceholderLimitsReadAsNoLimit) {
  const std::string xml = robot(link("base") + link("arm") +
                                R"(<joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
                                   <limit lower="0" upper="0" effort="0" velocity="0"/></joint>)");
  std::vector<std::string> warnings;
  const ArticulationSpec spec = parse(xml, &warnings);
  EXPECT_FALSE(spec.links[1].joint.limited);
  EXPECT_EQ(spec.links[1].joint.velocity_limit, Model::kInfinity);
  EXPECT_EQ(spec.links[1].joint.effort_limit, Model::kInfinity);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("joint 'j'"), std::string::npos);
}

TEST(UrdfImport, AddUrdfForwardsWarningsToBuilder) {
  const fs::path file = fs::temp_directory_path() / "lockstep_add_urdf.urdf";
  std::ofstream(file) << robot(link("base", std::string(kInertial) +
                                                R"(<collision><geometry><mesh filename="gone.stl"/></geometry></collision>)"));
  ModelBuilder builder;
  EXPECT_EQ(add_urdf(builder, file.string()), 0);
  ASSERT_EQ(builder.warnings().size(), 1u);
  EXPECT_NE(builder.warnings()[0].find("gone.stl"), std::string::npos);
  fs::remove(file);
}

// ---- errors: one test per case -------------------------------------------

TEST(UrdfImportError, MissingFile) {
  EXPECT_MODEL_ERROR(load_urdf("/nonexistent/robot.urdf"), "/nonexistent/robot.urdf");
}

TEST(UrdfImportError, NotXml) {
  EXPECT_MODEL_ERROR(parse("<robot name=\"x\">\n<link name=\"a\">\n</robot>"), "test.urdf:", "not valid XML");
}

TEST(UrdfImportError, NotARobot) { EXPECT_MODEL_ERROR(parse("<model name=\"x\"/>"), "test.urdf", "<robot>"); }

TEST(UrdfImportError, NoRoot) {
  const std::string xml = robot(link("a") + link("b") + joint("ab", "revolute", "a", "b") + joint("ba", "revolute", "b", "a"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "cycle");
}

TEST(UrdfImportError, SeveralRoots) {
  const std::string xml = robot(link("a") + link("b") + link("c") + joint("ab", "revolute", "a", "b"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "several root links", "'a'", "'c'");
}

TEST(UrdfImportError, DisjointCycleBesideTree) {
  const std::string xml = robot(link("base") + link("arm") + link("p") + link("q") + link("r") +
                                joint("j", "revolute", "base", "arm") + joint("pq", "revolute", "p", "q") +
                                joint("qr", "revolute", "q", "r") + joint("rp", "revolute", "r", "p"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "cycle", "'p'", "'q'", "'r'");
}

TEST(UrdfImportError, LinkWithTwoParents) {
  const std::string xml = robot(link("a") + link("b") + link("c") + joint("ab", "revolute", "a", "b") +
                                joint("cb", "revolute", "c", "b"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "'b' has two parents", "'ab'", "'cb'");
}

TEST(UrdfImportError, MissingParentLink) {
  const std::string xml = robot(link("a") + link("b") + joint("ab", "revolute", "ghost", "b"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "joint 'ab'", "parent link 'ghost' does not exist");
}

TEST(UrdfImportError, MissingChildLink) {
  const std::string xml = robot(link("a") + joint("ab", "revolute", "a", "ghost"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "joint 'ab'", "child link 'ghost' does not exist");
}

TEST(UrdfImportError, NanMass) {
  const std::string xml = chain(R"(<axis xyz="0 1 0"/>)", R"(<inertial><mass value="nan"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>)");
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf:", "link 'arm' <mass>", "value=\"nan\"", "not a finite number");
}

TEST(UrdfImportError, NanInertia) {
  const std::string xml = chain(R"(<axis xyz="0 1 0"/>)", R"(<inertial><mass value="1"/>
      <inertia ixx="0.1" ixy="NaN" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>)");
  EXPECT_MODEL_ERROR(parse(xml), "link 'arm' <inertia>", "ixy");
}

TEST(UrdfImportError, InfiniteOrigin) {
  EXPECT_MODEL_ERROR(parse(chain(R"(<origin xyz="0 inf 0"/><axis xyz="0 1 0"/>)")), "joint 'shoulder' <origin>",
                     "not a finite number");
}

TEST(UrdfImportError, UnparsableAxis) {
  EXPECT_MODEL_ERROR(parse(chain(R"(<axis xyz="0 one 0"/>)")), "joint 'shoulder' <axis>", "not a number");
}

TEST(UrdfImportError, AxisWithTwoNumbers) {
  EXPECT_MODEL_ERROR(parse(chain(R"(<axis xyz="0 1"/>)")), "joint 'shoulder' <axis>", "expected 3 numbers");
}

TEST(UrdfImportError, OutOfRangeLimit) {
  EXPECT_MODEL_ERROR(parse(chain(R"(<axis xyz="0 1 0"/><limit effort="1e999" velocity="1"/>)")),
                     "joint 'shoulder' <limit>", "out of range");
}

TEST(UrdfImportError, NanDynamics) {
  EXPECT_MODEL_ERROR(parse(chain(R"(<axis xyz="0 1 0"/><dynamics damping="-nan"/>)")), "joint 'shoulder' <dynamics>",
                     "damping");
}

TEST(UrdfImportError, SpringAttributes) {
  // (urdfdom wants damping or friction in a <dynamics> tag)
  EXPECT_MODEL_ERROR(parse(chain(R"(<axis xyz="0 1 0"/><dynamics damping="0" stiffness="stiff"/>)")),
                     "joint 'shoulder' <dynamics>", "stiffness");
  EXPECT_MODEL_ERROR(parse(chain(R"(<axis xyz="0 1 0"/><dynamics damping="0" spring_mount="nan"/>)")),
                     "joint 'shoulder' <dynamics>", "spring_mount");
  ModelBuilder builder;
  EXPECT_MODEL_ERROR(
      builder.add_articulation(parse(chain(R"(<axis xyz="0 1 0"/><dynamics damping="0" stiffness="-2"/>)"))),
      "test.urdf:4: joint 'shoulder'", "negative spring stiffness");
}

TEST(UrdfImportError, PlanarJoint) {
  const std::string xml = robot(link("a") + link("b") + joint("ab", "planar", "a", "b"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "joint 'ab'", "planar");
}

TEST(UrdfImportError, FloatingJointInsideTree) {
  const std::string xml = robot(link("a") + link("b") + joint("ab", "floating", "a", "b"));
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "joint 'ab'", "floating joint inside the tree is not supported");
}

TEST(UrdfImportError, UnknownJointType) {
  const std::string xml = robot(link("a") + link("b") + joint("ab", "hinge", "a", "b"));
  EXPECT_MODEL_ERROR(parse(xml), "joint 'ab'", "unknown joint type 'hinge'");
}

TEST(UrdfImportError, UrdfdomReasonIsKeptAndNotPrinted) {
  const std::string xml = robot(link("a") + link("b") +
                                R"(<joint name="ab" type="revolute"><parent link="a"/><child link="b"/></joint>)");
  testing::internal::CaptureStderr();
  testing::internal::CaptureStdout();
  EXPECT_MODEL_ERROR(parse(xml), "test.urdf", "limit");
  const std::string printed = testing::internal::GetCapturedStderr() + testing::internal::GetCapturedStdout();
  EXPECT_EQ(printed, "");
}

// A robot-level material without a colour (urdfdom logs an error for it)
// is the visuals' business, which the loader leaves out: the file loads.
TEST(UrdfImport, AMaterialWithoutColourIsNoError) {
  const std::string xml = chain(R"(<axis xyz="0 1 0"/>)");
  const std::string with_material = std::string(xml).insert(xml.find('>') + 1, R"(<material name="grey"/>)");
  EXPECT_EQ(parse(with_material).links.size(), parse(xml).links.size());
}

// urdfdom logs these and still returns a model, the inertial read as
// zero: refused with its reason, not loaded massless.
TEST(UrdfImportError, AnInertialUrdfdomCannotReadIsRefused) {
  const std::string products = R"(ixy="0" ixz="0" iyz="0")";
  for (const auto& [inertial, reason] : std::vector<std::pair<std::string, std::string>>{
           {R"(<mass value="3 "/><inertia ixx="1" iyy="1" izz="1" )" + products + "/>", "mass [3 ] is not a float"},
           {R"(<mass value="3"/><inertia ixx="1" iyy="1" izz="1"/>)", "inertia"},
           {R"(<inertia ixx="1" iyy="1" izz="1" )" + products + "/>", "mass"}}) {
    const std::string xml = chain(R"(<axis xyz="0 1 0"/>)", std::string("<inertial>") + inertial + "</inertial>");
    testing::internal::CaptureStderr();
    EXPECT_MODEL_ERROR(parse(xml), "test.urdf: invalid URDF: ", reason.c_str());
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "") << inertial;
  }
}

TEST(UrdfImportError, BuilderRejectionNamesFile) {
  const fs::path file = fs::temp_directory_path() / "lockstep_negative_mass.urdf";
  std::ofstream(file) << chain(R"(<axis xyz="0 1 0"/>)", R"(<inertial><mass value="-1"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>)");
  const std::string name = file.string(), where = name + ":3: link 'arm'";
  EXPECT_MODEL_ERROR(load_urdf(name), where.c_str(), "negative mass");
  fs::remove(file);
}

TEST(UrdfImportError, ZeroAxis) {
  ModelBuilder builder;
  EXPECT_MODEL_ERROR(builder.add_articulation(parse(chain(R"(<axis xyz="0 0 0"/>)"))), "test.urdf:4: joint 'shoulder'",
                     "zero axis");
}

// The model's own rules, checked by the builder, name the file, the line
// and the element of a URDF too (the line once went missing: the builder
// knew the file only).
Model build_urdf(const std::string& xml) {
  ModelBuilder builder;
  builder.add_articulation(parse(xml));
  return builder.finalize();
}

TEST(UrdfImportError, MasslessMovingSubtree) {
  EXPECT_MODEL_ERROR(build_urdf(chain(R"(<axis xyz="0 1 0"/>)", "")), "test.urdf", "joint 'shoulder'",
                     "massless subtree");
}

TEST(UrdfImportError, InertiaWithANegativeEigenvalue) {
  const std::string xml = chain(R"(<axis xyz="0 1 0"/>)", R"(<inertial><mass value="1"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="-0.01"/></inertial>)");
  EXPECT_MODEL_ERROR(build_urdf(xml), "test.urdf:3: link 'arm'", "positive semi-definite");
}

TEST(UrdfImportError, LowerLimitAboveUpper) {
  const std::string xml = robot(link("base") + link("arm") +
                                R"(<joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>
                                   <axis xyz="0 1 0"/><limit lower="1" upper="-1" effort="1" velocity="1"/></joint>)");
  EXPECT_MODEL_ERROR(build_urdf(xml), "test.urdf:4: joint 'shoulder'", "exceeds upper");
}

TEST(UrdfImportError, MimicOfAMissingJoint) {
  const std::string xml = robot(link("base") + link("a") + link("b") + joint("ja", "revolute", "base", "a") +
                                joint("jb", "revolute", "base", "b", R"(<mimic joint="ghost"/>)"));
  EXPECT_MODEL_ERROR(build_urdf(xml), "test.urdf", "joint 'jb'", "'ghost'");
}

TEST(UrdfImportError, MimicOfItself) {
  const std::string xml = robot(link("base") + link("a") + joint("ja", "revolute", "base", "a", R"(<mimic joint="ja"/>)"));
  EXPECT_MODEL_ERROR(build_urdf(xml), "test.urdf", "joint 'ja'", "mimics itself");
}

TEST(UrdfImportError, MimicTagsInACycle) {
  const std::string xml = robot(link("base") + link("a") + link("b") +
                                joint("ja", "revolute", "base", "a", R"(<mimic joint="jb"/>)") +
                                joint("jb", "revolute", "base", "b", R"(<mimic joint="ja"/>)"));
  EXPECT_MODEL_ERROR(build_urdf(xml), "test.urdf", "mimic tags form a cycle");
}

// A mimic tag on a fixed joint is ignored with a warning, but one naming no
// joint, or the joint itself, is malformed and refused with its line.
TEST(UrdfImportError, MimicTagOnAFixedJointNamingNoJoint) {
  for (const char* leader : {"ghost", "jf"}) {
    const std::string xml = robot(link("base") + link("a") + link("tool") + joint("ja", "revolute", "base", "a") +
                                  joint("jf", "fixed", "a", "tool", std::string("<mimic joint=\"") + leader + "\"/>"));
    EXPECT_MODEL_ERROR(parse(xml), "test.urdf:", "joint 'jf'", "mimic tag names");
  }
  std::vector<std::string> warnings;
  parse(robot(link("base") + link("a") + link("tool") + joint("ja", "revolute", "base", "a") +
              joint("jf", "fixed", "a", "tool", R"(<mimic joint="ja"/>)")),
        &warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("mimic tag on a fixed joint ignored"), std::string::npos) << warnings[0];
}

// ---- the robots in ../shared/models and the bundled quadruped -------------

struct RobotCase {
  const char* path;
  int movable;  // revolute + continuous + prismatic joints, counted in the file
};

const RobotCase kRobots[] = {
    {LOCKSTEP_SHARED_MODELS_DIR "/a1.urdf", 12},
    {LOCKSTEP_SHARED_MODELS_DIR "/allegro_right_hand.urdf", 16},
    {LOCKSTEP_SHARED_MODELS_DIR "/anymal_b.urdf", 12},
    {LOCKSTEP_SHARED_MODELS_DIR "/double_pendulum.urdf", 2},
    {LOCKSTEP_SHARED_MODELS_DIR "/finger_edu.urdf", 3},
    {LOCKSTEP_SHARED_MODELS_DIR "/panda.urdf", 9},
    {LOCKSTEP_SHARED_MODELS_DIR "/simple_humanoid.urdf", 29},
    {LOCKSTEP_SHARED_MODELS_DIR "/solo12.urdf", 12},
    {LOCKSTEP_SHARED_MODELS_DIR "/talos_reduced.urdf", 32},
    {LOCKSTEP_SHARED_MODELS_DIR "/ur5.urdf", 6},
    {LOCKSTEP_MODELS_DIR "/quadruped.urdf", 12},
};

// Link masses and the movable-joint count straight from the file.
struct RawRobot {
  std::map<std::string, double> mass;
  int movable = 0;
};

RawRobot read_raw(const std::string& path) {
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.LoadFile(path.c_str()), tinyxml2::XML_SUCCESS);
  RawRobot raw;
  const tinyxml2::XMLElement* robot_el = doc.RootElement();
  for (auto* l = robot_el->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
    const auto* in = l->FirstChildElement("inertial");
    const auto* m = in ? in->FirstChildElement("mass") : nullptr;
    raw.mass[l->Attribute("name")] = m ? m->DoubleAttribute("value") : 0.0;
  }
  for (auto* j = robot_el->FirstChildElement("joint"); j; j = j->NextSiblingElement("joint")) {
    const std::string type = j->Attribute("type");
    raw.movable += type == "revolute" || type == "continuous" || type == "prismatic";
  }
  return raw;
}

class Robots : public testing::TestWithParam<RobotCase> {};

TEST_P(Robots, LoadsFixedAndFloating) {
  const RobotCase& c = GetParam();
  const RawRobot raw = read_raw(c.path);
  ASSERT_EQ(raw.movable, c.movable);
  double total = 0.0;
  for (const auto& [name, m] : raw.mass) total += m;
  for (const bool floating : {false, true}) {
    SCOPED_TRACE(std::string(c.path) + (floating ? " floating" : " fixed"));
    UrdfOptions options;
    options.floating_base = floating;
    const Model m = load_urdf(c.path, options);
    EXPECT_EQ(m.nbody, c.movable + floating);
    EXPECT_EQ(m.nv, c.movable + 6 * floating);
    EXPECT_EQ(m.nq, c.movable + 7 * floating);
    EXPECT_EQ(m.frame_name.size(), raw.mass.size());
    double expected = total;
    for (std::size_t f = 0; f < m.frame_name.size(); ++f)
      if (m.frame_body[f] < 0) expected -= raw.mass.at(m.frame_name[f]);
    EXPECT_NEAR(m.total_mass(), expected, 1e-9 * total);
    if (!floating) {
      EXPECT_LT(m.total_mass(), total + 1e-12);
    }
    for (std::size_t f = 0; f < m.frame_name.size(); ++f) {
      const JointType t = m.frame_joint_type[f];
      if (t != JointType::Revolute && t != JointType::Prismatic) continue;
      const Eigen::Vector3d axis = m.frame_joint_axis[f].normalized();
      EXPECT_LT((m.frame_placement[f].linear() * axis - Eigen::Vector3d::UnitZ()).norm(), 1e-12) << m.frame_name[f];
      EXPECT_EQ(m.body_frame[m.frame_body[f]], static_cast<int>(f));
    }
    for (int b = 0; b < m.nbody; ++b) EXPECT_LT(m.body_parent[b], b);
  }
}

INSTANTIATE_TEST_SUITE_P(Models, Robots, testing::ValuesIn(kRobots), [](const testing::TestParamInfo<RobotCase>& param) {
  std::string name = fs::path(param.param.path).stem().string();
  for (char& ch : name)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  return name;
});

void expect_triangle_warnings_and_strict_failure(const std::string& path, const std::string& link_name) {
  std::vector<std::string> warnings;
  const ArticulationSpec spec = urdf_articulation_from_file(path, {}, &warnings);
  load_urdf(path, {}, {}, &warnings);
  bool named = false;
  for (const std::string& w : warnings)
    named = named || (w.find("triangle") != std::string::npos && w.find("'" + link_name + "'") != std::string::npos);
  EXPECT_TRUE(named) << "no triangle-inequality warning naming " << link_name;
  // Values are kept as written.
  const RawRobot raw = read_raw(path);
  for (const LinkSpec& l : spec.links) EXPECT_EQ(l.inertial.mass, raw.mass.at(l.name)) << l.name;
  BuildOptions strict;
  strict.strict = true;
  EXPECT_MODEL_ERROR(load_urdf(path, {}, strict), path.c_str(), "(an error in strict mode)");
  try {
    load_urdf(path, {}, strict);
  } catch (const ModelError& e) {
    EXPECT_EQ(std::string(e.what()).find("kept as written"), std::string::npos) << "strict mode keeps nothing";
  }
}

TEST(UrdfRobots, AllegroTriangleWarnings) {
  const std::string path = LOCKSTEP_SHARED_MODELS_DIR "/allegro_right_hand.urdf";
  expect_triangle_warnings_and_strict_failure(path, "link_1.0");
  // The inertia of one offending link survives exactly.
  const ArticulationSpec spec = urdf_articulation_from_file(path);
  tinyxml2::XMLDocument doc;
  doc.LoadFile(path.c_str());
  for (auto* l = doc.RootElement()->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
    if (std::string(l->Attribute("name")) != "link_1.0") continue;
    const auto* i = l->FirstChildElement("inertial")->FirstChildElement("inertia");
    for (const LinkSpec& s : spec.links)
      if (s.name == "link_1.0") {
        EXPECT_EQ(s.inertial.inertia(0, 0), i->DoubleAttribute("ixx"));
        EXPECT_EQ(s.inertial.inertia(1, 2), i->DoubleAttribute("iyz"));
        EXPECT_EQ(s.inertial.inertia(2, 2), i->DoubleAttribute("izz"));
      }
  }
}

TEST(UrdfRobots, TalosTriangleWarnings) {
  expect_triangle_warnings_and_strict_failure(LOCKSTEP_SHARED_MODELS_DIR "/talos_reduced.urdf",
                                              "gripper_left_motor_single_link");
}

TEST(UrdfRobots, BundledQuadrupedIsClean) {
  std::vector<std::string> warnings;
  BuildOptions strict;
  strict.strict = true;
  UrdfOptions options;
  options.floating_base = true;
  const Model m = load_urdf(LOCKSTEP_MODELS_DIR "/quadruped.urdf", options, strict, &warnings);
  EXPECT_TRUE(warnings.empty());
  EXPECT_NEAR(m.total_mass(), 13.6, 1e-12);
  EXPECT_GE(m.total_mass(), 10.0);
  EXPECT_LE(m.total_mass(), 15.0);
  EXPECT_EQ(m.shapes.size(), 17u);
  for (int d = 0; d < m.nv; ++d) {
    if (d < 6) continue;
    EXPECT_TRUE(std::isfinite(m.dof_lower[d]) && std::isfinite(m.dof_upper[d])) << m.dof_name[d];
    EXPECT_GT(m.dof_damping[d], 0.0);
    EXPECT_TRUE(std::isfinite(m.dof_effort_limit[d]));
  }
}

}  // namespace
}  // namespace lockstep
