// What writing a rollout costs: BM_rollout/<contacts>/<record> steps N = 4096
// copies of anymal_b (floating, standing under position-target drives, on
// the ground or without contacts) through VecEnv, one thread for the step,
// and with record=1 hands every step to a RolloutRecorder (its background
// thread writes the file in a temporary folder). The overhead is the ratio of
// the record=1 and record=0 times per env-step.
//
//   build/release/bin/lockstep_bench --benchmark_filter=BM_rollout
#include "io/rollout_recorder.hpp"
#include "io/scene_file.hpp"
#include "tools/step_scene.hpp"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <filesystem>
#include <memory>
#include <string>

namespace lockstep {
namespace {

constexpr int kCopies = 4096;

void run_rollout(benchmark::State& bench, bool contacts, bool record) {
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  Scene scene = scene_from_urdf(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/anymal_b.urdf", true, contacts);
  const step_scene::Scene standing = step_scene::make_scene(scene.model, contacts);
  scene.env.dofs = standing.dofs;
  scene.env.initial_q = standing.q0;
  scene.env.action_mode = ActionMode::PositionTarget;
  if (!contacts) disable_contacts(scene);
  VecEnv env(scene.model, kCopies, scene.env);
  env.reset();
  RowMatrix actions(kCopies, env.action_size());
  for (int j = 0; j < env.action_size(); ++j)
    actions.col(j).setConstant(standing.q0[scene.model.body_q_offset[scene.model.dof_body[env.action_dofs()[j]]]]);
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("lockstep_rollout_bench_" + std::to_string(::getpid()) + ".h5");
  std::unique_ptr<RolloutRecorder> recorder;
  if (record)
    recorder = std::make_unique<RolloutRecorder>(env, file.string(), RolloutInfo{"{}", scene.model_path, "hold", {}});
  env.step(actions);  // warm-up: the threads' workspaces
  for (auto _ : bench) {
    env.step(actions);
    if (recorder) recorder->record(actions);
  }
  if (recorder) recorder->close();
  std::filesystem::remove(file);
  const double env_steps = static_cast<double>(bench.iterations()) * kCopies;
  bench.counters["env_steps_per_s"] = benchmark::Counter(env_steps, benchmark::Counter::kIsRate);
  bench.counters["ns_per_env_step"] =
      benchmark::Counter(env_steps / 1e9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

int register_all() {
  for (bool contacts : {true, false})
    for (bool record : {false, true}) {
      const std::string name = std::string("BM_rollout/") + (contacts ? "ground" : "no_contacts") + "/record:" +
                               (record ? "1" : "0");
      benchmark::RegisterBenchmark(name.c_str(), [=](benchmark::State& st) { run_rollout(st, contacts, record); })
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
    }
  return 0;
}
const int registered = register_all();

}  // namespace
}  // namespace lockstep
