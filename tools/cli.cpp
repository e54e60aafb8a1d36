#include "tools/cli.hpp"

#include "io/urdf_import.hpp"
#include "io/json.hpp"
#include "io/joint_state.hpp"
#include "io/rollout_file.hpp"
#include "layout/name_hint.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <exception>
#include <filesystem>
#include <new>
#include <ostream>

#ifndef LOCKSTEP_SOURCE_MODELS_DIR
#define LOCKSTEP_SOURCE_MODELS_DIR ""
#endif
#ifndef LOCKSTEP_INSTALL_MODELS_DIR
#define LOCKSTEP_INSTALL_MODELS_DIR ""
#endif

namespace lockstep::cli {

namespace fs = std::filesystem;

namespace {

constexpr const char* kDefaultModel = "quadruped.urdf";
constexpr const char* kDefaultState = "quadruped_state.json";

// Each command's lines of the usage, in the order `lockstep help` lists them.
struct CommandUsage {
  const char* name;
  const char* lines;
};
constexpr CommandUsage kCommands[] = {
    {"info",
     "  info MODEL.urdf [--floating-base] [--json] [--strict]\n"
     "      the articulation tree: bodies, frames, DOFs, mass, loading warnings\n"},
    {"dynamics",
     "  dynamics MODEL.urdf --state STATE.json [--floating-base] [--precision float|double]\n"
     "      mass matrix, bias and gravity forces, forward dynamics, energies and\n"
     "      link poses for one state, as JSON\n"},
    {"bench",
     "  bench [MODEL.urdf|SCENE.json] [--envs N] [--threads 1,2] [--precision float,double]\n"
     "        [--steps S] [--repeats R] [--dt DT] [--solver pgs|tgs] [--iterations N]\n"
     "        [--mujoco-steps M] [--no-mujoco] [--spread S]\n"
     "        [--floating-base] [--ground] [--no-contacts] [--json]\n"
     "      env-steps per second of the simulation step, copies holding their initial\n"
     "      pose (default: anymal_b, floating), time by phase, MuJoCo beside it if built in\n"},
    {"rollout",
     "  rollout MODEL.urdf|SCENE.json --out FILE.h5 [--envs N] [--steps T]\n"
     "          [--policy zero|hold|sine|random] [--threads K] [--precision float|double]\n"
     "          [--seed S] [--episode-steps E] [--floating-base] [--ground] [--no-contacts]\n"
     "          [--compression 0-9] [--flush-seconds S]\n"
     "      N copies under a built-in policy for T env steps, written to a rollout file\n"},
    {"demo",
     "  demo\n"
     "      info and dynamics on the bundled model (also what no command does)\n"},
    {"help",
     "  help [COMMAND]\n"
     "      this text, or one command's (also COMMAND --help)\n"},
};

constexpr const char* kExitCodes =
    "Exit codes: 0 ok, 1 internal error, 2 bad arguments or input, 3 CPU lacks\n"
    "required instructions, 4 the output file cannot be written, 130 a rollout\n"
    "interrupted (its file keeps the steps taken). Formats: docs/cli.md.\n";

const CommandUsage* find_command(const std::string& name) {
  for (const CommandUsage& c : kCommands)
    if (name == c.name) return &c;
  return nullptr;
}

// " (did you mean \"rollout\"?)" for a misspelled command, or empty.
std::string command_hint(const std::string& name) {
  std::vector<std::string> names;
  for (const CommandUsage& c : kCommands) names.emplace_back(c.name);
  return did_you_mean(name, names);
}

// The whole usage, or one command's.
std::string usage(const CommandUsage* only = nullptr) {
  std::string text = "usage: lockstep <command> [arguments]\n\n";
  if (only) return text + only->lines + "\n(lockstep help: every command; docs/cli.md: formats, exit codes)\n";
  text += "commands:\n";
  for (const CommandUsage& c : kCommands) text += c.lines;
  return text + "\n" + kExitCodes;
}

bool asks_for_help(const std::vector<std::string>& args) {
  return std::any_of(args.begin(), args.end(), [](const std::string& a) { return a == "--help" || a == "-h"; });
}

}  // namespace

bool ParsedArgs::has(const std::string& flag) const {
  return std::find(flags.begin(), flags.end(), flag) != flags.end();
}

const std::string* ParsedArgs::value(const std::string& option) const {
  for (const auto& [name, value] : options)
    if (name == option) return &value;
  return nullptr;
}

ParsedArgs parse_args(const std::vector<std::string>& args, const std::vector<std::string>& flags,
                      const std::vector<std::string>& options) {
  const auto contains = [](const std::vector<std::string>& list, const std::string& s) {
    return std::find(list.begin(), list.end(), s) != list.end();
  };
  ParsedArgs parsed;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg.size() < 2 || arg[0] != '-') {
      parsed.positional.push_back(arg);
      continue;
    }
    if (arg == "--") throw UsageError("unexpected \"--\": options and files may come in any order");
    if (arg[1] != '-') throw UsageError("unknown option " + arg + " (options start with --)");
    const std::size_t eq = arg.find('=');
    const std::string name = arg.substr(0, eq);
    if (contains(flags, name)) {
      if (eq != std::string::npos) throw UsageError("option " + name + " takes no value");
      if (!parsed.has(name)) parsed.flags.push_back(name);
    } else if (contains(options, name)) {
      std::string value;
      if (eq != std::string::npos) value = arg.substr(eq + 1);
      else if (i + 1 < args.size()) value = args[++i];
      if (value.empty()) throw UsageError("option " + name + " needs a value");
      if (parsed.value(name)) throw UsageError("option " + name + " given twice");
      parsed.options.emplace_back(name, value);
    } else {
      std::vector<std::string> known = flags;
      known.insert(known.end(), options.begin(), options.end());
      throw UsageError("unknown option " + name + did_you_mean(name, known));
    }
  }
  return parsed;
}

// Decimal only, the whole text: no leading space, no hexadecimal (which
// std::stod took: --envs 0x10 ran 16 copies).
double parse_number(const std::string& option, const std::string& text) {
  double x = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), x, std::chars_format::general);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size() || !std::isfinite(x))
    throw UsageError(option + " expects a number, not \"" + text + "\"");
  return x;
}

long parse_count(const std::string& option, const std::string& text, long minimum, double maximum) {
  const double x = parse_number(option, text);
  if (x > maximum && x == std::floor(x))
    throw UsageError(option + " must be at most " + std::to_string(static_cast<long long>(maximum)) + ", not \"" +
                     text + "\"");
  if (x < static_cast<double>(minimum) || x != std::floor(x))
    throw UsageError(option + " expects a whole number >= " + std::to_string(minimum) + ", not \"" + text + "\"");
  return static_cast<long>(x);
}

std::uint64_t parse_unsigned(const std::string& option, const std::string& text) {
  std::uint64_t x = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), x);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size())
    throw UsageError(option + " expects a whole number in [0, 18446744073709551615], not \"" + text + "\"");
  return x;
}

Precision parse_precision(const std::string& text) {
  if (text == "float") return Precision::Float;
  if (text == "double") return Precision::Double;
  throw UsageError("--precision must be float or double, not \"" + text + "\"");
}

LoadedModel load_model(const std::string& path, bool floating_base, bool strict) {
  LoadedModel loaded;
  loaded.path = path;
  loaded.floating_base = floating_base;
  UrdfOptions urdf_options;
  urdf_options.floating_base = floating_base;
  BuildOptions build_options;
  build_options.strict = strict;
  try {
    loaded.model = load_urdf(path, urdf_options, build_options, &loaded.warnings);
  } catch (const ModelError&) {
    throw;
  } catch (const std::exception& e) {
    // Any failure to load is bad input; make sure the message names the file.
    const std::string what = e.what();
    throw ModelError(what.find(path) == std::string::npos ? path + ": " + what : what);
  }
  return loaded;
}

std::string bundled_models_dir() {
  std::vector<fs::path> candidates;
  candidates.emplace_back(LOCKSTEP_SOURCE_MODELS_DIR);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) candidates.push_back(exe.parent_path().parent_path() / "share" / "lockstep" / "models");
  candidates.emplace_back(LOCKSTEP_INSTALL_MODELS_DIR);
  for (const fs::path& dir : candidates)
    if (!dir.empty() && fs::exists(dir / kDefaultModel, ec)) return dir.string();
  std::string tried;
  for (const fs::path& dir : candidates)
    if (!dir.empty()) tried += "\n  " + dir.string();
  throw UsageError(std::string("cannot find the bundled model ") + kDefaultModel + "; looked in:" + tried);
}

int run_demo(const std::vector<std::string>& args, std::ostream& out) {
  if (!args.empty()) throw UsageError("demo takes no arguments");
  const fs::path dir = bundled_models_dir();
  const std::string model = (dir / kDefaultModel).string();
  const std::string state = (dir / kDefaultState).string();
  out << "$ lockstep info " << model << " --floating-base\n";
  int rc = run_info({model, "--floating-base"}, out);
  if (rc != kExitOk) return rc;
  out << "\n$ lockstep dynamics " << model << " --state " << state << " --floating-base\n";
  return run_dynamics({model, "--state", state, "--floating-base"}, out);
}

int main(int argc, char** argv, std::ostream& out, std::ostream& err) {
  std::vector<std::string> args(argv + std::min(argc, 1), argv + argc);
  const std::string command = args.empty() ? "demo" : args.front();
  if (!args.empty()) args.erase(args.begin());
  const CommandUsage* known = find_command(command);
  try {
    if (known && known->name != std::string("help") && asks_for_help(args)) {
      out << usage(known);
      return kExitOk;
    }
    if (command == "info") return run_info(args, out);
    if (command == "dynamics") return run_dynamics(args, out);
    if (command == "bench") return run_bench(args, out);
    if (command == "rollout") return run_rollout(args, out);
    if (command == "demo") return run_demo(args, out);
    if (command == "help" || command == "--help" || command == "-h") {
      if (args.size() > 1) throw UsageError("help takes at most one command");
      const CommandUsage* about = args.empty() ? nullptr : find_command(args.front());
      if (!args.empty() && !about)
        throw UsageError("no command \"" + args.front() + "\"" + command_hint(args.front()));
      out << usage(about);
      return kExitOk;
    }
    known = nullptr;
    throw UsageError("unknown command \"" + command + "\"" + command_hint(command));
  } catch (const UsageError& e) {
    err << "lockstep" << (known ? std::string(" ") + known->name : std::string()) << ": " << e.what() << "\n\n"
        << usage(known && known->name != std::string("help") ? known : nullptr);
    return kExitBadInput;
  } catch (const ModelError& e) {
    err << "lockstep: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const StateError& e) {
    err << "lockstep: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const json::ParseError& e) {
    err << "lockstep: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const SceneError& e) {
    err << "lockstep: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const RolloutFileError& e) {
    err << "lockstep: " << e.what() << "\n";
    return kExitOutput;
  } catch (const std::bad_alloc&) {
    // the copies (and a rollout's buffers) grow with --envs
    err << "lockstep: not enough memory for this run: give fewer --envs\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    err << "lockstep: internal error: " << e.what() << "\n";
    return kExitInternal;
  }
}

}  // namespace lockstep::cli
