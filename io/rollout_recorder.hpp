// Recording a vectorised environment's rollout into a rollout file (the
// dataset schema of docs/rollout_files.md, "Datasets of `lockstep rollout`"):
// per env step the state after the step (the terminal state for copies that
// ended and were reset), the actions, the applied torques, rewards, episode
// flags and, when the scene has contacts, the contact force on every body;
// once, the initial state and what ran (scene, model hash, names, options).
//
//   env.reset();
//   lockstep::RolloutRecorder recorder(env, "out.h5", info);  // the initial state
//   for (int t = 0; t < T; ++t) {
//     env.step(actions);
//     recorder.record(actions);
//   }
//   recorder.close(summary);
#pragma once

#include "batch/vec_env.hpp"
#include "io/rollout_file.hpp"

#include <memory>
#include <string>
#include <vector>

namespace lockstep {

// What a rollout file records about its run besides the data.
struct RolloutInfo {
  std::string scene_json;  // the scene as scene_to_json wrote it
  std::string model_path;  // its model's URDF (hashed)
  std::string policy;      // what chose the actions
  std::vector<Attribute> extra;  // more attributes
};

class RolloutRecorder {
 public:
  // Creates the file with the environment's current state as the initial
  // state (construct it after env.reset()). RolloutFileError on failure.
  // The environment must outlive the recorder.
  RolloutRecorder(const VecEnv& env, const std::string& path, const RolloutInfo& info, RolloutFileOptions file = {});
  ~RolloutRecorder();

  // The step just taken with `actions` (N x action_size); once per env
  // step (std::invalid_argument for other actions' shape, std::logic_error
  // when the environment has not stepped since the last record).
  void record(const RowMatrix& actions);
  // Writes the rest and marks the file complete, with `summary` attributes
  // (`steps`, the steps recorded, is added here: std::invalid_argument if
  // the summary has its own).
  void close(std::vector<Attribute> summary = {});
  // Writes the rest and closes the file without marking it complete (a run
  // stopped early; RolloutWriter::close_incomplete).
  void close_incomplete();

  std::int64_t steps() const { return steps_; }
  double seconds_recording() const { return seconds_recording_; }  // in record(), waiting included
  double seconds_waiting() const;                                   // for the disk
  std::int64_t steps_flushed() const;

 private:
  const VecEnv& env_;
  std::unique_ptr<RolloutWriter> writer_;
  std::string path_;
  std::vector<int> ended_;  // copies whose episode ended in the step recorded
  std::int64_t steps_ = 0;
  std::int64_t env_steps_recorded_;  // env_.steps() at the last record (at construction, the initial state)
  double seconds_recording_ = 0;
};

}  // namespace lockstep
