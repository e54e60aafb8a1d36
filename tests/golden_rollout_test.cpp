// The bundled quadruped scene (contacts, randomised masses, friction and
// joint positions, auto-resets every 30 env steps) under the random policy
// gives the same bits on every x86-64 machine with FMA: the SIMD width
// (AVX2 or AVX-512), the compiler (clang 14 or g++ 12) and the thread count
// do not enter (README, "Build options"). This test holds that claim to
// fixed hashes of every observation of every copy and step, so that CI on
// whatever machine it gets checks it, and any change that moves a single
// bit of the numerics shows. A change meant to move them updates the
// constants below (a failure prints the new value); one not meant to is a
// defect. A build without FMA (the portable preset) rounds each a*b+c twice
// and gets other bits: the test skips there.
#include "batch/fnv1a.hpp"
#include "batch/vec_env.hpp"
#include "io/scene_file.hpp"
#include "tools/rollout_policy.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstdint>
#include <iomanip>
#include <sstream>
#include <string>

namespace lockstep {
namespace {

// Every value of m, row by row.
template <class Matrix>
void add_values(Fnv1a& hash, const Matrix& m) {
  for (Eigen::Index r = 0; r < m.rows(); ++r)
    for (Eigen::Index c = 0; c < m.cols(); ++c) hash.add(static_cast<double>(m(r, c)));
}

std::string hex(std::uint64_t x) {
  std::ostringstream s;
  s << "0x" << std::hex << std::setw(16) << std::setfill('0') << x << "ull";
  return s.str();
}

// 48 copies (a partial last block in float with AVX-512 and in double with
// AVX2), 90 env steps of 4 simulator steps, on `threads` threads.
std::uint64_t rollout_hash(Precision precision, SolverType solver, int threads) {
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  Scene scene = load_scene(std::string(LOCKSTEP_MODELS_DIR) + "/quadruped_scene.json");
  scene.env.step.precision = precision;
  scene.env.step.solver = solver;
  scene.env.episode_steps = 30;
  scene.env.seed = 7;
  VecEnv env(scene.model, 48, scene.env);
  env.reset();
  cli::Policy policy(cli::PolicyKind::Random, env, scene.env.seed);
  RowMatrix actions;
  Fnv1a hash;
  for (int t = 0; t < 90; ++t) {
    policy.act(env, t, actions);
    env.step(actions);
    const Observations& o = env.observations();
    for (const RowMatrix* m : {&o.q, &o.qd, &o.applied_torque, &o.contact_force}) add_values(hash, *m);
    for (int c = 0; c < env.copies(); ++c)  // where an episode ended, the state it ended in
      if (env.truncated()[c] || env.terminated()[c]) add_values(hash, env.terminal_observations().q.row(c));
  }
  return hash.value();
}

struct Golden {
  Precision precision;
  SolverType solver;
  int threads;
  std::uint64_t hash;
};

TEST(GoldenRollout, QuadrupedSceneHashesTheSameOnEveryFmaMachine) {
#ifndef __FMA__
  GTEST_SKIP() << "built without FMA (-march=x86-64): each a*b+c rounds twice, so the bits differ by design";
#endif
  const Golden cases[] = {
      {Precision::Float, SolverType::PGS, 1, 0x1d95ee891a39e3c7ull},
      {Precision::Float, SolverType::TGS, 2, 0xe183d98b8a8d84edull},
      {Precision::Double, SolverType::PGS, 2, 0x90e4995ada922844ull},
  };
  for (const Golden& c : cases)
    EXPECT_EQ(hex(rollout_hash(c.precision, c.solver, c.threads)), hex(c.hash))
        << precision_name(c.precision) << " " << solver_name(c.solver) << ", " << c.threads << " thread(s)";
}

}  // namespace
}  // namespace lockstep
