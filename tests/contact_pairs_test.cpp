// Which shapes touch (batch/contact_pairs.hpp): the ground, adjacency,
// fused links, shapeless links between, self-collision, layers and named
// overrides; meshes noted; bad settings named; overflow counted; no
// collision code without shapes; a saved state with its warm start replays.
#include "tests/contact_support.hpp"
#include "tools/step_scene.hpp"

#include <gtest/gtest.h>

#include <algorithm>

namespace lockstep::test {
namespace {

// A fixed-base chain base - a - b - c - d (revolute about y), each link
// with a sphere (c without one when bare_c), and link e fused to d by a
// fixed joint, with a box.
Model chain(bool bare_c) {
  ArticulationSpec spec;
  spec.name = "chain";
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  std::string parent = "base";
  for (const char* name : {"a", "b", "c", "d"}) {
    LinkSpec link = joint_link(name, parent, JointType::Revolute, Eigen::Vector3d::UnitY(), Eigen::Vector3d(0, 0, -0.1));
    link.inertial.mass = 1.0;
    link.inertial.inertia = Eigen::Matrix3d::Identity() * 1e-3;
    if (!(bare_c && std::string(name) == "c")) {
      Shape s;
      s.type = ShapeType::Sphere;
      s.size = Eigen::Vector3d(0.03, 0, 0);
      link.shapes.push_back(s);
    }
    spec.links.push_back(link);
    parent = name;
  }
  LinkSpec e = joint_link("e", "d", JointType::Fixed, Eigen::Vector3d::UnitY(), Eigen::Vector3d(0, 0, -0.05));
  Shape s;
  s.type = ShapeType::Box;
  s.size = Eigen::Vector3d::Constant(0.02);
  e.shapes.push_back(s);
  spec.links.push_back(e);
  ModelBuilder builder;
  builder.add_articulation(spec);
  return builder.finalize();
}

// The frame-name pairs of the candidate pairs, sorted, "ground" for the plane.
std::vector<std::pair<std::string, std::string>> pair_names(const Model& model, const ContactSettings& settings) {
  std::vector<std::pair<std::string, std::string>> out;
  auto name = [&](const PairSide& side) {
    return side.shape == kGroundShape ? std::string("ground") : model.frame_name[model.shapes[side.shape].frame];
  };
  for (const ContactPair& p : build_contact_pairs(model, settings).pairs) {
    std::string x = name(p.a), y = name(p.b);
    if (y < x) std::swap(x, y);
    out.emplace_back(x, y);
  }
  std::sort(out.begin(), out.end());
  return out;
}

using Names = std::vector<std::pair<std::string, std::string>>;

TEST(ContactPairs, SelfCollisionSkipsAdjacentFusedAndShapelessLinks) {
  ContactSettings s;
  s.self_collision = {true};
  // a-b, b-c, c-d and c-e are adjacent (e is fused into d), d-e one body: left out
  EXPECT_EQ(pair_names(chain(false), s), (Names{{"a", "c"}, {"a", "d"}, {"a", "e"}, {"b", "d"}, {"b", "e"}}));
  // with c shapeless, b and d are joined only through it: left out too
  EXPECT_EQ(pair_names(chain(true), s), (Names{{"a", "d"}, {"a", "e"}}));
  s.self_collision = {false};
  EXPECT_TRUE(pair_names(chain(false), s).empty());
}

// In the step: drives (kp 50, kd 3; no gravity) hold joints a, c and d at 0
// and fold joint b from 1.7 rad towards 3.0 rad, where c's sphere would lie
// 1.4 cm from a's; the spheres (radius 3 cm each) meet at 6 cm, b at 2.53
// rad. With self-collision on the pair's contact stops the fold there (less
// than 1 mm deeper); off, c passes into a (to 2 cm and less). PGS and TGS,
// float and double.
TEST(ContactPairs, SelfCollisionStopsAFoldingChain) {
  const Model model = chain(false);
  const CopyDynamics dynamics(model);
  const int a = model.frame_index("a"), c = model.frame_index("c");
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 50, d.drive_damping = 3;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq), target = q;
  q[1] = 1.7;  // a and c 13 cm apart
  target[1] = 3.0;
  for (const Precision precision : {Precision::Float, Precision::Double})
    for (const SolverType solver : {SolverType::PGS, SolverType::TGS})
      for (const bool self : {true, false}) {
        StepOptions o;
        o.precision = precision;
        o.solver = solver;
        o.contacts.self_collision = {self};
        Simulator sim(model, 1, o, dofs);
        sim.set_gravity(0, Eigen::Vector3d::Zero());
        sim.set_state(0, q, Eigen::VectorXd::Zero(model.nv));
        sim.set_drive_target(0, target, Eigen::VectorXd::Zero(model.nv));
        double closest = 1.0;
        int touching = 0;
        for (int i = 0; i < 500; ++i) {  // 1 s
          sim.step();
          const std::vector<Eigen::Isometry3d> poses = dynamics.frame_poses(sim.q(0));
          closest = std::min(closest, (poses[a].translation() - poses[c].translation()).norm());
          touching += !sim.contacts(0).empty();
        }
        const std::string what = std::string(precision_name(precision)) + " " + solver_name(solver) +
                                 (self ? ", self-collision on" : ", off");
        EXPECT_EQ(sim.fault(0), Fault::None) << what;
        if (self) {
          EXPECT_GT(closest, 0.06 - 1e-3) << what;
          EXPECT_GT(touching, 0) << what;
        } else {
          EXPECT_LT(closest, 0.02) << what;
          EXPECT_EQ(touching, 0) << what;
        }
      }
}

// Links of one robot whose shapes overlap in its neutral pose are left out
// with self-collision on, each pair named in Simulator::warnings; named in
// enabled_pairs, a pair is kept. anymal_b's front hips' cylinders overlap
// by 6 mm across their joints' axes, where no motion of the joints can part
// them. Shapes that overlapped so (a1's hips, by 38 mm when its cylinders
// were capsules as long as themselves) were pushed apart with 1.5e16 N in
// the second step, and a1 standing in the bench pose turned to NaN by the
// seventh (double). Both robots now stand with self-collision on (|v|
// below 0.1 m/s after 1 s, as without it), in float and double.
TEST(ContactPairs, SelfCollisionLeavesOutLinksThatOverlapInTheNeutralPose) {
  const Model anymal = load_shared_model("anymal_b", true);
  ContactSettings s;
  s.self_collision = {true};
  const std::pair<std::string, std::string> hips("LF_HIP", "RF_HIP");
  const Names pairs = pair_names(anymal, s);
  // each hip has two cylinders: of their four pairs, the overlapping one goes
  EXPECT_EQ(std::count(pairs.begin(), pairs.end(), hips), 3);
  EXPECT_GT(pairs.size(), 10u) << "the other self pairs stay";
  s.enabled_pairs = {{"RF_HIP", "LF_HIP"}};
  const Names named = pair_names(anymal, s);
  EXPECT_EQ(std::count(named.begin(), named.end(), hips), 4);

  for (const char* robot : {"anymal_b", "a1"}) {
    const Model model = load_shared_model(robot, true);
    const step_scene::Scene scene = step_scene::make_scene(model, true);
    for (const Precision precision : {Precision::Float, Precision::Double}) {
      const std::string what = std::string(robot) + " " + precision_name(precision);
      StepOptions o;
      o.precision = precision;
      o.contacts.ground = true;
      o.contacts.self_collision = {true};
      Simulator sim(model, 1, o, scene.dofs);
      const std::vector<std::string> warnings = sim.warnings();
      if (std::string(robot) == "anymal_b")
        EXPECT_EQ(std::count_if(warnings.begin(), warnings.end(),
                                [](const std::string& w) {
                                  return w.find("self-collision: LF_HIP (cylinder, shape 9) and RF_HIP (cylinder, "
                                                "shape 17) overlap by 6 mm in the neutral pose, so they are left "
                                                "out") == 0;
                                }),
                  1)
            << ::testing::PrintToString(warnings);
      sim.set_state(0, scene.q0, scene.v0);
      sim.set_drive_target(0, scene.q_target, scene.v0);
      sim.step(500);
      EXPECT_EQ(sim.fault(0), Fault::None) << what;
      EXPECT_LT(sim.v(0).norm(), 0.1) << what;
    }
  }
}

// Every candidate number names the pair whose narrowphase makes it: the
// pairs' ranges [first_candidate, next pair's) tile [0, candidates).
TEST(ContactPairs, CandidateNumbersMapToTheirPair) {
  ContactSettings s;
  s.self_collision = {true};
  s.ground = true;
  const ContactPairs pairs = build_contact_pairs(chain(false), s);
  ASSERT_GT(pairs.pairs.size(), 2u);
  ASSERT_EQ(static_cast<int>(pairs.candidate_pair.size()), pairs.candidates);
  for (std::size_t p = 0; p < pairs.pairs.size(); ++p) {
    const int end = p + 1 < pairs.pairs.size() ? pairs.pairs[p + 1].first_candidate : pairs.candidates;
    ASSERT_LT(pairs.pairs[p].first_candidate, end) << "pair " << p << " has no candidates";
    for (int id = pairs.pairs[p].first_candidate; id < end; ++id)
      EXPECT_EQ(pairs.candidate_pair[id], static_cast<int>(p)) << "candidate " << id;
  }
  EXPECT_EQ(pairs.pairs.front().first_candidate, 0);
}

TEST(ContactPairs, NamedPairsOverrideAndLayersFilter) {
  const Model model = chain(false);
  ContactSettings s;
  s.enabled_pairs = {{"a", "b"}};  // adjacent, and self-collision off: enabled by name
  EXPECT_EQ(pair_names(model, s), (Names{{"a", "b"}}));
  s.self_collision = {true};
  s.disabled_pairs = {{"e", "a"}, {"c", "a"}};
  EXPECT_EQ(pair_names(model, s), (Names{{"a", "b"}, {"a", "d"}, {"b", "d"}, {"b", "e"}}));
  // the ground touches every moving shape whose layers meet its mask
  s = ContactSettings{};
  s.ground = true;
  s.shapes.assign(model.shapes.size(), ShapeContact{});
  s.shapes[0].layers = 2;              // a's sphere
  s.ground_contact.collides_with = 1;  // the ground meets layer 1 only
  EXPECT_EQ(pair_names(model, s), (Names{{"b", "ground"}, {"c", "ground"}, {"d", "ground"}, {"e", "ground"}}));
  s.enabled_pairs = {{"a", "nope"}};
  expect_invalid([&] { build_contact_pairs(model, s); }, "nope");
  // a name cannot make one body touch itself (e is fused into d): noted, where it once went unsaid
  s = ContactSettings{};
  s.self_collision = {true};
  s.enabled_pairs = {{"d", "e"}};
  EXPECT_EQ(pair_names(model, s), (Names{{"a", "c"}, {"a", "d"}, {"a", "e"}, {"b", "d"}, {"b", "e"}}));
  EXPECT_EQ(build_contact_pairs(model, s).notes,
            std::vector<std::string>{"enabled pair (\"d\", \"e\"): one body (links fused by fixed joints), and such "
                                     "shapes never touch"});
}

TEST(ContactPairs, BadSettingsAreNamed) {
  const Model model = chain(false);
  auto fails = [&](ContactSettings s, const char* piece) {
    StepOptions o;
    o.contacts = s;
    expect_invalid([&] { Simulator sim(model, 1, o); }, piece);
  };
  ContactSettings s;
  s.capacity = 0;
  fails(s, "capacity must lie in [1, 256] points per copy, got 0");
  s.capacity = kMaxContactCapacity + 1;  // its scratch would be gigabytes (or overflow int)
  fails(s, "capacity must lie in [1, 256] points per copy, got 257");
  s = {};
  s.shapes.assign(model.shapes.size(), ShapeContact{});
  s.shapes[2].friction = -1;
  fails(s, "shapes[2] (link c)");
  s = {};
  s.boxes.push_back(StaticBox{});
  s.boxes[0].half_extents.x() = 0;
  fails(s, "boxes[0]");
  s = {};
  s.boxes.push_back(StaticBox{});
  s.boxes[0].pose.linear() = Eigen::Vector3d(1, 1, 2).asDiagonal();  // a scale, not a rotation
  fails(s, "boxes[0]: pose's rotation is not a rotation matrix");
  s.boxes[0].pose.linear() = Eigen::Vector3d(1, 1, -1).asDiagonal();  // a reflection
  fails(s, "boxes[0]: pose's rotation is not a rotation matrix");
  s = {};
  s.ground_normal.setZero();
  fails(s, "ground_normal");
}

TEST(ContactPairs, MeshesAreNotedAndModelsWithoutShapesRunNoCollisionCode) {
  // solo12's collisions are meshes whose files are absent: dropped at import
  // with a warning; finger_edu likewise. A scene without shapes skips the stage.
  const Model model = load_shared_model("solo12", true);
  StepOptions o;
  o.contacts.ground = true;
  Simulator sim(model, 1, o);
  EXPECT_TRUE(sim.contact_pairs().pairs.empty());
  EXPECT_FALSE(sim.plan()[static_cast<int>(Stage::Contacts)].runs);
  EXPECT_NE(sim.describe_plan().find("contacts: skipped (no candidate shape pairs)"), std::string::npos);
  EXPECT_EQ(sim.bytes_per_copy(), Simulator(model, 1).bytes_per_copy()) << "no contact arrays";
  // a mesh shape that is present takes no part, and the pair list says so
  ModelBuilder builder;
  ArticulationSpec spec = free_shape_spec("thing", ShapeType::Sphere, Eigen::Vector3d(0.1, 0, 0), 1.0);
  spec.links[0].shapes[0].type = ShapeType::Mesh;
  spec.links[0].shapes[0].mesh_path = "thing.stl";
  builder.add_articulation(spec);
  const Model mesh_model = builder.finalize();
  const ContactPairs pairs = build_contact_pairs(mesh_model, o.contacts);
  EXPECT_TRUE(pairs.pairs.empty());
  ASSERT_EQ(pairs.notes.size(), 1u);
  EXPECT_NE(pairs.notes[0].find("thing.stl"), std::string::npos);
  // and the simulator's warnings (which `lockstep rollout` prints) carry it
  const Simulator mesh_sim(mesh_model, 1, o);
  EXPECT_EQ(mesh_sim.warnings(), pairs.notes);
}

// A box lying on the ground has 4 contact points; with capacity 2 the other
// two are dropped, counted per step and per copy, and the box still rests.
// A step of 4 pipeline runs (substeps) counts once, its drop not summed.
TEST(ContactPairs, OverflowIsCountedPerCopy) {
  const Model model = single_body(ShapeType::Box, Eigen::Vector3d::Constant(0.1), 1.0);
  for (const int substeps : {1, 4}) {
    StepOptions o;
    o.contacts.ground = true;
    o.contacts.capacity = 2;
    o.substeps = substeps;
    Simulator sim(model, 3, o);
    for (int c = 0; c < 3; ++c)
      sim.set_state(c, free_pose(Eigen::Vector3d(0, 0, c == 1 ? 1.0 : 0.1)), Eigen::VectorXd::Zero(6));
    sim.step(5);
    EXPECT_EQ(sim.contact_overflow(0).dropped, 2) << substeps << " substeps";
    EXPECT_EQ(sim.contact_overflow(0).overflow_steps, 5) << substeps << " substeps";
    EXPECT_EQ(sim.contact_overflow(1).dropped, 0) << "copy 1 is in the air";
    EXPECT_EQ(sim.contact_overflow(1).overflow_steps, 0) << "copy 1 is in the air";
    EXPECT_EQ(sim.contacts(0).size(), 2u);
    sim.reset(0);
    EXPECT_EQ(sim.contact_overflow(0).overflow_steps, 0);
  }
}

// A restored copy reports its snapshot's contacts and overflow, and goes on
// counting from there: a 0.1 m box on the ground keeps 2 of its 4 corner
// points (capacity 2) and drops 2 every step. Restored into a copy that was
// in the air, that copy once paired the snapshot's warm start with its own
// stale points and normals (zero normals, friction-only forces) and kept
// its own overflow count.
TEST(ContactPairs, RestoreCarriesTheContactReport) {
  const Model model = single_body(ShapeType::Box, Eigen::Vector3d::Constant(0.1), 1.0);
  StepOptions o;
  o.contacts.ground = true;
  o.contacts.capacity = 2;
  Simulator sim(model, 2, o);
  sim.set_state(0, free_pose(Eigen::Vector3d(0, 0, 0.1)), Eigen::VectorXd::Zero(6));
  sim.set_state(1, free_pose(Eigen::Vector3d(3, 0, 5)), Eigen::VectorXd::Zero(6));
  sim.step(10);
  ASSERT_EQ(sim.contacts(0).size(), 2u);
  ASSERT_TRUE(sim.contacts(1).empty());
  auto expect_same_report = [&](const std::string& when) {
    const std::vector<Contact> a = sim.contacts(0), b = sim.contacts(1);
    ASSERT_EQ(a.size(), b.size()) << when;
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].point, b[i].point) << when;
      EXPECT_EQ(a[i].normal, b[i].normal) << when;
      EXPECT_EQ(a[i].force, b[i].force) << when;
      EXPECT_EQ(a[i].separation, b[i].separation) << when;
    }
    EXPECT_EQ(sim.contact_overflow(0).dropped, sim.contact_overflow(1).dropped) << when;
    EXPECT_EQ(sim.contact_overflow(0).overflow_steps, sim.contact_overflow(1).overflow_steps) << when;
  };
  sim.restore(1, sim.snapshot(0));
  expect_same_report("after the restore");
  EXPECT_EQ(sim.contact_overflow(1).overflow_steps, 10);
  sim.step(5);
  expect_same_report("5 steps on");
  EXPECT_EQ(sim.contact_overflow(1).overflow_steps, 15);
}

// With substeps the step's contact wrenches (summed over its runs) are in
// snapshots and cleared by a reset or set_state; a snapshot of a simulator with one run
// per step, which has none, restores them as zero until the next step.
TEST(ContactPairs, SnapshotsCarryTheStepsContactWrenchesWithSubsteps) {
  const Model model = single_body(ShapeType::Box, Eigen::Vector3d::Constant(0.1), 1.0);
  StepOptions o;
  o.contacts.ground = true;
  o.substeps = 3;
  Simulator sim(model, 2, o);
  sim.set_state(0, free_pose(Eigen::Vector3d(0, 0, 0.1)), Eigen::VectorXd::Zero(6));
  sim.set_state(1, free_pose(Eigen::Vector3d(3, 0, 5)), Eigen::VectorXd::Zero(6));
  sim.step(10);
  const Eigen::Matrix<double, 6, Eigen::Dynamic> resting = sim.body_contact_wrenches(0);
  EXPECT_NEAR(resting(2, 0), 9.81, 1e-4) << "the box's weight";
  EXPECT_EQ(sim.body_contact_wrenches(1).norm(), 0.0);
  sim.restore(1, sim.snapshot(0));
  EXPECT_EQ(sim.body_contact_wrenches(1), resting);
  sim.reset(1);
  EXPECT_EQ(sim.body_contact_wrenches(1).norm(), 0.0);
  sim.restore(1, sim.snapshot(0));
  sim.set_state(1, free_pose(Eigen::Vector3d(3, 0, 5)), Eigen::VectorXd::Zero(6));  // no contacts until a step
  EXPECT_EQ(sim.body_contact_wrenches(1).norm(), 0.0);
  StepOptions one_run = o;
  one_run.substeps = 1;
  Simulator other(model, 1, one_run);
  other.set_state(0, free_pose(Eigen::Vector3d(0, 0, 0.1)), Eigen::VectorXd::Zero(6));
  other.step(10);
  sim.restore(1, other.snapshot(0));
  EXPECT_EQ(sim.body_contact_wrenches(1).norm(), 0.0);
  sim.step();
  EXPECT_NEAR(sim.body_contact_wrenches(1)(2, 0), 9.81, 1e-4);
}

// Contact forces per contact and per body: a 2 kg ball resting on the
// ground presses with 2 g; the body wrench holds the same force.
TEST(ContactPairs, ForcesPerContactAndPerBody) {
  const Model model = single_body(ShapeType::Sphere, Eigen::Vector3d(0.1, 0, 0), 2.0);
  StepOptions o;
  o.precision = Precision::Double;
  o.contacts.ground = true;
  Simulator sim(model, 1, o);
  sim.set_state(0, free_pose(Eigen::Vector3d(0.3, 0, 0.1)), Eigen::VectorXd::Zero(6));
  sim.step(50);
  const std::vector<Contact> contacts = sim.contacts(0);
  ASSERT_EQ(contacts.size(), 1u);
  EXPECT_EQ(contacts[0].shape_a, kGroundShape);
  EXPECT_NEAR(contacts[0].force.z(), 2 * 9.81, 1e-9);
  const Eigen::Matrix<double, 6, Eigen::Dynamic> w = sim.body_contact_wrenches(0);
  EXPECT_NEAR(w(2, 0), 2 * 9.81, 1e-9);
  EXPECT_NEAR(w(4, 0), -0.3 * 2 * 9.81, 1e-9) << "torque about the world origin: x cross f";
}

// The per-copy ground: one copy's plane raised by 0.5 m holds its ball there.
TEST(ContactPairs, GroundDiffersPerCopy) {
  const Model model = single_body(ShapeType::Sphere, Eigen::Vector3d(0.1, 0, 0), 1.0);
  StepOptions o;
  o.contacts.ground = true;
  Simulator sim(model, 2, o);
  sim.set_state_all(free_pose(Eigen::Vector3d(0, 0, 0.7)), Eigen::VectorXd::Zero(6));
  sim.set_ground(1, 0.5, Eigen::Vector3d::UnitZ(), 1.0);
  sim.step(500);
  EXPECT_NEAR(sim.q(0)[2], 0.1, 1e-3);
  EXPECT_NEAR(sim.q(1)[2], 0.6, 1e-3);
  Simulator no_ground(model, 1);
  expect_invalid([&] { no_ground.set_ground(0, 0.0, Eigen::Vector3d::UnitZ(), 1.0); }, "no ground");
}

// Tilt and friction per copy too: a 0.2 m cube (friction 0.5) on three
// copies' grounds, each pair's mu the mean of the two: flat; tilted 35
// degrees with ground friction 0.5 (mu 0.5 < tan 35 = 0.70: it slides at
// g (sin - mu cos) within 2 %, as in ContactPrecision.BoxOnInclineSticksOrSlides);
// tilted 35 degrees with ground friction 1.5 (mu 1.0: it sticks, less than
// 0.1 mm in 1 s). One block: the copies differ lane by lane.
TEST(ContactPairs, GroundTiltAndFrictionDifferPerCopy) {
  const double half = 0.1;
  const Incline incline(35 * kPi / 180);
  const Model model = single_body(ShapeType::Box, Eigen::Vector3d::Constant(half), 1.0);
  for (const Precision precision : {Precision::Float, Precision::Double}) {
    StepOptions o;
    o.precision = precision;
    o.contacts.ground = true;
    o.contacts.shapes = {ShapeContact{0.5, 0.0}};
    Simulator sim(model, 3, o);
    sim.set_ground(0, 0.0, Eigen::Vector3d::UnitZ(), 0.5);
    sim.set_ground(1, 0.0, incline.normal, 0.5);
    sim.set_ground(2, 0.0, incline.normal, 1.5);
    const Eigen::Vector3d start = half * incline.normal;
    sim.set_state(0, free_pose(Eigen::Vector3d(0, 0, half)), Eigen::VectorXd::Zero(6));
    for (int c = 1; c < 3; ++c) sim.set_state(c, free_pose(start, incline.tilt), Eigen::VectorXd::Zero(6));
    sim.step(500);  // 1 s
    auto travelled = [&](int c) { return (sim.q(c).head<3>() - start).dot(incline.downhill); };
    const double sliding = incline.sliding(0.5);
    const std::string what = precision_name(precision);
    EXPECT_LT((sim.q(0).head<3>() - Eigen::Vector3d(0, 0, half)).norm(), 1e-4) << what << ": flat";
    EXPECT_NEAR(2 * travelled(1), sliding, 0.02 * sliding) << what << ": mu 0.5 slides";
    EXPECT_LT(std::abs(travelled(2)), 1e-4) << what << ": mu 1.0 sticks";
  }
}

}  // namespace
}  // namespace lockstep::test
