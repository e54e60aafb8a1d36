// The hot path allocates nothing: Simulator::step after its first step,
// with contacts and joint rows, PGS and TGS, float and double, and
// VecEnv::step with and without auto-reset. This test program defines
// malloc and its kin, which count every allocation of any thread while
// `counting` is set. They run on one thread and on two (the step's
// workspace of every thread slot is made before its blocks run); the
// uncounted first steps let TBB start its workers.
#include "batch/simulator.hpp"
#include "batch/vec_env.hpp"
#include "tests/sim_support.hpp"
#include "tools/step_scene.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <execinfo.h>

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <string>
#include <vector>

namespace {

std::atomic<bool> counting{false};
std::atomic<long> allocations{0};

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

void note_allocation() {
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

void* malloc(std::size_t size) {
  note_allocation();
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) {
  note_allocation();
  return __libc_calloc(count, size);
}
void* realloc(void* p, std::size_t size) {
  note_allocation();
  return __libc_realloc(p, size);
}
void* memalign(std::size_t alignment, std::size_t size) {
  note_allocation();
  return __libc_memalign(alignment, size);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) {
  note_allocation();
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) {
  note_allocation();
  *out = __libc_memalign(alignment, size);
  return *out ? 0 : ENOMEM;
}
void free(void* p) { __libc_free(p); }
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

// anymal_b standing on the ground (4 foot contacts, 24 joint rows), 200
// copies (a partial last block). The first step runs on one thread, so
// that on two threads the second one steps its first block while counted.
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
  for (int threads : {1, 2})
    for (Precision precision : {Precision::Float, Precision::Double})
      for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
        tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, threads);
        StepOptions o = test::scene_options(precision, solver);
        o.contacts.ground = true;
        const auto standing = [&] {
          Simulator sim(model, copies, o, scene.dofs);
          for (int c = 0; c < copies; ++c) {
            sim.set_state(c, scene.q0, Eigen::VectorXd::Zero(model.nv));
            sim.set_drive_target(c, scene.q_target, Eigen::VectorXd::Zero(model.nv));
          }
          return sim;
        };
        standing().step(20);
        Simulator sim = standing();
        {
          tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
          sim.step();
        }
        EXPECT_EQ(allocations_of([&] { sim.step(5); }), 0)
            << threads << " thread(s), " << precision_name(precision) << " " << solver_name(solver)
            << counted_allocation_stacks();
        EXPECT_GT(sim.contacts(0).size(), 0u) << "the scene has contacts";
      }
}

// VecEnv::step: the actions, the steps, the observations and the
// episodes' bookkeeping, and with episodes of 3 env steps also auto-reset
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

}  // namespace
}  // namespace lockstep
