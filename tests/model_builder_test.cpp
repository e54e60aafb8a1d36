#include "layout/model_builder.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace lockstep {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();


InertialSpec box_inertial(double mass, double x, double y, double z) {
  InertialSpec in;
  in.mass = mass;
  in.inertia = Eigen::Vector3d(mass / 12 * (y * y + z * z), mass / 12 * (x * x + z * z), mass / 12 * (x * x + y * y))
                   .asDiagonal();
  return in;
}

LinkSpec make_link(const std::string& name, const std::string& parent, JointType type,
                   const Eigen::Vector3d& axis = Eigen::Vector3d::UnitZ(), double mass = 1.0) {
  LinkSpec l = test::joint_link(name, parent, type, axis, Eigen::Vector3d(0.0, 0.0, 0.5));
  l.inertial = box_inertial(mass, 0.1, 0.2, 0.3);
  return l;
}

// base -> a (revolute x) -> a_tip (fixed)
//      -> b (prismatic y) -> c (spherical)
ArticulationSpec sample(const std::string& name = "robot", bool floating = false) {
  ArticulationSpec s;
  s.name = name;
  s.floating_base = floating;
  s.links.push_back(make_link(name + "_base", "", JointType::Fixed));
  s.links.push_back(make_link(name + "_a", name + "_base", JointType::Revolute, Eigen::Vector3d::UnitX()));
  s.links.push_back(make_link(name + "_b", name + "_base", JointType::Prismatic, Eigen::Vector3d::UnitY()));
  s.links.push_back(make_link(name + "_a_tip", name + "_a", JointType::Fixed));
  s.links.push_back(make_link(name + "_c", name + "_b", JointType::Spherical));
  return s;
}

Model build(const ArticulationSpec& spec, BuildOptions options = {}) {
  ModelBuilder b(options);
  b.add_articulation(spec);
  return b.finalize();
}

void expect_near(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, double tol = 1e-12) {
  ASSERT_EQ(a.rows(), b.rows());
  ASSERT_EQ(a.cols(), b.cols());
  EXPECT_LE((a - b).cwiseAbs().maxCoeff(), tol) << "\n" << a << "\nvs\n" << b;
}

TEST(ModelBuilder, DepthFirstOrderAcrossArticulations) {
  ModelBuilder b;
  b.add_articulation(sample("one"));
  b.add_articulation(sample("two", true));
  const Model m = b.finalize();
  ASSERT_EQ(m.nbody, 3 + 4);
  const std::vector<std::string> frames = {"one_base", "one_a", "one_a_tip", "one_b", "one_c",
                                           "two_base", "two_a", "two_a_tip", "two_b", "two_c"};
  EXPECT_EQ(m.frame_name, frames);
  EXPECT_EQ(m.body_parent, (std::vector<int>{-1, -1, 1, -1, 3, 3, 5}));
  for (int i = 0; i < m.nbody; ++i) EXPECT_LT(m.body_parent[i], i);
  EXPECT_EQ(m.frame_parent, (std::vector<int>{-1, 0, 1, 0, 3, -1, 5, 6, 5, 8}));
  EXPECT_EQ(m.frame_body, (std::vector<int>{-1, 0, 0, 1, 2, 3, 4, 4, 5, 6}));
  EXPECT_EQ(m.body_frame, (std::vector<int>{1, 3, 4, 5, 6, 8, 9}));
  EXPECT_EQ(m.body_articulation, (std::vector<int>{0, 0, 0, 1, 1, 1, 1}));
  ASSERT_EQ(m.articulations.size(), 2u);
  EXPECT_EQ(m.articulations[1].name, "two");
  EXPECT_TRUE(m.articulations[1].floating_base);
  EXPECT_EQ(m.articulations[1].first_body, 3);
  EXPECT_EQ(m.articulations[1].body_count, 4);
  EXPECT_EQ(m.articulations[1].root_frame, 5);
  EXPECT_EQ(m.articulations[0].root_frame, 0);
  EXPECT_EQ(m.frame_index("two_c"), 9);
  EXPECT_EQ(m.joint_index("two_root"), 3);
  EXPECT_EQ(m.joint_index("one_b_joint"), 1);
  EXPECT_EQ(m.frame_joint_type[2], JointType::Fixed);
  EXPECT_EQ(m.frame_joint_name[2], "one_a_tip_joint");
  EXPECT_EQ(m.frame_joint_name[0], "");
  EXPECT_EQ(m.frame_joint_type[5], JointType::Free);
  EXPECT_EQ(m.frame_articulation[7], 1);
}

TEST(ModelBuilder, DofLayout) {
  ArticulationSpec s = sample("r", true);
  s.links[1].joint.limited = true;
  s.links[1].joint.lower = -1.0;
  s.links[1].joint.upper = 2.0;
  s.links[1].joint.velocity_limit = 3.0;
  s.links[1].joint.effort_limit = 4.0;
  s.links[1].joint.damping = 0.5;
  s.links[1].joint.friction = 0.25;
  s.links[1].joint.armature = 0.125;
  s.links[4].joint.damping = 0.75;
  const Model m = build(s);
  EXPECT_EQ(m.nq, 7 + 1 + 1 + 4);
  EXPECT_EQ(m.nv, 6 + 1 + 1 + 3);
  EXPECT_EQ(m.body_q_offset, (std::vector<int>{0, 7, 8, 9}));
  EXPECT_EQ(m.body_dof_offset, (std::vector<int>{0, 6, 7, 8}));
  EXPECT_EQ(m.dof_name[0], "r_root[0]");
  EXPECT_EQ(m.dof_name[6], "r_a_joint");
  EXPECT_EQ(m.dof_name[10], "r_c_joint[2]");
  EXPECT_EQ(m.dof_index("r_c_joint[1]"), 9);
  EXPECT_EQ(m.dof_parent, (std::vector<int>{-1, 0, 1, 2, 3, 4, 5, 5, 7, 8, 9}));
  EXPECT_EQ(m.dof_body, (std::vector<int>{0, 0, 0, 0, 0, 0, 1, 2, 3, 3, 3}));
  EXPECT_EQ(m.dof_lower[6], -1.0);
  EXPECT_EQ(m.dof_upper[6], 2.0);
  EXPECT_EQ(m.dof_velocity_limit[6], 3.0);
  EXPECT_EQ(m.dof_effort_limit[6], 4.0);
  EXPECT_EQ(m.dof_damping[6], 0.5);
  EXPECT_EQ(m.dof_friction[6], 0.25);
  EXPECT_EQ(m.dof_armature[6], 0.125);
  EXPECT_EQ(m.dof_lower[7], -Model::kInfinity);  // not limited
  EXPECT_EQ(m.dof_upper[7], Model::kInfinity);
  for (int d = 8; d < 11; ++d) {
    EXPECT_EQ(m.dof_damping[d], 0.75);
    EXPECT_EQ(m.dof_lower[d], -Model::kInfinity);
  }
  EXPECT_EQ(m.body_joint[0], JointType::Free);
  EXPECT_TRUE(m.body_placement[0].isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_EQ(m.joint_name[3], "r_c_joint");
}

TEST(ModelBuilder, RootJointNameFromSpec) {
  ArticulationSpec s = sample("r", true);
  s.links[0].joint.name = "float";
  const Model m = build(s);
  EXPECT_EQ(m.joint_name[0], "float");
  EXPECT_EQ(m.frame_joint_name[0], "float");
}

TEST(ModelBuilder, FixedBaseFusedIntoWorld) {
  ArticulationSpec s = sample();
  s.root_pose.translation() = Eigen::Vector3d(1.0, 2.0, 3.0);
  s.root_pose.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  s.links.push_back(make_link("robot_plate", "robot_base", JointType::Fixed, Eigen::Vector3d::UnitZ(), 5.0));
  const Model m = build(s);
  EXPECT_EQ(m.frame_body[0], -1);
  EXPECT_TRUE(m.frame_placement[0].isApprox(s.root_pose));
  const int plate = m.frame_index("robot_plate");
  EXPECT_EQ(m.frame_body[plate], -1);
  EXPECT_TRUE(m.frame_placement[plate].isApprox(s.root_pose * s.links.back().joint.origin));
  // The revolute joint on the base is placed relative to the world.
  expect_near(m.body_placement[0].translation(), s.root_pose * Eigen::Vector3d(0, 0, 0.5));
  EXPECT_DOUBLE_EQ(m.total_mass(), 4.0);  // base (1) and plate (5) dropped
}

TEST(ModelBuilder, JointAxisBecomesBodyZ) {
  ArticulationSpec s = sample();
  const Eigen::Vector3d axis(1.0, -2.0, 0.5);
  s.links[1].joint.axis = axis;
  s.links[1].joint.origin.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  const Model m = build(s);
  const Eigen::Vector3d a = axis.normalized();
  // Body z axis, seen in the parent (world) frame, is the joint axis there.
  expect_near(m.body_placement[0].linear() * Eigen::Vector3d::UnitZ(), s.links[1].joint.origin.linear() * a);
  expect_near(m.body_placement[0].translation(), s.links[1].joint.origin.translation());
  // The link frame in the body: rotation(frame_placement) * axis == e_z.
  const int f = m.frame_index("robot_a");
  expect_near(m.frame_placement[f].linear() * a, Eigen::Vector3d::UnitZ());
  expect_near(m.frame_placement[f].translation(), Eigen::Vector3d::Zero());
  EXPECT_EQ(m.frame_joint_axis[f], axis);
  // Link frame composed with the body placement gives back the joint frame.
  EXPECT_TRUE((m.body_placement[0] * m.frame_placement[f]).isApprox(s.links[1].joint.origin));
}

TEST(ModelBuilder, AxisAlongZAndMinusZ) {
  ArticulationSpec s = sample();
  s.links[1].joint.axis = Eigen::Vector3d(0, 0, 2.0);
  s.links[2].joint.type = JointType::Revolute;
  s.links[2].joint.axis = Eigen::Vector3d(0, 0, -1.0);
  const Model m = build(s);
  EXPECT_TRUE(m.frame_placement[m.frame_index("robot_a")].linear().isIdentity(0.0));
  const Eigen::Matrix3d flip = Eigen::Vector3d(1, -1, -1).asDiagonal();
  EXPECT_EQ(m.body_placement[1].linear(), flip);
  EXPECT_EQ(m.frame_placement[m.frame_index("robot_b")].linear(), flip);
}

TEST(ModelBuilder, SphericalKeepsJointFrame) {
  const ArticulationSpec s = sample();
  const Model m = build(s);
  EXPECT_EQ(m.body_joint[2], JointType::Spherical);
  EXPECT_TRUE(m.body_placement[2].isApprox(m.frame_placement[m.frame_index("robot_b")] * s.links[4].joint.origin));
  EXPECT_TRUE(m.frame_placement[m.frame_index("robot_c")].isApprox(Eigen::Isometry3d::Identity()));
}

TEST(ModelBuilder, FixedChildLumpedByParallelAxis) {
  ArticulationSpec s = sample();
  LinkSpec& a = s.links[1];
  a.joint.axis = Eigen::Vector3d::UnitZ();
  a.inertial = box_inertial(2.0, 0.1, 0.1, 0.1);
  a.inertial.origin.translation() = Eigen::Vector3d(0.1, 0.0, 0.0);
  LinkSpec& tip = s.links[3];
  tip.joint.origin = Eigen::Isometry3d::Identity();
  tip.joint.origin.translation() = Eigen::Vector3d(0.0, 0.4, 0.0);
  tip.joint.origin.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  tip.inertial = box_inertial(3.0, 0.1, 0.2, 0.3);
  tip.inertial.origin.translation() = Eigen::Vector3d(0.0, 0.0, 0.2);  // in tip frame: +z_tip = -y_body
  const Model m = build(s);
  EXPECT_DOUBLE_EQ(m.body_mass[0], 5.0);
  const Eigen::Vector3d c1(0.1, 0.0, 0.0), c2 = tip.joint.origin * Eigen::Vector3d(0, 0, 0.2);
  expect_near(c2, Eigen::Vector3d(0.0, 0.2, 0.0));
  const Eigen::Vector3d com = (2.0 * c1 + 3.0 * c2) / 5.0;
  expect_near(m.body_com[0], com);
  const Eigen::Matrix3d r2 = tip.joint.origin.linear();
  auto shift = [](double mass, const Eigen::Vector3d& d) {
    return Eigen::Matrix3d(mass * (d.squaredNorm() * Eigen::Matrix3d::Identity() - d * d.transpose()));
  };
  const Eigen::Matrix3d expected = a.inertial.inertia + shift(2.0, c1 - com) +
                                   r2 * tip.inertial.inertia * r2.transpose() + shift(3.0, c2 - com);
  expect_near(m.body_inertia[0], expected);
  EXPECT_EQ(m.frame_body[m.frame_index("robot_a_tip")], 0);
}

TEST(ModelBuilder, RotatedInertialAndExactSingleLinkValues) {
  ArticulationSpec s = sample();
  s.links[2].joint.axis = Eigen::Vector3d::UnitZ();
  s.links[2].inertial.inertia << 0.3, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.4;
  const Eigen::Matrix3d rc = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  s.links[2].inertial.origin.linear() = rc;
  s.links[2].inertial.origin.translation() = Eigen::Vector3d(0.1, 0.2, 0.3);
  s.links[1].inertial.inertia << 0.3, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.4;
  const Model m = build(s);
  expect_near(m.body_inertia[1], rc * s.links[2].inertial.inertia * rc.transpose(), 1e-15);
  EXPECT_EQ(m.body_com[1], Eigen::Vector3d(0.1, 0.2, 0.3));
  // Identity rotations keep the values bit for bit (a: axis x; c: spherical).
  EXPECT_EQ(m.body_inertia[2], s.links[4].inertial.inertia);
  EXPECT_EQ(m.body_mass[2], s.links[4].inertial.mass);
}

TEST(ModelBuilder, ShapesInBodyFrame) {
  ArticulationSpec s = sample();
  Shape box;
  box.type = ShapeType::Box;
  box.size = Eigen::Vector3d(0.1, 0.2, 0.3);
  box.pose.translation() = Eigen::Vector3d(0.0, 0.0, 0.1);
  s.links[3].shapes.push_back(box);
  s.links[0].shapes.push_back(box);
  const Model m = build(s);
  ASSERT_EQ(m.shapes.size(), 2u);
  EXPECT_EQ(m.shapes[0].body, -1);
  EXPECT_EQ(m.shapes[0].frame, 0);
  const int tip = m.frame_index("robot_a_tip");
  EXPECT_EQ(m.shapes[1].body, 0);
  EXPECT_EQ(m.shapes[1].frame, tip);
  EXPECT_TRUE(m.shapes[1].pose.isApprox(m.frame_placement[tip] * box.pose));
  EXPECT_EQ(m.shapes[1].size, box.size);
}

TEST(ModelBuilder, MimicAcrossArticulations) {
  ArticulationSpec one = sample("one");
  one.links[1].joint.mimic.leader_joint = "two_b_joint";
  one.links[1].joint.mimic.multiplier = -2.0;
  one.links[1].joint.mimic.offset = 0.5;
  ModelBuilder b;
  b.add_articulation(one);
  b.add_articulation(sample("two"));
  const Model m = b.finalize();
  ASSERT_EQ(m.mimics.size(), 1u);
  EXPECT_EQ(m.mimics[0].dof, m.dof_index("one_a_joint"));
  EXPECT_EQ(m.mimics[0].leader_dof, m.dof_index("two_b_joint"));
  EXPECT_EQ(m.mimics[0].multiplier, -2.0);
  EXPECT_EQ(m.mimics[0].offset, 0.5);
}

TEST(ModelBuilder, GravityAndMessagesNameTheSource) {
  ModelBuilder b;
  b.set_gravity(Eigen::Vector3d(0, 0, -1.62));
  b.add_articulation(sample());
  EXPECT_EQ(b.finalize().gravity, Eigen::Vector3d(0, 0, -1.62));
  ArticulationSpec s = sample();
  s.source = "robots/arm.urdf";
  s.links[2].inertial.mass = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robots/arm.urdf", "robot_b");
}

// ---- errors: one test per case -------------------------------------------

TEST(ModelBuilderError, NegativeMass) {
  ArticulationSpec s = sample();
  s.links[2].inertial.mass = -0.5;
  EXPECT_MODEL_ERROR(build(s), "articulation 'robot'", "link 'robot_b'", "negative mass");
}

TEST(ModelBuilderError, NonFiniteMass) {
  ArticulationSpec s = sample();
  s.links[2].inertial.mass = kNaN;
  EXPECT_MODEL_ERROR(build(s), "robot_b", "mass");
}

TEST(ModelBuilderError, NonFiniteInertia) {
  ArticulationSpec s = sample();
  s.links[1].inertial.inertia(1, 1) = std::numeric_limits<double>::infinity();
  EXPECT_MODEL_ERROR(build(s), "robot_a", "inertia");
}

TEST(ModelBuilderError, NonFiniteInertialOrigin) {
  ArticulationSpec s = sample();
  s.links[1].inertial.origin.translation().x() = kNaN;
  EXPECT_MODEL_ERROR(build(s), "robot_a", "inertial origin");
}

TEST(ModelBuilderError, NonFiniteJointOrigin) {
  ArticulationSpec s = sample();
  s.links[3].joint.origin.translation().y() = kNaN;
  EXPECT_MODEL_ERROR(build(s), "robot_a_tip_joint", "origin");
}

TEST(ModelBuilderError, NonFiniteAxis) {
  ArticulationSpec s = sample();
  s.links[1].joint.axis.x() = kNaN;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "axis");
}

TEST(ModelBuilderError, NonFiniteLimit) {
  ArticulationSpec s = sample();
  s.links[1].joint.limited = true;
  s.links[1].joint.lower = kNaN;
  s.links[1].joint.upper = 1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "limits");
}

TEST(ModelBuilderError, NonFiniteVelocityLimit) {
  ArticulationSpec s = sample();
  s.links[1].joint.velocity_limit = kNaN;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "velocity limit");
}

TEST(ModelBuilderError, NonFiniteDamping) {
  ArticulationSpec s = sample();
  s.links[2].joint.damping = std::numeric_limits<double>::infinity();
  EXPECT_MODEL_ERROR(build(s), "robot_b_joint", "damping");
}

TEST(ModelBuilderError, AsymmetricInertia) {
  ArticulationSpec s = sample();
  s.links[1].inertial.inertia(0, 1) = 0.001;
  EXPECT_MODEL_ERROR(build(s), "robot_a", "not symmetric");
}

TEST(ModelBuilderError, NegativeEigenvalue) {
  ArticulationSpec s = sample();
  s.links[1].inertial.inertia = Eigen::Vector3d(0.1, 0.1, -0.01).asDiagonal();
  EXPECT_MODEL_ERROR(build(s), "robot_a", "positive semi-definite");
}

TEST(ModelBuilder, TinyNegativeEigenvalueIsRoundOff) {
  ArticulationSpec s = sample();
  s.links[2].joint.axis = Eigen::Vector3d::UnitZ();
  s.links[2].inertial.inertia = Eigen::Vector3d(0.1, 0.1, -1e-15).asDiagonal();
  ModelBuilder b;
  b.add_articulation(s);
  const Model m = b.finalize();
  EXPECT_EQ(m.body_inertia[1](2, 2), -1e-15);  // kept as written
}

// The tolerance is relative to the link's inertia: at a scale of 1e-6
// kg m^2, an eigenvalue of -1e-19 (1e-13 of the scale) is round-off, one of
// -1e-17 (1e-11) is an error, although both are far below 1e-12 absolute.
TEST(ModelBuilder, NegativeEigenvalueToleranceIsRelative) {
  ArticulationSpec s = sample();
  s.links[1].inertial.inertia = Eigen::Vector3d(1e-6, 1e-6, -1e-19).asDiagonal();
  EXPECT_NO_THROW(build(s));
  s.links[1].inertial.inertia = Eigen::Vector3d(1e-6, 1e-6, -1e-17).asDiagonal();
  EXPECT_MODEL_ERROR(build(s), "robot_a", "positive semi-definite");
}

TEST(ModelBuilderError, MasslessMovingSubtree) {
  ArticulationSpec s = sample();
  s.links[1].inertial = InertialSpec{};
  s.links[3].inertial = InertialSpec{};
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "massless");
}

TEST(ModelBuilder, MasslessLinkWithMassiveChildIsFine) {
  ArticulationSpec s = sample();
  s.links[1].inertial = InertialSpec{};  // a's child a_tip has mass
  EXPECT_NO_THROW(build(s));
}

TEST(ModelBuilderError, MasslessFloatingArticulation) {
  ArticulationSpec s;
  s.name = "ghost";
  s.floating_base = true;
  s.links.push_back(make_link("ghost_base", "", JointType::Fixed, Eigen::Vector3d::UnitZ(), 0.0));
  s.links[0].inertial = InertialSpec{};
  EXPECT_MODEL_ERROR(build(s), "ghost", "no mass");
}

TEST(ModelBuilderError, LowerAboveUpper) {
  ArticulationSpec s = sample();
  s.links[1].joint.limited = true;
  s.links[1].joint.lower = 1.0;
  s.links[1].joint.upper = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "exceeds upper");
}

TEST(ModelBuilderError, ZeroAxis) {
  ArticulationSpec s = sample();
  s.links[2].joint.axis.setZero();
  EXPECT_MODEL_ERROR(build(s), "robot_b_joint", "zero axis");
}

TEST(ModelBuilderError, NegativeVelocityLimit) {
  ArticulationSpec s = sample();
  s.links[1].joint.velocity_limit = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "negative velocity limit");
}

TEST(ModelBuilderError, NegativeEffortLimit) {
  ArticulationSpec s = sample();
  s.links[1].joint.effort_limit = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "negative effort limit");
}

TEST(ModelBuilderError, NegativeDamping) {
  ArticulationSpec s = sample();
  s.links[1].joint.damping = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "negative damping");
}

TEST(ModelBuilderError, NegativeFriction) {
  ArticulationSpec s = sample();
  s.links[1].joint.friction = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "negative friction");
}

TEST(ModelBuilderError, NegativeArmature) {
  ArticulationSpec s = sample();
  s.links[1].joint.armature = -1.0;
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "negative armature");
}

TEST(ModelBuilderError, MimicLeaderMissing) {
  ArticulationSpec s = sample();
  s.links[1].joint.mimic.leader_joint = "nowhere";
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "'nowhere'");
}

TEST(ModelBuilderError, MimicLeaderIsItself) {
  ArticulationSpec s = sample();
  s.links[1].joint.mimic.leader_joint = "robot_a_joint";
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "mimics itself");
}

TEST(ModelBuilderError, MimicTagsInACycle) {
  ArticulationSpec s = sample();
  s.links[1].joint.mimic.leader_joint = "robot_b_joint";
  s.links[2].joint.mimic.leader_joint = "robot_a_joint";
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "mimic tags form a cycle",
                     "robot_a_joint follows robot_b_joint follows robot_a_joint");
  s.links[2].joint.mimic.leader_joint.clear();  // a chain that ends is fine
  EXPECT_EQ(build(s).mimics.size(), 1u);
}

TEST(ModelBuilderError, MimicLeaderNotOneDof) {
  ArticulationSpec s = sample();
  s.links[1].joint.mimic.leader_joint = "robot_c_joint";
  EXPECT_MODEL_ERROR(build(s), "robot_a_joint", "robot_c_joint");
}

TEST(ModelBuilderError, MimicFollowerNotOneDof) {
  ArticulationSpec s = sample();
  s.links[4].joint.mimic.leader_joint = "robot_a_joint";
  EXPECT_MODEL_ERROR(build(s), "robot_c_joint", "mimic");
}

TEST(ModelBuilderError, FreeJointInsideTree) {
  ArticulationSpec s = sample();
  s.links[2].joint.type = JointType::Free;
  EXPECT_MODEL_ERROR(build(s), "robot_b_joint", "floating joint inside the tree is not supported");
}

TEST(ModelBuilderError, DuplicateLinkAcrossArticulations) {
  ModelBuilder b;
  b.add_articulation(sample("one"));
  ArticulationSpec two = sample("two");
  two.links[4].name = "one_a";
  EXPECT_MODEL_ERROR(b.add_articulation(two), "'one_a'", "articulation 'one'", "articulation 'two'");
}

TEST(ModelBuilderError, DuplicateLinkInArticulation) {
  ArticulationSpec s = sample();
  s.links[4].name = "robot_a";
  EXPECT_MODEL_ERROR(build(s), "robot_a", "duplicate link name");
}

TEST(ModelBuilderError, DuplicateJointAcrossArticulations) {
  ModelBuilder b;
  b.add_articulation(sample("one"));
  ArticulationSpec two = sample("two");
  two.links[2].joint.name = "one_a_tip_joint";
  EXPECT_MODEL_ERROR(b.add_articulation(two), "'one_a_tip_joint'", "articulation 'one'", "articulation 'two'");
}

TEST(ModelBuilderError, ParentMissing) {
  ArticulationSpec s = sample();
  s.links[2].parent = "nobody";
  EXPECT_MODEL_ERROR(build(s), "robot_b", "'nobody' does not exist");
}

TEST(ModelBuilderError, ParentListedAfterChild) {
  ArticulationSpec s = sample();
  s.links[1].parent = "robot_c";
  EXPECT_MODEL_ERROR(build(s), "robot_a", "listed after the child");
}

// Found among the listed links, a link's own name once made it its own
// parent: dropped from the model with its shapes and everything below it.
TEST(ModelBuilderError, LinkIsItsOwnParent) {
  ArticulationSpec s = sample();
  s.links[2].parent = "robot_b";
  EXPECT_MODEL_ERROR(build(s), "robot_b", "its own parent");
}

// A joint's DOF names ("ball[1]") may not be another joint's name.
TEST(ModelBuilderError, DuplicateDofName) {
  ArticulationSpec s = sample();
  s.links[4].joint.name = "ball";  // spherical: DOFs ball[0], ball[1], ball[2]
  s.links[1].joint.name = "ball[1]";
  EXPECT_MODEL_ERROR(build(s), "'ball[1]'", "already another DOF's");
}

// Only the root's joint name counts: its other values (which no check
// sees) do not reach the Free joint's DOFs.
TEST(ModelBuilder, FloatingRootTakesOnlyItsJointName) {
  ArticulationSpec s = sample("r", true);
  s.links[0].joint.name = "float";
  s.links[0].joint.armature = -1.0;
  s.links[0].joint.damping = -3.0;
  s.links[0].joint.friction = kNaN;
  s.links[0].joint.effort_limit = -2.0;
  const Model m = build(s);
  EXPECT_EQ(m.joint_name[0], "float");
  for (int d = 0; d < 6; ++d) {
    EXPECT_EQ(m.dof_armature[d], 0.0);
    EXPECT_EQ(m.dof_damping[d], 0.0);
    EXPECT_EQ(m.dof_friction[d], 0.0);
    EXPECT_EQ(m.dof_effort_limit[d], Model::kInfinity);
  }
}

// Axes whose norm overflows or underflows in plain arithmetic: 1e200 became
// the zero vector and the joint turned about -z (so did (1.7e308, 1.7e308,
// 0), whose norm overflows even computed stably).
TEST(ModelBuilder, HugeAndTinyAxesKeepTheirDirection) {
  for (double scale : {1e200, 1.7e308, 1e-200, 4.9e-324}) {
    ArticulationSpec s = sample();
    s.links[1].joint.axis = Eigen::Vector3d(scale, scale, 0);
    const Model m = build(s);
    expect_near(m.body_placement[0].linear() * Eigen::Vector3d::UnitZ(), Eigen::Vector3d(1, 1, 0).normalized(),
                1e-15);
  }
}

TEST(ModelBuilderError, SeveralRoots) {
  ArticulationSpec s = sample();
  s.links[2].parent.clear();
  EXPECT_MODEL_ERROR(build(s), "robot_b", "several roots");
}

// ---- warnings ------------------------------------------------------------

TEST(ModelBuilderWarning, MasslessFixedLink) {
  ArticulationSpec s = sample();
  s.links[3].inertial = InertialSpec{};
  ModelBuilder b;
  b.add_articulation(s);
  ASSERT_EQ(b.warnings().size(), 1u);
  EXPECT_NE(b.warnings()[0].find("robot_a_tip"), std::string::npos);
  BuildOptions strict;
  strict.strict = true;
  EXPECT_MODEL_ERROR(build(s, strict), "robot_a_tip", "massless");
}

// A point mass warns, naming its link, on a fixed joint (robot_a_tip, fused)
// and inside the chain on a moving joint (robot_a); strict refuses it.
TEST(ModelBuilderWarning, PointMass) {
  for (const int link : {3, 1}) {
    ArticulationSpec s = sample();
    s.links[link].inertial.inertia.setZero();
    const std::string name = "link '" + s.links[link].name + "'";
    ModelBuilder b;
    b.add_articulation(s);
    ASSERT_EQ(b.warnings().size(), 1u);
    EXPECT_NE(b.warnings()[0].find(name), std::string::npos) << b.warnings()[0];
    EXPECT_NE(b.warnings()[0].find("point mass"), std::string::npos) << b.warnings()[0];
    EXPECT_EQ(b.finalize().nbody, 3) << "it loads";
    BuildOptions strict;
    strict.strict = true;
    EXPECT_MODEL_ERROR(build(s, strict), name.c_str(), "point mass");
  }
}

TEST(ModelBuilderWarning, TriangleInequalityKeepsValues) {
  ArticulationSpec s = sample();
  s.links[2].joint.axis = Eigen::Vector3d::UnitZ();
  s.links[2].inertial.inertia = Eigen::Vector3d(0.1, 0.1, 0.5).asDiagonal();
  ModelBuilder b;
  b.add_articulation(s);
  ASSERT_EQ(b.warnings().size(), 1u);
  EXPECT_NE(b.warnings()[0].find("robot_b"), std::string::npos);
  EXPECT_NE(b.warnings()[0].find("triangle"), std::string::npos);
  EXPECT_EQ(b.finalize().body_inertia[1], s.links[2].inertial.inertia);
  BuildOptions strict;
  strict.strict = true;
  EXPECT_MODEL_ERROR(build(s, strict), "robot_b", "triangle");
}

TEST(ModelBuilderWarning, CleanModelHasNone) {
  ModelBuilder b;
  b.add_articulation(sample());
  EXPECT_TRUE(b.warnings().empty());
}

}  // namespace
}  // namespace lockstep
