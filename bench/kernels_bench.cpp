// FK, RNEA, CRBA and ABA over a batch of N copies on one thread, SIMD lanes.
// Each benchmark is named BM_<kernel>/<model>/<precision>[/N] and reports
// ns_per_copy. The joint transforms (with their sin/cos) are part of every
// kernel's time; ABA and RNEA run with gravity and without link wrenches.
//
//   build/release/bin/lockstep_bench --benchmark_filter=BM_aba
#include "batch/batch_dynamics.hpp"
#include "io/urdf_import.hpp"

#include <benchmark/benchmark.h>

#include <random>
#include <string>

#ifndef LOCKSTEP_SHARED_MODELS_DIR
#define LOCKSTEP_SHARED_MODELS_DIR "../shared/models"
#endif

namespace lockstep {
namespace {

enum class Kernel { Fk, Rnea, Crba, Aba };
const char* kernel_name(Kernel k) {
  switch (k) {
    case Kernel::Fk: return "fk";
    case Kernel::Rnea: return "rnea";
    case Kernel::Crba: return "crba";
    case Kernel::Aba: return "aba";
  }
  return "";
}

struct ModelChoice {
  const char* name;
  bool floating_base;
};

template <class T>
void run_kernel(benchmark::State& bench, const ModelChoice& choice, Kernel kernel, int copies) {
  using L = lane::simd<T>;
  constexpr int W = static_cast<int>(lane::width_v<L>);
  UrdfOptions options;
  options.floating_base = choice.floating_base;
  const Model model = load_urdf(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/" + choice.name + ".urdf", options);
  const KernelModel<T> km(model);
  Workspace<L> ws(km);
  BatchState<T> s(model, copies, W);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int c = 0; c < copies; ++c) {
    Eigen::VectorXd q = model.neutral_configuration();
    for (int b = 0; b < model.nbody; ++b)
      if (model.body_joint[b] == JointType::Revolute) q[model.body_q_offset[b]] = unit(rng);
    s.q.set(c, q);
    s.v.set(c, Eigen::VectorXd::Random(model.nv));
    s.tau.set(c, Eigen::VectorXd::Random(model.nv));
    s.qacc.set(c, Eigen::VectorXd::Random(model.nv));
  }
  const int size = kernel == Kernel::Crba ? model.nv * model.nv : kernel == Kernel::Fk ? 12 * km.nframe : model.nv;
  BatchArray<T> out(copies, size, W);
  for (auto _ : bench) {
    for (int b = 0; b < s.q.blocks(); ++b) {
      BlockInputs<T> in = block_inputs(s, b);
      in.wrench = nullptr;
      joint_transforms<L>(km, in.q, ws);
      // the dynamics read the bodies' world poses where gravity is switched off
      if (kernel != Kernel::Fk && km.needs_world(false)) world_transforms<L>(km, ws);
      switch (kernel) {
        case Kernel::Fk:
          world_transforms<L>(km, ws);
          body_velocities<L>(km, in.v, ws);
          frame_transforms<L>(km, ws, out.block(b));
          break;
        case Kernel::Rnea: in.tau = nullptr; rnea<L>(km, in, ws, out.block(b)); break;
        case Kernel::Crba: crba<L>(km, in.inertia, ws, out.block(b)); break;
        case Kernel::Aba: in.qacc = nullptr; aba<L>(km, in, ws, out.block(b)); break;
      }
    }
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  bench.SetItemsProcessed(bench.iterations() * copies);
  // An inverted rate of (copies / 1e9) per second is nanoseconds per copy.
  bench.counters["ns_per_copy"] = benchmark::Counter(static_cast<double>(bench.iterations()) * copies / 1e9,
                                                     benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

int register_all() {
  const ModelChoice models[] = {{"ur5", false}, {"anymal_b", true}, {"talos_reduced", true}};
  const Kernel kernels[] = {Kernel::Fk, Kernel::Rnea, Kernel::Crba, Kernel::Aba};
  for (Kernel k : kernels)
    for (const ModelChoice& m : models)
      for (const char* precision : {"float", "double"}) {
        const std::string model_name = std::string(m.name) + (m.floating_base ? "_floating" : "_fixed");
        std::vector<int> sizes = {4096};
        if (k == Kernel::Aba && std::string(m.name) == "anymal_b") sizes.push_back(65536);
        for (int n : sizes) {
          std::string name = std::string("BM_") + kernel_name(k) + "/" + model_name + "/" + precision;
          if (n != 4096) name += "/N" + std::to_string(n);
          const bool single = std::string(precision) == "float";
          benchmark::RegisterBenchmark(name.c_str(), [=](benchmark::State& st) {
            if (single) run_kernel<float>(st, m, k, n);
            else run_kernel<double>(st, m, k, n);
          })->Unit(benchmark::kMicrosecond);
        }
      }
  return 0;
}
const int registered = register_all();

}  // namespace
}  // namespace lockstep
