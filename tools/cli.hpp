// The `lockstep` command-line program: subcommands and what they share.
// Output formats and exit codes: docs/cli.md.
#pragma once

#include "batch/precision.hpp"
#include "io/scene_file.hpp"
#include "layout/model.hpp"

#include <cstdint>
#include <iosfwd>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace lockstep::cli {

// Exit codes (3, a CPU without the required instructions, comes from
// tools/cpu_check.hpp before main runs).
inline constexpr int kExitOk = 0;
inline constexpr int kExitInternal = 1;  // a bug or an unexpected failure
inline constexpr int kExitBadInput = 2;  // bad arguments, model, state or scene file
inline constexpr int kExitOutput = 4;    // the output file cannot be written (path, permissions, full disk)
inline constexpr int kExitInterrupted = 130;  // SIGINT or SIGTERM stopped a rollout (128 + SIGINT, as shells report it)

// Bad command-line arguments; main prints the message and exits kExitBadInput.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct LoadedModel {
  std::string path;
  bool floating_base = false;
  Model model;
  std::vector<std::string> warnings;
};

// Command-line arguments split into positionals, flags (--json) and
// options with a value (--state X or --state=X); anything else is a
// UsageError naming the argument.
struct ParsedArgs {
  std::vector<std::string> positional;
  std::vector<std::string> flags;
  std::vector<std::pair<std::string, std::string>> options;
  bool has(const std::string& flag) const;
  const std::string* value(const std::string& option) const;  // nullptr when not given
};
ParsedArgs parse_args(const std::vector<std::string>& args, const std::vector<std::string>& flags,
                      const std::vector<std::string>& options);

// Option values; a UsageError names the option and the text.
double parse_number(const std::string& option, const std::string& text);  // finite
long parse_count(const std::string& option, const std::string& text, long minimum = 1, double maximum = 1e9);
// A whole number in [0, 2^64) in decimal digits, exactly (a seed).
std::uint64_t parse_unsigned(const std::string& option, const std::string& text);
Precision parse_precision(const std::string& text);  // float or double

// "1 thread", "2 threads": a count and its noun, plural past one.
inline std::string count_of(long n, const std::string& noun) {
  return std::to_string(n) + " " + noun + (n == 1 ? "" : "s");
}

// Loads a URDF; errors (missing file, invalid model, a warning under
// `strict`) propagate as exceptions naming the file.
LoadedModel load_model(const std::string& path, bool floating_base, bool strict);

// `lockstep info MODEL.urdf [--floating-base] [--json] [--strict]`
int run_info(const std::vector<std::string>& args, std::ostream& out);
void print_info_text(const LoadedModel& loaded, std::ostream& out);
void print_info_json(const LoadedModel& loaded, std::ostream& out);

// `lockstep dynamics MODEL.urdf --state STATE.json [--floating-base] [--precision float|double]`
int run_dynamics(const std::vector<std::string>& args, std::ostream& out);

// `lockstep bench [MODEL.urdf|SCENE.json] [--envs N] [--threads LIST] [--precision LIST]
// [--steps S] [--repeats R] [--dt DT] [--solver pgs|tgs] [--iterations N] [--mujoco-steps M]
// [--no-mujoco] [--spread S] [--floating-base]
// [--ground] [--no-contacts] [--json]`: env-steps per second of the simulation step,
// its time by phase (and MuJoCo's speed when built with it).
int run_bench(const std::vector<std::string>& args, std::ostream& out);

// `lockstep rollout MODEL.urdf|SCENE.json --out FILE.h5 [--envs N] [--steps T]
// [--policy zero|hold|sine|random] [--threads K] [--precision float|double] [--seed S]
// [--episode-steps E] [--floating-base] [--ground] [--no-contacts] [--compression L]
// [--flush-seconds S]`: a rollout file of N copies under a built-in policy.
int run_rollout(const std::vector<std::string>& args, std::ostream& out);

// The scene the CLI runs: a scene file, or a bare URDF standing under
// position-target drives as `lockstep bench` poses it (tools/step_scene.hpp);
// --ground adds the plane, --no-contacts turns contacts off.
Scene load_cli_scene(const std::string& path, bool floating_base, bool ground, bool no_contacts);

// Returns build() (a Simulator or VecEnv of the scene): a scene whose
// settings the simulator refuses once they meet (RK4 with solver rows,
// position-target actions on DOFs without gains, ...) is bad input, a
// SceneError naming the scene's file, not an internal error.
template <class Build>
auto build_from_scene(const Scene& scene, Build&& build) -> decltype(build()) {
  try {
    return build();
  } catch (const std::invalid_argument& e) {
    throw SceneError(scene.source + ": the scene cannot be simulated: " + e.what());
  }
}

// `lockstep demo`: info and dynamics on the bundled model.
int run_demo(const std::vector<std::string>& args, std::ostream& out);

// The folder holding the bundled models: the source tree's models/ when it is
// still there, else the installed share/lockstep/models (found next to the
// executable first, then at the configured install prefix).
std::string bundled_models_dir();

// Parses argv and runs a subcommand; prints errors to `err` and returns the
// exit code.
int main(int argc, char** argv, std::ostream& out, std::ostream& err);

}  // namespace lockstep::cli
