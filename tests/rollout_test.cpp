// Rollouts end to end: a vectorised environment recorded to a rollout file,
// read back, replayed bit for bit from the stored scene, initial state and
// actions; the same file whatever the thread count; `lockstep rollout`
// killed with SIGKILL leaves a readable, finite, incomplete file; its default
// thread count follows the CPU affinity.
#include "io/rollout_recorder.hpp"
#include "io/scene_file.hpp"
#include "io/sha256.hpp"
#include "tests/test_support.hpp"
#include "tools/rollout_policy.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <signal.h>
#include <sys/wait.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>
#include <tuple>

namespace lockstep {
namespace {

namespace fs = std::filesystem;

TEST(Sha256, MatchesTheStandardsExamples) {
  EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  // two blocks (FIPS 180-4 example, 448 bits)
  EXPECT_EQ(sha256_hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}

// A temporary folder removed at the end of the test.
struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("lockstep_rollout_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
};

std::string bundled_scene() { return std::string(LOCKSTEP_MODELS_DIR) + "/quadruped_scene.json"; }

// What a recorded run saw, per step, for comparison with the file.
struct Seen {
  std::vector<Eigen::VectorXd> q;  // all copies' q after the step, terminal rows where the episode ended
  std::vector<RowMatrix> actions;
};

// The bundled quadruped scene with short episodes (auto-resets inside the
// run), random actions, recorded to `file`.
Seen record(const Scene& scene, int envs, int steps, const std::string& file, int threads = 2) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  VecEnv env(scene.model, envs, scene.env);
  env.reset();
  RolloutRecorder recorder(env, file, {scene_to_json(scene), scene.model_path, "random", {}});
  cli::Policy policy(cli::PolicyKind::Random, env, scene.env.seed);
  Seen seen;
  RowMatrix actions;
  for (int t = 0; t < steps; ++t) {
    policy.act(env, t, actions);
    env.step(actions);
    recorder.record(actions);
    RowMatrix q = env.observations().q;
    for (int c = 0; c < envs; ++c)
      if (env.terminated()[c] || env.truncated()[c]) q.row(c) = env.terminal_observations().q.row(c);
    seen.q.push_back(Eigen::Map<const Eigen::VectorXd>(q.data(), q.size()));
    seen.actions.push_back(actions);
  }
  recorder.close();
  return seen;
}

Scene short_episode_scene() {
  Scene scene = load_scene(bundled_scene());
  scene.env.episode_steps = 7;
  scene.env.seed = 5;
  return scene;
}

// Records `steps` env steps of `scene` under random actions (one thread) to
// `file`, and returns, per observation field asked for, its matrix after
// each step as the file should hold it: terminal rows where an episode ended.
std::vector<std::vector<RowMatrix>> record_observed(const Scene& scene, int envs, int steps, const std::string& file,
                                                    const std::vector<RowMatrix Observations::*>& fields) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
  VecEnv env(scene.model, envs, scene.env);
  env.reset();
  RolloutRecorder recorder(env, file, {scene_to_json(scene), scene.model_path, "random", {}});
  cli::Policy policy(cli::PolicyKind::Random, env, scene.env.seed);
  RowMatrix actions;
  std::vector<std::vector<RowMatrix>> seen(fields.size());
  for (int t = 0; t < steps; ++t) {
    policy.act(env, t, actions);
    env.step(actions);
    recorder.record(actions);
    for (std::size_t f = 0; f < fields.size(); ++f) {
      RowMatrix field = env.observations().*fields[f];
      for (int c = 0; c < envs; ++c)
        if (env.truncated()[c] || env.terminated()[c]) field.row(c) = (env.terminal_observations().*fields[f]).row(c);
      seen[f].push_back(field);
    }
  }
  recorder.close();
  return seen;
}

// record() takes one step's actions of the environment's shape, once per
// env step; close() keeps `steps` for itself. Each misuse says what and
// where, and the file still closes with the steps recorded.
TEST(Rollout, TheRecorderRefusesMisuseByName) {
  TempDir dir;
  const std::string file = (dir.path / "misuse.h5").string();
  const Scene scene = short_episode_scene();
  VecEnv env(scene.model, 3, scene.env);
  env.reset();
  RolloutRecorder recorder(env, file, {scene_to_json(scene), scene.model_path, "zero", {}});
  const RowMatrix actions = RowMatrix::Zero(3, env.action_size());
  EXPECT_THROW_WITH(recorder.record(actions), std::logic_error,
                    file + ": record: the environment has not stepped since the last record (env step 0)");
  env.step(actions);
  EXPECT_THROW_WITH(recorder.record(RowMatrix::Zero(2, env.action_size())), std::invalid_argument,
                    file + ": record: actions must be 3 x " + std::to_string(env.action_size()) +
                        " (copies x action_size), got 2 x " + std::to_string(env.action_size()));
  recorder.record(actions);
  EXPECT_THROW(recorder.record(actions), std::logic_error);
  EXPECT_THROW_WITH(recorder.close({{"steps", std::int64_t(5)}}), std::invalid_argument,
                    "the summary attribute 'steps' is the recorder's own");
  recorder.close();
  EXPECT_EQ(RolloutReader(file).steps(), 1);
}

// model_file is the URDF's absolute path, as documented, however the path
// was given (it was stored as given: relative to wherever the run started).
TEST(Rollout, ModelFileIsAbsolute) {
  const TempDir dir;
  const std::string file = (dir.path / "run.h5").string();
  Scene scene = short_episode_scene();
  const std::filesystem::path absolute = std::filesystem::absolute(scene.model_path).lexically_normal();
  scene.model_path = std::filesystem::relative(absolute).string();
  ASSERT_TRUE(std::filesystem::path(scene.model_path).is_relative());
  record(scene, 2, 1, file);
  EXPECT_EQ(std::get<std::string>(RolloutReader(file).attribute("model_file")), absolute.string());
}

TEST(Rollout, TheFileHoldsWhatTheEnvironmentDidWithItsSchema) {
  const TempDir dir;
  const std::string file = (dir.path / "run.h5").string();
  const Scene scene = short_episode_scene();
  const int envs = 6, steps = 16;
  const Seen seen = record(scene, envs, steps, file);

  const RolloutReader r(file);
  EXPECT_TRUE(r.complete());
  ASSERT_EQ(r.steps(), steps);
  const Model& m = scene.model;
  const std::size_t n = envs, T = steps;
  EXPECT_EQ(r.shape("q"), (std::vector<std::size_t>{T, n, std::size_t(m.nq)}));
  EXPECT_EQ(r.shape("qd"), (std::vector<std::size_t>{T, n, std::size_t(m.nv)}));
  EXPECT_EQ(r.shape("actions"), (std::vector<std::size_t>{T, n, std::size_t(m.nv - 6)}));
  EXPECT_EQ(r.shape("applied_torque"), (std::vector<std::size_t>{T, n, std::size_t(m.nv)}));
  EXPECT_EQ(r.shape("contact_force"), (std::vector<std::size_t>{T, n, std::size_t(m.nbody), 3}));
  for (const char* flag : {"reward", "terminated", "truncated", "faulted"})
    EXPECT_EQ(r.shape(flag), (std::vector<std::size_t>{T, n})) << flag;
  EXPECT_EQ(r.shape("initial_q"), (std::vector<std::size_t>{n, std::size_t(m.nq)}));
  EXPECT_EQ(r.type("q"), ElementType::Float32);  // the scene's precision
  EXPECT_EQ(r.type("actions"), ElementType::Float64);
  EXPECT_EQ(r.type("terminated"), ElementType::UInt8);

  EXPECT_EQ(std::get<std::string>(r.attribute("model_sha256")), sha256_file(scene.model_path));
  EXPECT_EQ(std::get<std::string>(r.attribute("model_file")), scene.model_path);
  EXPECT_EQ(std::get<std::vector<std::string>>(r.attribute("dof_names")), m.dof_name);
  EXPECT_EQ(std::get<double>(r.attribute("dt")), scene.env.step.dt);
  EXPECT_EQ(std::get<std::int64_t>(r.attribute("seed")), 5);
  EXPECT_EQ(std::get<std::int64_t>(r.attribute("control_steps")), scene.env.control_steps);
  EXPECT_EQ(std::get<std::string>(r.attribute("precision")), "float");
  EXPECT_EQ(std::get<std::string>(r.attribute("policy")), "random");
  EXPECT_EQ(std::get<std::vector<double>>(r.attribute("randomization.mass_scale")),
            (std::vector<double>{scene.env.randomization.mass_scale.low, scene.env.randomization.mass_scale.high}));
  EXPECT_FALSE(std::get<std::string>(r.attribute("lockstep_version")).empty());
  EXPECT_EQ(std::get<std::int64_t>(r.attribute("steps")), steps);

  const std::vector<float> q = r.read_as<float>("q");
  const std::vector<double> actions = r.read_as<double>("actions");
  const std::vector<std::uint8_t> truncated = r.read_as<std::uint8_t>("truncated");
  int ended = 0;
  for (int t = 0; t < steps; ++t) {
    for (Eigen::Index i = 0; i < seen.q[t].size(); ++i)
      ASSERT_EQ(q[t * seen.q[t].size() + i], static_cast<float>(seen.q[t][i])) << "step " << t;
    for (Eigen::Index i = 0; i < seen.actions[t].size(); ++i)
      ASSERT_EQ(actions[t * seen.actions[t].size() + i], seen.actions[t].data()[i]);
    for (int c = 0; c < envs; ++c) ended += truncated[t * envs + c];
  }
  EXPECT_EQ(ended, envs * (steps / 7));  // episodes of 7 steps: two auto-resets each
}

// The file's scene, initial state and actions reproduce every stored step.
TEST(Rollout, ReplayingTheStoredSceneAndActionsReproducesTheFileBitForBit) {
  const TempDir dir;
  const std::string file = (dir.path / "run.h5").string();
  const int envs = 5, steps = 15;
  record(short_episode_scene(), envs, steps, file);

  const RolloutReader r(file);
  const std::string scene_path = (dir.path / "replay.json").string();
  std::ofstream(scene_path) << std::get<std::string>(r.attribute("scene"));
  const Scene scene = load_scene(scene_path);
  VecEnv env(scene.model, envs, scene.env);
  env.reset();
  const std::vector<float> initial_q = r.read_as<float>("initial_q"), initial_qd = r.read_as<float>("initial_qd");
  const Model& m = scene.model;
  for (int c = 0; c < envs; ++c) {
    Eigen::VectorXd q(m.nq), v(m.nv);
    for (int i = 0; i < m.nq; ++i) q[i] = initial_q[c * m.nq + i];
    for (int k = 0; k < m.nv; ++k) v[k] = initial_qd[c * m.nv + k];
    ASSERT_EQ(q, env.observations().q.row(c).transpose()) << "the stored initial state is the reset's";
    env.simulator().set_state(c, q, v);
  }
  const std::vector<double> actions = r.read_as<double>("actions");
  const std::vector<float> q = r.read_as<float>("q"), qd = r.read_as<float>("qd");
  const std::vector<double> reward = r.read_as<double>("reward");
  const int na = env.action_size();
  for (int t = 0; t < steps; ++t) {
    const RowMatrix a = Eigen::Map<const RowMatrix>(actions.data() + t * envs * na, envs, na);
    env.step(a);
    for (int c = 0; c < envs; ++c) {
      const bool ended = env.terminated()[c] || env.truncated()[c];
      const Observations& o = ended ? env.terminal_observations() : env.observations();
      for (int i = 0; i < m.nq; ++i)
        ASSERT_EQ(static_cast<float>(o.q(c, i)), q[(t * envs + c) * m.nq + i]) << "step " << t << " copy " << c;
      for (int k = 0; k < m.nv; ++k) ASSERT_EQ(static_cast<float>(o.qd(c, k)), qd[(t * envs + c) * m.nv + k]);
      ASSERT_EQ(env.reward()[c], reward[t * envs + c]);
    }
  }
}

TEST(Rollout, FilesDoNotDependOnTheThreadCount) {
  const TempDir dir;
  const std::string one = (dir.path / "one.h5").string(), two = (dir.path / "two.h5").string();
  record(short_episode_scene(), 40, 10, one, 1);
  record(short_episode_scene(), 40, 10, two, 2);
  const RolloutReader a(one), b(two);
  for (const char* name : {"initial_q", "q", "qd", "applied_torque", "contact_force"})
    EXPECT_EQ(a.read_as<float>(name), b.read_as<float>(name)) << name;
  for (const char* name : {"truncated", "terminated", "faulted"})
    EXPECT_EQ(a.read_as<std::uint8_t>(name), b.read_as<std::uint8_t>(name)) << name;
}

// Runs `lockstep rollout` on the bundled scene into `file` until the file
// shows at least 20 flushed steps, then sends `signal`; returns the wait
// status and the steps seen before the signal. Its stderr goes to `err`.
std::pair<int, std::int64_t> interrupt_rollout(const std::string& file, int signal, const std::string& err) {
  const pid_t child = ::fork();
  if (child < 0) return {-1, 0};
  if (child == 0) {
    const int fd = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0 || ::dup2(fd, 2) < 0) ::_exit(126);
    ::execl(LOCKSTEP_TOOL_PATH, "lockstep", "rollout", bundled_scene().c_str(), "--envs", "64", "--steps", "1000000",
            "--flush-seconds", "0.05", "--threads", "1", "--out", file.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  std::int64_t seen = 0;
  for (int tries = 0; tries < 400 && seen < 20; ++tries) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (!fs::exists(file)) continue;
    try {
      seen = RolloutReader(file).steps();
    } catch (const RolloutFileError&) {
      // not yet a whole file header: try again
    }
  }
  ::kill(child, signal);
  int status = 0;
  ::waitpid(child, &status, 0);
  return {status, seen};
}

// `lockstep rollout` without --threads runs as many threads as its process
// may use: pinned to one CPU (one this test may use, inherited by the child
// through fork and exec), one thread, as its file's "threads" attribute says.
TEST(Rollout, DefaultThreadsFollowTheCpuAffinity) {
  const TempDir dir;
  const std::string file = (dir.path / "pinned.h5").string();
  cpu_set_t allowed;
  ASSERT_EQ(::sched_getaffinity(0, sizeof(allowed), &allowed), 0);
  int cpu = 0;
  while (!CPU_ISSET(cpu, &allowed)) ++cpu;
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(cpu, &one);
    if (::sched_setaffinity(0, sizeof(one), &one) != 0) ::_exit(126);
    ::execl(LOCKSTEP_TOOL_PATH, "lockstep", "rollout", bundled_scene().c_str(), "--envs", "8", "--steps", "2",
            "--out", file.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  EXPECT_EQ(std::get<std::int64_t>(RolloutReader(file).attribute("threads")), 1);
}

// `lockstep rollout` with arguments, stdout and stderr together: the exit
// code and the text.
std::pair<int, std::string> run_rollout_program(const std::string& arguments) {
  const std::string command = std::string(LOCKSTEP_TOOL_PATH) + " rollout " + arguments + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  std::string text;
  char buffer[4096];
  while (const std::size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) text.append(buffer, n);
  const int status = ::pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text};
}

// "replacing FILE" is said when the file is replaced: it was said before a
// scene that cannot be simulated stopped the run (the file left as it was)
// and for a link, which the writer refuses.
TEST(Rollout, SaysReplacingOnlyWhenItReplacesTheFile) {
  const TempDir dir;
  const std::string file = (dir.path / "old.h5").string(), link = (dir.path / "link.h5").string();
  std::ofstream(file) << "old";
  const std::string unsimulable =
      std::string(LOCKSTEP_MODELS_DIR) + "/../tests/data/scene_position_targets_without_gains.json";
  auto [rc, text] = run_rollout_program(unsimulable + " --envs 2 --steps 1 --out " + file);
  EXPECT_EQ(rc, 2) << text;
  EXPECT_EQ(text.find("replacing"), std::string::npos) << text;
  std::string kept;
  std::getline(std::ifstream(file), kept);
  EXPECT_EQ(kept, "old");
  fs::create_symlink(file, link);
  std::tie(rc, text) = run_rollout_program(bundled_scene() + " --envs 2 --steps 1 --out " + link);
  EXPECT_EQ(rc, 4) << text;
  EXPECT_EQ(text.find("replacing"), std::string::npos) << text;
  std::tie(rc, text) = run_rollout_program(bundled_scene() + " --envs 2 --steps 1 --out " + file);
  EXPECT_EQ(rc, 0) << text;
  EXPECT_NE(text.find("replacing " + file), std::string::npos) << text;
  EXPECT_TRUE(RolloutReader(file).complete());
}

// With record_motion the file holds the joint forces and link
// accelerations, as the environment observed them (terminal rows where an
// episode ended), with the links' names.
TEST(Rollout, RecordsTheJointForcesAndLinkAccelerations) {
  const TempDir dir;
  const std::string file = (dir.path / "motion.h5").string();
  Scene scene = short_episode_scene();
  scene.env.step.record_motion = true;
  const int envs = 3, steps = 9;
  const auto seen = record_observed(scene, envs, steps, file, {&Observations::joint_force, &Observations::link_acceleration});
  const std::vector<RowMatrix>& forces = seen[0];
  const std::vector<RowMatrix>& accelerations = seen[1];
  const RolloutReader r(file);
  const Model& m = scene.model;
  const std::size_t T = steps, n = envs, frames = m.frame_name.size();
  ASSERT_EQ(r.shape("joint_force"), (std::vector<std::size_t>{T, n, std::size_t(m.nbody), 6}));
  ASSERT_EQ(r.shape("link_acceleration"), (std::vector<std::size_t>{T, n, frames, 6}));
  EXPECT_EQ(std::get<std::vector<std::string>>(r.attribute("link_names")), m.frame_name);
  const std::vector<double> stored_forces = r.read("joint_force"), stored_accelerations = r.read("link_acceleration");
  for (std::size_t t = 0; t < T; ++t)
    for (int c = 0; c < envs; ++c)
      for (int k = 0; k < forces[t].cols(); ++k)
        ASSERT_EQ(stored_forces[(t * n + c) * forces[t].cols() + k], static_cast<float>(forces[t](c, k)))
            << "step " << t << ", copy " << c;
  for (std::size_t t = 0; t < T; ++t)
    for (int c = 0; c < envs; ++c)
      for (int k = 0; k < accelerations[t].cols(); ++k)
        ASSERT_EQ(stored_accelerations[(t * n + c) * accelerations[t].cols() + k],
                  static_cast<float>(accelerations[t](c, k)));
}

// The bundled scene driven through actuators on its knees: the actions are
// named after them, and the motors' speeds and torques are stored per step.
TEST(Rollout, RecordsTheMotorsOfActuatorTorqueActions) {
  const TempDir dir;
  const std::string file = (dir.path / "motors.h5").string();
  Scene scene = short_episode_scene();
  scene.env.action_mode = ActionMode::ActuatorTorque;
  for (const char* knee : {"FL_knee", "HR_knee"}) {
    Actuator a;
    a.name = std::string(knee) + "_motor";
    a.dof = scene.model.dof_index(knee);
    a.gear = 9;
    a.torque_constant = 0.12, a.bus_voltage = 48, a.resistance = 0.3, a.velocity_constant = 8, a.peak_torque = 3.5;
    scene.env.step.actuators.push_back(a);
  }
  const int envs = 3, steps = 9;
  const auto seen = record_observed(scene, envs, steps, file, {&Observations::motor_speed, &Observations::motor_torque});
  const std::vector<RowMatrix>& speeds = seen[0];
  const std::vector<RowMatrix>& torques = seen[1];
  const RolloutReader r(file);
  const std::vector<std::string> names = {"FL_knee_motor", "HR_knee_motor"};
  EXPECT_EQ(std::get<std::vector<std::string>>(r.attribute("action_names")), names);
  EXPECT_EQ(std::get<std::vector<std::string>>(r.attribute("actuator_names")), names);
  ASSERT_EQ(r.shape("motor_speed"), (std::vector<std::size_t>{std::size_t(steps), std::size_t(envs), 2}));
  ASSERT_EQ(r.shape("motor_torque"), (std::vector<std::size_t>{std::size_t(steps), std::size_t(envs), 2}));
  const std::vector<double> stored_speeds = r.read("motor_speed"), stored_torques = r.read("motor_torque");
  double moving = 0;
  for (int t = 0; t < steps; ++t)
    for (int c = 0; c < envs; ++c)
      for (int a = 0; a < 2; ++a) {
        const std::size_t i = (t * envs + c) * 2 + a;
        ASSERT_EQ(stored_speeds[i], static_cast<float>(speeds[t](c, a))) << "step " << t << ", copy " << c;
        ASSERT_EQ(stored_torques[i], static_cast<float>(torques[t](c, a))) << "step " << t << ", copy " << c;
        moving = std::max(moving, std::abs(stored_speeds[i]));
      }
  EXPECT_GT(moving, 0.0) << "the motors turned";
}

// The file after an interrupted rollout opens, holds at least `seen` steps,
// all finite, and does not claim to be complete.
void expect_readable_incomplete(const std::string& file, std::int64_t seen) {
  const RolloutReader r(file);
  EXPECT_FALSE(r.complete());
  EXPECT_GE(r.steps(), seen);
  for (const std::string& name : r.datasets())
    for (double x : r.read(name)) ASSERT_TRUE(std::isfinite(x)) << name;
  EXPECT_FALSE(r.has_attribute("steps"));  // the summary of a finished run
}

// `lockstep rollout` killed with SIGKILL mid-run: the file holds every step
// it flushed.
TEST(Rollout, AKilledRolloutLeavesAReadableIncompleteFile) {
  const TempDir dir;
  const std::string file = (dir.path / "killed.h5").string();
  const auto [status, seen] = interrupt_rollout(file, SIGKILL, (dir.path / "stderr.txt").string());
  ASSERT_TRUE(WIFSIGNALED(status)) << "the rollout ended by itself (status " << status << ")";
  ASSERT_GE(seen, 20) << "the rollout never flushed 20 steps";
  expect_readable_incomplete(file, seen);
}

// SIGINT (Ctrl-C) stops it after the step under way: exit code 130, every
// recorded step written, the file marked incomplete, and the message says
// how many steps it keeps.
TEST(Rollout, AnInterruptedRolloutKeepsEveryStepItTook) {
  const TempDir dir;
  const std::string file = (dir.path / "interrupted.h5").string();
  const std::string err = (dir.path / "stderr.txt").string();
  const auto [status, seen] = interrupt_rollout(file, SIGINT, err);
  ASSERT_TRUE(WIFEXITED(status)) << "status " << status;
  EXPECT_EQ(WEXITSTATUS(status), 130);
  ASSERT_GE(seen, 20);
  expect_readable_incomplete(file, seen);
  // the message counts the steps the file keeps
  std::ifstream in(err);
  const std::string said((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string keeps = file + " keeps " + std::to_string(RolloutReader(file).steps()) + ", marked incomplete";
  EXPECT_NE(said.find(keeps), std::string::npos) << "no '" << keeps << "' in\n" << said;
}

}  // namespace
}  // namespace lockstep
