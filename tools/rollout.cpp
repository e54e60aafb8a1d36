// `lockstep rollout`: N copies of a scene under a built-in policy for T env
// steps, written to a rollout file (docs/cli.md, docs/rollout_files.md).
#include "io/rollout_recorder.hpp"
#include "io/scene_file.hpp"
#include "tools/cli.hpp"
#include "tools/rollout_policy.hpp"
#include "tools/step_scene.hpp"

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <optional>
#include <ostream>
#include <sstream>

namespace lockstep::cli {

namespace {

using Clock = std::chrono::steady_clock;

// SIGINT or SIGTERM during a rollout: the loop stops after its step, and
// the file keeps every step recorded, marked incomplete.
std::atomic<bool> stop_requested{false};
extern "C" void request_stop(int) { stop_requested.store(true); }

// Installs request_stop for SIGINT and SIGTERM, and ignores SIGXFSZ: past
// a file-size limit (ulimit -f) a write then fails with EFBIG, which the
// writer reports with the file's name (exit 4), where the signal would kill
// the process without a word. The old handlers come back with the object.
class StopOnSignal {
 public:
  StopOnSignal()
      : old_int_(std::signal(SIGINT, request_stop)),
        old_term_(std::signal(SIGTERM, request_stop)),
        old_xfsz_(std::signal(SIGXFSZ, SIG_IGN)) {
    stop_requested.store(false);
  }
  ~StopOnSignal() {
    std::signal(SIGINT, old_int_);
    std::signal(SIGTERM, old_term_);
    std::signal(SIGXFSZ, old_xfsz_);
  }
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

 private:
  void (*old_int_)(int);
  void (*old_term_)(int);
  void (*old_xfsz_)(int);
};

struct RolloutConfig {
  std::string model;
  std::string out;
  int envs = 1024;
  std::int64_t steps = 500;
  PolicyKind policy = PolicyKind::Hold;
  int threads = 0;  // 0: every core this process may run on
  std::optional<Precision> precision;
  std::optional<std::uint64_t> seed;
  std::optional<int> episode_steps;
  bool floating_base = false, ground = false, no_contacts = false;
  RolloutFileOptions file;
};

RolloutConfig parse_config(const std::vector<std::string>& args) {
  const ParsedArgs parsed = parse_args(args, {"--floating-base", "--ground", "--no-contacts"},
                                       {"--envs", "--steps", "--out", "--policy", "--threads", "--precision", "--seed",
                                        "--episode-steps", "--compression", "--flush-seconds"});
  if (parsed.positional.size() != 1)
    throw UsageError("rollout takes one MODEL.urdf or SCENE.json, got " + std::to_string(parsed.positional.size()));
  RolloutConfig c;
  c.model = parsed.positional[0];
  const std::string* out = parsed.value("--out");
  if (!out || out->empty()) throw UsageError("rollout needs --out FILE.h5");
  c.out = *out;
  if (const auto* v = parsed.value("--envs")) c.envs = static_cast<int>(parse_count("--envs", *v));
  if (const auto* v = parsed.value("--steps")) c.steps = parse_count("--steps", *v);
  if (const auto* v = parsed.value("--policy")) c.policy = parse_policy(*v);
  if (const auto* v = parsed.value("--threads")) c.threads = static_cast<int>(parse_count("--threads", *v));
  if (const auto* v = parsed.value("--precision")) c.precision = parse_precision(*v);
  if (const auto* v = parsed.value("--seed")) c.seed = parse_unsigned("--seed", *v);
  if (const auto* v = parsed.value("--episode-steps"))
    c.episode_steps = static_cast<int>(parse_count("--episode-steps", *v, 0));
  if (const auto* v = parsed.value("--compression")) {
    c.file.compression = static_cast<int>(parse_count("--compression", *v, 0));
    if (c.file.compression > 9) throw UsageError("--compression must be a gzip level 0..9, not \"" + *v + "\"");
  }
  if (const auto* v = parsed.value("--flush-seconds")) {
    c.file.flush_seconds = parse_number("--flush-seconds", *v);
    if (!(c.file.flush_seconds >= 0 && c.file.flush_seconds <= 1e6))  // the writer's own range
      throw UsageError("--flush-seconds must lie in [0, 1e6] (0: at every step), not \"" + *v + "\"");
  }
  c.floating_base = parsed.has("--floating-base");
  c.ground = parsed.has("--ground");
  c.no_contacts = parsed.has("--no-contacts");
  return c;
}

// Progress on a terminal: a bar redrawn in place; otherwise a plain line
// every 10 % of the run.
class Progress {
 public:
  Progress(std::int64_t total, std::int64_t envs) : total_(total), envs_(envs), tty_(isatty(STDERR_FILENO)) {}
  void update(std::int64_t done, double seconds) {
    const int tenth = static_cast<int>(10 * done / total_);
    const bool redraw = tty_ ? seconds - last_ >= 0.2 || done == total_ : tenth > last_tenth_;
    if (!redraw) return;
    last_ = seconds;
    last_tenth_ = tenth;
    const double rate = seconds > 0 ? static_cast<double>(done * envs_) / seconds : 0.0;
    const double eta = done > 0 ? seconds * static_cast<double>(total_ - done) / static_cast<double>(done) : 0.0;
    std::ostringstream line;
    line << std::fixed << std::setprecision(0) << 100.0 * static_cast<double>(done) / static_cast<double>(total_)
         << "% " << done << "/" << total_ << " steps, " << std::setprecision(3) << rate / 1e6 << " M env-steps/s, ETA "
         << std::setprecision(1) << eta << " s";
    if (tty_) {
      const int width = 30, filled = static_cast<int>(width * done / total_);
      std::fprintf(stderr, "\r[%s%s] %s   ", std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(),
                   line.str().c_str());
      if (done == total_) std::fprintf(stderr, "\n");
    } else {
      std::fprintf(stderr, "lockstep rollout: %s\n", line.str().c_str());
    }
  }

 private:
  std::int64_t total_, envs_;
  bool tty_;
  double last_ = -1.0;
  int last_tenth_ = 0;
};

}  // namespace

Scene load_cli_scene(const std::string& path, bool floating_base, bool ground, bool no_contacts) {
  Scene scene = load_scene_or_urdf(path, floating_base, ground);
  if (scene.source == scene.model_path) {
    // A bare URDF: bench's standing scene, its drives taking position targets.
    const step_scene::Scene standing = step_scene::make_scene(scene.model, scene.env.step.contacts.ground);
    scene.env.dofs = standing.dofs;
    scene.env.initial_q = standing.q0;
    scene.env.action_mode = ActionMode::PositionTarget;
  }
  fill_initial_state(scene.model, scene.env);  // what VecEnv fills too: bench reads the scene's state directly
  if (no_contacts) disable_contacts(scene);
  // The URDF's import warnings (a mesh not found leaves its link without
  // collision geometry): the first few, and where to read them all.
  constexpr std::size_t kShown = 3;
  for (std::size_t i = 0; i < std::min(scene.warnings.size(), kShown); ++i)
    std::fprintf(stderr, "lockstep: warning: %s\n", scene.warnings[i].c_str());
  if (scene.warnings.size() > kShown)
    std::fprintf(stderr, "lockstep: warning: %zu more loading warnings (`lockstep info %s` lists them all)\n",
                 scene.warnings.size() - kShown, scene.model_path.c_str());
  for (const std::string& warning : scene.value_warnings) std::fprintf(stderr, "lockstep: warning: %s\n", warning.c_str());
  if (const std::optional<std::string> start = ground_start_warning(scene))  // the state and contacts that run
    std::fprintf(stderr, "lockstep: warning: %s\n", start->c_str());
  return scene;
}

int run_rollout(const std::vector<std::string>& args, std::ostream& out) {
  const RolloutConfig config = parse_config(args);
  Scene scene = load_cli_scene(config.model, config.floating_base, config.ground, config.no_contacts);
  std::error_code missing;  // equivalent() is false, with an error, for a file that does not exist
  for (const std::string& input : {scene.source, scene.model_path})
    if (std::filesystem::equivalent(config.out, input, missing))
      throw UsageError("--out " + config.out + " is the input file " + input + "; the rollout would overwrite it");
  // said once the file is replaced (the recorder refuses a link, and leaves
  // the file as it was when the scene cannot be simulated)
  const bool replacing = std::filesystem::is_regular_file(std::filesystem::symlink_status(config.out, missing));
  if (config.precision) scene.env.step.precision = *config.precision;
  if (config.seed) scene.env.seed = *config.seed;
  if (config.episode_steps) scene.env.episode_steps = *config.episode_steps;
  // by default every hardware thread this process may run on (its affinity mask)
  // TBB runs no more threads than its default arena has: more asked for is
  // said, and what runs is recorded
  const int usable = tbb::info::default_concurrency();
  const int threads = config.threads > 0 ? std::min(config.threads, usable) : usable;
  if (config.threads > usable)
    std::fprintf(stderr, "lockstep rollout: warning: --threads %d, but this process may run on %d hardware threads: "
                 "running %d\n", config.threads, usable, threads);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);

  // the first reset sets the initial state and draws, which the simulator checks too
  VecEnv env = build_from_scene(scene, [&] {
    VecEnv built(scene.model, config.envs, scene.env);
    built.reset();
    return built;
  });
  for (const std::string& warning : env.simulator().warnings())
    std::fprintf(stderr, "lockstep rollout: warning: %s\n", warning.c_str());
  RolloutInfo info{scene_to_json(scene), scene.model_path, policy_name(config.policy), {}};
  info.extra.push_back({"threads", static_cast<std::int64_t>(threads)});
  // the writer refuses blocks of steps beyond its memory bound: --envs here
  auto record = [&] {
    try {
      return RolloutRecorder(env, config.out, info, config.file);
    } catch (const std::invalid_argument& e) {
      throw UsageError("--envs " + std::to_string(config.envs) + ": " + e.what());
    }
  };
  RolloutRecorder recorder = record();
  if (replacing) std::fprintf(stderr, "lockstep rollout: replacing %s\n", config.out.c_str());
  Policy policy(config.policy, env, scene.env.seed);

  RowMatrix actions;
  Progress progress(config.steps, config.envs);
  double stepping = 0;
  std::int64_t faults_seen = 0, episodes_ended = 0;
  // Without auto_reset a copy's episode ends once, though it goes on
  // stepping with terminated or truncated set: counted at the first.
  std::vector<char> over(static_cast<std::size_t>(config.envs), 0);
  const StopOnSignal stop_on_signal;
  const auto start = Clock::now();
  for (std::int64_t t = 0; t < config.steps; ++t) {
    if (stop_requested.load()) {
      // the steps so far written and flushed, complete = 0; a failure to
      // write them is the output's error (RolloutFileError: kExitOutput)
      recorder.close_incomplete();
      std::fprintf(stderr, "\nlockstep rollout: interrupted after %lld of %lld steps; %s keeps %lld, marked incomplete\n",
                   static_cast<long long>(t), static_cast<long long>(config.steps), config.out.c_str(),
                   static_cast<long long>(recorder.steps_flushed()));
      return kExitInterrupted;
    }
    policy.act(env, t, actions);
    const auto before = Clock::now();
    env.step(actions);
    stepping += std::chrono::duration<double>(Clock::now() - before).count();
    faults_seen += std::count(env.faulted().begin(), env.faulted().end(), 1);
    for (int c = 0; c < env.copies(); ++c)
      if (env.terminated()[c] || env.truncated()[c]) {
        episodes_ended += !over[c];
        over[c] = !scene.env.auto_reset;
      }
    recorder.record(actions);
    progress.update(t + 1, std::chrono::duration<double>(Clock::now() - start).count());
  }
  const double wall = std::chrono::duration<double>(Clock::now() - start).count();
  const double env_steps = static_cast<double>(config.envs) * static_cast<double>(config.steps);
  recorder.close({{"faulted_env_steps", faults_seen},
                  {"episodes_ended", episodes_ended},
                  {"wall_seconds", wall},
                  {"stepping_seconds", stepping},
                  {"recording_seconds", recorder.seconds_recording()},
                  {"waiting_seconds", recorder.seconds_waiting()},
                  {"env_steps_per_s", env_steps / wall}});
  out << std::fixed << std::setprecision(2) << "wrote " << config.out << ": " << config.envs << " envs x "
      << count_of(config.steps, "step") << " (" << count_of(scene.env.control_steps, "simulator step") << " each) in "
      << wall << " s, " << std::setprecision(3) << env_steps / wall / 1e6 << " M env-steps/s ("
      << count_of(threads, "thread") << ", " << precision_name(scene.env.step.precision) << "), "
      << count_of(faults_seen, "faulted env-step") << ", " << count_of(episodes_ended, "episode")
      << " ended; recording " << std::setprecision(1) << 100.0 * recorder.seconds_recording() / stepping
      << " % of the stepping time, of which waiting for the disk " << 100.0 * recorder.seconds_waiting() / stepping
      << " %\n";
  return kExitOk;
}

}  // namespace lockstep::cli
