// What the readouts of a step's motion cost (StepOptions::record_motion):
// BM_readout/<readout> reads every one of N = 4096 copies of anymal_b
// (floating, standing on the ground under the stance drives, so that the
// joint forces take four contacts per copy) after a step, through the bulk
// call (all_incoming_joint_forces, all_link_accelerations) or the per-copy
// one N times. Compare ns_per_copy with the step's ns per env-step.
//
//   build/release/bin/lockstep_bench --benchmark_filter=BM_readout
#include "batch/simulator.hpp"
#include "io/urdf_import.hpp"
#include "tools/step_scene.hpp"

#include <benchmark/benchmark.h>

#include <string>

namespace lockstep {
namespace {

constexpr int kCopies = 4096;

enum class Readout { JointForces, LinkAccelerations };

void BM_readout(benchmark::State& bench, Readout readout, bool bulk) {
  UrdfOptions floating;
  floating.floating_base = true;
  const Model model = load_urdf(std::string(LOCKSTEP_SHARED_MODELS_DIR) + "/anymal_b.urdf", floating);
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  StepOptions o;
  o.contacts.ground = true;
  o.record_motion = true;
  Simulator sim(model, kCopies, o, scene.dofs);
  sim.set_state_all(scene.q0, scene.v0);
  for (int c = 0; c < kCopies; ++c) sim.set_drive_target(c, scene.q_target, Eigen::VectorXd::Zero(model.nv));
  sim.step(10);
  const int columns = readout == Readout::JointForces ? model.nbody : static_cast<int>(model.frame_name.size());
  RowMatrix all(kCopies, 6 * columns);
  for (auto _ : bench) {
    if (bulk && readout == Readout::JointForces) sim.all_incoming_joint_forces(all);
    else if (bulk) sim.all_link_accelerations(all);
    else
      for (int c = 0; c < kCopies; ++c) {
        const Eigen::Matrix<double, 6, Eigen::Dynamic> m =
            readout == Readout::JointForces ? sim.incoming_joint_forces(c) : sim.link_accelerations(c);
        all.row(c) = Eigen::Map<const Eigen::RowVectorXd>(m.data(), m.size());
      }
    benchmark::DoNotOptimize(all.data());
  }
  const double copies = static_cast<double>(bench.iterations()) * kCopies;
  bench.counters["ns_per_copy"] =
      benchmark::Counter(copies / 1e9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

BENCHMARK_CAPTURE(BM_readout, joint_forces_bulk, Readout::JointForces, true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_readout, joint_forces_per_copy, Readout::JointForces, false)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_readout, link_accelerations_bulk, Readout::LinkAccelerations, true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_readout, link_accelerations_per_copy, Readout::LinkAccelerations, false)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace lockstep
