// `lockstep bench`: how fast the simulation step runs, in env-steps per
// second per core and ns per env-step, for each precision and thread count;
// MuJoCo on the same URDF beside it when the build found MuJoCo
// (docs/cli.md, docs/performance.md).
#include "batch/build_info.hpp"
#include "io/json.hpp"
#include "tools/cli.hpp"
#include "tools/step_scene.hpp"
#ifdef LOCKSTEP_HAVE_MUJOCO
#include "tools/mujoco_peer.hpp"
#endif

#include <tbb/global_control.h>
#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <optional>
#include <ostream>
#include <sstream>
#include <thread>

#ifndef LOCKSTEP_SHARED_MODELS_DIR
#define LOCKSTEP_SHARED_MODELS_DIR ""
#endif

namespace lockstep::cli {

namespace {

namespace fs = std::filesystem;

struct BenchConfig {
  std::string model;  // a URDF or a scene file
  bool default_model = false;  // none given: anymal_b with a floating base
  // Without anymal_b among the shared models the build knows, the default
  // is the bundled quadruped, and this says so; empty otherwise.
  std::string stand_in_note;
  int copies = 4096;
  std::vector<int> threads{1, 2};
  std::vector<Precision> precisions{Precision::Float, Precision::Double};
  int steps = 200;
  int repeats = 5;
  std::optional<double> dt;  // overrides the scene's
  std::optional<SolverType> solver;
  std::optional<int> iterations;
  long mujoco_steps = 20000;
  bool mujoco = true;
  bool json = false;
  bool floating_base = false, ground = false, no_contacts = false;
  double spread = 0.0;  // [rad or m] largest per-copy offset of the 1-DOF joints' pose; 0: every copy the same
};

// One timed configuration: `copies` environments advanced `steps` steps in
// `seconds` (the median of the repeats).
struct Row {
  std::string engine;
  std::string precision;
  int threads = 1;
  int copies = 1;
  long steps = 0;
  double seconds = 0.0;

  double env_steps_per_s() const { return static_cast<double>(copies) * steps / seconds; }
  double per_core() const { return env_steps_per_s() / threads; }
  double ns_per_env_step() const { return seconds * 1e9 * threads / (static_cast<double>(copies) * steps); }
};

struct PrecisionResult {
  Precision precision;
  std::size_t bytes_per_copy = 0;
  int faults = 0;
  double max_pose_error = 0.0;
  double mean_height = 0.0;    // of the floating root over all copies at the end
  double mean_contacts = 0.0;  // contact points pushing, per copy, at the end
  StepProfile profile;         // CPU time per phase of one profiled run
  bool contacts = false;       // the contact stage runs
};

// The CPU's model name as Linux reports it, its hardware threads, and how
// many of them this process may run on when that is fewer (taskset, cgroup
// cpusets).
std::string machine_description() {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string name = "unknown CPU";
  for (std::string line; std::getline(cpuinfo, line);)
    if (line.rfind("model name", 0) == 0 && line.find(':') != std::string::npos) {
      name = line.substr(line.find(':') + 2);
      break;
    }
  const int hardware = static_cast<int>(std::thread::hardware_concurrency());
  const int usable = tbb::info::default_concurrency();
  return name + ", " + std::to_string(hardware) + " hardware threads" +
         (usable < hardware ? " (" + std::to_string(usable) + " usable by this process)" : "");
}

// anymal_b from the shared models the build knows, else the bundled
// quadruped with `note` saying why.
std::string default_model(std::string& note) {
  const fs::path shared = fs::path(LOCKSTEP_SHARED_MODELS_DIR) / "anymal_b.urdf";
  std::error_code ec;
  if (!shared.parent_path().empty() && fs::exists(shared, ec)) return shared.string();
  const std::string bundled = (fs::path(bundled_models_dir()) / "quadruped.urdf").string();
  note = "the default model " + shared.string() + " is not there, so the bundled " + bundled +
         " stands in: its numbers are not anymal_b's (name a model to bench it)";
  return bundled;
}

// Every item between commas, empty ones too ("1,2," is three, the last
// empty: std::getline dropped it, and the list was taken as "1,2").
std::vector<std::string> split(const std::string& list) {
  std::vector<std::string> items;
  std::size_t start = 0;
  for (std::size_t comma; (comma = list.find(',', start)) != std::string::npos; start = comma + 1)
    items.push_back(list.substr(start, comma - start));
  items.push_back(list.substr(start));
  return items;
}

// The first entry a list gives a second time, if any.
template <class T>
std::optional<T> repeated(const std::vector<T>& list) {
  for (std::size_t i = 0; i < list.size(); ++i)
    if (std::find(list.begin(), list.begin() + i, list[i]) != list.begin() + i) return list[i];
  return std::nullopt;
}

BenchConfig parse_config(const std::vector<std::string>& args) {
  const ParsedArgs parsed =
      parse_args(args, {"--no-mujoco", "--json", "--floating-base", "--ground", "--no-contacts"},
                 {"--envs", "--threads", "--precision", "--steps", "--repeats", "--dt", "--mujoco-steps", "--solver",
                  "--iterations", "--spread"});
  if (parsed.positional.size() > 1) throw UsageError("bench takes at most one MODEL.urdf or SCENE.json");
  BenchConfig config;
  config.default_model = parsed.positional.empty();
  config.model = config.default_model ? default_model(config.stand_in_note) : parsed.positional[0];
  if (const std::string* v = parsed.value("--envs")) config.copies = static_cast<int>(parse_count("--envs", *v));
  if (const std::string* v = parsed.value("--steps")) config.steps = static_cast<int>(parse_count("--steps", *v));
  if (const std::string* v = parsed.value("--repeats")) config.repeats = static_cast<int>(parse_count("--repeats", *v));
  if (const std::string* v = parsed.value("--mujoco-steps")) config.mujoco_steps = parse_count("--mujoco-steps", *v);
  if (const std::string* v = parsed.value("--solver")) {
    if (*v == "pgs") config.solver = SolverType::PGS;
    else if (*v == "tgs") config.solver = SolverType::TGS;
    else throw UsageError("--solver must be pgs or tgs, not \"" + *v + "\"");
  }
  if (const std::string* v = parsed.value("--iterations"))
    config.iterations = static_cast<int>(parse_count("--iterations", *v));
  if (const std::string* v = parsed.value("--dt")) {
    config.dt = parse_number("--dt", *v);
    if (*config.dt <= 0) throw UsageError("--dt must be positive, not \"" + *v + "\"");
  }
  if (const std::string* v = parsed.value("--spread")) {
    config.spread = parse_number("--spread", *v);
    if (!(config.spread >= 0)) throw UsageError("--spread must be zero or positive, not \"" + *v + "\"");
  }
  if (const std::string* v = parsed.value("--threads")) {
    config.threads.clear();
    for (const std::string& item : split(*v)) config.threads.push_back(static_cast<int>(parse_count("--threads", item)));
  }
  if (const std::string* v = parsed.value("--precision")) {
    config.precisions.clear();
    for (const std::string& item : split(*v)) {
      if (item == "float") config.precisions.push_back(Precision::Float);
      else if (item == "double") config.precisions.push_back(Precision::Double);
      else throw UsageError("--precision must be a list of float and double, not \"" + *v + "\"");
    }
  }
  if (config.threads.empty() || config.precisions.empty())
    throw UsageError("--threads and --precision need at least one entry");
  if (const auto twice = repeated(config.threads))
    throw UsageError("--threads lists " + std::to_string(*twice) + " twice");
  if (const auto twice = repeated(config.precisions))
    throw UsageError(std::string("--precision lists ") + precision_name(*twice) + " twice");
  config.mujoco = !parsed.has("--no-mujoco");
  config.floating_base = config.default_model || parsed.has("--floating-base");
  config.ground = parsed.has("--ground");
  config.no_contacts = parsed.has("--no-contacts");
  config.json = parsed.has("--json");
  return config;
}

double median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// The largest |q - q_target| of copy 0 over the driven 1-DOF joints.
double pose_error(const Model& model, const Simulator& sim, const Eigen::VectorXd& q_target) {
  const Eigen::VectorXd q = sim.q(0);
  double error = 0.0;
  for (int b = 0; b < model.nbody; ++b)
    if (model.body_joint[b] == JointType::Revolute || model.body_joint[b] == JointType::Prismatic) {
      const int i = model.body_q_offset[b];
      error = std::max(error, std::abs(q[i] - q_target[i]));
    }
  return error;
}

// Times the step for one precision at every thread count: a warm-up, then
// `repeats` runs of `steps` steps, each from the initial state; then one
// profiled run on the first thread count for the time split by phase. Every
// copy holds the scene's initial pose with its drives.
PrecisionResult time_lockstep(const Scene& scene, const BenchConfig& config, Precision precision,
                              std::vector<Row>& rows, std::string& plan) {
  const Model& model = scene.model;
  StepOptions options = scene.env.step;
  options.precision = precision;
  const step_scene::CopyPoses poses = step_scene::copy_poses(model, scene.env.dofs, scene.env.drive_target_q,
                                                             scene.env.initial_q, config.copies, config.spread);
  const Eigen::VectorXd v0 = Eigen::VectorXd::Zero(model.nv);
  auto reset = [&](Simulator& sim) {
    for (int c = 0; c < config.copies; ++c) sim.set_state(c, poses.q0_of(c), v0);
  };
  // the poses and targets are the scene's: the simulator's checks of them are the scene's errors
  Simulator sim = build_from_scene(scene, [&] {
    Simulator built(model, config.copies, options, scene.env.dofs);
    for (int c = 0; c < config.copies; ++c) built.set_drive_target(c, poses.target_of(c), v0);
    reset(built);
    return built;
  });
  if (plan.empty()) plan = sim.describe_plan();
  for (int threads : config.threads) {
    tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    sim.step(config.steps);
    std::vector<double> seconds;
    for (int r = 0; r < config.repeats; ++r) {
      reset(sim);
      const auto start = std::chrono::steady_clock::now();
      sim.step(config.steps);
      seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
    rows.push_back({"lockstep", precision_name(precision), threads, config.copies, config.steps, median(seconds)});
  }
  PrecisionResult result;
  result.precision = precision;
  result.bytes_per_copy = sim.bytes_per_copy();
  result.faults = sim.fault_count();
  result.max_pose_error = pose_error(model, sim, poses.target_of(0));
  result.contacts = sim.plan()[static_cast<int>(Stage::Contacts)].runs;
  {
    tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism,
                                    static_cast<std::size_t>(config.threads.front()));
    reset(sim);
    sim.set_profiling(true);
    sim.step(config.steps);
    result.profile = sim.profile();
    sim.set_profiling(false);
  }
  // the root's z is q[2] of a Free root only (a fixed base may have nq < 3)
  const bool free_root = step_scene::free_root(model);
  for (int c = 0; c < sim.copies(); ++c) {
    if (free_root) result.mean_height += sim.q(c)[2] / sim.copies();
    for (const Contact& contact : sim.contacts(c)) result.mean_contacts += contact.force.norm() > 0 ? 1.0 / sim.copies() : 0.0;
  }
  return result;
}

const Row* find_row(const std::vector<Row>& rows, const std::string& engine, const std::string& precision,
                    int threads) {
  for (const Row& row : rows)
    if (row.engine == engine && row.precision == precision && row.threads == threads) return &row;
  return nullptr;
}

std::string fixed(double x, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << x;
  return s.str();
}

// Everything one run measured, for either output.
struct BenchReport {
  BenchConfig config;
  std::string model_name;
  std::string model_path;  // the URDF (a scene file's model)
  std::string machine;
  bool floating_base = false, contacts = false;
  bool standing = false;  // a floating base on a ground plane: the standing statistics mean something
  double dt = 0.0;
  int nv = 0, driven_dofs = 0;
  int nbody = 0, weightless_bodies = 0;  // bodies gravity is switched off on
  std::vector<Row> rows;
  std::vector<PrecisionResult> precisions;
  std::string plan;
  std::string mujoco_status;  // why MuJoCo did not run; empty when it did
  MujocoReport mujoco;  // when it ran
};

// "mjWARN_BADQACC 12 times, mjWARN_CONTACTFULL once"
std::string warning_counts(const std::vector<std::pair<std::string, long>>& warnings) {
  std::string text;
  for (const auto& [kind, count] : warnings)
    text += (text.empty() ? "" : ", ") + kind + (count == 1 ? " once" : " " + std::to_string(count) + " times");
  return text;
}

// Lockstep rows of `precision` against the engine's rows at the same thread
// count: lockstep's speed-up (threads > 1 over 1 thread) or its ratio to MuJoCo.
struct Comparison {
  std::string precision;
  int threads = 1;
  double value = 0.0;
};
std::vector<Comparison> speedups(const BenchReport& report) {
  std::vector<Comparison> out;
  for (const PrecisionResult& p : report.precisions) {
    const char* name = precision_name(p.precision);
    const Row* one = find_row(report.rows, "lockstep", name, 1);
    for (int t : report.config.threads)
      if (const Row* row = find_row(report.rows, "lockstep", name, t); one && row && t > 1)
        out.push_back({name, t, row->env_steps_per_s() / one->env_steps_per_s()});
  }
  return out;
}
std::vector<Comparison> mujoco_ratios(const BenchReport& report) {
  std::vector<Comparison> out;
  for (const PrecisionResult& p : report.precisions)
    for (int t : report.config.threads) {
      const Row* ours = find_row(report.rows, "lockstep", precision_name(p.precision), t);
      const Row* theirs = find_row(report.rows, "mujoco", "double", t);
      if (ours && theirs) out.push_back({precision_name(p.precision), t, ours->per_core() / theirs->per_core()});
    }
  return out;
}

void print_text(const BenchReport& r, std::ostream& out) {
  const BenchConfig& c = r.config;
  out << "lockstep bench: " << c.model << (r.floating_base ? " (floating base)" : " (fixed base)") << "\n";
  if (!c.stand_in_note.empty()) out << "note: " << c.stand_in_note << "\n";
  out << "scene: " << (r.contacts ? "contacts on" : "no contacts") << ", gravity on";
  if (r.weightless_bodies > 0) out << " (off on " << r.weightless_bodies << " of " << r.nbody << " bodies)";
  out << ", PD drives on " << r.driven_dofs
      << " of " << r.nv << " DOFs holding their targets, dt " << r.dt << " s\n"
      << "machine: " << r.machine << "\n"
      << "build: " << build_description() << "\n"
      << "timing: median of " << count_of(c.repeats, "repeat") << " of " << count_of(c.steps, "step") << " of "
      << c.copies << (c.copies == 1 ? " copy" : " copies");
  if (c.spread > 0) out << " (each copy's pose its own, within " << c.spread << " of the scene's per joint)";
  if (c.mujoco) out << " (MuJoCo: " << count_of(c.mujoco_steps, "step") << " of one mjData per thread)";
  out << ", after a warm-up\n";
  const int most = *std::max_element(c.threads.begin(), c.threads.end());
  const int usable = tbb::info::default_concurrency();
  if (most > usable)
    out << "note: " << count_of(most, "thread") << " on " << count_of(usable, "usable hardware thread")
        << ": the per-core columns divide by the threads asked for, not the cores used\n";
  out << "\n";

  std::vector<std::vector<std::string>> table = {
      {"model", "engine", "precision", "threads", "copies", "env-steps/s", "env-steps/s/core", "ns/env-step/core"}};
  for (const Row& row : r.rows)
    table.push_back({r.model_name, row.engine, row.precision, std::to_string(row.threads), std::to_string(row.copies),
                     fixed(row.env_steps_per_s() / 1e6, 3) + " M", fixed(row.per_core() / 1e6, 3) + " M",
                     fixed(row.ns_per_env_step(), 1)});
  std::vector<std::size_t> width(table.front().size(), 0);
  for (const auto& line : table)
    for (std::size_t i = 0; i < line.size(); ++i) width[i] = std::max(width[i], line[i].size());
  for (const auto& line : table) {
    for (std::size_t i = 0; i < line.size(); ++i)
      out << "  " << (i < 3 ? std::left : std::right) << std::setw(static_cast<int>(width[i])) << line[i];
    out << std::right << "\n";
  }

  out << "\n";
  for (const Comparison& s : speedups(r))
    out << "speed-up, " << s.precision << ", " << s.threads << " threads over 1: " << fixed(s.value, 2) << "x\n";
  if (!r.mujoco_status.empty()) {
    out << "MuJoCo: " << r.mujoco_status << "\n";
  } else {
    for (const Comparison& m : mujoco_ratios(r))
      out << "lockstep " << m.precision << " / MuJoCo, env-steps/s per core, " << m.threads
          << (m.threads == 1 ? " thread: " : " threads: ") << fixed(m.value, 1) << "x"
          << (r.mujoco.diverged ? " (not equal work: MuJoCo diverged)" : "") << "\n";
    if (r.mujoco.diverged)
      out << "MuJoCo diverged: mj_step reset its state after " << count_of(r.mujoco.resets, "timed step")
          << (r.mujoco.warnings.empty() ? "" : " (" + warning_counts(r.mujoco.warnings) + ")")
          << ", as it does when qpos, qvel or qacc is not finite or too large, so its steps were not all the same "
             "work as lockstep's\n";
    else if (!r.mujoco.warnings.empty())
      out << "MuJoCo warnings in its timed steps: " << warning_counts(r.mujoco.warnings) << "\n";
    for (const std::string& message : r.mujoco.warning_messages) out << "  MuJoCo: " << message << "\n";
    out << "MuJoCo " << r.mujoco.version << " set-up:\n";
    for (const std::string& note : r.mujoco.notes) out << "  - " << note << "\n";
  }

  out << "\nbytes per copy (state, inputs, per-copy parameters, warm start):";
  for (const PrecisionResult& p : r.precisions) out << " " << precision_name(p.precision) << " " << p.bytes_per_copy;
  out << "\nafter the run, copy 0's largest |q - q_target| on the driven joints:";
  const char* separator = " ";
  for (const PrecisionResult& p : r.precisions) {
    out << separator << "lockstep " << precision_name(p.precision) << " " << p.max_pose_error;
    separator = ", ";
  }
  if (r.mujoco_status.empty()) out << ", MuJoCo " << r.mujoco.max_pose_error;
  if (r.standing) {
    out << "\nstanding (mean root height, mean pushing contacts per copy):";
    separator = " ";
    for (const PrecisionResult& p : r.precisions) {
      out << separator << "lockstep " << precision_name(p.precision) << " " << fixed(p.mean_height, 4) << " m, "
          << fixed(p.mean_contacts, 2);
      separator = "; ";
    }
    if (r.mujoco_status.empty())
      out << separator << "MuJoCo " << fixed(r.mujoco.mean_base_height, 4) << " m, " << fixed(r.mujoco.mean_contacts, 2);
  }
  out << "\ntime by phase (one profiled run, " << count_of(c.threads.front(), "thread") << "):";
  for (const PrecisionResult& p : r.precisions) {
    const StepProfile& t = p.profile;
    const double total = t.total() > 0 ? t.total() : 1.0;
    out << "\n  " << precision_name(p.precision) << ": dynamics " << fixed(100 * t.dynamics / total, 1)
        << " %, contact detection " << fixed(100 * t.contact_detection / total, 1) << " %, constraint solve "
        << fixed(100 * t.constraint_solve / total, 1) << " %, integration " << fixed(100 * t.integration / total, 1)
        << " %";
  }
  out << "\nfaulted copies:";
  for (const PrecisionResult& p : r.precisions) out << " " << precision_name(p.precision) << " " << p.faults;
  out << "\n\nstage plan:\n" << r.plan;
  if (!r.plan.empty() && r.plan.back() != '\n') out << "\n";
}

std::string comparisons_json(const std::vector<Comparison>& list) {
  std::string s = "[";
  for (std::size_t i = 0; i < list.size(); ++i)
    s += std::string(i ? ", " : "") + "{\"precision\": " + json::quote(list[i].precision) +
         ", \"threads\": " + std::to_string(list[i].threads) + ", \"value\": " + json::number(list[i].value) + "}";
  return s + "]";
}

// With --ground: the mean root height and pushing contacts per copy after the run.
std::string standing_json(double height, double contacts) {
  return "{\"mean_root_height\": " + json::number(height) + ", \"mean_pushing_contacts\": " + json::number(contacts) +
         "}";
}

void print_json(const BenchReport& r, std::ostream& out) {
  const BenchConfig& c = r.config;
  out << "{\n  \"model\": " << json::quote(c.model);
  if (!c.stand_in_note.empty()) out << ",\n  \"model_note\": " << json::quote(c.stand_in_note);
  out << ",\n  \"floating_base\": " << (r.floating_base ? "true" : "false")
      << ",\n  \"contacts\": " << (r.contacts ? "true" : "false")
      << ",\n  \"machine\": " << json::quote(r.machine) << ",\n  \"build\": " << json::quote(build_description())
      << ",\n  \"copies\": " << c.copies << ",\n  \"spread\": " << json::number(c.spread)
      << ",\n  \"steps\": " << c.steps << ",\n  \"repeats\": " << c.repeats
      << ",\n  \"dt\": " << json::number(r.dt) << ",\n  \"driven_dofs\": " << r.driven_dofs << ",\n  \"rows\": [";
  for (std::size_t i = 0; i < r.rows.size(); ++i) {
    const Row& row = r.rows[i];
    out << (i ? "," : "") << "\n    {\"engine\": " << json::quote(row.engine) << ", \"precision\": "
        << json::quote(row.precision) << ", \"threads\": " << row.threads << ", \"copies\": " << row.copies
        << ", \"steps\": " << row.steps << ", \"seconds\": " << json::number(row.seconds)
        << ", \"env_steps_per_s\": " << json::number(row.env_steps_per_s())
        << ", \"env_steps_per_s_per_core\": " << json::number(row.per_core())
        << ", \"ns_per_env_step\": " << json::number(row.ns_per_env_step()) << "}";
  }
  out << "\n  ],\n  \"speedup\": " << comparisons_json(speedups(r));
  out << ",\n  \"mujoco\": ";
  if (!r.mujoco_status.empty()) {
    out << "{\"ran\": false, \"reason\": " << json::quote(r.mujoco_status) << "}";
  } else {
    out << "{\"ran\": true, \"version\": " << json::quote(r.mujoco.version)
        << ", \"ratio_per_core\": " << comparisons_json(mujoco_ratios(r));
    if (r.standing) out << ", \"standing\": " << standing_json(r.mujoco.mean_base_height, r.mujoco.mean_contacts);
    out << ", \"diverged\": " << (r.mujoco.diverged ? "true" : "false") << ", \"resets\": " << r.mujoco.resets
        << ", \"warnings\": {";
    for (std::size_t i = 0; i < r.mujoco.warnings.size(); ++i)
      out << (i ? ", " : "") << json::quote(r.mujoco.warnings[i].first) << ": " << r.mujoco.warnings[i].second;
    out << "}, \"warning_messages\": [";
    for (std::size_t i = 0; i < r.mujoco.warning_messages.size(); ++i)
      out << (i ? ", " : "") << json::quote(r.mujoco.warning_messages[i]);
    out << "], \"notes\": [";
    for (std::size_t i = 0; i < r.mujoco.notes.size(); ++i) out << (i ? ", " : "") << json::quote(r.mujoco.notes[i]);
    out << "]}";
  }
  out << ",\n  \"precisions\": [";
  for (std::size_t i = 0; i < r.precisions.size(); ++i) {
    const PrecisionResult& p = r.precisions[i];
    out << (i ? ", " : "") << "{\"precision\": " << json::quote(precision_name(p.precision))
        << ", \"bytes_per_copy\": " << p.bytes_per_copy << ", \"faults\": " << p.faults
        << ", \"max_pose_error\": " << json::number(p.max_pose_error)
        << ", \"phase_seconds\": {\"dynamics\": " << json::number(p.profile.dynamics)
        << ", \"contact_detection\": " << json::number(p.profile.contact_detection)
        << ", \"constraint_solve\": " << json::number(p.profile.constraint_solve)
        << ", \"integration\": " << json::number(p.profile.integration) << "}";
    if (r.standing) out << ", \"standing\": " << standing_json(p.mean_height, p.mean_contacts);
    out << "}";
  }
  out << "],\n  \"plan\": " << json::quote(r.plan) << "\n}\n";
}

// MuJoCo's peer of the scene: one kp and kd for every drive, so a scene
// whose gains differ between joints has none.
std::optional<std::string> mujoco_difference(const Scene& scene) {
  if (!scene.env.step.actuators.empty())
    return "the scene has actuators (" + scene.env.step.actuators.front().name +
           "), whose motor operating regions the MuJoCo peer does not model";
  if (scene.model.damped_bodies() > 0)
    return "the scene has link damping, which MuJoCo (joint damping only) does not model";
  if (!scene.model.mimics.empty())
    return "the scene has mimic joints (" + scene.model.dof_name[scene.model.mimics.front().dof] +
           "), which the MuJoCo peer does not couple";
  if (!scene.model.fixed_tendons.empty())
    return "the scene has fixed tendons (" + scene.model.fixed_tendons.front().name +
           "), which the MuJoCo peer does not model";
  std::optional<std::pair<double, double>> gains;
  for (int k = 0; k < scene.model.nv; ++k) {
    if (scene.model.body_joint[scene.model.dof_body[k]] == JointType::Free) continue;
    const DofSettings& d = scene.env.dofs[k];
    if (!gains) gains = {d.drive_stiffness, d.drive_damping};
    if (gains->first != d.drive_stiffness || gains->second != d.drive_damping)
      return "the scene's drive gains differ between joints; the MuJoCo peer takes one kp and kd";
    if (d.spring_stiffness != 0)
      return "the scene has joint springs (" + scene.model.dof_name[k] + "), which MuJoCo's URDF reader does not take";
  }
  return std::nullopt;
}

// Drive targets by joint name, for each 1-DOF joint.
std::vector<std::pair<std::string, double>> joint_targets(const Scene& scene) {
  const Model& m = scene.model;
  std::vector<std::pair<std::string, double>> targets;
  for (int b = 0; b < m.nbody; ++b)
    if (m.body_joint[b] == JointType::Revolute || m.body_joint[b] == JointType::Prismatic)
      targets.emplace_back(m.joint_name[b], scene.env.drive_target_q[m.body_q_offset[b]]);
  return targets;
}

}  // namespace

int run_bench(const std::vector<std::string>& args, std::ostream& out) {
  BenchReport report;
  report.config = parse_config(args);
  const BenchConfig& config = report.config;
  Scene scene = load_cli_scene(config.model, config.floating_base, config.ground, config.no_contacts);
  if (config.dt) scene.env.step.dt = *config.dt;
  if (config.solver) scene.env.step.solver = *config.solver;
  if (config.iterations) scene.env.step.iterations = *config.iterations;
  const Model& model = scene.model;
  report.model_name = fs::path(scene.model_path).stem().string();
  report.model_path = scene.model_path;
  report.machine = machine_description();
  report.floating_base = scene.floating_base;
  report.dt = scene.env.step.dt;
  report.nv = model.nv;
  for (int k = 0; k < model.nv; ++k) report.driven_dofs += scene.env.dofs[k].drive_stiffness > 0;
  report.nbody = model.nbody;
  report.weightless_bodies = static_cast<int>(model.links_without_gravity().size());

  for (Precision precision : config.precisions)
    report.precisions.push_back(time_lockstep(scene, config, precision, report.rows, report.plan));
  report.contacts = report.precisions.front().contacts;
  report.standing = report.contacts && scene.env.step.contacts.ground && scene.floating_base;

  const std::optional<std::string> unlike = mujoco_difference(scene);
  if (!config.mujoco) {
    report.mujoco_status = "not run (--no-mujoco)";
  } else if (unlike) {
    report.mujoco_status = "not run: " + *unlike;
  } else {
#ifdef LOCKSTEP_HAVE_MUJOCO
    MujocoScene peer;
    peer.urdf_path = scene.model_path;
    peer.floating_base = scene.floating_base;
    peer.dt = scene.env.step.dt;
    const int first = step_scene::free_root(model) ? 6 : 0;
    peer.kp = first < model.nv ? scene.env.dofs[first].drive_stiffness : 0.0;
    peer.kd = first < model.nv ? scene.env.dofs[first].drive_damping : 0.0;
    peer.targets = joint_targets(scene);
    peer.base_height = scene.floating_base ? scene.env.initial_q[2] : step_scene::kBaseHeight;
    for (int k = 0; k < 3; ++k) peer.gravity[k] = model.gravity[k];
    peer.links_without_gravity = model.links_without_gravity();
    peer.ground = report.contacts && scene.env.step.contacts.ground;
    peer.friction = scene.env.step.contacts.ground_contact.friction;
    try {
      report.mujoco = run_mujoco_peer(peer, config.threads, config.mujoco_steps, config.repeats);
      for (const MujocoTiming& t : report.mujoco.timings)
        report.rows.push_back({"mujoco", "double", t.threads, t.threads, t.steps, t.seconds});
    } catch (const std::runtime_error& e) {
      // The peer is a comparison: a model MuJoCo cannot load leaves lockstep's numbers standing.
      report.mujoco_status = std::string("failed: ") + e.what();
    }
#else
    report.mujoco_status = "not built (libmujoco-dev was not found when this program was configured)";
#endif
  }

  if (config.json) print_json(report, out);
  else print_text(report, out);
  return kExitOk;
}

}  // namespace lockstep::cli
