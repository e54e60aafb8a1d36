// What resetting copies costs: BM_reset/<randomization> resets all N = 4096
// copies of anymal_b (floating, on the ground) through VecEnv::reset(which),
// with no randomization or with every field of Randomization drawn. A
// copy's reset is what auto-reset does to it within step(); compare its
// ns_per_reset with BM_rollout's ns_per_env_step times the episode length.
//
//   build/release/bin/lockstep_bench --benchmark_filter=BM_reset
#include "io/scene_file.hpp"
#include "tools/step_scene.hpp"

#include <benchmark/benchmark.h>

#include <numeric>
#include <string>
#include <vector>

namespace lockstep {
namespace {

constexpr int kCopies = 4096;

void BM_reset(benchmark::State& bench, bool randomized) {
  Scene scene = scene_from_urdf(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/anymal_b.urdf", true, true);
  const step_scene::Scene standing = step_scene::make_scene(scene.model, true);
  scene.env.dofs = standing.dofs;
  scene.env.initial_q = standing.q0;
  if (randomized) {
    Randomization& r = scene.env.randomization;
    r.mass_scale = {0.9, 1.1};
    r.com_offset = {-0.01, 0.01};
    r.kp_scale = r.kd_scale = r.damping_scale = r.joint_friction_scale = {0.9, 1.1};
    r.armature_add = {0.0, 0.01};
    r.gravity_offset = {-0.1, 0.1};
    r.joint_position_noise = r.joint_velocity_noise = {-0.05, 0.05};
    r.root_position_noise = r.root_velocity_noise = r.root_yaw_noise = {-0.1, 0.1};
    r.ground_friction = {0.6, 1.0};
    r.randomize_ground_friction = true;
  }
  VecEnv env(scene.model, kCopies, scene.env);
  env.reset();
  std::vector<int> all(kCopies);
  std::iota(all.begin(), all.end(), 0);
  for (auto _ : bench) env.reset(all);
  const double resets = static_cast<double>(bench.iterations()) * kCopies;
  bench.counters["ns_per_reset"] =
      benchmark::Counter(resets / 1e9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

BENCHMARK_CAPTURE(BM_reset, plain, false)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_reset, randomized, true)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace lockstep
