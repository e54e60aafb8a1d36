// Faults: a copy given a non-finite torque, drive target, link wrench or
// gravity, or whose state overflows from finite inputs, is flagged with the
// reason; every other copy, in its block and in others, goes on bit for bit
// as in a run where that copy's inputs were clean. With reset_on_fault the
// copy is put back at its initial state with no warm start; clear_fault and
// reset undo a fault by hand. anymal_b floating, float and double, PGS and
// TGS, in a scene whose rows push (narrow limits, friction), the same on the
// ground (contacts, whose detection decides per block what any lane needs),
// and in one where they never do (so the solver is skipped in clean blocks).
#include "tests/sim_support.hpp"

#include <functional>
#include <limits>

namespace lockstep {
namespace {

using test::CopyInputs;
using test::same_bits;
using test::same_state;

constexpr int kCopies = 40;  // float: blocks 0-15, 16-31, 32-39; double: 5 blocks of 8
constexpr int kSteps = 4;
constexpr int kFaulty[] = {5, 37};  // in the first block and in the last, partial one
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// A non-finite input given to one copy, and the reason it must be flagged with.
struct BadInput {
  std::string name;
  Fault code;
  std::function<void(Simulator&, int, const CopyInputs&)> apply;
};

std::vector<BadInput> bad_inputs() {
  auto torque = [](int dof, double x) {
    return [dof, x](Simulator& sim, int c, const CopyInputs& in) {
      Eigen::VectorXd tau = in.tau;
      tau[dof < 0 ? tau.size() + dof : dof] = x;
      sim.set_torque(c, tau);  // set_torque does not check finiteness
    };
  };
  auto wrench = [](int k, double x) {
    return [k, x](Simulator& sim, int c, const CopyInputs& in) {
      Eigen::Matrix<double, 6, 1> w = in.wrench;
      w[k] = x;
      sim.set_link_wrench(c, in.body, w);
    };
  };
  auto gravity = [](int k, double x) {
    return [k, x](Simulator& sim, int c, const CopyInputs&) {
      Eigen::Vector3d g(0, 0, -9.81);
      g[k] = x;
      sim.set_gravity(c, g);
    };
  };
  return {
      {"NaN knee torque", Fault::NonFiniteTorque, torque(-1, kNaN)},
      {"+Inf knee torque", Fault::NonFiniteTorque, torque(-1, kInf)},
      {"-Inf base torque", Fault::NonFiniteTorque, torque(0, -kInf)},
      {"NaN target position", Fault::NonFiniteTarget,
       [](Simulator& sim, int c, const CopyInputs& in) {
         Eigen::VectorXd q = in.target_q;
         q[q.size() - 1] = kNaN;
         sim.set_drive_target(c, q, in.target_v);
       }},
      {"Inf target velocity", Fault::NonFiniteTarget,
       [](Simulator& sim, int c, const CopyInputs& in) {
         Eigen::VectorXd v = in.target_v;
         v[v.size() - 2] = -kInf;
         sim.set_drive_target(c, in.target_q, v);
       }},
      {"NaN wrench force", Fault::NonFiniteWrench, wrench(1, kNaN)},
      {"Inf wrench torque", Fault::NonFiniteWrench, wrench(5, kInf)},
      {"NaN gravity", Fault::NonFiniteGravity, gravity(1, kNaN)},
      {"-Inf gravity", Fault::NonFiniteGravity, gravity(2, -kInf)},
  };
}

// Puts back the clean inputs of one copy without touching its state.
void restore_inputs(Simulator& sim, int c, const CopyInputs& in) {
  sim.set_torque(c, in.tau);
  sim.set_drive_target(c, in.target_q, in.target_v);
  sim.set_link_wrench(c, in.body, in.wrench);
  sim.set_gravity(c, sim.model().gravity);
}

struct Case {
  bool rows_push;  // narrow limits and friction; else wide limits, no friction
  bool ground;     // contacts with the ground plane at z = 0
  Precision precision;
  SolverType solver;
};

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  const Case& c = info.param;
  return std::string(c.rows_push ? "rows_push_" : "rows_at_rest_") + (c.ground ? "ground_" : "") +
         precision_name(c.precision) + "_" + solver_name(c.solver);
}

std::vector<Case> all_cases() {
  std::vector<Case> cases;
  for (bool rows_push : {true, false})
    for (bool ground : {false, true})
      for (Precision precision : {Precision::Float, Precision::Double})
        for (SolverType solver : {SolverType::PGS, SolverType::TGS})
          if (rows_push || !ground) cases.push_back({rows_push, ground, precision, solver});
  return cases;
}

class StepFaults : public ::testing::TestWithParam<Case> {
 protected:
  void SetUp() override {
    model_ = test::load_shared_model("anymal_b", true);
    if (GetParam().rows_push) {
      dofs_ = test::limited_dofs(model_, 0.4, 6.0);
    } else {
      dofs_ = test::limited_dofs(model_, 3.0, 1e3);
      for (DofSettings& d : dofs_) d.friction = 0.0;
    }
    seeds_ = test::seed_range(kCopies, 500u);
  }

  StepOptions options(bool reset_on_fault) const {
    StepOptions o = test::scene_options(GetParam().precision, GetParam().solver);
    o.reset_on_fault = reset_on_fault;
    o.contacts.ground = GetParam().ground;
    return o;
  }

  Simulator make(bool reset_on_fault) const {
    return test::simulator_with_inputs(model_, dofs_, options(reset_on_fault), seeds_);
  }
  CopyInputs inputs(int c) const { return test::random_copy_inputs(model_, dofs_, seeds_[c]); }

  // Every copy but `skip` of `a` equals the same copy of `b`, bit for bit.
  static void expect_others_same(const Simulator& a, const Simulator& b, int skip, const std::string& what) {
    for (int c = 0; c < a.copies(); ++c)
      if (c != skip) EXPECT_TRUE(same_state(a, c, b, c)) << what << ": copy " << c << " (faulty copy " << skip << ")";
  }

  // The clean run: no faults; rows push in some copies or in none.
  Simulator clean_run(bool reset_on_fault) const {
    Simulator clean = make(reset_on_fault);
    clean.step(kSteps);
    EXPECT_EQ(clean.fault_count(), 0);
    if (GetParam().rows_push) EXPECT_GT(test::copies_with_impulses(clean), 0);
    else EXPECT_EQ(test::copies_with_impulses(clean), 0);
    int touching = 0;
    for (int c = 0; c < clean.copies(); ++c) touching += !clean.contacts(c).empty();
    if (GetParam().ground) EXPECT_GT(touching, 0) << "copies on the ground";
    if (GetParam().ground) EXPECT_LT(touching, clean.copies()) << "copies in the air";
    return clean;
  }

  Model model_;
  std::vector<DofSettings> dofs_;
  std::vector<unsigned> seeds_;
};

// Without reset_on_fault the faulty copy keeps whatever its step gave.
TEST_P(StepFaults, NonFiniteInputFaultsOnlyItsCopy) {
  const Simulator clean = clean_run(false);
  for (const BadInput& bad : bad_inputs())
    for (int f : kFaulty) {
      Simulator sim = make(false);
      bad.apply(sim, f, inputs(f));
      sim.step(kSteps);
      EXPECT_EQ(sim.fault(f), bad.code) << bad.name << " in copy " << f << ": " << fault_name(sim.fault(f));
      EXPECT_EQ(sim.fault_count(), 1) << bad.name;
      expect_others_same(clean, sim, f, bad.name);
    }
}

// With reset_on_fault the faulty copy is at its initial state after every
// step, its warm start zero; the others are as in the clean run.
TEST_P(StepFaults, ResetOnFaultRestoresTheInitialState) {
  const Simulator clean = clean_run(true);
  for (const BadInput& bad : bad_inputs())
    for (int f : kFaulty) {
      Simulator sim = make(true);
      const Eigen::VectorXd q0 = sim.q(f), v0 = sim.v(f);
      bad.apply(sim, f, inputs(f));
      sim.step(kSteps);
      EXPECT_EQ(sim.fault(f), bad.code) << bad.name << " in copy " << f << ": " << fault_name(sim.fault(f));
      EXPECT_EQ(sim.fault_count(), 1) << bad.name;
      EXPECT_TRUE(same_bits(sim.q(f), q0)) << bad.name << ": q of copy " << f;
      EXPECT_TRUE(same_bits(sim.v(f), v0)) << bad.name << ": v of copy " << f;
      EXPECT_TRUE(same_bits(test::row_impulses(sim, f), Eigen::VectorXd::Zero(sim.row_count())))
          << bad.name << ": warm start of copy " << f;
      expect_others_same(clean, sim, f, bad.name);
    }
}

// A finite torque too large for the precision (the largest finite value on
// a knee without an effort limit) overflows the state: NonFiniteState, and
// the other copies are untouched; with reset_on_fault the copy restarts.
TEST_P(StepFaults, OverflowFaultsTheStateOnly) {
  dofs_[model_.nv - 1].max_force = Model::kInfinity;
  const double huge = GetParam().precision == Precision::Float ? std::numeric_limits<float>::max()
                                                               : std::numeric_limits<double>::max();
  for (bool reset_on_fault : {false, true}) {
    const Simulator clean = clean_run(reset_on_fault);
    for (int f : kFaulty) {
      Simulator sim = make(reset_on_fault);
      const Eigen::VectorXd q0 = sim.q(f), v0 = sim.v(f);
      Eigen::VectorXd tau = inputs(f).tau;
      tau[model_.nv - 1] = huge;
      sim.set_torque(f, tau);
      sim.step(kSteps);
      EXPECT_EQ(sim.fault(f), Fault::NonFiniteState) << "copy " << f << ": " << fault_name(sim.fault(f));
      EXPECT_EQ(sim.fault_count(), 1);
      if (reset_on_fault) {
        EXPECT_TRUE(same_bits(sim.q(f), q0)) << "q of copy " << f;
        EXPECT_TRUE(same_bits(sim.v(f), v0)) << "v of copy " << f;
        EXPECT_TRUE(same_bits(test::row_impulses(sim, f), Eigen::VectorXd::Zero(sim.row_count())));
      } else {
        EXPECT_FALSE(sim.v(f).allFinite());
      }
      expect_others_same(clean, sim, f, reset_on_fault ? "overflow, reset on fault" : "overflow");
    }
  }
}

// clear_fault drops the flag, which the next step raises again while the
// input is bad; with the input fixed, reset puts the copy at its initial
// state with no warm start, and from there it steps exactly as a fresh copy.
TEST_P(StepFaults, ClearFaultAndResetRestartTheCopy) {
  Simulator clean = make(false);
  clean.step(kSteps);
  std::vector<Eigen::VectorXd> fresh_q, fresh_v;  // each copy kSteps after its start
  for (int c = 0; c < kCopies; ++c) fresh_q.push_back(clean.q(c)), fresh_v.push_back(clean.v(c));
  clean.step(kSteps + 1);
  for (const BadInput& bad : bad_inputs()) {
    const int f = kFaulty[0];
    Simulator sim = make(false);
    const Eigen::VectorXd q0 = sim.q(f), v0 = sim.v(f);
    bad.apply(sim, f, inputs(f));
    sim.step(kSteps);
    ASSERT_EQ(sim.fault(f), bad.code) << bad.name;
    sim.clear_fault(f);
    EXPECT_EQ(sim.fault(f), Fault::None) << bad.name;
    EXPECT_EQ(sim.fault_count(), 0) << bad.name;
    sim.step();
    EXPECT_EQ(sim.fault(f), bad.code) << bad.name << ": flagged again while the input is bad";
    restore_inputs(sim, f, inputs(f));
    sim.reset(f);
    EXPECT_EQ(sim.fault(f), Fault::None) << bad.name;
    EXPECT_EQ(sim.fault_count(), 0) << bad.name;
    EXPECT_TRUE(same_bits(sim.q(f), q0)) << bad.name;
    EXPECT_TRUE(same_bits(sim.v(f), v0)) << bad.name;
    EXPECT_TRUE(same_bits(test::row_impulses(sim, f), Eigen::VectorXd::Zero(sim.row_count()))) << bad.name;
    sim.step(kSteps);
    EXPECT_EQ(sim.fault_count(), 0) << bad.name;
    EXPECT_TRUE(same_bits(sim.q(f), fresh_q[f])) << bad.name << ": q after the reset";
    EXPECT_TRUE(same_bits(sim.v(f), fresh_v[f])) << bad.name << ": v after the reset";
    expect_others_same(clean, sim, f, bad.name + ", after the reset");
  }
}

// After reset_on_fault restarted a copy, fixing its input and clearing the
// flag lets it step exactly as a fresh copy: the warm start was cleared.
TEST_P(StepFaults, CopyResetOnFaultStepsAsAFreshCopy) {
  Simulator clean = make(true);
  clean.step(kSteps);
  const int f = kFaulty[1];
  const BadInput bad = bad_inputs()[0];
  Simulator sim = make(true);
  bad.apply(sim, f, inputs(f));
  sim.step(kSteps);
  ASSERT_EQ(sim.fault(f), bad.code);
  restore_inputs(sim, f, inputs(f));
  sim.clear_fault(f);
  sim.step(kSteps);
  EXPECT_EQ(sim.fault_count(), 0);
  EXPECT_TRUE(same_state(sim, f, clean, f));
}

INSTANTIATE_TEST_SUITE_P(, StepFaults, ::testing::ValuesIn(all_cases()), case_name);

}  // namespace
}  // namespace lockstep
