// The `lockstep` command-line program: subcommands and what they share.
// Output formats and exit codes: docs/cli.md.
#pragma once

#include "layout/model.hpp"

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
inline constexpr int kExitBadInput = 2;  // bad arguments, model or state file

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

// Loads a URDF; errors (missing file, invalid model, a warning under
// `strict`) propagate as exceptions naming the file.
LoadedModel load_model(const std::string& path, bool floating_base, bool strict);

// `lockstep info MODEL.urdf [--floating-base] [--json] [--strict]`
int run_info(const std::vector<std::string>& args, std::ostream& out);
void print_info_text(const LoadedModel& loaded, std::ostream& out);
void print_info_json(const LoadedModel& loaded, std::ostream& out);

// `lockstep dynamics MODEL.urdf --state STATE.json [--floating-base] [--precision float|double]`
int run_dynamics(const std::vector<std::string>& args, std::ostream& out);

// `lockstep bench [MODEL.urdf] [--copies N] [--threads LIST] [--precision LIST]
// [--steps S] [--repeats R] [--dt DT] [--mujoco-steps M] [--no-mujoco] [--json]`:
// env-steps per second of the simulation step (and of MuJoCo when built with it).
int run_bench(const std::vector<std::string>& args, std::ostream& out);

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
