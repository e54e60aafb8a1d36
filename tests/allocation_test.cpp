// The hot path allocates nothing: Simulator::step after its first step,
// with contacts and joint rows, PGS and TGS, float and double, and
// VecEnv::step with and without auto-reset; and a simulator keeps
// bytes_per_copy() per copy and nothing else per copy. This test program
// defines malloc and its kin, which count every allocation of any thread,
// and the heap bytes it holds, while `counting` is set. The steps run on
// one thread and on two (the step's workspace of every thread slot is made
// before its blocks run); the uncounted first steps let TBB start its
// workers.
#include "batch/simulator.hpp"
#include "batch/vec_env.hpp"
#include "tests/sim_support.hpp"
#include "tools/step_scene.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <execinfo.h>
#include <malloc.h>

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

namespace {

std::atomic<bool> counting{false};
std::atomic<long> allocations{0};
std::atomic<long> live_bytes{0};  // allocated minus freed while counting, as malloc_usable_size gives them

// The call stacks of the first few counted allocations, kept in static
// arrays (backtrace() allocates nothing once warmed up below), so that a
// failure says who allocated.
constexpr int kStacksKept = 4, kFramesKept = 24;
void* stacks[kStacksKept][kFramesKept];
int stack_depths[kStacksKept];
thread_local bool in_backtrace = false;
[[maybe_unused]] const bool backtrace_warmed = [] {
  void* frames[2];
  return backtrace(frames, 2) > 0;  // loads the unwinder before anything is counted
}();

// Unused under the sanitizers, which keep their own operator new (below).
[[maybe_unused]] void note_allocation() {
  if (!counting.load(std::memory_order_relaxed) || in_backtrace) return;
  const long n = allocations.fetch_add(1, std::memory_order_relaxed);
  if (n < kStacksKept) {
    in_backtrace = true;
    stack_depths[n] = backtrace(stacks[n], kFramesKept);
    in_backtrace = false;
  }
}

// The kept call stacks of the last count, for a failure's message
// (symbols as backtrace_symbols gives them: function+offset, or the
// object's offset for static functions, for addr2line).
std::string counted_allocation_stacks() {
  std::string text;
  for (long n = 0; n < allocations.load() && n < kStacksKept; ++n) {
    text += "\ncounted allocation " + std::to_string(n + 1) + ":";
    char** symbols = backtrace_symbols(stacks[n], stack_depths[n]);
    for (int f = 0; symbols && f < stack_depths[n]; ++f) text += std::string("\n  ") + symbols[f];
    std::free(symbols);
  }
  return text;
}

}  // namespace

// AddressSanitizer and ThreadSanitizer replace malloc and its kin
// themselves: memory they hand out must not reach glibc's free, so under
// them nothing below is defined and the tests skip (the release build
// counts).
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define LOCKSTEP_COUNTS_ALLOCATIONS 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define LOCKSTEP_COUNTS_ALLOCATIONS 0
#endif
#endif
#ifndef LOCKSTEP_COUNTS_ALLOCATIONS
#define LOCKSTEP_COUNTS_ALLOCATIONS 1
#endif

#if LOCKSTEP_COUNTS_ALLOCATIONS
// glibc's allocator under its own names; the definitions below take the
// standard names for the whole program (operator new, Eigen, TBB and the
// libraries all call them).
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void __libc_free(void* p);

// p's bytes into (sign +1) or out of (-1) live_bytes while counting.
void* note_bytes(void* p, long sign) {
  if (p && counting.load(std::memory_order_relaxed))
    live_bytes.fetch_add(sign * static_cast<long>(malloc_usable_size(p)), std::memory_order_relaxed);
  return p;
}

void* malloc(std::size_t size) {
  note_allocation();
  return note_bytes(__libc_malloc(size), 1);
}
void* calloc(std::size_t count, std::size_t size) {
  note_allocation();
  return note_bytes(__libc_calloc(count, size), 1);
}
void* realloc(void* p, std::size_t size) {
  note_allocation();
  note_bytes(p, -1);
  return note_bytes(__libc_realloc(p, size), 1);
}
void* memalign(std::size_t alignment, std::size_t size) {
  note_allocation();
  return note_bytes(__libc_memalign(alignment, size), 1);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) {
  note_allocation();
  return note_bytes(__libc_memalign(alignment, size), 1);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) {
  note_allocation();
  *out = note_bytes(__libc_memalign(alignment, size), 1);
  return *out ? 0 : ENOMEM;
}
void free(void* p) { __libc_free(note_bytes(p, -1)); }
}
#endif

namespace lockstep {
namespace {

constexpr bool kCounts = LOCKSTEP_COUNTS_ALLOCATIONS;
constexpr const char* kNotCounted = "a sanitizer owns malloc here: the release build counts allocations";

// Allocations made by f.
template <class F>
long allocations_of(F&& f) {
  allocations = 0;
  counting = true;
  f();
  counting = false;
  return allocations.load();
}

int* volatile kept = nullptr;  // an allocation that escapes, so the compiler cannot elide it

TEST(Allocations, TheCountCanSeeOne) {
  if (!kCounts) GTEST_SKIP() << kNotCounted;
  EXPECT_EQ(allocations_of([] { kept = new int(1); }), 1);
  delete kept;
  EXPECT_EQ(allocations_of([] { std::vector<double> v(7); kept = reinterpret_cast<int*>(v.data()); }), 1);
  EXPECT_EQ(allocations_of([] { Eigen::VectorXd v(7); kept = reinterpret_cast<int*>(v.data()); }), 1) << "Eigen's own";
}

// anymal_b landing on the ground, 200 copies (a partial last block), each
// in a pose of its own (step_scene::copy_poses): blocks whose lanes hold 3
// to 10 contacts, Coulomb friction rows on the legs' joints taken into the
// solve beside them, 24 limit rows; 50 counted steps. The first step runs
// on one thread, so that on two threads the second one steps its first
// block while counted.
// Before that, another simulator of the same scene steps uncounted on as
// many threads: TBB keeps its task objects in per-thread pools that grow
// to their working size in the first parallel loops, and where its
// scalable allocator (libtbbmalloc, beside libtbb) is missing they grow
// through malloc (seen on a 16-core machine: 5 allocations in the first
// counted steps, all in tbb::detail::r1::allocate(small_object_pool&)).
TEST(Allocations, StepAllocatesNothingAfterItsFirst) {
  if (!kCounts) GTEST_SKIP() << kNotCounted;
  const Model model = test::load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  const int copies = 200;
  // Coulomb friction on the legs' joints (rows that act while a joint
  // moves), so that rounds take joint rows beside the contacts
  std::vector<DofSettings> dofs = scene.dofs;
  for (int k = 6; k < model.nv; ++k) dofs[k].friction = 2.0;
  // each copy in a pose of its own, landing on its own feet: blocks whose
  // lanes hold different numbers of contacts
  const step_scene::CopyPoses poses = step_scene::copy_poses(model, dofs, scene.q_target, scene.q0, copies, 0.3);
  for (int threads : {1, 2})
    for (Precision precision : {Precision::Float, Precision::Double})
      for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
        tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, threads);
        StepOptions o = test::scene_options(precision, solver);
        o.contacts.ground = true;
        o.record_applied_torque = true;
        const auto landing = [&] {
          Simulator sim(model, copies, o, dofs);
          for (int c = 0; c < copies; ++c) {
            sim.set_state(c, poses.q0_of(c), Eigen::VectorXd::Zero(model.nv));
            sim.set_drive_target(c, poses.target_of(c), Eigen::VectorXd::Zero(model.nv));
          }
          return sim;
        };
        landing().step(20);
        Simulator sim = landing();
        {
          tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
          sim.step();
        }
        EXPECT_EQ(allocations_of([&] { sim.step(50); }), 0)
            << threads << " thread(s), " << precision_name(precision) << " " << solver_name(solver)
            << counted_allocation_stacks();
        EXPECT_GT(sim.contacts(0).size(), 0u) << "the scene has contacts";
        int rubbing = 0, fewest = 100, most = 0;
        for (int c = 0; c < copies; ++c) {
          rubbing += sim.applied_torque(c).friction.norm() > 0;
          const int n = static_cast<int>(sim.contacts(c).size());
          fewest = std::min(fewest, n);
          most = std::max(most, n);
        }
        EXPECT_GT(rubbing, 0) << "joint friction rows act";
        EXPECT_LT(fewest, most) << "copies hold different numbers of contacts";
      }
}

// What a simulator holds: its heap bytes, built and stepped once, grow by
// bytes_per_copy() per copy (state, inputs, per-copy parameters, warm
// starts, contacts) and by nothing else per copy; the step's scratch is
// per worker block. So N copies of anymal_b standing take about
// N bytes_per_copy(): a million 2.45 GiB in float (`lockstep bench
// --envs 1000000` peaked at 2.47 GiB resident, docs/performance.md).
// Between 1024 and 16384 copies the slope may exceed bytes_per_copy() only
// by the heap's rounding of each array (malloc_usable_size, whole pages for
// large blocks: up to 4 KiB for each of about 40 arrays, 11 bytes a copy
// over the 15360 copies between them), never fall short of it.
TEST(Allocations, ASimulatorHoldsBytesPerCopyForEachCopyAndNothingElsePerCopy) {
  if (!kCounts) GTEST_SKIP() << kNotCounted;
  const Model model = test::load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  for (Precision precision : {Precision::Float, Precision::Double}) {
    StepOptions o = test::scene_options(precision, SolverType::PGS);
    o.contacts.ground = true;
    Simulator(model, 64, o, scene.dofs).step();  // TBB's first loops, uncounted
    std::size_t per_copy = 0;
    const auto held = [&](int copies) {
      live_bytes = 0;
      counting = true;
      auto sim = std::make_unique<Simulator>(model, copies, o, scene.dofs);
      sim->set_state_all(scene.q0, Eigen::VectorXd::Zero(model.nv));
      sim->step();
      counting = false;
      const long bytes = live_bytes.load();
      per_copy = sim->bytes_per_copy();
      counting = true;
      sim.reset();
      counting = false;
      EXPECT_LE(std::abs(live_bytes.load()), 4096) << copies << " copies: their simulator gave back what it held";
      return bytes;
    };
    const long small = held(1024), large = held(16384);
    const double slope = static_cast<double>(large - small) / (16384 - 1024);
    EXPECT_GE(slope, static_cast<double>(per_copy)) << precision_name(precision);
    EXPECT_LE(slope, static_cast<double>(per_copy) + 11) << precision_name(precision);
    EXPECT_GT(per_copy, 0u);
  }
}

// VecEnv::step: the actions, the steps, the observations, the reward
// function's call and the episodes' bookkeeping, and with episodes of 3 env steps also auto-reset
// (randomisation, the copies' new state, terminal observations). The
// counted steps follow two uncounted ones; with episodes they include the
// first step that resets copies.
TEST(Allocations, VecEnvStepAllocatesNothingWithOrWithoutResets) {
  if (!kCounts) GTEST_SKIP() << kNotCounted;
  const Model model = test::load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  for (int threads : {1, 2})
    for (int episode : {0, 3}) {
      tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, threads);
      VecEnvOptions o;
      o.step.contacts.ground = true;
      o.step.record_motion = episode > 0;  // the joint forces and link accelerations observed too
      o.dofs = scene.dofs;
      o.action_mode = ActionMode::PositionTarget;
      o.initial_q = scene.q0;
      o.episode_steps = episode;
      Randomization& r = o.randomization;
      r.mass_scale = {0.9, 1.1};
      r.kp_scale = r.damping_scale = {0.9, 1.1};
      r.randomize_ground_friction = true;
      r.ground_friction = {0.6, 1.0};
      r.joint_position_noise = r.root_yaw_noise = {-0.05, 0.05};
      VecEnv env(model, 40, o);
      // a reward function too: its actions were a new matrix every step
      env.set_reward([](const Observations& obs, const RowMatrix& actions, Eigen::VectorXd& reward,
                        std::vector<std::uint8_t>&) { reward = obs.q.col(2) - actions.rowwise().squaredNorm(); });
      env.reset();
      const RowMatrix actions = RowMatrix::Zero(40, env.action_size());
      env.step(actions);
      env.step(actions);
      long resets = 0;
      EXPECT_EQ(allocations_of([&] {
                  for (int i = 0; i < 3; ++i) {
                    env.step(actions);
                    for (std::uint8_t t : env.truncated()) resets += t;
                  }
                }),
                0)
          << threads << " thread(s), episodes of " << episode << " env steps" << counted_allocation_stacks();
      EXPECT_EQ(resets, episode > 0 ? 40 : 0) << "the counted steps reset every copy once";
    }
}

// VecEnv::step with actuator_torque actions: each leg joint's motor, the
// knees coupled to their hips, commanded past their operating regions.
TEST(Allocations, VecEnvStepThroughActuatorsAllocatesNothing) {
  if (!kCounts) GTEST_SKIP() << kNotCounted;
  const Model model = test::load_shared_model("anymal_b", true);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  VecEnvOptions o;
  o.step.contacts.ground = true;
  o.dofs = scene.dofs;
  o.initial_q = scene.q0;
  o.action_mode = ActionMode::ActuatorTorque;
  for (int k = 6; k < model.nv; ++k) {
    Actuator a;
    a.name = model.dof_name[k];
    a.dof = k;
    a.gear = 9;
    a.torque_constant = 0.12, a.bus_voltage = 48, a.resistance = 0.3, a.velocity_constant = 8, a.peak_torque = 3.5;
    if ((k - 6) % 3 == 2) a.couplings = {{k - 1, 0.5}};
    o.step.actuators.push_back(a);
  }
  VecEnv env(model, 40, o);
  env.reset();
  const RowMatrix actions = RowMatrix::Constant(40, env.action_size(), 50.0);
  env.step(actions);
  env.step(actions);
  EXPECT_EQ(allocations_of([&] {
              for (int i = 0; i < 3; ++i) env.step(actions);
            }),
            0)
      << counted_allocation_stacks();
  EXPECT_NE(env.observations().motor_torque.norm(), 0.0) << "the motors act";
}

}  // namespace
}  // namespace lockstep
