// What a stage costs when a scene does not use it: anymal_b (floating, no
// contacts, no drives, no damping or friction, limits never reached)
// stepped with one stage forced On and then Off. The states are the same
// bit for bit (tests/step_stages_test.cpp); this measures the time.
// Named BM_stage_cost/<stage>/<on|off>, counter ns_per_env_step; float,
// SIMD lanes, N = 4096, one thread.
//
//   build/release/bin/lockstep_bench --benchmark_filter=BM_stage_cost
#include "batch/simulator.hpp"
#include "io/urdf_import.hpp"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <string>

#ifndef LOCKSTEP_SHARED_MODELS_DIR
#define LOCKSTEP_SHARED_MODELS_DIR "../shared/models"
#endif

namespace lockstep {
namespace {

constexpr int kCopies = 4096;
constexpr int kSteps = 10;

void stage_cost(benchmark::State& bench, Stage stage, StageMode mode) {
  const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  UrdfOptions urdf;
  urdf.floating_base = true;
  const Model model = load_urdf(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/anymal_b.urdf", urdf);
  StepOptions options;
  // the limit rows of the URDF are off unless they are the stage measured
  options.force(Stage::HardLimits, StageMode::Off).force(Stage::VelocityLimits, StageMode::Off);
  options.force(stage, mode);
  Simulator sim(model, kCopies, options);
  sim.step();  // first touch of the per-thread scratch
  for (auto _ : bench) sim.step(kSteps);
  const double env_steps = static_cast<double>(bench.iterations()) * kCopies * kSteps;
  bench.counters["ns_per_env_step"] =
      benchmark::Counter(env_steps * 1e-9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void register_all() {
  for (int s = 0; s < kStageCount; ++s)
    for (StageMode mode : {StageMode::On, StageMode::Off}) {
      const Stage stage = static_cast<Stage>(s);
      std::string name = std::string("BM_stage_cost/") + stage_name(stage) + (mode == StageMode::On ? "/on" : "/off");
      for (char& c : name)
        if (c == ' ') c = '_';
      benchmark::RegisterBenchmark(name.c_str(), [stage, mode](benchmark::State& b) { stage_cost(b, stage, mode); })
          ->Unit(benchmark::kMillisecond);
    }
}

const int registered = (register_all(), 0);

}  // namespace
}  // namespace lockstep
