// The simulation step on one thread: BM_step/<model>/<precision> advances
// N = 4096 copies of the scene `lockstep bench` times (tools/step_scene.hpp:
// floating base, no contacts, PD drives holding a standing pose) by one
// step per iteration and reports ns_per_env_step and env_steps_per_s.
//
//   build/release/bin/lockstep_bench --benchmark_filter=BM_step
#include "io/urdf_import.hpp"
#include "tools/step_scene.hpp"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <string>

// LOCKSTEP_SHARED_MODELS_DIR comes from the lockstep_model_dirs target.

namespace lockstep {
namespace {

constexpr int kCopies = 4096;

void run_step(benchmark::State& bench, const std::string& model_name, Precision precision) {
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  UrdfOptions urdf;
  urdf.floating_base = true;
  const Model model = load_urdf(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/" + model_name + ".urdf", urdf);
  const step_scene::Scene scene = step_scene::make_scene(model);
  StepOptions options;
  options.precision = precision;
  Simulator sim = step_scene::make_simulator(model, scene, kCopies, options);
  sim.step();  // warm-up: the threads' workspaces
  for (auto _ : bench) sim.step();
  const double env_steps = static_cast<double>(bench.iterations()) * kCopies;
  bench.counters["env_steps_per_s"] = benchmark::Counter(env_steps, benchmark::Counter::kIsRate);
  // An inverted rate of (env-steps / 1e9) per second is nanoseconds per env-step.
  bench.counters["ns_per_env_step"] =
      benchmark::Counter(env_steps / 1e9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  if (sim.fault_count() != 0) bench.SkipWithError("copies faulted");
}

int register_all() {
  for (Precision precision : {Precision::Float, Precision::Double}) {
    const std::string name = std::string("BM_step/anymal_b_floating/") + precision_name(precision);
    benchmark::RegisterBenchmark(name.c_str(), [=](benchmark::State& st) { run_step(st, "anymal_b", precision); })
        ->Unit(benchmark::kMillisecond);
  }
  return 0;
}
const int registered = register_all();

}  // namespace
}  // namespace lockstep
