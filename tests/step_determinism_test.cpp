// A copy's step is the same bit for bit whatever the thread count, the batch
// size, its position in the batch, the steps per call, and the lanes (SIMD or the scalar
// reference): anymal_b floating and ur5 fixed, with per-copy drives,
// damping, Coulomb friction, narrow hard limits and velocity limits that
// engage, link wrenches and random initial states, in float and double,
// PGS and TGS.
#include "tests/sim_support.hpp"

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

namespace lockstep {
namespace {

using test::same_state;

constexpr int kSteps = 6;

struct Case {
  std::string model;
  bool floating_base;
  Precision precision;
  SolverType solver;
};

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  const Case& c = info.param;
  return c.model + (c.floating_base ? "_floating_" : "_fixed_") + precision_name(c.precision) + "_" +
         solver_name(c.solver);
}

std::vector<Case> all_cases() {
  std::vector<Case> cases;
  for (const auto& [model, floating] : {std::pair<std::string, bool>{"anymal_b", true}, {"ur5", false}})
    for (Precision precision : {Precision::Float, Precision::Double})
      for (SolverType solver : {SolverType::PGS, SolverType::TGS}) cases.push_back({model, floating, precision, solver});
  return cases;
}

class StepDeterminism : public ::testing::TestWithParam<Case> {
 protected:
  void SetUp() override {
    model_ = test::load_shared_model(GetParam().model, GetParam().floating_base);
    dofs_ = test::limited_dofs(model_, 0.4, 6.0);
  }

  StepOptions options(Lanes lanes = Lanes::Simd) const {
    StepOptions o = test::scene_options(GetParam().precision, GetParam().solver);
    o.lanes = lanes;
    return o;
  }

  // A simulator whose copy c holds the inputs drawn from seeds[c].
  Simulator make(const std::vector<unsigned>& seeds, const StepOptions& o) const {
    return test::simulator_with_inputs(model_, dofs_, o, seeds);
  }

  static std::vector<unsigned> seeds(int n) { return test::seed_range(n, 1000u); }

  // Every copy of `other` equals the copy of `reference` that has its seed.
  static void expect_same_copies(const Simulator& reference, const std::vector<unsigned>& reference_seeds,
                                 const Simulator& other, const std::vector<unsigned>& other_seeds,
                                 const std::string& what) {
    for (std::size_t c = 0; c < other_seeds.size(); ++c) {
      const auto at = std::find(reference_seeds.begin(), reference_seeds.end(), other_seeds[c]);
      ASSERT_NE(at, reference_seeds.end());
      const int r = static_cast<int>(at - reference_seeds.begin());
      EXPECT_TRUE(same_state(reference, r, other, static_cast<int>(c)))
          << what << ": copy " << c << " against copy " << r << " of the reference";
    }
  }

  Model model_;
  std::vector<DofSettings> dofs_;
};

// The scene really exercises what it should: drives, wrenches and every row
// type run, limits push in some copies and not in others, and no copy faults.
TEST_P(StepDeterminism, SceneEngagesTheRowsInSomeCopies) {
  const std::vector<unsigned> s = seeds(97);
  Simulator sim = make(s, options());
  for (Stage stage : {Stage::Drives, Stage::Damping, Stage::ExternalWrenches, Stage::HardLimits, Stage::VelocityLimits,
                      Stage::CoulombFriction})
    EXPECT_TRUE(sim.plan()[static_cast<int>(stage)].runs) << stage_name(stage) << "\n" << sim.describe_plan();
  sim.step(kSteps);
  EXPECT_EQ(sim.fault_count(), 0);
  EXPECT_GT(test::copies_with_impulses(sim), 0);
  // friction rows push in every moving copy; position limits in some only
  int at_limit = 0;
  for (int c = 0; c < sim.copies(); ++c) {
    const Eigen::VectorXd q = sim.q(c);
    for (int k = 0; k < model_.nv; ++k) {
      const int b = model_.dof_body[k];
      if (model_.body_joint[b] != JointType::Revolute) continue;
      if (std::abs(std::abs(q[model_.body_q_offset[b]]) - 0.4) < 1e-3) {
        ++at_limit;
        break;
      }
    }
  }
  EXPECT_GT(at_limit, 0);
  EXPECT_LT(at_limit, sim.copies());
}

// 1, 2 and 7 threads over 97 copies (7 float blocks, 13 double blocks).
TEST_P(StepDeterminism, ThreadCountDoesNotChangeResults) {
  const std::vector<unsigned> s = seeds(97);
  std::vector<Simulator> runs;
  for (int threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    tbb::task_arena arena(threads);
    Simulator sim = make(s, options());
    arena.execute([&] {
      EXPECT_EQ(tbb::this_task_arena::max_concurrency(), threads);
      sim.step(kSteps);
    });
    EXPECT_EQ(sim.fault_count(), 0);
    runs.push_back(std::move(sim));
  }
  expect_same_copies(runs[0], s, runs[1], s, "2 threads");
  expect_same_copies(runs[0], s, runs[2], s, "7 threads");
}

// Copies of a 300-copy batch against the same copies in batches of 20 and 1
// at other positions, and against a permutation of the whole batch.
TEST_P(StepDeterminism, BatchSizeAndPositionDoNotChangeResults) {
  const std::vector<unsigned> all = seeds(300);
  Simulator reference = make(all, options());
  reference.step(kSteps);

  std::vector<unsigned> twenty(20), permuted(300);
  for (int j = 0; j < 20; ++j) twenty[j] = all[(37 * j + 11) % 300];  // positions 11, 48, 85, ... of 300
  for (int p = 0; p < 300; ++p) permuted[p] = all[(7 * p + 3) % 300];
  std::vector<unsigned> one = {all[123]};
  for (const std::vector<unsigned>* subset : {&twenty, &permuted, &one}) {
    Simulator sim = make(*subset, options());
    sim.step(kSteps);
    expect_same_copies(reference, all, sim, *subset, std::to_string(subset->size()) + " copies");
  }
}

// step(n) takes every block through all n steps before the next block:
// the same bits as n calls of step(), on one thread and on two.
TEST_P(StepDeterminism, OneCallOfNStepsMatchesNCalls) {
  const std::vector<unsigned> s = seeds(97);
  for (int threads : {1, 2}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    Simulator together = make(s, options());
    Simulator apart = make(s, options());
    together.step(kSteps);
    for (int k = 0; k < kSteps; ++k) apart.step();
    EXPECT_EQ(together.time(), apart.time());
    expect_same_copies(apart, s, together, s, std::to_string(threads) + " thread(s), step(" +
                                                  std::to_string(kSteps) + ") against " + std::to_string(kSteps) +
                                                  " calls of step()");
  }
}

// The SIMD lanes reproduce the scalar reference (one copy a block) bit for
// bit.
TEST_P(StepDeterminism, SimdLanesMatchScalarReference) {
  const std::vector<unsigned> s = seeds(37);
  Simulator simd = make(s, options(Lanes::Simd));
  Simulator scalar = make(s, options(Lanes::Scalar));
  simd.step(kSteps);
  scalar.step(kSteps);
  expect_same_copies(scalar, s, simd, s, "SIMD lanes");
}

INSTANTIATE_TEST_SUITE_P(, StepDeterminism, ::testing::ValuesIn(all_cases()), case_name);

// Explicit Euler, whose resting copies move by v0 and whose copies with
// acting rows move as the solver leaves them: the lanes match the scalar
// reference with both solvers.
TEST(StepDeterminismExplicitEuler, SimdLanesMatchScalarReference) {
  const Model model = test::load_shared_model("anymal_b", true);
  std::vector<DofSettings> dofs = test::limited_dofs(model, 0.4, 6.0);
  for (DofSettings& d : dofs) d.friction = 0;  // friction rows hold a joint at rest too
  const std::vector<unsigned> seeds = test::seed_range(37, 3000u);
  for (Precision precision : {Precision::Float, Precision::Double})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      std::vector<Simulator> runs;
      for (Lanes lanes : {Lanes::Scalar, Lanes::Simd}) {
        StepOptions o = test::scene_options(precision, solver);
        o.integrator = Integrator::ExplicitEuler;
        o.lanes = lanes;
        Simulator sim = test::simulator_with_inputs(model, dofs, o, seeds);
        for (int c = 0; c < sim.copies(); c += 2) {  // falling freely from rest: no row acts
          sim.set_state(c, model.neutral_configuration(), Eigen::VectorXd::Zero(model.nv));
          sim.set_torque(c, Eigen::VectorXd::Zero(model.nv));
          sim.set_drive_target(c, model.neutral_configuration(), Eigen::VectorXd::Zero(model.nv));
          for (int b = 0; b < model.nbody; ++b) sim.set_link_wrench(c, b, Eigen::Matrix<double, 6, 1>::Zero());
        }
        sim.step(kSteps);
        runs.push_back(std::move(sim));
      }
      int pushed = 0;
      for (int c = 0; c < runs[0].copies(); ++c) {
        EXPECT_TRUE(same_state(runs[0], c, runs[1], c))
            << precision_name(precision) << " " << solver_name(solver) << " copy " << c;
        pushed += test::row_impulses(runs[1], c).norm() > 0;
      }
      EXPECT_GT(pushed, 0) << "rows act in some copies";
      EXPECT_LT(pushed, runs[0].copies()) << "and rest in others";
    }
}

// The same with the joint effects of the ABA stage: springs, spring-damper
// limits (on every other leg DOF, hard limits on the rest) and Stribeck
// friction (every third leg DOF, whose exp is lane::exp, the same code on
// both lane types), on anymal_b.
TEST(StepDeterminismImplicitTerms, SimdLanesMatchScalarReference) {
  const Model model = test::load_shared_model("anymal_b", true);
  std::vector<DofSettings> dofs = test::limited_dofs(model, 0.3, 6.0);
  for (int k = 0, leg = 0; k < model.nv; ++k) {
    if (model.body_joint[model.dof_body[k]] == JointType::Free) continue;
    DofSettings& d = dofs[k];
    d.spring_stiffness = 4.0;
    d.spring_rest = 0.1;
    if (leg % 2 == 0) d.limit_stiffness = 400.0, d.limit_damping = 4.0;
    if (leg % 3 == 0) {
      d.friction_model = FrictionModel::Stribeck;
      d.friction = 0.1, d.stiction_extra = 1.0, d.stribeck_velocity = 0.5;
    }
    ++leg;
  }
  const std::vector<unsigned> seeds = test::seed_range(37, 2000u);
  for (Precision precision : {Precision::Float, Precision::Double}) {
    std::vector<Simulator> runs;
    for (Lanes lanes : {Lanes::Scalar, Lanes::Simd}) {
      StepOptions o = test::scene_options(precision, SolverType::PGS);
      o.lanes = lanes;
      Simulator sim = test::simulator_with_inputs(model, dofs, o, seeds);
      for (Stage stage :
           {Stage::Springs, Stage::SoftLimits, Stage::StribeckFriction, Stage::HardLimits, Stage::CoulombFriction})
        EXPECT_TRUE(sim.plan()[static_cast<int>(stage)].runs) << stage_name(stage);
      sim.step(kSteps);
      runs.push_back(std::move(sim));
    }
    for (int c = 0; c < runs[0].copies(); ++c)
      EXPECT_TRUE(same_state(runs[0], c, runs[1], c)) << precision_name(precision) << " copy " << c;
  }
}

// Spherical drives: the drive's error is the rotation vector of
// target^-1 q, whose angle comes from lane::atan2. With libm's atan2 on the
// scalar lane and xsimd's on SIMD lanes this differed by an ulp; both lanes
// now share one atan2, so the step is bit-identical here too.
TEST(StepDeterminismSpherical, SimdLanesMatchScalarReference) {
  const Model model = test::ball_joint();
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (DofSettings& d : dofs) d.drive_stiffness = 20.0, d.drive_damping = 2.0;
  const int copies = 37;
  for (Precision precision : {Precision::Float, Precision::Double}) {
    std::vector<Simulator> runs;
    for (Lanes lanes : {Lanes::Scalar, Lanes::Simd}) {
      StepOptions o = test::scene_options(precision, SolverType::PGS);
      o.lanes = lanes;
      Simulator sim(model, copies, o, dofs);
      std::mt19937 rng(19);
      for (int c = 0; c < copies; ++c) {
        sim.set_state(c, test::random_configuration(model, rng), test::random_vector(model.nv, rng, 3.0));
        sim.set_drive_target(c, test::random_configuration(model, rng), Eigen::VectorXd::Zero(model.nv));
      }
      ASSERT_TRUE(sim.plan()[static_cast<int>(Stage::Drives)].runs);
      sim.step(50);
      runs.push_back(std::move(sim));
    }
    for (int c = 0; c < copies; ++c)
      EXPECT_TRUE(same_state(runs[0], c, runs[1], c)) << precision_name(precision) << " copy " << c;
  }
}

}  // namespace
}  // namespace lockstep
