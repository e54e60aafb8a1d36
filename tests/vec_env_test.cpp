// The vectorised environment: observations, actions, randomisation at
// reset, episodes and auto-reset, fault isolation, and copy states that
// replay bit for bit.
#include "batch/vec_env.hpp"
#include "tests/sim_support.hpp"
#include "tools/step_scene.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <set>

namespace lockstep {
namespace {

using test::same_bits;

// anymal_b standing on the ground under position targets, 4 simulator
// steps per env step, with every randomisation on.
VecEnvOptions standing_options(const Model& model, Precision precision = Precision::Float) {
  const step_scene::Scene scene = step_scene::make_scene(model, true);
  VecEnvOptions o;
  o.step.precision = precision;
  o.step.contacts.ground = true;
  o.dofs = scene.dofs;
  for (DofSettings& d : o.dofs) d.damping = d.drive_stiffness > 0 ? 0.05 : 0.0;
  o.action_mode = ActionMode::PositionTarget;
  o.control_steps = 4;
  o.seed = 11;
  o.initial_q = scene.q0;
  Randomization& r = o.randomization;
  r.mass_scale = {0.8, 1.2};
  r.com_offset = {-0.01, 0.01};
  r.randomize_ground_friction = true;
  r.ground_friction = {0.4, 1.2};
  r.kp_scale = {0.9, 1.1};
  r.kd_scale = {0.9, 1.1};
  r.damping_scale = {0.5, 2.0};
  r.armature_add = {0.0, 0.01};
  r.gravity_offset = {-0.2, 0.2};
  r.joint_position_noise = {-0.05, 0.05};
  r.joint_velocity_noise = {-0.1, 0.1};
  r.root_position_noise = {-0.1, 0.1};
  r.root_yaw_noise = {-0.5, 0.5};
  r.root_velocity_noise = {-0.05, 0.05};
  return o;
}

int first_revolute_body(const Model& m) {
  for (int b = 0; b < m.nbody; ++b)
    if (m.body_joint[b] == JointType::Revolute) return b;
  return -1;
}

const Model& anymal() {
  static const Model model = test::load_shared_model("anymal_b", true);
  return model;
}

// Actions of copy `copy` at env step t: the standing pose plus a wave, the
// same wherever the copy sits in a batch.
RowMatrix wave_actions(const VecEnv& env, const std::vector<int>& copy_ids, int t) {
  RowMatrix a(static_cast<int>(copy_ids.size()), env.action_size());
  for (int r = 0; r < a.rows(); ++r)
    for (int j = 0; j < a.cols(); ++j) {
      const int dof = env.action_dofs()[j];
      const int qi = env.model().body_q_offset[env.model().dof_body[dof]];
      a(r, j) = env.options().initial_q[qi] + 0.2 * std::sin(0.1 * t + 0.7 * j + 0.3 * copy_ids[r]);
    }
  return a;
}

std::vector<int> iota(int n, int first = 0) {
  std::vector<int> ids(n);
  for (int i = 0; i < n; ++i) ids[i] = first + i;
  return ids;
}

// The base observations are the first articulation's: a static table
// listed first is the base, at rest at its pose, though the free box after
// it owns body 0 (the box's pose was reported as the base); listed after
// the box, the box is.
TEST(VecEnv, TheBaseIsTheFirstArticulationsRootEvenWhenItIsStatic) {
  ArticulationSpec table;
  table.name = "table";
  LinkSpec top;
  top.name = "table";
  table.links.push_back(top);
  table.root_pose = Eigen::Isometry3d(Eigen::Translation3d(5, 0, 0));
  ArticulationSpec box;
  box.name = "box";
  box.floating_base = true;
  LinkSpec body;
  body.name = "box";
  body.inertial.mass = 1;
  body.inertial.inertia = Eigen::Matrix3d::Identity() * 0.01;
  box.links.push_back(body);
  for (const bool table_first : {true, false}) {
    ModelBuilder builder;
    builder.add_articulation(table_first ? table : box);
    builder.add_articulation(table_first ? box : table);
    const Model model = builder.finalize();
    VecEnvOptions options;
    options.initial_q = model.neutral_configuration();
    options.initial_q[2] = 2.0;  // the box, 2 m up, falling
    VecEnv env(model, 1, options);
    env.reset();
    env.step(RowMatrix(1, env.action_size()));
    const Observations& o = env.observations();
    if (table_first) {
      EXPECT_EQ(o.base_position.row(0), Eigen::RowVector3d(5, 0, 0));
      EXPECT_EQ(o.base_linear_velocity_world.row(0).norm(), 0.0);
    } else {
      EXPECT_EQ(o.base_position(0, 2), env.simulator().q(0)[2]);
      EXPECT_LT(o.base_linear_velocity_world(0, 2), 0.0) << "falling";
    }
  }
}

TEST(VecEnv, ObservationsDescribeTheSimulatorState) {
  VecEnv env(anymal(), 5, standing_options(anymal()));
  env.reset();
  env.step(wave_actions(env, iota(5), 0));
  const Observations& o = env.observations();
  const Simulator& sim = env.simulator();
  const Observations& terminal = env.terminal_observations();
  for (const RowMatrix* m : {&terminal.q, &terminal.qd, &terminal.applied_torque, &terminal.contact_force})
    EXPECT_TRUE(m->isZero(0.0)) << "before any copy's episode ended, its terminal rows are zeros";
  ASSERT_EQ(o.q.rows(), 5);
  ASSERT_EQ(o.contact_force.cols(), 3 * anymal().nbody);
  for (int c = 0; c < 5; ++c) {
    EXPECT_TRUE(same_bits(o.q.row(c).transpose(), sim.q(c)));
    EXPECT_TRUE(same_bits(o.qd.row(c).transpose(), sim.v(c)));
    const Eigen::Quaterniond R = Eigen::Quaterniond(o.q(c, 3), o.q(c, 4), o.q(c, 5), o.q(c, 6)).normalized();
    EXPECT_EQ(o.base_position.row(c), o.q.row(c).head<3>());
    EXPECT_TRUE(o.base_linear_velocity_world.row(c).transpose().isApprox(
        R * o.qd.row(c).head<3>().transpose(), 1e-12));
    EXPECT_TRUE(o.base_angular_velocity_world.row(c).transpose().isApprox(
        R * o.qd.row(c).segment<3>(3).transpose(), 1e-12));
    const Eigen::Vector3d g = Eigen::Vector3d(sim.batch<float>().state.gravity.get(c)).normalized();
    EXPECT_TRUE(o.projected_gravity.row(c).transpose().isApprox(R.inverse() * g, 1e-12));
    const AppliedTorque applied = sim.applied_torque(c);
    EXPECT_TRUE(o.applied_torque.row(c).transpose().isApprox(
        applied.drive + applied.passive + applied.friction + applied.limits, 1e-12));
    const Eigen::Matrix<double, 6, Eigen::Dynamic> wrenches = sim.body_contact_wrenches(c);
    for (int b = 0; b < anymal().nbody; ++b)
      EXPECT_EQ(o.contact_force.row(c).segment<3>(3 * b), wrenches.col(b).head<3>().transpose());
  }
}

// With record_motion the observations hold the step's joint forces and link
// accelerations, the simulator's own bit for bit (the bulk readouts); a
// copy that ended keeps its last step's in the terminal observation and
// starts its new episode with zeros (no step yet). Without it, no columns.
TEST(VecEnv, ObservesTheStepsJointForcesAndLinkAccelerations) {
  VecEnvOptions options = standing_options(anymal());
  EXPECT_EQ(VecEnv(anymal(), 2, options).observations().joint_force.cols(), 0);
  options.step.record_motion = true;
  options.episode_steps = 3;
  VecEnv env(anymal(), 5, options);
  env.reset();
  const int frames = static_cast<int>(anymal().frame_name.size());
  ASSERT_EQ(env.observations().joint_force.cols(), 6 * anymal().nbody);
  ASSERT_EQ(env.observations().link_acceleration.cols(), 6 * frames);
  EXPECT_TRUE(env.observations().joint_force.isZero(0));
  RowMatrix last_forces;
  for (int t = 0; t < 3; ++t) {
    last_forces = env.observations().joint_force;
    env.step(wave_actions(env, iota(5), t));
  }
  const Observations &o = env.observations(), &terminal = env.terminal_observations();
  for (int c = 0; c < 5; ++c) {
    EXPECT_TRUE(env.truncated()[c]);
    EXPECT_TRUE(o.joint_force.row(c).isZero(0)) << "reset: no step of the new episode yet";
    EXPECT_TRUE(o.link_acceleration.row(c).isZero(0));
    EXPECT_GT(terminal.joint_force.row(c).norm(), 10.0) << "the ended episode's last step";
  }
  env.step(wave_actions(env, iota(5), 3));
  const Simulator& sim = env.simulator();
  for (int c = 0; c < 5; ++c) {
    const Eigen::Matrix<double, 6, Eigen::Dynamic> f = sim.incoming_joint_forces(c), a = sim.link_accelerations(c);
    EXPECT_TRUE(same_bits(o.joint_force.row(c).transpose(), Eigen::Map<const Eigen::VectorXd>(f.data(), f.size())));
    EXPECT_TRUE(
        same_bits(o.link_acceleration.row(c).transpose(), Eigen::Map<const Eigen::VectorXd>(a.data(), a.size())));
  }
}

// Standing under the drives, the ground carries the robot: the feet's
// contact forces add up to its weight (the copy's own mass and gravity).
TEST(VecEnv, ContactForcesCarryTheWeightOfAStandingRobot) {
  VecEnvOptions options = standing_options(anymal());
  options.randomization = {};
  VecEnv env(anymal(), 3, options);
  env.reset();
  RowMatrix hold(3, env.action_size());
  for (int j = 0; j < env.action_size(); ++j)
    hold.col(j).setConstant(options.initial_q[anymal().body_q_offset[anymal().dof_body[env.action_dofs()[j]]]]);
  for (int t = 0; t < 250; ++t) env.step(hold);  // 2 s
  const double weight = 9.81 * anymal().total_mass();
  for (int c = 0; c < 3; ++c) {
    double vertical = 0;
    for (int b = 0; b < anymal().nbody; ++b) vertical += env.observations().contact_force(c, 3 * b + 2);
    // at rest to the solver's residual: 1 % of the weight
    EXPECT_NEAR(vertical, weight, 0.01 * weight) << "copy " << c;
    EXPECT_LT(env.observations().base_linear_velocity_world.row(c).norm(), 1e-2);
  }
}

// With the contacts stage forced off (the CLI's --no-contacts) the ground
// stays in the options but no copy keeps one: a drawn ground friction has
// nothing to go to, and the other draws are the same as with contacts (each
// draw is keyed by its field, copy and reset, not by the order of draws).
// It once stopped every reset with an internal error from set_ground.
TEST(VecEnv, GroundFrictionDrawWithoutContactsIsSkipped) {
  VecEnvOptions off = standing_options(anymal());
  off.step.force(Stage::Contacts, StageMode::Off);
  VecEnv without(anymal(), 3, off), with(anymal(), 3, standing_options(anymal()));
  without.reset();
  with.reset();
  for (int c = 0; c < 3; ++c) {
    const CopySnapshot a = without.simulator().snapshot(c), b = with.simulator().snapshot(c);
    EXPECT_TRUE(test::same_bits(a.q, b.q)) << "copy " << c;
    EXPECT_EQ(without.simulator().batch<float>().state.inertia.get(c), with.simulator().batch<float>().state.inertia.get(c));
  }
  Simulator& sim = without.simulator();
  try {
    sim.set_ground(0, 0.0, Eigen::Vector3d::UnitZ(), 1.0);
    ADD_FAILURE() << "set_ground without contacts running was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("set_ground: the scene's contacts do not run (forced off"), std::string::npos)
        << e.what();
  }
}

TEST(VecEnv, ResetDrawsEveryParameterInItsRangePerCopyAndPerReset) {
  const VecEnvOptions options = standing_options(anymal());
  VecEnv env(anymal(), 4, options);
  env.reset();
  const auto& b = env.simulator().batch<float>();
  const Model& m = anymal();
  std::set<float> masses;
  for (int c = 0; c < 4; ++c) {
    for (int body = 0; body < m.nbody; ++body) {
      const double mass = b.state.inertia.at(c, 10 * body);
      EXPECT_GE(mass, 0.8 * m.body_mass[body] * (1 - 1e-6));
      EXPECT_LE(mass, 1.2 * m.body_mass[body] * (1 + 1e-6));
      masses.insert(static_cast<float>(mass / m.body_mass[body]));
    }
    const double mu = b.ground_friction.at(c, 0);
    EXPECT_GE(mu, 0.4);
    EXPECT_LE(mu, 1.2);
    for (int axis = 0; axis < 3; ++axis) EXPECT_NEAR(b.state.gravity.at(c, axis), m.gravity[axis], 0.2 + 1e-6);
    for (int k : env.action_dofs()) {
      EXPECT_GE(b.armature.at(c, k), 0.0f);
      EXPECT_LE(b.armature.at(c, k), 0.01f + 1e-6f);
      EXPECT_GE(b.drive_stiffness.at(c, k), 0.9 * options.dofs[k].drive_stiffness * (1 - 1e-6));
      EXPECT_LE(b.drive_stiffness.at(c, k), 1.1 * options.dofs[k].drive_stiffness * (1 + 1e-6));
    }
    const Eigen::VectorXd q = env.simulator().q(c);
    EXPECT_NEAR(q[0], options.initial_q[0], 0.1 + 1e-6);
    EXPECT_EQ(q[2], static_cast<float>(options.initial_q[2]));  // root height: no noise
  }
  EXPECT_EQ(masses.size(), static_cast<std::size_t>(4 * m.nbody));  // every body of every copy its own draw
  const CopySnapshot before = env.simulator().snapshot(2);
  env.reset(std::vector<int>{2});
  EXPECT_EQ(env.reset_count()[2], 2u);
  EXPECT_EQ(env.reset_count()[1], 1u);
  EXPECT_NE(env.simulator().snapshot(2).parameters, before.parameters);  // a new draw
}

// A scene may start a joint outside its limits (kept as written, with a
// warning); the reset once clamped it back without a word. Noise around
// such a start stays between the limits and the start.
TEST(VecEnv, AStartOutsideTheLimitsIsKeptAndItsNoiseStaysWithinReach) {
  VecEnvOptions options = standing_options(anymal());
  const Model& m = anymal();
  const int k = m.body_dof_offset[first_revolute_body(m)], qo = m.body_q_offset[m.dof_body[k]];
  ASSERT_TRUE(std::isfinite(options.dofs[k].upper));
  const double start = options.dofs[k].upper + 0.3;
  options.initial_q[qo] = start;
  options.randomization.joint_position_noise = {0.0, 0.0};
  VecEnv exact(m, 3, options);
  exact.reset();
  for (int c = 0; c < 3; ++c) EXPECT_EQ(exact.simulator().q(c)[qo], static_cast<float>(start)) << "copy " << c;
  options.randomization.joint_position_noise = {-0.05, 0.05};
  VecEnv noisy(m, 16, options);
  noisy.reset();
  for (int c = 0; c < 16; ++c) {
    EXPECT_GE(noisy.simulator().q(c)[qo], static_cast<float>(start - 0.05)) << "copy " << c;
    EXPECT_LE(noisy.simulator().q(c)[qo], static_cast<float>(start)) << "copy " << c;
  }
}

// A reset that draws nothing leaves every copy with the model's inertias
// and the scene's joint parameters, so the step reads one shared block of
// each; a range that draws turns the stage of what it draws on.
TEST(VecEnv, ResetsThatDrawNothingKeepTheSharedParameterBlocks) {
  const VecEnvOptions plain = [] {
    VecEnvOptions o = standing_options(anymal());
    o.randomization = Randomization{};
    return o;
  }();
  const int inertia = static_cast<int>(Stage::PerCopyInertia);
  const int joints = static_cast<int>(Stage::PerCopyJointParameters);
  VecEnv env(anymal(), 20, plain);
  env.reset();
  env.step(wave_actions(env, iota(20), 0));
  EXPECT_FALSE(env.simulator().plan()[inertia].runs) << env.simulator().describe_plan();
  EXPECT_FALSE(env.simulator().plan()[joints].runs) << env.simulator().describe_plan();

  VecEnvOptions masses = plain;
  masses.randomization.mass_scale = {0.9, 1.1};
  VecEnv heavier(anymal(), 20, masses);
  heavier.reset();
  EXPECT_TRUE(heavier.simulator().plan()[inertia].runs);
  EXPECT_FALSE(heavier.simulator().plan()[joints].runs);

  VecEnvOptions gains = plain;
  gains.randomization.kp_scale = {0.9, 1.1};
  VecEnv stiffer(anymal(), 20, gains);
  stiffer.reset();
  EXPECT_FALSE(stiffer.simulator().plan()[inertia].runs);
  EXPECT_TRUE(stiffer.simulator().plan()[joints].runs);
}

// Copy c of any batch, on any thread count, draws and steps the same.
TEST(VecEnv, CopiesDoNotDependOnBatchSizeOrThreads) {
  const VecEnvOptions options = standing_options(anymal());
  auto run = [&](int copies, int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    VecEnv env(anymal(), copies, options);
    env.reset();
    for (int t = 0; t < 20; ++t) env.step(wave_actions(env, iota(copies), t));
    return env;
  };
  const VecEnv reference = run(3, 1);
  for (const auto& [copies, threads] : {std::pair{3, 2}, std::pair{37, 2}, std::pair{37, 1}}) {
    const VecEnv other = run(copies, threads);
    for (int c = 0; c < 3; ++c) {
      EXPECT_TRUE(same_bits(reference.observations().q.row(c).transpose(), other.observations().q.row(c).transpose()))
          << copies << " copies, " << threads << " threads, copy " << c;
      EXPECT_TRUE(same_bits(reference.simulator().snapshot(c).parameters, other.simulator().snapshot(c).parameters));
    }
  }
}

// A copy's state written into another environment (another position,
// another batch size) replays it bit for bit, warm start included.
TEST(VecEnv, AWrittenCopyStateReplaysBitForBit) {
  const VecEnvOptions options = standing_options(anymal(), Precision::Double);
  VecEnv source(anymal(), 4, options);
  source.reset();
  for (int t = 0; t < 30; ++t) source.step(wave_actions(source, iota(4), t));
  const EnvCopyState saved = source.state(1);
  VecEnv target(anymal(), 9, options);
  target.reset();
  target.set_state(6, saved);
  EXPECT_TRUE(same_bits(target.observations().q.row(6).transpose(), source.observations().q.row(1).transpose()));
  for (int t = 30; t < 60; ++t) {
    source.step(wave_actions(source, iota(4), t));
    std::vector<int> ids = iota(9, 200);
    ids[6] = 1;
    target.step(wave_actions(target, ids, t));
    ASSERT_TRUE(same_bits(target.observations().q.row(6).transpose(), source.observations().q.row(1).transpose()))
        << "env step " << t;
    ASSERT_TRUE(same_bits(target.observations().qd.row(6).transpose(), source.observations().qd.row(1).transpose()));
  }
  EXPECT_EQ(target.episode_step()[6], source.episode_step()[1]);
}

TEST(VecEnv, EpisodesTruncateAndAutoResetKeepingTheTerminalObservation) {
  VecEnvOptions options = standing_options(anymal());
  options.episode_steps = 3;
  VecEnv env(anymal(), 2, options);
  VecEnvOptions manual_options = options;
  manual_options.auto_reset = false;
  VecEnv manual(anymal(), 2, manual_options);
  env.reset();
  manual.reset();
  for (int t = 0; t < 3; ++t) {
    env.step(wave_actions(env, iota(2), t));
    manual.step(wave_actions(manual, iota(2), t));
    const bool last = t == 2;
    for (int c = 0; c < 2; ++c) {
      EXPECT_EQ(env.truncated()[c], last ? 1 : 0);
      EXPECT_EQ(env.terminated()[c], 0);
      EXPECT_EQ(manual.truncated()[c], last ? 1 : 0);
    }
  }
  // auto-reset: the terminal rows are where the manual env stands; the
  // observations are a fresh episode's, like the manual env after reset().
  for (int c = 0; c < 2; ++c) {
    EXPECT_TRUE(same_bits(env.terminal_observations().q.row(c).transpose(), manual.observations().q.row(c).transpose()));
    EXPECT_EQ(env.episode_step()[c], 0);
    EXPECT_EQ(env.reset_count()[c], 2u);
    EXPECT_EQ(manual.episode_step()[c], 3);
  }
  manual.reset_masked({1, 1});
  for (int c = 0; c < 2; ++c)
    EXPECT_TRUE(same_bits(env.observations().q.row(c).transpose(), manual.observations().q.row(c).transpose()));
  // without auto-reset the episode stays truncated until reset
  manual.reset_masked({0, 0});
  EXPECT_EQ(manual.reset_count()[0], 2u);
}

TEST(VecEnv, TheRewardFunctionSetsRewardsAndTerminations) {
  VecEnvOptions options = standing_options(anymal());
  VecEnv env(anymal(), 4, options);
  int calls = 0;
  env.set_reward([&](const Observations& obs, const RowMatrix& actions, Eigen::VectorXd& reward,
                     std::vector<std::uint8_t>& terminated) {
    ++calls;
    EXPECT_EQ(actions.rows(), 4);
    EXPECT_TRUE((reward.array() == 0).all());
    for (int c = 0; c < 4; ++c) {
      reward[c] = obs.base_position(c, 2);
      terminated[c] = c == 3;
    }
  });
  env.reset();
  env.step(wave_actions(env, iota(4), 0));
  EXPECT_EQ(calls, 1);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(env.reward()[c], env.observations().base_position(c, 2));
    EXPECT_EQ(env.terminated()[c], 0);
  }
  EXPECT_EQ(env.terminated()[3], 1);
  EXPECT_EQ(env.reward()[3], env.terminal_observations().base_position(3, 2));
  EXPECT_EQ(env.episode_step()[3], 0);
  EXPECT_EQ(env.episode_step()[0], 1);
}

// A reward function that resizes its outputs is refused, and so is one
// that throws its own exception: that step's simulator stepped and its
// episodes did not (counters, faults, resets), so the env refuses to step
// until every copy is reset; then, with a sound reward function or none, it
// works. (It once stepped on, an episode a step longer than episode_steps.)
TEST(VecEnv, AStepAfterARewardFunctionThatThrewNeedsAReset) {
  VecEnv env(anymal(), 4, standing_options(anymal()));
  env.set_reward([](const Observations&, const RowMatrix&, Eigen::VectorXd& reward,
                    std::vector<std::uint8_t>& terminated) {
    reward.resize(0);
    terminated.clear();
    terminated.shrink_to_fit();
  });
  env.reset();
  EXPECT_THROW_WITH(env.step(wave_actions(env, iota(4), 0)), std::logic_error, "resized its outputs");
  env.set_reward([](const Observations&, const RowMatrix&, Eigen::VectorXd&, std::vector<std::uint8_t>&) {
    throw std::runtime_error("the user's own error");
  });
  EXPECT_THROW_WITH(env.step(wave_actions(env, iota(4), 0)), std::logic_error,
                    "reset every copy first (reset()): before the first step, and after a step whose reward "
                    "function threw");
  env.reset();
  EXPECT_THROW_WITH(env.step(wave_actions(env, iota(4), 0)), std::runtime_error, "the user's own error");
  env.reset(std::vector<int>{0, 1, 2});
  EXPECT_THROW_WITH(env.step(wave_actions(env, iota(4), 0)), std::logic_error, "reset every copy first");
  env.reset(std::vector<int>{3});
  env.set_reward([](const Observations&, const RowMatrix&, Eigen::VectorXd& reward,
                    std::vector<std::uint8_t>& terminated) {
    ASSERT_EQ(reward.size(), 4);
    ASSERT_EQ(terminated.size(), 4u);
    reward.setConstant(2.0);
  });
  env.step(wave_actions(env, iota(4), 1));
  EXPECT_TRUE((env.reward().array() == 2.0).all());
  env.set_reward(nullptr);
  env.step(wave_actions(env, iota(4), 2));
  EXPECT_TRUE((env.reward().array() == 0.0).all());
  EXPECT_EQ(env.terminated(), std::vector<std::uint8_t>(4, 0));
}

// Every copy reset by reset(indices) or reset_masked is ready to step as
// after reset(); some copies only are not.
TEST(VecEnv, ResettingEveryCopyByIndexOrMaskAllowsStepping) {
  VecEnv by_index(anymal(), 3, standing_options(anymal())), by_mask(anymal(), 3, standing_options(anymal()));
  by_index.reset(std::vector<int>{0, 2});
  EXPECT_THROW_WITH(by_index.step(wave_actions(by_index, iota(3), 0)), std::logic_error, "reset every copy first");
  by_index.reset(std::vector<int>{1});
  by_index.step(wave_actions(by_index, iota(3), 0));
  by_mask.reset_masked({1, 1, 1});
  by_mask.step(wave_actions(by_mask, iota(3), 0));
  for (int c = 0; c < 3; ++c) EXPECT_TRUE(test::same_state(by_index.simulator(), c, by_mask.simulator(), c));
}

// A ground set per copy (a terrain) keeps its height and normal through
// resets; with randomize_ground_friction a reset draws its friction only.
TEST(VecEnv, AResetKeepsACopysOwnGroundAndDrawsItsFriction) {
  VecEnvOptions options = standing_options(anymal());
  VecEnv env(anymal(), 2, options);
  env.reset();
  const Eigen::Vector3d tilted = Eigen::Vector3d(0.1, 0, 1).normalized();
  env.simulator().set_ground(1, -0.2, tilted, 0.1);
  const Eigen::VectorXf plane = env.simulator().batch<float>().ground.get(1).cast<float>();
  env.reset(std::vector<int>{1});
  EXPECT_EQ(env.simulator().batch<float>().ground.get(1).cast<float>(), plane);
  const float friction = env.simulator().batch<float>().ground_friction.at(1, 0);
  EXPECT_NE(friction, 0.1f);
  EXPECT_GE(friction, 0.4f);
  EXPECT_LE(friction, 1.2f);
  options.randomization.randomize_ground_friction = false;
  VecEnv kept(anymal(), 2, options);
  kept.reset();
  kept.simulator().set_ground(0, -0.2, tilted, 0.1);
  kept.reset(std::vector<int>{0});
  EXPECT_EQ(kept.simulator().batch<float>().ground_friction.at(0, 0), 0.1f);
  EXPECT_THROW_WITH(kept.simulator().set_ground_friction(0, -1.0), std::invalid_argument,
                    "set_ground_friction: friction must be finite");
}

// A non-finite action faults its copy only: the others step as without it,
// and the faulted copy is reported, terminated and restarted.
TEST(VecEnv, AFaultedCopyIsIsolatedReportedAndReset) {
  VecEnvOptions options = standing_options(anymal());
  options.action_mode = ActionMode::Torque;
  VecEnv env(anymal(), 3, options), clean(anymal(), 3, options);
  env.reset();
  clean.reset();
  RowMatrix actions = RowMatrix::Zero(3, env.action_size());
  env.step(actions);
  clean.step(actions);
  actions(1, 2) = std::numeric_limits<double>::quiet_NaN();
  env.step(actions);
  actions(1, 2) = 0;
  clean.step(actions);
  EXPECT_EQ(env.faulted(), (std::vector<std::uint8_t>{0, 1, 0}));
  EXPECT_EQ(env.fault(1), Fault::NonFiniteTorque);
  EXPECT_EQ(env.terminated()[1], 1);
  EXPECT_EQ(env.reward()[1], 0.0);
  EXPECT_EQ(env.reset_count()[1], 2u);
  EXPECT_TRUE(env.observations().q.row(1).allFinite());
  for (int c : {0, 2})
    EXPECT_TRUE(same_bits(env.observations().q.row(c).transpose(), clean.observations().q.row(c).transpose()));
  env.step(actions);
  EXPECT_EQ(env.faulted()[1], 0);
  EXPECT_EQ(env.fault(1), Fault::None);
}

TEST(VecEnv, TorqueAndPositionTargetActionsReachTheSimulator) {
  VecEnvOptions options = standing_options(anymal());
  options.randomization = {};
  options.action_mode = ActionMode::Torque;
  options.drive_target_q = options.initial_q;
  options.drive_target_q[anymal().body_q_offset[anymal().dof_body[6]]] = 0.25;  // the drives hold these
  VecEnv torque(anymal(), 2, options);
  torque.reset();
  EXPECT_TRUE(test::same_bits(torque.simulator().batch<float>().target_q.get(1),
                              options.drive_target_q.cast<float>().cast<double>()));
  RowMatrix a = RowMatrix::Constant(2, torque.action_size(), 1.5);
  a(1, 0) = -2.0;
  torque.step(a);
  const auto& bt = torque.simulator().batch<float>();
  EXPECT_EQ(bt.state.tau.at(1, torque.action_dofs()[0]), -2.0f);
  EXPECT_EQ(bt.state.tau.at(0, 0), 0.0f);  // the floating root takes no action
  EXPECT_EQ(torque.action_size(), anymal().nv - 6);

  options.action_mode = ActionMode::PositionTarget;
  VecEnv target(anymal(), 2, options);
  target.reset();
  target.step(wave_actions(target, iota(2), 5));
  const RowMatrix expected = wave_actions(target, iota(2), 5);
  const auto& bp = target.simulator().batch<float>();
  for (int j = 0; j < target.action_size(); ++j) {
    const int qi = anymal().body_q_offset[anymal().dof_body[target.action_dofs()[j]]];
    EXPECT_EQ(bp.target_q.at(1, qi), static_cast<float>(expected(1, j)));
  }
  // position_action: the row that targets a configuration, here the drives' own
  const Eigen::VectorXd hold = target.position_action(options.drive_target_q);
  ASSERT_EQ(hold.size(), target.action_size());
  for (int j = 0; j < target.action_size(); ++j)
    EXPECT_EQ(hold[j], options.drive_target_q[anymal().body_q_offset[anymal().dof_body[target.action_dofs()[j]]]]);
  EXPECT_EQ(hold[0], 0.25);
  EXPECT_THROW(target.position_action(Eigen::VectorXd::Zero(3)), std::invalid_argument);
}

// A Spherical joint's three actions are a rotation vector: its drive
// target is exp(r), and the drive takes the joint there.
TEST(VecEnv, ASphericalJointTakesARotationVectorAsItsTarget) {
  const Model model = test::ball_joint();
  VecEnvOptions options;
  options.step.precision = Precision::Double;
  options.dofs = default_dof_settings(model);
  for (DofSettings& d : options.dofs) d.drive_stiffness = 20, d.drive_damping = 2;
  options.action_mode = ActionMode::PositionTarget;
  VecEnv env(model, 2, options);
  ASSERT_EQ(env.action_size(), 3);
  env.reset();
  const Eigen::Vector3d r(0.3, -0.2, 0.5);
  RowMatrix actions(2, 3);
  actions.row(0) = r.transpose();
  actions.row(1).setZero();
  for (int t = 0; t < 1500; ++t) env.step(actions);  // 3 s, the drive's time constant ~0.1 s
  const Eigen::Quaterniond target(Eigen::AngleAxisd(r.norm(), r.normalized()));
  const Eigen::VectorXd stored = env.simulator().batch<double>().target_q.get(0);
  EXPECT_NEAR(stored[0], target.w(), 1e-15);
  EXPECT_NEAR(stored[1], target.x(), 1e-15);
  EXPECT_NEAR(stored[2], target.y(), 1e-15);
  EXPECT_NEAR(stored[3], target.z(), 1e-15);
  const Eigen::Vector4d wxyz(target.w(), target.x(), target.y(), target.z());
  EXPECT_LT((env.position_action(wxyz) - r).norm(), 1e-15) << "position_action inverts the rotation vector";
  const Eigen::RowVectorXd q = env.observations().q.row(0);
  const Eigen::Quaterniond reached(q[0], q[1], q[2], q[3]);
  EXPECT_LT(reached.angularDistance(target), 1e-6);  // no gravity torque on a ball at its COM
  EXPECT_LT(Eigen::Quaterniond(env.observations().q(1, 0), env.observations().q(1, 1), env.observations().q(1, 2),
                               env.observations().q(1, 3))
                .angularDistance(Eigen::Quaterniond::Identity()),
            1e-9);
}

// Per-copy armature, damping and Coulomb friction act as the model's and
// DofSettings' do (friction on DOFs that have friction rows).
TEST(VecEnv, PerCopyArmatureDampingAndFrictionMatchTheModelsOwn) {
  Model with = test::rod_chain({1.0, 0.5}, 0.4);
  Model without = with;
  with.dof_armature = {0.02, 0.03};
  std::vector<DofSettings> damped = default_dof_settings(with);
  damped[0].damping = 0.4;
  damped[1].damping = 0.1;
  damped[0].friction = 0.3;
  damped[1].friction = 0.2;
  std::vector<DofSettings> rows_only = default_dof_settings(without);
  for (DofSettings& d : rows_only) d.friction = 0.01;  // friction rows, their force per copy
  StepOptions options;
  options.precision = Precision::Double;
  Simulator reference(with, 1, options, damped);
  Simulator per_copy(without, 1, options, rows_only);
  per_copy.set_armature(0, Eigen::Vector2d(0.02, 0.03));
  per_copy.set_joint_damping(0, Eigen::Vector2d(0.4, 0.1));
  per_copy.set_joint_friction(0, Eigen::Vector2d(0.3, 0.2));
  const Eigen::Vector2d q0(0.7, -0.4), v0(0.5, 1.0);
  reference.set_state(0, q0, v0);
  per_copy.set_state(0, q0, v0);
  reference.step(200);
  per_copy.step(200);
  EXPECT_TRUE(test::same_state(reference, 0, per_copy, 0));
  // and they matter: without them the chain moves differently
  Simulator plain(without, 1, options);
  plain.set_state(0, q0, v0);
  plain.step(200);
  EXPECT_GT((plain.q(0) - reference.q(0)).norm(), 1e-3);
}

// joint_friction_scale scales each copy's Coulomb friction, DOF by DOF.
TEST(VecEnv, JointFrictionIsDrawnPerCopyAndDof) {
  const Model chain = test::rod_chain({1.0, 0.5}, 0.4);
  VecEnvOptions options;
  options.dofs = default_dof_settings(chain);
  for (DofSettings& d : options.dofs) d.friction = 0.3;
  options.randomization.joint_friction_scale = {0.5, 2.0};
  VecEnv env(chain, 6, options);
  env.reset();
  std::set<float> seen;
  for (int c = 0; c < 6; ++c)
    for (int k = 0; k < chain.nv; ++k) {
      const float f = env.simulator().batch<float>().joint_friction.at(c, k);
      EXPECT_GE(f, 0.15f * (1 - 1e-6f));
      EXPECT_LE(f, 0.6f * (1 + 1e-6f));
      seen.insert(f);
    }
  EXPECT_EQ(seen.size(), 12u);
}

TEST(VecEnv, RejectsBadUseWithClearErrors) {
  VecEnvOptions options = standing_options(anymal());
  VecEnv env(anymal(), 2, options);
  EXPECT_THROW(env.step(RowMatrix::Zero(2, env.action_size())), std::logic_error);  // before reset
  env.reset();
  EXPECT_THROW(env.step(RowMatrix::Zero(3, env.action_size())), std::invalid_argument);
  EXPECT_THROW(env.reset(std::vector<int>{2}), std::out_of_range);
  EXPECT_THROW(env.reset_masked({1}), std::invalid_argument);
  VecEnvOptions bad = options;
  bad.control_steps = 0;
  EXPECT_THROW(VecEnv(anymal(), 2, bad), std::invalid_argument);
  bad = options;
  bad.initial_q = Eigen::VectorXd::Zero(3);
  EXPECT_THROW(VecEnv(anymal(), 2, bad), std::invalid_argument);
  for (const char* which : {"initial_q", "initial_v"}) {  // named, with the entry, not at reset
    bad = options;
    bad.initial_v = Eigen::VectorXd::Zero(anymal().nv);
    (std::string(which) == "initial_q" ? bad.initial_q : bad.initial_v)[4] = std::nan("");
    EXPECT_THROW_WITH(VecEnv(anymal(), 2, bad), std::invalid_argument,
                      std::string("VecEnv: ") + which + " must be finite, entry 4 is nan");
  }
  bad = options;
  bad.randomization.mass_scale = {1.2, 0.8};
  EXPECT_THROW(VecEnv(anymal(), 2, bad), std::invalid_argument);
  bad = options;
  for (DofSettings& d : bad.dofs) d.drive_stiffness = 0;
  EXPECT_THROW(VecEnv(anymal(), 2, bad), std::invalid_argument);  // position targets without gains
  bad = options;
  const int knee = anymal().dof_index("LF_KFE");
  bad.dofs[knee].drive_stiffness = 0;  // one action column would do nothing
  EXPECT_THROW_WITH(VecEnv(anymal(), 2, bad), std::invalid_argument, "LF_KFE (DOF " + std::to_string(knee) + ") has 0");
  EXPECT_THROW_WITH(env.fault(2), std::out_of_range, "VecEnv::fault: copy index 2 outside [0, 2)");
  EXPECT_THROW_WITH(env.state(-1), std::out_of_range, "VecEnv::state: copy index -1 outside [0, 2)");
  EXPECT_THROW_WITH(env.set_state(2, env.state(0)), std::out_of_range, "VecEnv::set_state: copy index 2");
  EXPECT_THROW_WITH(env.reset(std::vector<int>{0, 5}), std::out_of_range, "VecEnv::reset: copy index 5");
  EXPECT_THROW_WITH(env.simulator().q(-1), std::out_of_range, "Simulator::q: copy index -1 outside [0, 2)");
  EXPECT_THROW_WITH(env.simulator().contacts(3), std::out_of_range, "Simulator::contacts: copy index 3");
}

}  // namespace
}  // namespace lockstep
