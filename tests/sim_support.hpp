// Small models for the simulation tests: chains of pendulum links, a free
// box, and helpers to run a Simulator.
#pragma once

#include "batch/simulator.hpp"
#include "tests/test_support.hpp"

namespace lockstep::test {

// A rod of mass m and length l along -z from its joint (a point mass at the
// end when `point`), hanging from a revolute joint about y.
inline LinkSpec rod_link(const std::string& name, const std::string& parent, double mass, double length,
                         double parent_length) {
  LinkSpec link = joint_link(name, parent, JointType::Revolute, Eigen::Vector3d::UnitY(),
                             Eigen::Vector3d(0, 0, -parent_length));
  link.inertial.mass = mass;
  link.inertial.origin.translation() = Eigen::Vector3d(0, 0, -0.5 * length);
  const double i = mass * length * length / 12.0;
  link.inertial.inertia = Eigen::Vector3d(i, i, 1e-6 * mass).asDiagonal();
  return link;
}

// The model of one articulation.
inline Model build(const ArticulationSpec& spec) {
  ModelBuilder builder;
  builder.add_articulation(spec);
  return builder.finalize();
}

// A fixed-base chain of revolute rods (about y) hanging from the world.
inline Model rod_chain(const std::vector<double>& masses, double length) {
  ArticulationSpec spec;
  spec.name = "chain";
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  std::string parent = "base";
  for (std::size_t i = 0; i < masses.size(); ++i) {
    const std::string name = "link" + std::to_string(i);
    spec.links.push_back(rod_link(name, parent, masses[i], length, i == 0 ? 0.0 : length));
    parent = name;
  }
  return build(spec);
}

// A fixed base and one 1 kg link on a joint through its COM (no gravity
// torque, axis z), principal inertia `inertia`; the joint's limits may be
// set on the returned spec's links[1].
inline ArticulationSpec one_link_spec(const std::string& name, const std::string& link_name, JointType type,
                                      const Eigen::Vector3d& inertia) {
  ArticulationSpec spec;
  spec.name = name;
  LinkSpec base;
  base.name = "base";
  spec.links.push_back(base);
  LinkSpec link = joint_link(link_name, "base", type, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero());
  link.inertial.mass = 1.0;
  link.inertial.inertia = inertia.asDiagonal();
  spec.links.push_back(link);
  return spec;
}

// One link turning about z through its COM, with the given moment of
// inertia about the axis; limits when lower < upper.
inline Model spinner(double inertia, double lower = -Model::kInfinity, double upper = Model::kInfinity) {
  ArticulationSpec spec = one_link_spec("spinner", "wheel", JointType::Revolute, Eigen::Vector3d::Constant(inertia));
  JointSpec& joint = spec.links[1].joint;
  joint.limited = lower < upper && (std::isfinite(lower) || std::isfinite(upper));
  joint.lower = lower;
  joint.upper = upper;
  return build(spec);
}

// One link on a Spherical joint, principal inertia (0.02, 0.03, 0.04) kg m^2.
inline Model ball_joint() {
  return build(one_link_spec("ball", "arm", JointType::Spherical, Eigen::Vector3d(0.02, 0.03, 0.04)));
}

// A free box of the given half sizes and mass.
inline Model free_box(const Eigen::Vector3d& half, double mass) {
  ArticulationSpec spec;
  spec.name = "box";
  spec.floating_base = true;
  LinkSpec body;
  body.name = "box";
  body.inertial.mass = mass;
  const Eigen::Vector3d s = half.cwiseAbs2();
  body.inertial.inertia = (mass / 3.0 * Eigen::Vector3d(s.y() + s.z(), s.x() + s.z(), s.x() + s.y())).asDiagonal();
  spec.links.push_back(body);
  return build(spec);
}

}  // namespace lockstep::test

// ---- Step scenes with random per-copy inputs (determinism, faults, stages) ----
#include <algorithm>
#include <cstring>
#include <ios>
#include <sstream>

namespace lockstep::test {

// Bit-for-bit equality of two vectors (a float batch's values widen to
// double exactly, so this compares the stored bits, signs of zero included).
inline ::testing::AssertionResult same_bits(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  if (a.size() != b.size()) return ::testing::AssertionFailure() << "sizes " << a.size() << " and " << b.size();
  for (Eigen::Index i = 0; i < a.size(); ++i)
    if (std::memcmp(&a[i], &b[i], sizeof(double)) != 0) {
      std::ostringstream values;
      values << std::hexfloat << a[i] << " vs " << b[i];
      return ::testing::AssertionFailure() << "entry " << i << ": " << values.str();
    }
  return ::testing::AssertionSuccess();
}

// Copy ca of a and copy cb of b hold the same q and v, bit for bit.
inline ::testing::AssertionResult same_state(const Simulator& a, int ca, const Simulator& b, int cb) {
  ::testing::AssertionResult r = same_bits(a.q(ca), b.q(cb));
  if (!r) return r << " in q";
  r = same_bits(a.v(ca), b.v(cb));
  if (!r) return r << " in v";
  return r;
}

// Joint effects on every revolute or prismatic DOF: damping, Coulomb
// friction, hard limits [-range, range] and a velocity limit (drives come
// per copy, from CopyInputs). A floating base stays free.
inline std::vector<DofSettings> limited_dofs(const Model& model, double range, double velocity_limit) {
  std::vector<DofSettings> dofs = default_dof_settings(model);
  for (int k = 0; k < model.nv; ++k) {
    if (model.body_joint[model.dof_body[k]] == JointType::Free) continue;
    dofs[k].damping = 0.3;
    dofs[k].friction = 0.2;
    dofs[k].lower = -range;
    dofs[k].upper = range;
    dofs[k].velocity_limit = velocity_limit;
  }
  return dofs;
}

// One copy's initial state and inputs, drawn from its own seed so that the
// same copy can be placed anywhere in any batch.
struct CopyInputs {
  Eigen::VectorXd q, v, tau, target_q, target_v, kp, kd;  // kp = kd = 0: no set_drive_gains
  bool push = true;  // set_link_wrench(body, wrench)
  int body = 0;
  Eigen::Matrix<double, 6, 1> wrench;
};

// 1-DOF joints start in the middle 80 % of their range clipped to
// [-1, 1] and are driven toward targets in [-1, 1] (beyond narrow limits);
// velocities up to `speed`.
inline CopyInputs random_copy_inputs(const Model& model, const std::vector<DofSettings>& dofs, unsigned seed,
                                     double speed = 4.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  CopyInputs in;
  in.q = random_configuration(model, rng);
  in.v = random_vector(model.nv, rng, speed);
  in.tau = random_vector(model.nv, rng, 5.0);
  in.target_q = model.neutral_configuration();
  in.target_v = random_vector(model.nv, rng, 1.0);
  in.kp = Eigen::VectorXd::Zero(model.nv);
  in.kd = Eigen::VectorXd::Zero(model.nv);
  for (int k = 0; k < model.nv; ++k) {
    const int b = model.dof_body[k];
    if (model.body_joint[b] != JointType::Revolute && model.body_joint[b] != JointType::Prismatic) continue;
    const int qk = model.body_q_offset[b] + (k - model.body_dof_offset[b]);
    const double lo = std::max(dofs[k].lower, -1.0), hi = std::min(dofs[k].upper, 1.0);
    in.q[qk] = lo + (hi - lo) * (0.1 + 0.8 * unit(rng));
    in.target_q[qk] = 2.0 * unit(rng) - 1.0;
    in.kp[k] = 100.0 * unit(rng);
    in.kd[k] = 3.0 * unit(rng);
  }
  in.body = static_cast<int>(unit(rng) * model.nbody) % model.nbody;
  in.wrench << random_vector(3, rng, 20.0), random_vector(3, rng, 2.0);
  return in;
}

// The row impulses of one copy's last step: its warm start.
inline Eigen::VectorXd row_impulses(const Simulator& sim, int copy) {
  if (sim.options().precision == Precision::Float) return sim.batch<float>().impulse.get(copy);
  return sim.batch<double>().impulse.get(copy);
}

// Copies whose rows pushed in the last step (a non-zero impulse).
inline int copies_with_impulses(const Simulator& sim) {
  int count = 0;
  for (int c = 0; c < sim.copies(); ++c)
    count += sim.row_count() > 0 && row_impulses(sim, c).cwiseAbs().maxCoeff() > 0;
  return count;
}

inline void apply_copy_inputs(Simulator& sim, int copy, const CopyInputs& in) {
  sim.set_state(copy, in.q, in.v);
  sim.set_torque(copy, in.tau);
  sim.set_drive_target(copy, in.target_q, in.target_v);
  sim.set_drive_gains(copy, in.kp, in.kd);
  if (in.push) sim.set_link_wrench(copy, in.body, in.wrench);
}

// n seeds from `first` on.
inline std::vector<unsigned> seed_range(int n, unsigned first) {
  std::vector<unsigned> seeds(n);
  for (int c = 0; c < n; ++c) seeds[c] = first + static_cast<unsigned>(c);
  return seeds;
}

// The step options of these scenes: dt 4 ms, 8 solver iterations.
inline StepOptions scene_options(Precision precision, SolverType solver) {
  StepOptions o;
  o.dt = 0.004;
  o.precision = precision;
  o.solver = solver;
  o.iterations = 8;
  return o;
}

// A simulator whose copy c holds the inputs drawn from seeds[c].
inline Simulator simulator_with_inputs(const Model& model, const std::vector<DofSettings>& dofs,
                                       const StepOptions& options, const std::vector<unsigned>& seeds) {
  Simulator sim(model, static_cast<int>(seeds.size()), options, dofs);
  for (std::size_t c = 0; c < seeds.size(); ++c)
    apply_copy_inputs(sim, static_cast<int>(c), random_copy_inputs(model, dofs, seeds[c]));
  return sim;
}

// The SIMD lanes give the scalar path's bits: `copies` copies with the
// inputs of seeds first, first + 1, ... (padding lanes in the last block
// where copies is not a multiple of the width), `steps` steps with PGS and
// TGS in float and double, the solver pushing somewhere.
inline void expect_simd_lanes_match_the_scalar_path(const Model& model, const std::vector<DofSettings>& dofs,
                                                    int copies, unsigned first, int steps) {
  for (Precision precision : {Precision::Float, Precision::Double})
    for (SolverType solver : {SolverType::PGS, SolverType::TGS}) {
      StepOptions o = scene_options(precision, solver);
      const std::vector<unsigned> seeds = seed_range(copies, first);
      o.lanes = Lanes::Simd;
      Simulator simd = simulator_with_inputs(model, dofs, o, seeds);
      o.lanes = Lanes::Scalar;
      Simulator scalar = simulator_with_inputs(model, dofs, o, seeds);
      simd.step(steps);
      scalar.step(steps);
      EXPECT_GT(copies_with_impulses(simd), 0);
      for (int c = 0; c < simd.copies(); ++c)
        EXPECT_TRUE(same_state(simd, c, scalar, c))
            << precision_name(precision) << " " << solver_name(solver) << ", copy " << c;
    }
}

}  // namespace lockstep::test
