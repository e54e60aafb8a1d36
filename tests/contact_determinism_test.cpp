// Contacts keep the step's guarantees: a copy's trajectory is the same bit
// for bit whatever the other copies in its block do, the batch size, the
// thread count and the lanes (SIMD or scalar), and a restored snapshot
// (state and warm start) replays bit for bit. Scene: anymal_b dropped on
// the ground next to a static step from random heights and poses under
// random PD targets, so that in one block some copies touch with several
// feet (and more), some with one and some not at all; float and double,
// PGS and TGS.
#include "tests/contact_support.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <random>

namespace lockstep::test {
namespace {

constexpr int kSteps = 40;

struct Case {
  Precision precision;
  SolverType solver;
};

class ContactDeterminism : public ::testing::TestWithParam<Case> {
 protected:
  void SetUp() override {
    UrdfOptions floating;
    floating.floating_base = true;
    model_ = load_urdf(shared_model_path("anymal_b"), floating);
    dofs_ = default_dof_settings(model_);
    for (int k = 6; k < model_.nv; ++k) dofs_[k].drive_stiffness = 200, dofs_[k].drive_damping = 5;
  }

  StepOptions options(Lanes lanes = Lanes::Simd) const {
    StepOptions o;
    o.precision = GetParam().precision;
    o.solver = GetParam().solver;
    o.iterations = 8;
    o.lanes = lanes;
    o.contacts.ground = true;
    StaticBox step;  // 1.5 cm high, under the front feet of copies shifted forward
    step.pose.translation() = Eigen::Vector3d(0.6, 0, 0.0);
    step.half_extents = Eigen::Vector3d(0.2, 1.0, 0.015);
    o.contacts.boxes.push_back(step);
    return o;
  }

  // Copy c starts from the pose drawn from seeds[c].
  Simulator make(const std::vector<unsigned>& seeds, const StepOptions& o) const { return make(seeds, o, dofs_); }
  Simulator make(const std::vector<unsigned>& seeds, const StepOptions& o, const std::vector<DofSettings>& dofs) const {
    Simulator sim(model_, static_cast<int>(seeds.size()), o, dofs);
    for (std::size_t c = 0; c < seeds.size(); ++c) {
      std::mt19937 rng(seeds[c]);
      std::uniform_real_distribution<double> unit(0.0, 1.0);
      Eigen::VectorXd q = stance(model_);
      q[0] = 0.3 * unit(rng);
      q[2] += 0.02 + 0.15 * unit(rng);  // feet 2 to 17 cm above the ground, clear of the step
      const Eigen::Quaterniond tilt(Eigen::AngleAxisd(0.3 * unit(rng) - 0.15, Eigen::Vector3d::UnitX()));
      q.segment<4>(3) << tilt.w(), tilt.x(), tilt.y(), tilt.z();
      Eigen::VectorXd target = q;
      for (int k = 7; k < model_.nq; ++k) target[k] += 0.4 * unit(rng) - 0.2;
      sim.set_state(static_cast<int>(c), q, random_vector(model_.nv, rng, 0.5));
      sim.set_drive_target(static_cast<int>(c), target, Eigen::VectorXd::Zero(model_.nv));
    }
    return sim;
  }

  static void expect_same(const Simulator& a, int ca, const Simulator& b, int cb, const std::string& what) {
    EXPECT_TRUE(same_state(a, ca, b, cb)) << what;
    const CopySnapshot x = a.snapshot(ca), y = b.snapshot(cb);
    EXPECT_TRUE(same_bits(x.contact_impulse, y.contact_impulse)) << what << ": contact impulses";
    EXPECT_TRUE(same_bits(x.contact_id, y.contact_id)) << what << ": contact points";
  }

  Model model_;
  std::vector<DofSettings> dofs_;
};

// The scene does what it should: copies differ in how many contacts they
// have, and none faults.
TEST_P(ContactDeterminism, SceneMixesContactCounts) {
  Simulator sim = make(seed_range(16, 7u), options());
  sim.step(kSteps);
  std::vector<int> counts;
  for (int c = 0; c < sim.copies(); ++c) counts.push_back(static_cast<int>(sim.contacts(c).size()));
  EXPECT_EQ(sim.fault_count(), 0);
  EXPECT_GE(*std::max_element(counts.begin(), counts.end()), 4);
  EXPECT_EQ(*std::min_element(counts.begin(), counts.end()), 0) << "some copy is still in the air";
}

// A copy between other copies, alone, or at another position in a batch of
// another size: the same bits. Also with one thread against 2 and 7.
TEST_P(ContactDeterminism, CopiesAreIndependentOfTheirNeighboursAndThreads) {
  const std::vector<unsigned> wide = seed_range(21, 100u);
  std::vector<unsigned> shuffled(wide.rbegin(), wide.rbegin() + 13);  // seeds 120..108, other positions
  Simulator reference = make(wide, options());
  {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    reference.step(kSteps);
  }
  EXPECT_EQ(reference.fault_count(), 0);
  Simulator other = make(shuffled, options());
  other.step(kSteps);
  for (std::size_t c = 0; c < shuffled.size(); ++c)
    expect_same(reference, static_cast<int>(shuffled[c] - 100u), other, static_cast<int>(c),
                "seed " + std::to_string(shuffled[c]));
  Simulator alone = make({105u}, options());
  alone.step(kSteps);
  expect_same(reference, 5, alone, 0, "alone");
  for (int threads : {2, 7}) {
    tbb::task_arena arena(threads);
    Simulator sim = make(wide, options());
    arena.execute([&] { sim.step(kSteps); });
    for (int c = 0; c < sim.copies(); ++c) expect_same(reference, c, sim, c, std::to_string(threads) + " threads");
  }
}

// The same with joint rows acting in some copies and not in others: Coulomb
// friction on every leg joint in copies of odd seed (none in the others),
// and knee limits 0.1 rad either side of the stance, which the random
// targets (up to 0.2 rad off) press some copies against. PGS then solves,
// per block, the joint rows some copy needs, each copy with its own.
TEST_P(ContactDeterminism, CopiesAreIndependentWithJointRowsActingInSome) {
  std::vector<DofSettings> dofs = dofs_;
  const Eigen::VectorXd standing = stance(model_);
  for (int k = 6; k < model_.nv; ++k) {
    dofs[k].friction = 0.3;
    if (model_.dof_name[k].find("KFE") != std::string::npos) {
      const double q0 = standing[model_.body_q_offset[model_.dof_body[k]]];
      dofs[k].lower = q0 - 0.1;
      dofs[k].upper = q0 + 0.1;
    }
  }
  auto build = [&](const std::vector<unsigned>& seeds) {
    Simulator sim = make(seeds, options(), dofs);
    for (std::size_t c = 0; c < seeds.size(); ++c)
      if (seeds[c] % 2 == 0) sim.set_joint_friction(static_cast<int>(c), Eigen::VectorXd::Zero(model_.nv));
    return sim;
  };
  const std::vector<unsigned> wide = seed_range(21, 100u);
  Simulator reference = build(wide);
  reference.step(kSteps);
  EXPECT_EQ(reference.fault_count(), 0);
  int acting = 0;  // copies with a joint row's impulse at the end
  for (int c = 0; c < reference.copies(); ++c) acting += reference.snapshot(c).joint_impulse.cwiseAbs().maxCoeff() > 0;
  EXPECT_GT(acting, 0);
  EXPECT_LT(acting, reference.copies());
  std::vector<unsigned> shuffled(wide.rbegin(), wide.rbegin() + 13);
  Simulator other = build(shuffled);
  other.step(kSteps);
  for (std::size_t c = 0; c < shuffled.size(); ++c)
    expect_same(reference, static_cast<int>(shuffled[c] - 100u), other, static_cast<int>(c),
                "seed " + std::to_string(shuffled[c]));
  for (unsigned seed : {104u, 105u}) {
    Simulator alone = build({seed});
    alone.step(kSteps);
    expect_same(reference, static_cast<int>(seed - 100u), alone, 0, "alone, seed " + std::to_string(seed));
  }
}

TEST_P(ContactDeterminism, SimdLanesMatchTheScalarReference) {
  const std::vector<unsigned> s = seed_range(11, 300u);
  Simulator simd = make(s, options(Lanes::Simd)), scalar = make(s, options(Lanes::Scalar));
  simd.step(kSteps);
  scalar.step(kSteps);
  for (int c = 0; c < simd.copies(); ++c) expect_same(scalar, c, simd, c, "copy " + std::to_string(c));
}

// With 3 slots, fewer than some copies' points: those keep their deepest
// (replacing a shallower point per lane), the others all of theirs, and
// the lanes still give the scalar path's bits.
TEST_P(ContactDeterminism, SimdLanesMatchTheScalarReferenceWhenSlotsOverflow) {
  const std::vector<unsigned> s = seed_range(11, 300u);
  StepOptions simd_options = options(Lanes::Simd), scalar_options = options(Lanes::Scalar);
  simd_options.contacts.capacity = scalar_options.contacts.capacity = 3;
  Simulator simd = make(s, simd_options), scalar = make(s, scalar_options);
  int overflowed = 0;
  for (int step = 0; step < kSteps; ++step) {
    simd.step();
    scalar.step();
    for (int c = 0; c < simd.copies(); ++c) overflowed += simd.contact_overflow(c).dropped > 0;
  }
  EXPECT_GT(overflowed, 0);
  EXPECT_LT(overflowed, kSteps * simd.copies());
  for (int c = 0; c < simd.copies(); ++c) expect_same(scalar, c, simd, c, "copy " + std::to_string(c));
}

// Mid-run snapshot, 20 more steps, restore, the same 20 steps again.
TEST_P(ContactDeterminism, RestoredSnapshotReplays) {
  Simulator sim = make(seed_range(9, 500u), options());
  sim.step(kSteps);
  std::vector<CopySnapshot> saved;
  for (int c = 0; c < sim.copies(); ++c) saved.push_back(sim.snapshot(c));
  sim.step(20);
  std::vector<CopySnapshot> first;
  for (int c = 0; c < sim.copies(); ++c) first.push_back(sim.snapshot(c));
  for (int c = 0; c < sim.copies(); ++c) sim.restore(c, saved[c]);
  sim.step(20);
  for (int c = 0; c < sim.copies(); ++c) {
    const CopySnapshot again = sim.snapshot(c);
    EXPECT_TRUE(same_bits(first[c].q, again.q)) << "copy " << c;
    EXPECT_TRUE(same_bits(first[c].v, again.v)) << "copy " << c;
    EXPECT_TRUE(same_bits(first[c].contact_impulse, again.contact_impulse)) << "copy " << c;
  }
}

// Two free boxes 0.43 m apart in every copy, within the margin (0.3 m) of
// each other only by the box-box test's separation, a lower bound of their
// distance (0.25 m), not by their bounding spheres; in one copy of the
// block the boxes touch. The far copies take no points from the pair the
// touching copy's block keeps, as alone: once they took the lower bound's
// points, 4 per copy (contact_rows.hpp, detect_contacts).
TEST_P(ContactDeterminism, APairKeptForANeighbourGivesACopyNoPointsItsBoundsReject) {
  ModelBuilder builder;
  builder.add_articulation(free_shape_spec("a", ShapeType::Box, Eigen::Vector3d::Constant(0.1), 1.0));
  builder.add_articulation(free_shape_spec("b", ShapeType::Box, Eigen::Vector3d::Constant(0.1), 1.0));
  const Model model = builder.finalize();
  StepOptions o;
  o.precision = GetParam().precision;
  o.solver = GetParam().solver;
  o.dt = 0.02;
  o.contacts.margin = 0.3;
  auto place = [&](Simulator& sim, int c, const Eigen::Vector3d& b, const Eigen::Vector3d& vb) {
    Eigen::VectorXd q = model.neutral_configuration(), v = Eigen::VectorXd::Zero(model.nv);
    q.segment<3>(7) = b;
    v.segment<3>(6) = vb;
    sim.set_state(c, q, v);
    sim.set_gravity(c, Eigen::Vector3d::Zero());
  };
  const Eigen::Vector3d far(0.45, 0.45, 0.45), towards = -0.5 * far.normalized();
  const int n = 16;  // one block of float lanes, two of double
  Simulator alone(model, n, o), beside(model, n, o);
  for (int c = 0; c < n; ++c) place(alone, c, far, towards), place(beside, c, far, towards);
  place(beside, 1, Eigen::Vector3d(0.2, 0, 0), Eigen::Vector3d::Zero());  // touching
  for (int step = 0; step < 6; ++step) {
    alone.step();
    beside.step();
    ASSERT_FALSE(beside.contacts(1).empty()) << "step " << step << ": the touching copy has its points";
    for (int c = 0; c < n; ++c) {
      if (c == 1) continue;
      EXPECT_EQ(beside.contacts(c).size(), alone.contacts(c).size()) << "step " << step << " copy " << c;
      expect_same(alone, c, beside, c, "step " + std::to_string(step) + " copy " + std::to_string(c));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(, ContactDeterminism,
                         ::testing::Values(Case{Precision::Float, SolverType::PGS}, Case{Precision::Float, SolverType::TGS},
                                           Case{Precision::Double, SolverType::PGS},
                                           Case{Precision::Double, SolverType::TGS}),
                         [](const auto& info) {
                           return std::string(precision_name(info.param.precision)) + "_" +
                                  solver_name(info.param.solver);
                         });

}  // namespace
}  // namespace lockstep::test
