#include "batch/simulator.hpp"

#include "batch/batch_dynamics.hpp"
#include "batch/fnv1a.hpp"
#include "batch/require.hpp"
#include "batch/step_engine.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace lockstep {

template <class T>
StepBatch<T>::StepBatch(const Model& model, int copies, int width, int rows)
    : state(model, copies, width), target_q(copies, model.nq, width), target_v(copies, model.nv, width),
      drive_stiffness(copies, model.nv, width), drive_damping(copies, model.nv, width), joint_damping(copies, model.nv, width),
      armature(copies, model.nv, width), joint_friction(copies, model.nv, width), impulse(copies, rows, width),
      initial_q(copies, model.nq, width), initial_v(copies, model.nv, width), fault(copies, 1, width) {
  target_q.set_all(model.neutral_configuration());
  initial_q.set_all(model.neutral_configuration());
}

template <class T>
std::size_t StepBatch<T>::bytes_per_copy() const {
  std::size_t values = 0;
  for (const BatchArray<T>* a : {&state.q, &state.v, &state.tau, &state.qacc, &state.wrench, &state.inertia,
                                 &state.gravity, &target_q, &target_v, &drive_stiffness, &drive_damping, &joint_damping, &armature, &joint_friction, &impulse,
                                 &initial_q, &initial_v, &fault, &applied_drive, &applied_passive, &applied_friction,
                                 &applied_limits, &ground, &ground_friction, &contact_id, &contact_impulse,
                                 &contact_point, &contact_normal, &contact_separation, &contact_count,
                                 &contact_dropped, &contact_overflow_steps, &contact_wrench, &momentum_remainder, &motion_q, &motion_v,
                                 &motion_acceleration, &motion_unbalanced, &motion_recorded, &applied_actuation,
                                 &actuator_command, &actuator_state, &actuator_strength})
    values += static_cast<std::size_t>(a->size());
  return values * sizeof(T);
}

template struct StepBatch<float>;
template struct StepBatch<double>;

namespace {

// FNV-1a over what gives a snapshot's arrays their meaning: the bodies'
// joints (name, type, q and DOF offsets), the links, the joint rows (kind
// and DOF of each warm-started impulse), the contact pairs (their
// shapes, bodies and candidate numbering, which the warm start's contact
// ids refer to) and the actuators (name, driven and coupled DOFs: what a
// command drives).
std::uint64_t scene_key_of(const Model& model, const std::vector<std::pair<int, int>>& rows,
                           const ContactPairs& pairs, const std::vector<Actuator>& actuators) {
  Fnv1a key;
  key.add(static_cast<std::uint64_t>(model.nbody));
  for (int b = 0; b < model.nbody; ++b) {
    key.add(model.joint_name[b]);
    key.add(static_cast<std::uint64_t>(model.body_joint[b]));
    key.add(static_cast<std::uint64_t>(model.body_parent[b] + 1));
    key.add(static_cast<std::uint64_t>(model.body_q_offset[b]));
    key.add(static_cast<std::uint64_t>(model.body_dof_offset[b]));
  }
  for (const std::string& frame : model.frame_name) key.add(frame);
  key.add(static_cast<std::uint64_t>(rows.size()));
  for (const auto& [kind, dof] : rows) {
    key.add(static_cast<std::uint64_t>(kind));
    key.add(static_cast<std::uint64_t>(dof));
  }
  key.add(static_cast<std::uint64_t>(pairs.pairs.size()));
  for (const ContactPair& pair : pairs.pairs)
    for (const int x : {static_cast<int>(pair.kind), pair.a.shape, pair.a.body, pair.b.shape, pair.b.body,
                        pair.first_candidate})
      key.add(static_cast<std::uint64_t>(static_cast<std::int64_t>(x)));
  key.add(static_cast<std::uint64_t>(actuators.size()));
  for (const Actuator& a : actuators) {
    key.add(a.name);
    key.add(static_cast<std::uint64_t>(a.dof));
    for (const auto& [dof, ratio] : a.couplings) key.add(static_cast<std::uint64_t>(dof));
  }
  return key.value();
}

// Whether the copy's entries [first, first + values.size()) of `a` differ
// from `values`, as the batch's precision holds them.
template <class T>
bool differs(const BatchArray<T>& a, int copy, int first, const Eigen::Ref<const Eigen::VectorXd>& values) {
  for (Eigen::Index k = 0; k < values.size(); ++k)
    if (a.at(copy, first + static_cast<int>(k)) != static_cast<T>(values[k])) return true;
  return false;
}

// How many copies have a nonzero count (or bit set) in `per_copy`.
template <class Count>
int copies_with_any(const std::vector<Count>& per_copy) {
  return static_cast<int>(per_copy.size()) - static_cast<int>(std::count(per_copy.begin(), per_copy.end(), 0));
}

// The per-DOF parameters a copy may hold of its own, each with the scene's
// values; entry f is bit 1 << f of Simulator::own_joint_parameters_.
enum JointParameterField : unsigned {
  kDriveStiffness = 1u << 0,
  kDriveDamping = 1u << 1,
  kDamping = 1u << 2,
  kArmature = 1u << 3,
  kFriction = 1u << 4,
  kAllJointParameters = (1u << 5) - 1,
};
template <class Batch>
auto joint_parameter_fields(Batch& b, const JointParameters& scene) {
  return std::array{std::pair{&b.drive_stiffness, &scene.drive_stiffness},
                    std::pair{&b.drive_damping, &scene.drive_damping}, std::pair{&b.joint_damping, &scene.damping},
                    std::pair{&b.armature, &scene.armature}, std::pair{&b.joint_friction, &scene.friction}};
}

// Zero joint-row impulses, no contact points: nothing to warm-start from;
// no momentum to carry; no step whose joint forces to report.
template <class T>
void clear_warm_start(StepBatch<T>& b, int copy) {
  b.impulse.fill(copy, 0);
  b.contact_id.fill(copy, -1);
  b.contact_wrench.fill(copy, 0);
  b.momentum_remainder.fill(copy, 0);
  b.motion_recorded.fill(copy, 0);
}

template <class Derived>
bool all_finite_in(Precision p, const Eigen::DenseBase<Derived>& x) {
  for (Eigen::Index i = 0; i < x.size(); ++i)
    if (!finite_in(p, x.derived().data()[i])) return false;
  return true;
}

// An enum's value among its enumerators [0, last] (an integer cast to it
// need not be).
template <class E>
bool enumerated(E value, E last) {
  return static_cast<int>(value) >= 0 && static_cast<int>(value) <= static_cast<int>(last);
}

template <class E>
std::string not_enumerated(const char* field, E value) {
  return std::string(field) + " holds " + std::to_string(static_cast<int>(value)) + ", which is none of its values";
}

// Symmetric positive semidefinite, round-off aside: asymmetry and the
// smallest eigenvalue within 1e-12 of the largest diagonal entry (or of 1).
// The smallest eigenvalue is >= -tolerance exactly when B = I + tolerance 1
// has no negative principal minor (Sylvester's criterion for semidefinite
// matrices: all seven minors, not only the three leading ones). Their
// round-off, about 1e-16 of the entries' scale, is far below the tolerance.
bool symmetric_positive_semidefinite(const Eigen::Matrix3d& inertia) {
  const double tolerance = 1e-12 * std::max(1.0, inertia.diagonal().cwiseAbs().maxCoeff());
  if ((inertia - inertia.transpose()).cwiseAbs().maxCoeff() > tolerance) return false;
  const Eigen::Matrix3d B = inertia + tolerance * Eigen::Matrix3d::Identity();
  auto minor2 = [&](int i, int j) { return B(i, i) * B(j, j) - B(i, j) * B(i, j); };
  return B.diagonal().minCoeff() >= 0 && minor2(0, 1) >= 0 && minor2(0, 2) >= 0 && minor2(1, 2) >= 0 &&
         B.determinant() >= 0;
}

// A model whose mass matrix is singular has no forward dynamics: its steps
// give NaN. Checked at the neutral configuration by an LDL^T in DOF order
// (no pivoting), where a pivot that vanishes names the first DOF whose motion
// moves no inertia the DOFs before it do not: a link with no inertia about
// its joint's axis, or a massless floating root that turns with its only
// child. Relative to the largest diagonal, 1e-12 is far below the lightest
// DOF of the bundled robots (a fingertip's 1e-6 of a hand's base) and far
// above round-off.
void check_mass_matrix(const Model& model) {
  if (model.nv == 0) return;
  const BatchDynamics<double> dynamics(model);
  const BatchState<double> state = dynamics.make_state(1);
  BatchArray<double> flat = dynamics.make_array(1, model.nv * model.nv);
  dynamics.mass_matrix(state, flat);
  const Eigen::VectorXd values = flat.get(0);
  Eigen::MatrixXd M = Eigen::Map<const Eigen::MatrixXd>(values.data(), model.nv, model.nv);
  const double scale = M.diagonal().cwiseAbs().maxCoeff();
  for (int k = 0; k < model.nv; ++k) {  // in place: M's lower triangle becomes L, its diagonal D
    for (int j = 0; j < k; ++j) M(k, k) -= M(k, j) * M(k, j) * M(j, j);
    require(M(k, k) > 1e-12 * scale, [&] {
      return "Simulator: the model's mass matrix is singular: DOF " + std::to_string(k) + " (" + model.dof_name[k] +
             ") moves no inertia of its own (a link without rotational inertia about its joint's axis, or a "
             "massless floating root that only turns with its child)";
    });
    for (int i = k + 1; i < model.nv; ++i) {
      for (int j = 0; j < k; ++j) M(i, k) -= M(i, j) * M(k, j) * M(j, j);
      M(i, k) /= M(k, k);
    }
  }
}

// The model's link damping as the step takes it, unless its stage is
// forced off: each coefficient >= 0 and, times the body's mass, finite in
// the step's precision; under the trapezoid and RK4, which take it
// explicitly, h c within their stability bound on the negative real axis
// (Heun's 2, RK4's 2.78: the damping's generalized force J^T D J is at most
// c M for the body's largest c, as D is at most c times its spatial
// inertia); and none on a floating articulation whose momentum the step
// keeps.
void validate_link_damping(const Model& model, const StepOptions& o) {
  if (o.stages[static_cast<int>(Stage::LinkDamping)] == StageMode::Off) return;
  const double h = o.dt / std::max(1, o.substeps);
  const double bound = o.integrator == Integrator::RK4 ? kRk4Bound : 2.0;
  for (int b = 0; b < model.nbody; ++b) {
    const std::string where = "link \"" + model.frame_name[model.body_frame[b]] + "\": ";
    for (const auto& [name, c] : {std::pair{"linear damping", model.body_linear_damping[b]},
                                  std::pair{"angular damping", model.body_angular_damping[b]}}) {
      require(c >= 0 && finite_in(o.precision, c * std::max(1.0, model.body_mass[b])),
              where + name + " must be >= 0 and, times the body's mass, " + finite_word(o.precision) + ", got " +
                  number_text(c));
      require(euler_velocity(o.integrator) || c * h < bound,
              where + name + " " + number_text(c) + " 1/s is taken explicitly by the " +
                  integrator_name(o.integrator) + ", stable only for dt / substeps below " + number_text(bound / c) +
                  " s (got " + number_text(h) + " s); the Eulers take it implicitly");
      require(c == 0 || !o.conserve_linear_momentum || !model.articulations[model.body_articulation[b]].floating_base,
              where + name + ": conserve_linear_momentum needs floating articulations without link damping");
    }
  }
}

// Model::mimics as the step takes them (the URDF loader checks its own;
// a caller may add or edit them): each couples two distinct DOFs of
// revolute or prismatic joints, with a multiplier and an offset finite in
// the step's precision. A DOF may follow several tags, as in PhysX.
void validate_mimics(const Model& model, const StepOptions& o) {
  auto in_range = [&](int k) { return k >= 0 && k < model.nv; };
  auto one_dof = [&](int k) {
    const JointType type = model.body_joint[model.dof_body[k]];
    return type == JointType::Revolute || type == JointType::Prismatic;
  };
  for (std::size_t i = 0; i < model.mimics.size(); ++i) {
    const Mimic& m = model.mimics[i];
    const std::string where = "Model::mimics[" + std::to_string(i) + "]: ";
    // named by Simulator::warnings whether the stage runs or not
    require(in_range(m.dof) && in_range(m.leader_dof), [&] {
      return where + "dof " + std::to_string(m.dof) + " and leader_dof " + std::to_string(m.leader_dof) +
             " must be DOFs of the model (of " + std::to_string(model.nv) + ")";
    });
    if (o.stages[static_cast<int>(Stage::MimicJoints)] == StageMode::Off) continue;
    require(one_dof(m.dof) && one_dof(m.leader_dof), [&] {
      return where + "dof " + std::to_string(m.dof) + " and leader_dof " + std::to_string(m.leader_dof) +
             " must be DOFs of revolute or prismatic joints (of " + std::to_string(model.nv) + ")";
    });
    require(m.dof != m.leader_dof, [&] { return where + model.dof_name[m.dof] + " follows itself"; });
    require(finite_in(o.precision, m.multiplier) && finite_in(o.precision, m.offset), [&] {
      return where + "multiplier and offset must be " + finite_word(o.precision) + ", got " +
             number_text(m.multiplier) + " and " + number_text(m.offset);
    });
  }
}

// Model::fixed_tendons as the step takes them: each over distinct DOFs of
// revolute or prismatic joints with nonzero coefficients, its parameters
// finite in the step's precision, its gains non-negative and its limits in
// order. Checked whether the stage runs or not, as the mimics' DOFs.
void validate_fixed_tendons(const Model& model, const StepOptions& o) {
  for (std::size_t i = 0; i < model.fixed_tendons.size(); ++i) {
    const FixedTendon& t = model.fixed_tendons[i];
    const std::string where = "Model::fixed_tendons[" + std::to_string(i) + "] ('" + t.name + "'): ";
    // named by errors, warnings and scene files, which read them back
    require(!t.name.empty(), where + "has no name");
    for (std::size_t other = 0; other < i; ++other)
      require(model.fixed_tendons[other].name != t.name,
              [&] { return where + "its name is also fixed_tendons[" + std::to_string(other) + "]'s"; });
    require(!t.joints.empty(), where + "has no joints");
    for (std::size_t j = 0; j < t.joints.size(); ++j) {
      const TendonJoint& joint = t.joints[j];
      const std::string at = where + "joints[" + std::to_string(j) + "]: ";
      require(joint.dof >= 0 && joint.dof < model.nv, [&] {
        return at + "dof " + std::to_string(joint.dof) + " must be a DOF of the model (of " + std::to_string(model.nv) +
               ")";
      });
      const JointType type = model.body_joint[model.dof_body[joint.dof]];
      require(type == JointType::Revolute || type == JointType::Prismatic, [&] {
        return at + model.dof_name[joint.dof] + " is a DOF of a " + joint_type_name(type) +
               " joint: a tendon spans revolute and prismatic joints";
      });
      // nonzero in the precision too: a float flushes 1e-46 to zero
      require(finite_in(o.precision, joint.coefficient) && std::abs(joint.coefficient) >= smallest_normal(o.precision),
              [&] {
                return at + "coefficient must be nonzero, a normal number and " + finite_word(o.precision) +
                       ", got " + number_text(joint.coefficient);
              });
      for (std::size_t other = 0; other < j; ++other)
        require(t.joints[other].dof != joint.dof,
                [&] {
                  return at + model.dof_name[joint.dof] + " appears twice (also joints[" + std::to_string(other) + "])";
                });
    }
    auto gain = [&](double x, const char* name) {
      require(finite_in(o.precision, x) && x >= 0.0,
              [&] {
                return where + name + " must be non-negative and " + finite_word(o.precision) + ", got " +
                       number_text(x);
              });
    };
    gain(t.stiffness, "stiffness");
    gain(t.damping, "damping");
    gain(t.limit_stiffness, "limit_stiffness");
    const double h = o.dt / o.substeps;
    require(compliance_finite_in(o.precision, h, t.stiffness, t.damping) &&
                compliance_finite_in(o.precision, h, t.limit_stiffness, 0.0),
            [&] {
              return where + "stiffness " + number_text(t.stiffness) + ", damping " + number_text(t.damping) +
                     " and limit_stiffness " + number_text(t.limit_stiffness) + " must each be 0 or large enough " +
                     "that h (k h + c) over the step h = " + number_text(h) + " s is a normal number in " +
                     precision_name(o.precision) + " (their compliance 1 / that would be infinite)";
            });
    require(finite_in(o.precision, t.rest_length) && finite_in(o.precision, t.offset), [&] {
      return where + "rest_length and offset must be " + finite_word(o.precision) + ", got " +
             number_text(t.rest_length) + " and " + number_text(t.offset);
    });
    // a limit may be infinite (none), not beyond the precision's range
    auto limit = [&](double x) { return !std::isnan(x) && (std::isinf(x) || finite_in(o.precision, x)); };
    require(limit(t.lower_limit) && limit(t.upper_limit) && t.lower_limit <= t.upper_limit &&
                t.lower_limit < std::numeric_limits<double>::infinity() &&
                t.upper_limit > -std::numeric_limits<double>::infinity(),
            [&] {
              return where + "lower_limit and upper_limit must be ordered, each " + finite_word(o.precision) +
                     " or infinite on its own side, got " + number_text(t.lower_limit) + " and " +
                     number_text(t.upper_limit);
            });
  }
}

void validate(const Model& model, int copies, const StepOptions& o, const std::vector<DofSettings>& dofs) {
  require(copies >= 1, "Simulator: copies must be at least 1, got " + std::to_string(copies));
  // and its substeps positive in the precision the step runs in
  require(finite_in(o.precision, o.dt) && o.dt > 0 &&
              (o.precision == Precision::Double || static_cast<float>(o.dt / std::max(1, o.substeps)) > 0),
          "StepOptions::dt must be positive and " + finite_word(o.precision) + ", got " + number_text(o.dt));
  require(o.substeps >= 1, "StepOptions::substeps must be at least 1, got " + std::to_string(o.substeps));
  require(enumerated(o.precision, Precision::Double), not_enumerated("StepOptions::precision", o.precision));
  require(enumerated(o.solver, SolverType::TGS), not_enumerated("StepOptions::solver", o.solver));
  require(enumerated(o.integrator, Integrator::ExplicitEuler), not_enumerated("StepOptions::integrator", o.integrator));
  require(enumerated(o.lanes, Lanes::Scalar), not_enumerated("StepOptions::lanes", o.lanes));
  for (int stage = 0; stage < kStageCount; ++stage)
    require(enumerated(o.stages[stage], StageMode::Off),
            not_enumerated(("StepOptions::stages[" + std::to_string(stage) + "]").c_str(), o.stages[stage]));
  require(o.iterations >= 1, "StepOptions::iterations must be at least 1, got " + std::to_string(o.iterations));
  require(o.error_reduction >= 0 && o.error_reduction <= 1,
          "StepOptions::error_reduction must lie in [0, 1], got " + number_text(o.error_reduction));
  require(o.warm_start >= 0 && o.warm_start <= 1,
          "StepOptions::warm_start must lie in [0, 1], got " + number_text(o.warm_start));
  require(!o.conserve_linear_momentum || o.integrator == Integrator::SemiImplicitEuler,
          "StepOptions::conserve_linear_momentum needs the semi-implicit Euler integrator");
  validate_link_damping(model, o);
  validate_mimics(model, o);
  validate_fixed_tendons(model, o);
  // a compliant contact's spring-damper is a compliant row, as a tendon's
  require(o.contacts.stiffness == 0 ||
              compliance_finite_in(o.precision, o.dt / o.substeps, o.contacts.stiffness, o.contacts.damping),
          [&] {
            return "ContactSettings::stiffness " + number_text(o.contacts.stiffness) + " N/m and damping " +
                   number_text(o.contacts.damping) + " N s/m are too small for " + precision_name(o.precision) +
                   ": h (k h + c) over the step h = " + number_text(o.dt / o.substeps) +
                   " s must be a normal number (the compliance 1 / that would be infinite; stiffness 0 is rigid)";
          });
  // every copy starts with these: beyond the precision's range each would fault
  require(!o.contacts.ground || finite_in(o.precision, o.contacts.ground_height), [&] {
    return "ContactSettings::ground_height must be " + finite_word(o.precision) + ", got " +
           number_text(o.contacts.ground_height);
  });
  require(all_finite_in(o.precision, model.gravity), [&] {
    return "Model::gravity must be " + finite_word(o.precision) + ", got (" + number_text(model.gravity.x()) + ", " +
           number_text(model.gravity.y()) + ", " + number_text(model.gravity.z()) + ")";
  });
  // a model loads in double: its bodies' inertias, placements and armature
  // must fit the step's precision too, as set_body_inertia requires
  for (int b = 0; b < model.nbody; ++b)
    require(finite_in(o.precision, model.body_mass[b]) && all_finite_in(o.precision, model.body_com[b]) &&
                all_finite_in(o.precision, model.body_inertia[b]) &&
                all_finite_in(o.precision, model.body_placement[b].matrix()),
            [&] {
              return "body " + std::to_string(b) + " (" + model.frame_name[model.body_frame[b]] +
                     "): its mass, centre of mass, inertia and joint placement must be " + finite_word(o.precision);
            });
  for (int f = 0; f < static_cast<int>(model.frame_placement.size()); ++f)
    require(all_finite_in(o.precision, model.frame_placement[f].matrix()), [&] {
      return "frame " + std::to_string(f) + " (" + model.frame_name[f] + "): its placement must be " +
             finite_word(o.precision);
    });
  for (int k = 0; k < model.nv; ++k)
    require(finite_in(o.precision, model.dof_armature[k]), [&] {
      return "DOF " + std::to_string(k) + " (" + model.dof_name[k] + "): its armature must be " +
             finite_word(o.precision);
    });
  require(static_cast<int>(dofs.size()) == model.nv, "Simulator: " + std::to_string(dofs.size()) +
                                                         " DOF settings for a model with " + std::to_string(model.nv) +
                                                         " DOFs");
  for (int k = 0; k < model.nv; ++k) {
    const DofSettings& d = dofs[k];
    const std::string where = "DOF " + std::to_string(k) + " (" + model.dof_name[k] + "): ";
    const JointType type = model.body_joint[model.dof_body[k]];
    const bool one_dof = type == JointType::Revolute || type == JointType::Prismatic;
    auto non_negative = [&](double x, const char* name) {
      require(finite_in(o.precision, x) && x >= 0,
              where + name + " must be " + finite_word(o.precision) + " and >= 0, got " + number_text(x));
    };
    non_negative(d.drive_stiffness, "drive_stiffness");
    non_negative(d.drive_damping, "drive_damping");
    non_negative(d.damping, "damping");
    non_negative(d.spring_stiffness, "spring_stiffness");
    non_negative(d.friction, "friction");
    non_negative(d.stiction_extra, "stiction_extra");
    non_negative(d.stribeck_velocity, "stribeck_velocity");
    non_negative(d.limit_stiffness, "limit_stiffness");
    non_negative(d.limit_damping, "limit_damping");
    require(finite_in(o.precision, d.falloff_velocity) && d.falloff_velocity > 0,
            where + "falloff_velocity must be positive, got " + number_text(d.falloff_velocity));
    require(d.max_force > 0, where + "max_force must be positive (+inf for none), got " + number_text(d.max_force));
    require(d.velocity_limit > 0,
            where + "velocity_limit must be positive (+inf for none), got " + number_text(d.velocity_limit));
    require(finite_in(o.precision, d.spring_rest), where + "spring_rest must be " + finite_word(o.precision));
    require(!std::isnan(d.lower) && !std::isnan(d.upper), where + "lower and upper limits must be numbers (+-inf for none)");
    require(!(d.lower > d.upper), where + "lower limit " + number_text(d.lower) + " above upper " +
                                      number_text(d.upper));
    require(d.lower < Model::kInfinity && d.upper > -Model::kInfinity,
            where + "a lower limit of +inf or an upper one of -inf leaves no range (-inf and +inf are none)");
    require(enumerated(d.drive_type, DriveType::Acceleration), where + not_enumerated("drive_type", d.drive_type));
    require(enumerated(d.friction_model, FrictionModel::Stribeck),
            where + not_enumerated("friction_model", d.friction_model));
    if (type == JointType::Free)
      require(d.drive_stiffness == 0 && d.drive_damping == 0,
              where + "a floating base takes no drive (set the gains of its 6 DOFs to 0)");
    if (type == JointType::Free && o.conserve_linear_momentum)
      require(d.damping == 0 && model.dof_armature[k] == 0,
              where + "conserve_linear_momentum needs a floating base without damping or armature");
    if (!one_dof) {
      require(d.spring_stiffness == 0, where + "springs act on revolute and prismatic joints only");
      const bool limited = !std::isinf(d.lower) || !std::isinf(d.upper);
      require(!limited || type == JointType::Spherical, where + "a floating base takes no position limits (got " +
                                                            number_text(d.lower) + " to " + number_text(d.upper) + ")");
      require(d.friction == 0 || type == JointType::Spherical,
              where + "friction acts on revolute, prismatic and spherical joints only");
      require(d.friction == 0 || d.friction_model == FrictionModel::Coulomb,
              where + "Stribeck friction acts on revolute and prismatic joints only (a spherical joint takes Coulomb)");
    }
  }
  // A spherical joint's limits bound the components of its rotation vector
  // r = log(q), taken the shorter way round: r jumps to the other side
  // where |r| reaches pi, and a limit there would push the joint by that
  // jump (an unlimited DOF lets |r| get there). So all three DOFs are
  // limited on both sides, the box within |r| < pi.
  for (int b = 0; b < model.nbody; ++b) {
    if (model.body_joint[b] != JointType::Spherical) continue;
    const int k0 = model.body_dof_offset[b];
    bool limited = false, closed = true;
    double corner = 0;
    for (int k = k0; k < k0 + 3; ++k) {
      limited = limited || !std::isinf(dofs[k].lower) || !std::isinf(dofs[k].upper);
      closed = closed && std::isfinite(dofs[k].lower) && std::isfinite(dofs[k].upper);
      if (closed) corner += std::pow(std::max(std::abs(dofs[k].lower), std::abs(dofs[k].upper)), 2);
    }
    if (!limited) continue;
    const std::string where = "DOFs " + std::to_string(k0) + "-" + std::to_string(k0 + 2) + " (spherical joint " +
                              model.joint_name[b] + "): ";
    require(closed, where + "limits on a spherical joint need all three DOFs limited on both sides: they bound the "
                            "components of its rotation vector, which jumps where |r| reaches pi");
    require(std::sqrt(corner) < EIGEN_PI,
            where + "the limits' box reaches |r| = " + number_text(std::sqrt(corner)) +
                "; it must stay within pi, where the joint's rotation vector jumps to the other side");
  }
}

// Whether the scene needs a stage, and what was found, into a decision.
StageDecision decide_found(Stage stage, StageMode mode, bool needed, const std::string& found) {
  StageDecision d{stage, false, ""};
  switch (mode) {
    case StageMode::Auto:
      d.runs = needed;
      d.reason = found;
      break;
    case StageMode::On:
      d.runs = true;
      d.reason = "forced on (" + found + ")";
      break;
    case StageMode::Off:
      d.runs = false;
      d.reason = "forced off (" + found + ")";
      break;
  }
  return d;
}

// Counts DOFs (pairs, copies) with a property and turns the count into a
// decision; `also`, when not empty, is a further reason the stage is needed.
StageDecision decide(Stage stage, StageMode mode, int count, const std::string& what, const std::string& also = "") {
  const std::string found = (count > 0 ? std::to_string(count) + " " + what : "no " + what) +
                            (also.empty() ? "" : ", and " + also);
  return decide_found(stage, mode, count > 0 || !also.empty(), found);
}

}  // namespace

// The bulk readouts' arrays for every copy, kept from their first call.
struct Simulator::MotionScratch {
  MotionScratch(const Model& model, int copies)
      : dynamics(model), state(dynamics.make_state(copies)), poses(dynamics.make_array(copies, 12 * model.nbody)),
        forces(dynamics.make_array(copies, 6 * model.nbody)),
        frames(dynamics.make_array(copies, 6 * static_cast<int>(model.frame_name.size()))) {}
  BatchDynamics<lane::simd<double>> dynamics;
  BatchState<double> state;
  BatchArray<double> poses, forces, frames;
  std::vector<char> recorded;
};

Simulator::Simulator(const Model& model, int copies, const StepOptions& options, std::vector<DofSettings> dofs,
                     HeaderBuild caller)
    : header_check_(caller),
      model_(&model),
      options_(options),
      dofs_(dofs.empty() ? default_dof_settings(model) : std::move(dofs)) {
  validate(model, copies, options_, dofs_);
  validate_actuators(model, options_.actuators, options_.precision);
  check_mass_matrix(model);
  validate_contact_settings(model, options_.contacts);
  pairs_ = build_contact_pairs(model, options_.contacts);
  own_inertia_bodies_.assign(copies, 0);
  own_joint_parameters_.assign(copies, 0);
  // as the step holds them: rounded to its precision
  model_inertia_ = BatchState<double>::model_inertia_params(model);
  if (options_.precision == Precision::Float) model_inertia_ = model_inertia_.cast<float>().cast<double>();
  joint_parameters_ = scene_joint_parameters(model, dofs_);
  make_plan();
  const StepPlan plan = step_plan();
  if (options_.integrator == Integrator::RK4 &&
      (plan.mimic_joints || plan.fixed_tendons || plan.hard_limits || plan.velocity_limits || plan.coulomb_friction ||
       plan.contacts))
    throw std::invalid_argument(
        "StepOptions::integrator RK4 integrates scenes without solver rows, and this scene has " + rows_summary() +
        ": use SemiImplicitEuler, Trapezoid or ExplicitEuler, or force those stages off");
  auto start = [&](auto engine) {  // the engine, and where its batch lives
    if constexpr (std::is_same_v<std::decay_t<decltype(engine->batch())>, StepBatch<float>>)
      float_batch_ = &engine->batch();
    else
      double_batch_ = &engine->batch();
    engine_ = std::move(engine);
  };
  const bool simd = options_.lanes == Lanes::Simd;
  if (options_.precision == Precision::Float) {
    if (simd) start(std::make_unique<StepEngine<lane::simd<float>>>(model, copies, options_, dofs_, plan, pairs_));
    else start(std::make_unique<StepEngine<float>>(model, copies, options_, dofs_, plan, pairs_));
  } else {
    if (simd) start(std::make_unique<StepEngine<lane::simd<double>>>(model, copies, options_, dofs_, plan, pairs_));
    else start(std::make_unique<StepEngine<double>>(model, copies, options_, dofs_, plan, pairs_));
  }
  scene_key_ = scene_key_of(model, engine_->row_layout(), pairs_, options_.actuators);
}

Simulator::~Simulator() = default;
Simulator::Simulator(Simulator&&) noexcept = default;
Simulator& Simulator::operator=(Simulator&&) noexcept = default;

Simulator::Engine& Simulator::engine() const {
  if (!engine_) throw std::logic_error("Simulator: used after it was moved from (assign another to it first)");
  return *engine_;
}

int Simulator::copies() const { return engine().copies(); }
void Simulator::set_profiling(bool on) { engine().set_profiling(on); }
StepProfile Simulator::profile() const { return engine().profile(); }
int Simulator::row_count() const { return engine().rows(); }
std::size_t Simulator::bytes_per_copy() const {
  return engine().bytes_per_copy() + sizeof(own_inertia_bodies_[0]) + sizeof(own_joint_parameters_[0]);
}

void Simulator::make_plan() const {
  int drives = 0, damping = 0, springs = 0, soft = 0, stribeck = 0, hard = 0, velocity = 0, coulomb = 0;
  for (int k = 0; k < model_->nv; ++k) {
    const DofSettings& d = dofs_[k];
    const JointType type = model_->body_joint[model_->dof_body[k]];
    const bool one_dof = type == JointType::Revolute || type == JointType::Prismatic;
    const bool limited = (one_dof || type == JointType::Spherical) && (std::isfinite(d.lower) || std::isfinite(d.upper));
    drives += d.drive_stiffness > 0 || d.drive_damping > 0;
    damping += d.damping > 0;
    springs += d.spring_stiffness > 0;
    soft += limited && d.limit_stiffness > 0;
    hard += limited && d.limit_stiffness == 0;
    velocity += std::isfinite(d.velocity_limit);
    stribeck += d.friction > 0 && d.friction_model == FrictionModel::Stribeck && one_dof;
    coulomb += d.friction > 0 && d.friction_model == FrictionModel::Coulomb;
  }
  // a tendon without a spring or a limit has no rows
  const int acting_tendons = static_cast<int>(
      std::count_if(model_->fixed_tendons.begin(), model_->fixed_tendons.end(),
                    [](const FixedTendon& t) { return t.has_spring() || t.has_limits(); }));
  auto mode = [&](Stage s) { return options_.stages[static_cast<int>(s)]; };
  plan_ = {
      decide(Stage::Drives, mode(Stage::Drives), drives, "DOFs with drive gains",
             per_copy_gains_ ? "copies given gains by set_drive_gains" : ""),
      decide(Stage::Damping, mode(Stage::Damping), damping, "DOFs with damping",
             per_copy_damping_ ? "copies given damping by set_joint_damping" : ""),
      decide(Stage::Springs, mode(Stage::Springs), springs, "DOFs with springs"),
      decide(Stage::SoftLimits, mode(Stage::SoftLimits), soft, "DOFs with spring-damper limits"),
      decide(Stage::StribeckFriction, mode(Stage::StribeckFriction), stribeck, "DOFs with Stribeck friction"),
      decide_found(Stage::ExternalWrenches, mode(Stage::ExternalWrenches), wrenches_used_,
                   wrenches_used_ ? "set_link_wrench called" : "no calls of set_link_wrench"),
      decide(Stage::LinkDamping, mode(Stage::LinkDamping), model_->damped_bodies(), "bodies with link damping"),
      decide(Stage::PerCopyInertia, mode(Stage::PerCopyInertia), copies_with_any(own_inertia_bodies_),
             "copies with their own inertial parameters"),
      decide(Stage::PerCopyJointParameters, mode(Stage::PerCopyJointParameters), copies_with_any(own_joint_parameters_),
             "copies with their own drive gains, damping, armature or joint friction"),
      decide(Stage::MimicJoints, mode(Stage::MimicJoints), static_cast<int>(model_->mimics.size()), "mimic tags"),
      decide(Stage::FixedTendons, mode(Stage::FixedTendons), acting_tendons, "fixed tendons with a spring or limits"),
      decide(Stage::HardLimits, mode(Stage::HardLimits), hard, "DOFs with hard position limits"),
      decide(Stage::VelocityLimits, mode(Stage::VelocityLimits), velocity, "DOFs with velocity limits"),
      decide(Stage::CoulombFriction, mode(Stage::CoulombFriction), coulomb, "DOFs with Coulomb friction"),
      decide(Stage::Contacts, mode(Stage::Contacts), static_cast<int>(pairs_.pairs.size()), "candidate shape pairs"),
  };
}

StepPlan Simulator::step_plan() const {
  auto runs = [&](Stage s) { return plan_[static_cast<int>(s)].runs; };
  StepPlan p;
  p.drives = runs(Stage::Drives);
  p.damping = runs(Stage::Damping);
  p.springs = runs(Stage::Springs);
  p.soft_limits = runs(Stage::SoftLimits);
  p.stribeck = runs(Stage::StribeckFriction);
  p.wrenches = runs(Stage::ExternalWrenches);
  p.link_damping = runs(Stage::LinkDamping);
  p.per_copy_inertia = runs(Stage::PerCopyInertia);
  p.per_copy_joint_parameters = runs(Stage::PerCopyJointParameters);
  p.mimic_joints = runs(Stage::MimicJoints);
  p.fixed_tendons = runs(Stage::FixedTendons);
  p.hard_limits = runs(Stage::HardLimits);
  p.velocity_limits = runs(Stage::VelocityLimits);
  p.coulomb_friction = runs(Stage::CoulombFriction);
  p.contacts = runs(Stage::Contacts);
  return p;
}

std::string Simulator::rows_summary() const {
  std::string out;
  for (Stage s : {Stage::MimicJoints, Stage::FixedTendons, Stage::HardLimits, Stage::VelocityLimits,
                  Stage::CoulombFriction, Stage::Contacts}) {
    const StageDecision& d = plan_[static_cast<int>(s)];
    if (!d.runs) continue;
    if (!out.empty()) out += ", ";
    out += std::string(stage_name(s)) + " (" + d.reason + ")";
  }
  return out;
}

std::string Simulator::describe_plan() const {
  refresh_plan();
  std::ostringstream out;
  out << "step: dt " << options_.dt << " s, " << options_.substeps << " substep(s), " << integrator_name(options_.integrator)
      << ", " << solver_name(options_.solver) << " x " << options_.iterations << ", " << precision_name(options_.precision)
      << (options_.lanes == Lanes::Simd ? " SIMD lanes" : " scalar lanes") << "\n";
  out << "  kinematics and ABA with gravity: always";
  const auto weightless = model_->links_without_gravity().size();
  if (weightless > 0) out << " (switched off on " << weightless << " of " << model_->nbody << " bodies)";
  out << "\n";
  if (!options_.actuators.empty()) {
    const auto enforced = std::count_if(options_.actuators.begin(), options_.actuators.end(),
                                        [](const Actuator& a) { return a.enforce_operating_region; });
    out << "  actuators: " << options_.actuators.size() << " (" << enforced
        << " within their motors' operating regions)\n";
  }
  for (const StageDecision& d : plan_)
    out << "  " << stage_name(d.stage) << ": " << (d.runs ? "runs" : "skipped") << " (" << d.reason << ")\n";
  const bool contacts = contacts_found();
  for (const std::string& warning : warnings()) out << "  " << warning << "\n";
  const int per_contact = options_.contacts.torsional_friction > 0 ? 4 : 3;
  out << "  solver: ";
  if (row_count() == 0 && !contacts) out << "skipped (no rows)";
  else out << "runs on " << row_count() << " joint rows per copy";
  if (contacts)
    out << " and " << per_contact << " rows per contact point, up to " << options_.contacts.capacity << " points";
  out << "\n";
  if (options_.conserve_linear_momentum) {
    const auto floating = std::count_if(model_->articulations.begin(), model_->articulations.end(),
                                        [](const Articulation& a) { return a.floating_base; });
    out << "  linear momentum projection: " << (floating > 0 ? "runs" : "skipped") << " (" << floating
        << " floating articulations)\n";
  }
  out << "  fault check: always\n";
  return out.str();
}

std::vector<StiffDrive> Simulator::stiff_drives() const {
  refresh_plan();
  // a drive stiff enough to act as a hard constraint matters beside other ones
  auto runs = [&](Stage stage) { return plan_[static_cast<int>(stage)].runs; };
  const bool hard =
      runs(Stage::MimicJoints) || runs(Stage::FixedTendons) || runs(Stage::HardLimits) || runs(Stage::VelocityLimits) ||
      contacts_found();
  if (!runs(Stage::Drives) || !hard || copies() == 0) return {};
  return lockstep::stiff_drives(*model_, dofs_, q(0), options_.dt / options_.substeps);
}

std::vector<std::string> Simulator::warnings() const {
  refresh_plan();
  std::vector<std::string> lines;
  std::string fast_modes;
  if (!euler_velocity(options_.integrator) && copies() > 0) {
    const double bound = options_.integrator == Integrator::RK4 ? kRk4Bound : kTrapezoidRingBound;
    fast_modes = describe_fast_joint_modes(
        *model_,
        fast_joint_modes(*model_, dofs_, q(0), options_.dt / options_.substeps, bound,
                         options_.integrator == Integrator::RK4 && plan_[static_cast<int>(Stage::LinkDamping)].runs),
        options_.integrator);
  }
  std::string actuators;
  if (!options_.actuators.empty() && copies() > 0) {
    const double bound = options_.integrator == Integrator::RK4 ? kRk4Bound : kExplicitDampingBound;
    actuators = describe_fast_actuators(
        options_.actuators, fast_actuators(*model_, dofs_, options_.actuators, q(0), options_.dt / options_.substeps, bound),
        bound);
  }
  for (std::string line : {describe_stiff_drives(*model_, stiff_drives(), options_.substeps), fast_modes, actuators,
                           unenforced_mimics(), unenforced_tendons()})
    if (!line.empty()) lines.push_back(std::move(line));
  lines.insert(lines.end(), pairs_.notes.begin(), pairs_.notes.end());
  return lines;
}

std::string Simulator::unenforced_mimics() const {
  const std::vector<Mimic>& mimics = model_->mimics;
  if (mimics.empty() || plan_[static_cast<int>(Stage::MimicJoints)].runs) return {};
  const Mimic& first = mimics.front();
  return "mimic joints: not enforced, their stage forced off (" + std::to_string(mimics.size()) +
         " mimic tag(s), such as " + model_->dof_name[first.dof] + " following " +
         model_->dof_name[first.leader_dof] + "; each DOF moves on its own)";
}

std::string Simulator::unenforced_tendons() const {
  const std::vector<FixedTendon>& tendons = model_->fixed_tendons;
  if (tendons.empty() || options_.stages[static_cast<int>(Stage::FixedTendons)] != StageMode::Off) return {};
  return "fixed tendons: not enforced, their stage forced off (" + std::to_string(tendons.size()) +
         " tendon(s), such as '" + tendons.front().name + "'; their joints move on their own)";
}

void Simulator::refresh_plan() const {
  if (!plan_stale_) return;
  make_plan();
  engine().set_plan(step_plan());
  plan_stale_ = false;
}

// The contacts' decision depends on the options and the shape pairs only, so
// a stale plan holds it too.
bool Simulator::contacts_run() const { return plan_[static_cast<int>(Stage::Contacts)].runs; }

bool Simulator::contacts_found() const { return contacts_run() && !pairs_.pairs.empty(); }

const std::vector<StageDecision>& Simulator::plan() const {
  refresh_plan();
  return plan_;
}

void Simulator::step(int n) {
  require(n >= 0, [&] { return "Simulator::step: the number of steps must be >= 0, got " + std::to_string(n); });
  if (n == 0) return;
  refresh_plan();
  engine().step(n, options_.substeps, options_.dt);
  for (int i = 0; i < n; ++i) time_ += options_.dt;  // summed as n calls would, not n * dt
}

void Simulator::check_copy(int copy, const char* function) const {
  require_copy_index(copy, copies(), "Simulator", function);
}

template <class T>
StepBatch<T>& Simulator::batch() {
  return const_cast<StepBatch<T>&>(static_cast<const Simulator*>(this)->batch<T>());
}

template <class T>
const StepBatch<T>& Simulator::batch() const {
  engine();  // throws once moved from: the batch pointers went with the engine
  const StepBatch<T>* b;
  if constexpr (std::is_same_v<T, float>) b = float_batch_;
  else b = double_batch_;
  if (b) return *b;
  throw std::logic_error(std::string("Simulator::batch<") + (sizeof(T) == 4 ? "float" : "double") +
                         ">: the simulator runs in " + precision_name(options_.precision));
}

template StepBatch<float>& Simulator::batch<float>();
template StepBatch<double>& Simulator::batch<double>();
template const StepBatch<float>& Simulator::batch<float>() const;
template const StepBatch<double>& Simulator::batch<double>() const;

// Runs f(batch) on the batch of the chosen precision.
template <class F>
decltype(auto) Simulator::visit(F&& f) const {
  if (options_.precision == Precision::Float) return f(const_cast<Simulator*>(this)->batch<float>());
  return f(const_cast<Simulator*>(this)->batch<double>());
}

Eigen::VectorXd Simulator::q(int copy) const {
  check_copy(copy, "q");
  return visit([&](auto& b) { return b.state.q.get(copy); });
}

Eigen::VectorXd Simulator::v(int copy) const {
  check_copy(copy, "v");
  return visit([&](auto& b) { return b.state.v.get(copy); });
}

void Simulator::checked_configuration(const Eigen::VectorXd& q, const char* what, Eigen::VectorXd& out) const {
  require(q.size() == model_->nq, [&] {
    return std::string(what) + ": expected " + std::to_string(model_->nq) + " values, got " + std::to_string(q.size());
  });
  out = q;  // no allocation once out has nq entries
  for (int i = 0; i < q.size(); ++i)
    require(finite_in(options_.precision, q[i]), [&] {
      return std::string(what) + ": entry " + std::to_string(i) + " is not " + finite_word(options_.precision);
    });
  normalize_quaternions(out, what, true);
}

void Simulator::normalize_quaternions(Eigen::VectorXd& q, const char* what, bool free_joints) const {
  for (int b = 0; b < model_->nbody; ++b) {
    const JointType type = model_->body_joint[b];
    if (type != JointType::Spherical && !(free_joints && type == JointType::Free)) continue;
    const int at = model_->body_q_offset[b] + (type == JointType::Free ? 3 : 0);
    const double norm = q.segment<4>(at).norm();
    if (!std::isfinite(norm)) continue;  // a drive target's: it faults its copy in the step
    require(norm > 1e-9,
            [&] { return std::string(what) + ": the quaternion of joint " + model_->joint_name[b] + " is zero"; });
    q.segment<4>(at) /= norm;
  }
}

void Simulator::check_velocity(const Eigen::VectorXd& v, const char* what) const {
  require(v.size() == model_->nv, [&] {
    return std::string(what) + ": expected " + std::to_string(model_->nv) + " values, got " + std::to_string(v.size());
  });
}

void Simulator::set_state(int copy, const Eigen::VectorXd& q, const Eigen::VectorXd& v) {
  check_copy(copy, "set_state");
  Eigen::VectorXd& qn = configuration_;
  checked_configuration(q, "set_state q", qn);
  check_velocity(v, "set_state v");
  for (int k = 0; k < v.size(); ++k)
    require(finite_in(options_.precision, v[k]), [&] {
      return "set_state v: entry " + std::to_string(k) + " is not " + finite_word(options_.precision);
    });
  visit([&](auto& b) {
    b.state.q.set(copy, qn);
    b.state.v.set(copy, v);
    b.initial_q.set(copy, qn);
    b.initial_v.set(copy, v);
    clear_warm_start(b, copy);
  });
}

namespace {

// The per-copy inputs and parameters a snapshot carries, in its order.
template <class Batch>
auto copy_parameters(Batch& b) {
  return std::array{&b.state.tau, &b.state.wrench, &b.state.inertia, &b.state.gravity, &b.target_q, &b.target_v,
                    &b.drive_stiffness, &b.drive_damping, &b.joint_damping, &b.armature, &b.joint_friction, &b.ground,
                    &b.ground_friction, &b.initial_q, &b.initial_v, &b.fault, &b.actuator_command, &b.actuator_state,
                    &b.actuator_strength};
}

// What Simulator::contacts and contact_overflow report of a copy's last
// step beside its warm start, in the snapshot's order (empty without
// contacts).
template <class Batch>
auto contact_report(Batch& b) {
  return std::array{&b.contact_point, &b.contact_normal, &b.contact_separation, &b.contact_count, &b.contact_dropped,
                    &b.contact_overflow_steps};
}

// applied_torque()'s sources of a copy's last step (empty arrays without
// StepOptions::record_applied_torque).
template <class Batch>
auto applied_torque_report(Batch& b) {
  return std::array{&b.applied_drive, &b.applied_passive, &b.applied_friction, &b.applied_limits,
                    &b.applied_actuation};
}

// The motion of a copy's last step that incoming_joint_forces() and
// link_accelerations() read (empty arrays without StepOptions::record_motion).
template <class Batch>
auto recorded_motion(Batch& b) {
  return std::array{&b.motion_q, &b.motion_v, &b.motion_acceleration, &b.motion_unbalanced, &b.motion_recorded};
}

template <class Arrays>
int packed_size(const Arrays& arrays) {
  int size = 0;
  for (const auto* a : arrays) size += a->size();
  return size;
}

// One copy's entries of several arrays, one after the other.
template <class Arrays>
Eigen::VectorXd pack(const Arrays& arrays, int copy) {
  Eigen::VectorXd packed(packed_size(arrays));
  int at = 0;
  for (const auto* a : arrays) {
    packed.segment(at, a->size()) = a->get(copy);
    at += a->size();
  }
  return packed;
}

// The entries of `array`, one of `arrays`, in a packed copy of them.
template <class Arrays, class Array>
Eigen::VectorXd packed_entries(const Eigen::VectorXd& packed, const Arrays& arrays, const Array* array) {
  int at = 0;
  for (const auto* a : arrays) {
    if (a == array) return packed.segment(at, a->size());
    at += a->size();
  }
  return {};
}

template <class Arrays>
void unpack(const Eigen::VectorXd& packed, int copy, const Arrays& arrays) {
  int at = 0;
  for (auto* a : arrays) {
    a->set(copy, packed.segment(at, a->size()));
    at += a->size();
  }
}

}  // namespace

CopySnapshot Simulator::snapshot(int copy) const {
  check_copy(copy, "snapshot");
  return visit([&](auto& b) {
    return CopySnapshot{b.state.q.get(copy),
                        b.state.v.get(copy),
                        b.impulse.get(copy),
                        b.contact_id.get(copy),
                        b.contact_impulse.get(copy),
                        b.momentum_remainder.get(copy),
                        pack(copy_parameters(b), copy),
                        pack(contact_report(b), copy),
                        b.contact_wrench.get(copy),
                        pack(applied_torque_report(b), copy),
                        pack(recorded_motion(b), copy),
                        scene_key_};
  });
}

void Simulator::restore(int copy, const CopySnapshot& s) {
  check_copy(copy, "restore");
  visit([&](auto& b) {
    // first: it names what differs, where the sizes below only say that they do
    require(s.scene_key == 0 || s.scene_key == scene_key_,
            "restore: the snapshot was taken from another scene (its model's joints or links, its joint rows, "
            "its contact pairs or its actuators differ from this simulator's)");
    require(s.q.size() == model_->nq && s.v.size() == model_->nv && s.joint_impulse.size() == b.impulse.size() &&
                s.contact_id.size() == b.contact_id.size() && s.contact_impulse.size() == b.contact_impulse.size() &&
                (s.momentum_remainder.size() == b.momentum_remainder.size() || s.momentum_remainder.size() == 0 ||
                 b.momentum_remainder.size() == 0),
            "restore: the snapshot's sizes do not match this simulator's scene");
    require(s.parameters.size() == packed_size(copy_parameters(b)),
            "restore: the snapshot's parameters do not match this simulator's scene");
    require(s.contact_report.size() == packed_size(contact_report(b)),
            "restore: the snapshot's contact report does not match this simulator's scene");
    require(s.applied_torque.size() == packed_size(applied_torque_report(b)),
            "restore: the snapshot's applied torques do not match this simulator's record_applied_torque");
    require(s.recorded_motion.size() == packed_size(recorded_motion(b)),
            "restore: the snapshot's recorded motion does not match this simulator's record_motion");
    // What the setters would refuse, refused here too: a snapshot may be
    // put together by hand (scene_key 0) or come from a simulator without
    // the momentum projection, and its values index arrays (contact ids)
    // or divide (masses) in the step and the readouts.
    auto entries = [&](const auto* array) { return packed_entries(s.parameters, copy_parameters(b), array); };
    const std::pair<const std::decay_t<decltype(b.drive_stiffness)>*, const char*> per_dof[] = {
        {&b.drive_stiffness, "restore: the snapshot's drive stiffness"},
        {&b.drive_damping, "restore: the snapshot's drive damping"},
        {&b.joint_damping, "restore: the snapshot's joint damping"},
        {&b.armature, "restore: the snapshot's armature"},
        {&b.joint_friction, "restore: the snapshot's joint friction"}};
    for (const auto& [array, what] : per_dof) check_per_dof(entries(array), what);
    check_free_of_floating_bases(entries(&b.joint_damping), "restore: the snapshot's joint damping");
    check_free_of_floating_bases(entries(&b.armature), "restore: the snapshot's armature");
    const Eigen::VectorXd inertia = entries(&b.state.inertia);
    constexpr int n = BatchState<double>::kInertiaParams;
    for (int body = 0; body < model_->nbody; ++body) {
      const double* x = inertia.data() + n * body;
      check_body_inertia(body, x[0], Eigen::Vector3d(x[1], x[2], x[3]), BatchState<double>::rotational_inertia(x),
                         "restore: the snapshot");
    }
    const double fault = entries(&b.fault)[0];
    require(fault >= 0 && fault <= static_cast<double>(Fault::NonFiniteState) && fault == std::floor(fault),
            "restore: the snapshot's fault code " + number_text(fault) + " is none of Fault's values");
    // each contact slot holds a candidate of this scene's pairs, or none
    // (-1) after the last one used
    bool ended = false;
    for (Eigen::Index i = 0; i < s.contact_id.size(); ++i) {
      const double id = s.contact_id[i];
      const bool none = id == -1;
      require((none || (id >= 0 && id < pairs_.candidates && id == std::floor(id))) && !(ended && !none), [&] {
        return "restore: the snapshot's contact slot " + std::to_string(i) + " holds " + number_text(id) +
               ", not a candidate of this scene's " + std::to_string(pairs_.candidates) + " (or -1 after the last)";
      });
      ended = ended || none;
    }
    unpack(s.parameters, copy, copy_parameters(b));
    unpack(s.contact_report, copy, contact_report(b));
    unpack(s.applied_torque, copy, applied_torque_report(b));
    unpack(s.recorded_motion, copy, recorded_motion(b));
    b.state.q.set(copy, s.q);
    b.state.v.set(copy, s.v);
    b.impulse.set(copy, s.joint_impulse);
    b.contact_id.set(copy, s.contact_id);
    b.contact_impulse.set(copy, s.contact_impulse);
    // none to carry where either side steps without the momentum projection
    if (s.momentum_remainder.size() == b.momentum_remainder.size()) b.momentum_remainder.set(copy, s.momentum_remainder);
    else b.momentum_remainder.fill(copy, 0);
    // a snapshot of one run per step has only its points: their wrench is the next step's
    if (s.contact_wrench.size() == b.contact_wrench.size()) b.contact_wrench.set(copy, s.contact_wrench);
    else b.contact_wrench.fill(copy, 0);
  });
  note_copy_inputs(copy);
  // the restored copy may carry parameters of its own, or the scene's again
  count_own_inertia(copy);
  note_own_joint_parameters(copy, kAllJointParameters);
}

void Simulator::note_copy_inputs(int copy) {
  bool changed = false;
  visit([&](auto& b) {
    auto nonzero = [&](const auto& a) { return a.any_nonzero(copy); };
    if (!per_copy_gains_ && (nonzero(b.drive_stiffness) || nonzero(b.drive_damping))) per_copy_gains_ = changed = true;
    if (!per_copy_damping_ && nonzero(b.joint_damping)) per_copy_damping_ = changed = true;
    if (!wrenches_used_ && nonzero(b.state.wrench)) wrenches_used_ = changed = true;
  });
  if (changed) invalidate_plan();
}

void Simulator::set_state_all(const Eigen::VectorXd& q, const Eigen::VectorXd& v) {
  for (int c = 0; c < copies(); ++c) set_state(c, q, v);
}

void Simulator::set_torque(int copy, const Eigen::VectorXd& tau) {
  check_copy(copy, "set_torque");
  check_velocity(tau, "set_torque");
  visit([&](auto& b) { b.state.tau.set(copy, tau); });
}

void Simulator::check_per_actuator(const Eigen::VectorXd& values, const char* what) const {
  const auto count = static_cast<Eigen::Index>(options_.actuators.size());
  require(values.size() == count, [&] {
    return std::string(what) + ": expects " + std::to_string(count) + " values (one per actuator), got " +
           std::to_string(values.size());
  });
}

void Simulator::set_actuator_torques(int copy, const Eigen::VectorXd& torques) {
  check_copy(copy, "set_actuator_torques");
  check_per_actuator(torques, "set_actuator_torques");
  visit([&](auto& b) { b.actuator_command.set(copy, torques); });
}

Eigen::VectorXd Simulator::actuator_torques(int copy) const {
  check_copy(copy, "actuator_torques");
  return visit([&](auto& b) { return Eigen::VectorXd(b.actuator_command.get(copy)); });
}

void Simulator::set_actuator_strength(int copy, const Eigen::VectorXd& strength) {
  check_copy(copy, "set_actuator_strength");
  check_per_actuator(strength, "set_actuator_strength");
  for (Eigen::Index a = 0; a < strength.size(); ++a)
    require(finite_in(options_.precision, strength[a]) && strength[a] > 0, [&] {
      return "set_actuator_strength: actuator " + std::to_string(a) + " (" + options_.actuators[a].name +
             "): the strength must be " + finite_word(options_.precision) + " and > 0, got " + number_text(strength[a]);
    });
  visit([&](auto& b) { b.actuator_strength.set(copy, strength); });
}

Eigen::VectorXd Simulator::actuator_strength(int copy) const {
  check_copy(copy, "actuator_strength");
  return visit([&](auto& b) { return Eigen::VectorXd(b.actuator_strength.get(copy)); });
}

std::vector<ActuatorState> Simulator::actuator_states(int copy) const {
  check_copy(copy, "actuator_states");
  return visit([&](auto& b) {
    std::vector<ActuatorState> states;
    for (std::size_t m = 0; m < options_.actuators.size(); ++m) {
      const Actuator& a = options_.actuators[m];
      const auto command = b.actuator_state.at(copy, static_cast<int>(3 * m));
      const auto torque = b.actuator_state.at(copy, static_cast<int>(3 * m + 2));
      ActuatorState state;
      state.command = static_cast<double>(command);
      state.motor_speed = static_cast<double>(b.actuator_state.at(copy, static_cast<int>(3 * m + 1)));
      state.motor_torque = static_cast<double>(torque);
      // against what the step's own precision gives unclipped
      state.clipped = torque != command / static_cast<decltype(command)>(a.gear);
      states.push_back(state);
    }
    return states;
  });
}

void Simulator::set_drive_target(int copy, const Eigen::VectorXd& q_target, const Eigen::VectorXd& v_target) {
  check_copy(copy, "set_drive_target");
  require(q_target.size() == model_->nq, [&] {
    return "set_drive_target: q_target expects " + std::to_string(model_->nq) + " values, got " +
           std::to_string(q_target.size());
  });
  check_velocity(v_target, "set_drive_target v_target");
  // a spherical joint's error is the rotation to a unit target (a Free
  // joint takes no drive: its target is not read)
  Eigen::VectorXd& unit = configuration_;
  unit = q_target;
  normalize_quaternions(unit, "set_drive_target q_target", false);
  visit([&](auto& b) {
    b.target_q.set(copy, unit);
    b.target_v.set(copy, v_target);
  });
}

void Simulator::set_drive_gains(int copy, const Eigen::VectorXd& kp, const Eigen::VectorXd& kd) {
  check_copy(copy, "set_drive_gains");
  check_velocity(kp, "set_drive_gains kp");
  check_velocity(kd, "set_drive_gains kd");
  for (int k = 0; k < model_->nv; ++k) {
    require(finite_in(options_.precision, kp[k]) && kp[k] >= 0 && finite_in(options_.precision, kd[k]) && kd[k] >= 0,
            [&] {
              return "set_drive_gains: DOF " + std::to_string(k) + " (" + model_->dof_name[k] + ") needs " +
                     finite_word(options_.precision) + " gains >= 0";
            });
    if (model_->body_joint[model_->dof_body[k]] == JointType::Free)
      require(kp[k] == 0 && kd[k] == 0, [&] {
        return "set_drive_gains: DOF " + std::to_string(k) + " (" + model_->dof_name[k] +
               ") belongs to a floating base, which takes no drive";
      });
  }
  visit([&](auto& b) {
    b.drive_stiffness.set(copy, kp);
    b.drive_damping.set(copy, kd);
  });
  note_copy_inputs(copy);
  note_own_joint_parameters(copy, kDriveStiffness | kDriveDamping);
}

void Simulator::check_per_dof(const Eigen::VectorXd& values, const char* what) const {
  check_velocity(values, what);
  for (int k = 0; k < model_->nv; ++k)
    require(finite_in(options_.precision, values[k]) && values[k] >= 0, [&] {
      return std::string(what) + ": DOF " + std::to_string(k) + " (" + model_->dof_name[k] + ") needs a " +
             finite_word(options_.precision) + " value >= 0";
    });
}

// With conserve_linear_momentum a floating base takes no damping or armature
// (batch/step_momentum.cpp).
void Simulator::check_free_of_floating_bases(const Eigen::VectorXd& values, const char* what) const {
  if (!options_.conserve_linear_momentum) return;
  for (int k = 0; k < model_->nv; ++k)
    require(values[k] == 0 || model_->body_joint[model_->dof_body[k]] != JointType::Free, [&] {
      return std::string(what) + ": DOF " + std::to_string(k) + " (" + model_->dof_name[k] +
             ") belongs to a floating base, which takes none with conserve_linear_momentum";
    });
}

void Simulator::set_joint_damping(int copy, const Eigen::VectorXd& damping) {
  check_copy(copy, "set_joint_damping");
  check_per_dof(damping, "set_joint_damping");
  check_free_of_floating_bases(damping, "set_joint_damping");
  visit([&](auto& b) { b.joint_damping.set(copy, damping); });
  note_copy_inputs(copy);
  note_own_joint_parameters(copy, kDamping);
}

void Simulator::set_armature(int copy, const Eigen::VectorXd& armature) {
  check_copy(copy, "set_armature");
  check_per_dof(armature, "set_armature");
  check_free_of_floating_bases(armature, "set_armature");
  visit([&](auto& b) { b.armature.set(copy, armature); });
  note_own_joint_parameters(copy, kArmature);
}

void Simulator::set_joint_friction(int copy, const Eigen::VectorXd& friction) {
  check_copy(copy, "set_joint_friction");
  check_per_dof(friction, "set_joint_friction");
  for (int k = 0; k < model_->nv; ++k)  // as DofSettings::friction (validate)
    require(friction[k] == 0 || model_->body_joint[model_->dof_body[k]] != JointType::Free, [&] {
      return "set_joint_friction: DOF " + std::to_string(k) + " (" + model_->dof_name[k] +
             ") belongs to a floating base: friction acts on revolute, prismatic and spherical joints only";
    });
  visit([&](auto& b) { b.joint_friction.set(copy, friction); });
  note_own_joint_parameters(copy, kFriction);
}

void Simulator::set_body_inertia(int copy, int body, double mass, const Eigen::Vector3d& com,
                                 const Eigen::Matrix3d& inertia) {
  check_copy(copy, "set_body_inertia");
  if (body < 0 || body >= model_->nbody)
    throw std::out_of_range("set_body_inertia: body index " + std::to_string(body) + " outside [0, " +
                            std::to_string(model_->nbody) + ")");
  check_body_inertia(body, mass, com, inertia, "set_body_inertia");
  const bool own_before = body_has_own_inertia(copy, body);
  visit([&](auto& b) { b.state.set_body_inertia(copy, body, mass, com, inertia); });
  note_own_inertia(copy, body, own_before);
}

void Simulator::check_body_inertia(int body, double mass, const Eigen::Vector3d& com, const Eigen::Matrix3d& inertia,
                                   const char* what) const {
  auto where = [&] {
    return std::string(what) + ": body " + std::to_string(body) + " (" + model_->frame_name[model_->body_frame[body]] +
           "): ";
  };
  const Precision p = options_.precision;
  require(finite_in(p, mass) && mass >= 0, [&] { return where() + "mass must be " + finite_word(p) + " and >= 0"; });
  require(all_finite_in(p, com) && all_finite_in(p, inertia),
          [&] { return where() + "COM and inertia must be " + finite_word(p); });
  require(symmetric_positive_semidefinite(inertia),
          [&] { return where() + "the rotational inertia must be symmetric positive semidefinite"; });
}

bool Simulator::body_has_own_inertia(int copy, int body) const {
  constexpr int n = BatchState<double>::kInertiaParams;
  return visit([&](auto& b) { return differs(b.state.inertia, copy, n * body, model_inertia_.segment(n * body, n)); });
}

void Simulator::note_own_inertia(int copy, int body, bool own_before) {
  int& count = own_inertia_bodies_[copy];
  const int before = count;
  count += static_cast<int>(body_has_own_inertia(copy, body)) - static_cast<int>(own_before);
  if ((before == 0) != (count == 0)) invalidate_plan();
}

void Simulator::count_own_inertia(int copy) {
  int count = 0;
  for (int body = 0; body < model_->nbody; ++body) count += body_has_own_inertia(copy, body);
  if ((own_inertia_bodies_[copy] == 0) != (count == 0)) invalidate_plan();
  own_inertia_bodies_[copy] = count;
}

void Simulator::note_own_joint_parameters(int copy, unsigned fields) {
  unsigned char& own = own_joint_parameters_[copy];
  const unsigned char before = own;
  visit([&](auto& b) {
    const auto arrays = joint_parameter_fields(b, joint_parameters_);
    for (std::size_t f = 0; f < arrays.size(); ++f)
      if (fields >> f & 1u) {
        const unsigned bit = 1u << f;
        own = differs(*arrays[f].first, copy, 0, *arrays[f].second) ? own | bit : own & ~bit;
      }
  });
  if ((before == 0) != (own == 0)) invalidate_plan();
}

void Simulator::set_link_wrench(int copy, int body, const Eigen::Matrix<double, 6, 1>& wrench) {
  check_copy(copy, "set_link_wrench");
  if (body < 0 || body >= model_->nbody)
    throw std::out_of_range("set_link_wrench: body index " + std::to_string(body) + " outside [0, " +
                            std::to_string(model_->nbody) + ")");
  visit([&](auto& b) {
    using T = std::decay_t<decltype(b.state.wrench.at(0, 0))>;
    for (int k = 0; k < 6; ++k) b.state.wrench.at(copy, 6 * body + k) = static_cast<T>(wrench[k]);
  });
  if (!wrenches_used_) {
    wrenches_used_ = true;
    invalidate_plan();
  }
}

void Simulator::set_gravity(int copy, const Eigen::Vector3d& gravity) {
  check_copy(copy, "set_gravity");
  visit([&](auto& b) { b.state.gravity.set(copy, gravity); });
}

Fault Simulator::fault(int copy) const {
  check_copy(copy, "fault");
  return visit([&](auto& b) { return static_cast<Fault>(static_cast<int>(b.fault.at(copy, 0))); });
}

int Simulator::fault_count() const {
  int count = 0;
  for (int c = 0; c < copies(); ++c) count += fault(c) != Fault::None;
  return count;
}

void Simulator::clear_fault(int copy) {
  check_copy(copy, "clear_fault");
  visit([&](auto& b) { b.fault.at(copy, 0) = 0; });
}

void Simulator::reset(int copy) {
  check_copy(copy, "reset");
  visit([&](auto& b) {
    b.state.q.set_from(copy, b.initial_q);
    b.state.v.set_from(copy, b.initial_v);
    clear_warm_start(b, copy);
    for (auto* a : {&b.contact_count, &b.contact_dropped, &b.contact_overflow_steps})
      if (a->size() > 0) a->at(copy, 0) = 0;
    for (auto* a : applied_torque_report(b)) a->fill(copy, 0);  // no step since
    b.actuator_state.fill(copy, 0);
    b.fault.at(copy, 0) = 0;
  });
}

AppliedTorque Simulator::applied_torque(int copy) const {
  check_copy(copy, "applied_torque");
  if (!options_.record_applied_torque)
    throw std::logic_error("Simulator::applied_torque needs StepOptions::record_applied_torque");
  return visit([&](auto& b) {
    return AppliedTorque{b.applied_drive.get(copy), b.applied_passive.get(copy), b.applied_friction.get(copy),
                         b.applied_limits.get(copy), b.applied_actuation.get(copy)};
  });
}

template <class Dynamics>
void Simulator::load_motions(int first, const Dynamics& dynamics, bool forces, const char* function,
                             BatchState<double>& s, BatchArray<double>& poses, std::vector<char>& recorded) const {
  if (!options_.record_motion)
    throw std::logic_error(std::string("Simulator::") + function + " needs StepOptions::record_motion");
  const int count = s.copies();
  // The runs' motions, and for the forces the copies' gravity, inertias and
  // wrenches as the step takes them (batch/step_engine.hpp: the model's
  // inertias and no wrenches where their stages are skipped), in double.
  const bool own_inertia = plan()[static_cast<int>(Stage::PerCopyInertia)].runs;
  const bool wrenches = plan()[static_cast<int>(Stage::ExternalWrenches)].runs;
  recorded.assign(count, 0);
  visit([&](auto& b) {
    auto load = [&](const auto& from, BatchArray<double>& to, int i) {  // lane by lane: no at()'s divisions
      const auto* in = from.lane(first + i);
      double* out = to.lane(i);
      for (int k = 0; k < from.size(); ++k) out[k * to.width()] = static_cast<double>(in[k * from.width()]);
    };
    for (int i = 0; i < count; ++i) {
      recorded[i] = b.motion_recorded.at(first + i, 0) != 0;
      if (!recorded[i]) continue;  // no motion: its row is zero whatever s holds
      load(b.motion_q, s.q, i);
      load(b.motion_v, s.v, i);
      load(b.motion_acceleration, s.qacc, i);
      if (!forces) continue;  // the kinematics need no more
      load(b.state.gravity, s.gravity, i);
      if (own_inertia) load(b.state.inertia, s.inertia, i);
      else s.inertia.set(i, model_inertia_);
      if (wrenches) load(b.state.wrench, s.wrench, i);
      else s.wrench.fill(i, 0);
      // the step's forces balance the motion without its unbalanced share
      const auto* unbalanced = b.motion_unbalanced.lane(first + i);
      double* qacc = s.qacc.lane(i);
      for (int k = 0; k < model_->nv; ++k)
        qacc[k * s.qacc.width()] -= static_cast<double>(unbalanced[k * b.motion_unbalanced.width()]);
    }
  });
  if (!forces || !contacts_found()) return;
  // The contact forces join the link wrenches, their torque taken about
  // each body's COM at the start of the step (where the contact points are).
  dynamics.body_poses(s, poses);
  constexpr int kParams = BatchState<double>::kInertiaParams;
  for (int i = 0; i < count; ++i) {
    if (!recorded[i]) continue;
    visit_body_contacts(first + i, [&](const Contact& c, int body, double sign) {
      Eigen::Matrix3d R;
      for (int k = 0; k < 9; ++k) R(k / 3, k % 3) = poses.at(i, 12 * body + k);
      const Eigen::Vector3d origin(poses.at(i, 12 * body + 9), poses.at(i, 12 * body + 10), poses.at(i, 12 * body + 11));
      const Eigen::Vector3d com = origin + R * Eigen::Vector3d(s.inertia.at(i, kParams * body + 1),
                                                                s.inertia.at(i, kParams * body + 2),
                                                                s.inertia.at(i, kParams * body + 3));
      const Eigen::Vector3d torque = (c.point - com).cross(c.force) + c.torsion * c.normal;
      for (int k = 0; k < 3; ++k) {
        s.wrench.at(i, 6 * body + k) += sign * c.force[k];
        s.wrench.at(i, 6 * body + 3 + k) += sign * torque[k];
      }
    });
  }
}

namespace {

// values' copies into out's rows, zero where no motion was recorded.
void write_rows(const BatchArray<double>& values, const std::vector<char>& recorded, Eigen::Ref<RowMatrix> out) {
  for (Eigen::Index i = 0; i < out.rows(); ++i) {
    const double* in = values.lane(static_cast<int>(i));
    for (Eigen::Index k = 0; k < out.cols(); ++k) out(i, k) = recorded[i] ? in[k * values.width()] : 0.0;
  }
}

void require_shape(const Eigen::Ref<RowMatrix>& out, int rows, int cols, const char* function) {
  require(out.rows() == rows && out.cols() == cols, [&] {
    return std::string(function) + ": out must be " + std::to_string(rows) + " x " + std::to_string(cols) + ", got " +
           std::to_string(out.rows()) + " x " + std::to_string(out.cols());
  });
}

}  // namespace

template <class Compute>
Eigen::Matrix<double, 6, Eigen::Dynamic> Simulator::copy_readout(int copy, int columns, bool forces,
                                                                 const char* function, Compute&& compute) const {
  check_copy(copy, function);
  const BatchDynamics<double> dynamics(*model_);
  BatchState<double> s = dynamics.make_state(1);
  BatchArray<double> poses = dynamics.make_array(1, 12 * model_->nbody), values = dynamics.make_array(1, 6 * columns);
  std::vector<char> recorded;
  load_motions(copy, dynamics, forces, function, s, poses, recorded);
  compute(dynamics, s, values);
  Eigen::Matrix<double, 6, Eigen::Dynamic> out(6, columns);
  write_rows(values, recorded, Eigen::Map<RowMatrix>(out.data(), 1, 6 * columns));
  return out;
}

// The link damping weight of the recorded runs (dt / substeps each), when
// the step applies link damping.
std::optional<double> Simulator::recorded_link_damping() const {
  if (!plan()[static_cast<int>(Stage::LinkDamping)].runs) return std::nullopt;
  return link_damping_weight(options_.integrator, options_.dt / options_.substeps);
}

Simulator::MotionScratch& Simulator::motion_scratch() const {
  if (!motion_scratch_) motion_scratch_ = std::make_unique<MotionScratch>(*model_, copies());
  return *motion_scratch_;
}

Eigen::Matrix<double, 6, Eigen::Dynamic> Simulator::incoming_joint_forces(int copy) const {
  return copy_readout(copy, model_->nbody, true, "incoming_joint_forces",
                      [&](const auto& d, const BatchState<double>& s, BatchArray<double>& o) {
                        d.transmitted_joint_forces(s, o, recorded_link_damping());
                      });
}

Eigen::Matrix<double, 6, Eigen::Dynamic> Simulator::link_accelerations(int copy) const {
  return copy_readout(copy, static_cast<int>(model_->frame_name.size()), false, "link_accelerations",
                      [](const auto& d, const BatchState<double>& s, BatchArray<double>& o) {
                        d.frame_accelerations(s, o);
                      });
}

void Simulator::all_incoming_joint_forces(Eigen::Ref<RowMatrix> out) const {
  require_shape(out, copies(), 6 * model_->nbody, "all_incoming_joint_forces");
  MotionScratch& m = motion_scratch();
  load_motions(0, m.dynamics, true, "all_incoming_joint_forces", m.state, m.poses, m.recorded);
  m.dynamics.transmitted_joint_forces(m.state, m.forces, recorded_link_damping());
  write_rows(m.forces, m.recorded, out);
}

void Simulator::all_link_accelerations(Eigen::Ref<RowMatrix> out) const {
  require_shape(out, copies(), 6 * static_cast<int>(model_->frame_name.size()), "all_link_accelerations");
  MotionScratch& m = motion_scratch();
  load_motions(0, m.dynamics, false, "all_link_accelerations", m.state, m.poses, m.recorded);
  m.dynamics.frame_accelerations(m.state, m.frames);
  write_rows(m.frames, m.recorded, out);
}

// set_ground's and set_ground_friction's checks of the copy and the
// scene, and of the friction; messages built only on failure (a reset
// calls these, and allocates nothing).
void Simulator::check_ground(int copy, const char* what, double friction) const {
  check_copy(copy, what);
  require(options_.contacts.ground, [&] { return std::string(what) + ": the scene has no ground (ContactSettings::ground)"; });
  require(contacts_run(), [&] {
    return std::string(what) + ": the scene's contacts do not run (" +
           plan_[static_cast<int>(Stage::Contacts)].reason + "), so it keeps no ground per copy";
  });
  const Precision p = options_.precision;
  require(finite_in(p, friction) && friction >= 0,
          [&] { return std::string(what) + ": friction must be " + finite_word(p) + " and >= 0"; });
}

void Simulator::set_ground(int copy, double height, const Eigen::Vector3d& normal, double friction) {
  check_ground(copy, "set_ground", friction);
  const Precision p = options_.precision;
  require(finite_in(p, height), [&] { return "set_ground: height must be " + finite_word(p); });
  require(all_finite_in(p, normal) && normal.norm() > 1e-9,
          [&] { return "set_ground: normal must be a " + finite_word(p) + " non-zero vector"; });
  visit([&](auto& b) {
    b.ground.set(copy, ground_plane(normal, height));
    b.ground_friction.fill(copy, friction);
  });
}

void Simulator::set_ground_friction(int copy, double friction) {
  check_ground(copy, "set_ground_friction", friction);
  visit([&](auto& b) { b.ground_friction.fill(copy, friction); });
}

template <class F>
void Simulator::visit_contacts(int copy, F&& f) const {
  if (!contacts_found()) return;
  const double h = options_.dt / options_.substeps;
  visit([&](auto& b) {
    using T = std::decay_t<decltype(b.contact_id.at(0, 0))>;
    const int W = b.contact_id.width(), k = b.contact_impulse.size() / b.contact_id.size();
    const T *ids = b.contact_id.lane(copy), *impulses = b.contact_impulse.lane(copy);
    const T *points = b.contact_point.lane(copy), *normals = b.contact_normal.lane(copy);
    const T* separations = b.contact_separation.lane(copy);
    for (int c = 0; c < b.contact_id.size(); ++c) {
      const int id = static_cast<int>(ids[c * W]);
      if (id < 0) break;  // a copy's contacts fill its slots from the first
      const ContactPair& pair = pairs_.pairs[pairs_.candidate_pair[id]];
      Contact contact;
      contact.shape_a = pair.a.shape;
      contact.shape_b = pair.b.shape;
      contact.body_a = pair.a.body;
      contact.body_b = pair.b.body;
      auto field = [&](const T* values, int i) { return values[i * W]; };
      Vec3<T> n, t1, t2;
      n = {field(normals, 3 * c), field(normals, 3 * c + 1), field(normals, 3 * c + 2)};
      tangent_frame<T>(n, t1, t2);  // the solver's frame, in its precision
      contact.normal = Eigen::Vector3d(n.x, n.y, n.z);
      contact.point = Eigen::Vector3d(field(points, 3 * c), field(points, 3 * c + 1), field(points, 3 * c + 2));
      contact.separation = field(separations, c);
      auto impulse = [&](int i) { return static_cast<double>(field(impulses, c * k + i)); };
      contact.force = (impulse(0) * contact.normal + impulse(1) * Eigen::Vector3d(t1.x, t1.y, t1.z) +
                       impulse(2) * Eigen::Vector3d(t2.x, t2.y, t2.z)) / h;
      contact.torsion = k > 3 ? impulse(3) / h : 0.0;
      f(contact);
    }
  });
}

template <class F>
void Simulator::visit_body_contacts(int copy, F&& f) const {
  visit_contacts(copy, [&](const Contact& c) {
    if (c.body_b >= 0) f(c, c.body_b, 1.0);
    if (c.body_a >= 0) f(c, c.body_a, -1.0);
  });
}

std::vector<Contact> Simulator::contacts(int copy) const {
  check_copy(copy, "contacts");
  std::vector<Contact> out;
  visit_contacts(copy, [&](const Contact& c) { out.push_back(c); });
  return out;
}

// With substeps, the step's summed impulse wrench of body b over dt
// (StepBatch::contact_wrench), entry i of 6; false without them.
template <class F>
bool Simulator::visit_step_contact_wrenches(int copy, F&& f) const {
  if (!contacts_found()) return false;
  return visit([&](auto& b) {
    if (b.contact_wrench.size() == 0) return false;
    const double inv_dt = 1.0 / options_.dt;
    for (int body = 0; body < model_->nbody; ++body)
      for (int i = 0; i < 6; ++i) f(body, i, inv_dt * static_cast<double>(b.contact_wrench.at(copy, 6 * body + i)));
    return true;
  });
}

void Simulator::body_contact_forces(int copy, double* forces) const {
  check_copy(copy, "body_contact_forces");
  std::fill(forces, forces + 3 * model_->nbody, 0.0);
  if (visit_step_contact_wrenches(copy, [&](int body, int i, double x) {
        if (i < 3) forces[3 * body + i] = x;
      }))
    return;
  visit_body_contacts(copy, [&](const Contact& c, int body, double sign) {
    for (int i = 0; i < 3; ++i) forces[3 * body + i] += sign * c.force[i];
  });
}

Eigen::Matrix<double, 6, Eigen::Dynamic> Simulator::body_contact_wrenches(int copy) const {
  check_copy(copy, "body_contact_wrenches");
  Eigen::Matrix<double, 6, Eigen::Dynamic> out = Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, model_->nbody);
  if (visit_step_contact_wrenches(copy, [&](int body, int i, double x) { out(i, body) = x; })) return out;
  visit_body_contacts(copy, [&](const Contact& c, int body, double sign) {
    const Eigen::Vector3d torque = c.point.cross(c.force) + c.torsion * c.normal;
    out.col(body) += sign * (Eigen::Matrix<double, 6, 1>() << c.force, torque).finished();
  });
  return out;
}

ContactOverflow Simulator::contact_overflow(int copy) const {
  check_copy(copy, "contact_overflow");
  if (!contacts_found()) return {};
  return visit([&](auto& b) {
    return ContactOverflow{static_cast<int>(b.contact_dropped.at(copy, 0)),
                           static_cast<int>(b.contact_overflow_steps.at(copy, 0))};
  });
}

double Simulator::energy(int copy) const {
  check_copy(copy, "energy");
  refresh_plan();
  // One copy's state, inertial parameters and gravity, in double; its own
  // inertias and armature where the step takes them (their stages run),
  // else the model's and the scene's
  const bool own_inertia = plan_[static_cast<int>(Stage::PerCopyInertia)].runs;
  const bool own_armature = plan_[static_cast<int>(Stage::PerCopyJointParameters)].runs;
  const BatchDynamics<double> dynamics(*model_);
  BatchState<double> one = dynamics.make_state(1);
  visit([&](auto& b) {
    one.q.set(0, b.state.q.get(copy));
    one.v.set(0, b.state.v.get(copy));
    one.inertia.set(0, own_inertia ? b.state.inertia.get(copy) : model_inertia_);
    one.gravity.set(0, b.state.gravity.get(copy));
  });
  BatchArray<double> kinetic = dynamics.make_array(1, 1), potential = dynamics.make_array(1, 1);
  dynamics.kinetic_energy(one, kinetic);
  dynamics.potential_energy(one, potential);
  // the kinetic energy holds the model's armature: the copy's own instead
  double armature_change = 0;
  visit([&](auto& b) {
    const Eigen::VectorXd armature = own_armature ? b.armature.get(copy) : joint_parameters_.armature;
    const Eigen::VectorXd v = b.state.v.get(copy);
    for (int k = 0; k < model_->nv; ++k) armature_change += 0.5 * (armature[k] - model_->dof_armature[k]) * v[k] * v[k];
  });
  return kinetic.at(0, 0) + armature_change + potential.at(0, 0);
}

}  // namespace lockstep
