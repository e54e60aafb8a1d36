#include "batch/step_engine.hpp"

#include "batch/denormal_guard.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <tuple>

namespace lockstep {

namespace {

// Lanes where any of n fields [field][lane] is not finite.
template <class L>
lane::mask_t<L> any_non_finite(const lane::scalar_t<L>* p, int n) {
  constexpr std::size_t W = lane::width_v<L>;
  lane::mask_t<L> bad(false);
  for (int k = 0; k < n; ++k) bad = bad || !lane::is_finite(lane::load<L>(p + k * W));
  return bad;
}

// The same over the fields listed.
template <class L>
lane::mask_t<L> any_non_finite(const lane::scalar_t<L>* p, const std::vector<int>& fields) {
  constexpr std::size_t W = lane::width_v<L>;
  lane::mask_t<L> bad(false);
  for (int k : fields) bad = bad || !lane::is_finite(lane::load<L>(p + k * W));
  return bad;
}

template <class L>
L fault_code(Fault f) {
  return L(static_cast<lane::scalar_t<L>>(static_cast<int>(f)));
}

}  // namespace

template <class L>
StepEngine<L>::Scratch::Scratch(const KernelModel<T>& km, int motors, int joint_rows, int columns,
                                const ContactParams<T>& contact, int candidates)
    : ws(km), terms(km.nv, motors), rows(joint_rows + contact.capacity * contact.rows_per_contact, columns, km.nv),
      contacts(contact.capacity, contact.rows_per_contact, km.nv, km.nbody, candidates), u0(km.nv), u1(km.nv), u_free(km.nv), qacc(km.nv),
      displacement(km.nv), q_next(km.nq), q_stage(km.nq), v_stage(km.nv),
      v_sum(km.nv), a_sum(km.nv), needed(joint_rows + contact.capacity * contact.rows_per_contact),
      needed_source(needed.m), need(joint_rows), violated(joint_rows),
      column_built(columns), new_columns(columns), held_coupling(static_cast<std::size_t>(columns) * needed.m),
      dof_velocity(columns), dof_displacement(columns), held_speed(columns), momentum_target(km.nbody),
      momentum_added(km.nbody), articulation_mass(km.nbody), command_sum(km.nv), passive_sum(km.nv),
      actuation_sum(km.nv) {}

template <class L>
StepEngine<L>::StepEngine(const Model& model, int copies, const StepOptions& options,
                          const std::vector<DofSettings>& dofs, const StepPlan& plan, const ContactPairs& pairs)
    : options_(options),
      plan_(plan),
      km_(model),
      batch_(model, copies, kWidth, 0),
      model_inertia_(kWidth, BatchState<T>::kInertiaParams * model.nbody, kWidth),
      scene_drive_stiffness_(kWidth, model.nv, kWidth),
      scene_drive_damping_(kWidth, model.nv, kWidth),
      scene_damping_(kWidth, model.nv, kWidth),
      scene_armature_(kWidth, model.nv, kWidth),
      scene_friction_(kWidth, model.nv, kWidth) {
  model_inertia_.set_all(BatchState<T>::model_inertia_params(model));
  const int nv = model.nv;
  jm_.acceleration_drive.resize(nv);
  for (int k = 0; k < nv; ++k) {
    const DofSettings& d = dofs[k];
    jm_.acceleration_drive[k] = d.drive_type == DriveType::Acceleration;
    jm_.max_force.push_back(static_cast<T>(d.max_force));
    jm_.spring_stiffness.push_back(static_cast<T>(d.spring_stiffness));
    jm_.spring_rest.push_back(static_cast<T>(d.spring_rest));
    jm_.lower.push_back(static_cast<T>(d.lower));
    jm_.upper.push_back(static_cast<T>(d.upper));
    jm_.limit_stiffness.push_back(static_cast<T>(d.limit_stiffness));
    jm_.limit_damping.push_back(static_cast<T>(d.limit_damping));
    const bool stribeck = d.friction_model == FrictionModel::Stribeck;
    jm_.coulomb.push_back(static_cast<T>(stribeck ? d.friction : 0.0));
    jm_.stiction_extra.push_back(static_cast<T>(d.stiction_extra));
    jm_.falloff_velocity.push_back(static_cast<T>(d.falloff_velocity));
    jm_.stribeck_velocity.push_back(static_cast<T>(d.stribeck_velocity));
  }
  std::vector<bool> actuated(nv, false);
  for (const Actuator& a : options.actuators) {
    typename JointTermModel<T>::Motor motor{a.dof,
                                            static_cast<T>(a.gear),
                                            static_cast<T>(a.stall_torque()),
                                            static_cast<T>(a.back_emf_damping()),
                                            static_cast<T>(a.peak_torque),
                                            a.enforce_operating_region,
                                            {}};
    actuated[a.dof] = true;
    for (const auto& [dof, ratio] : a.couplings) {
      motor.couplings.emplace_back(dof, static_cast<T>(ratio));
      actuated[dof] = true;
    }
    jm_.motors.push_back(std::move(motor));
  }
  for (int k = 0; k < nv; ++k)
    if (actuated[k]) jm_.actuated.push_back(k);
  const int motors = static_cast<int>(options.actuators.size());
  batch_.actuator_command = BatchArray<T>(copies, motors, kWidth);
  batch_.actuator_strength = BatchArray<T>(copies, motors, kWidth, T(1));
  batch_.actuator_state = BatchArray<T>(copies, 3 * motors, kWidth);
  set_plan(plan);
  if (options.conserve_linear_momentum) {
    momentum_root_.assign(model.nbody, -1);
    for (const Articulation& a : model.articulations)
      if (a.floating_base) {
        floating_roots_.push_back(a.first_body);
        std::fill_n(momentum_root_.begin() + a.first_body, a.body_count, a.first_body);
      }
  }
  batch_.momentum_remainder = BatchArray<T>(copies, 3 * static_cast<int>(floating_roots_.size()), kWidth);
  for (int b = 0; b < model.nbody; ++b) {
    const JointType type = model.body_joint[b];
    if (type == JointType::Free) continue;
    for (int i = 0; i < joint_nq(type); ++i) driven_q_.push_back(model.body_q_offset[b] + i);
    for (int i = 0; i < joint_nv(type); ++i) driven_v_.push_back(model.body_dof_offset[b] + i);
  }

  // Solver rows: the mimic couplings, the fixed tendons' rows, then DOF by
  // DOF position limit, velocity limit, friction.
  auto spherical = [&](int k) { return model.body_joint[model.dof_body[k]] == JointType::Spherical; };
  auto q_index_of = [&](int k) {
    const int body = model.dof_body[k];
    return model.body_q_offset[body] + (spherical(k) ? 0 : k - model.body_dof_offset[body]);
  };
  auto add_row = [&](JointRowKind kind, int k, double a, double b) {
    row_specs_.push_back({kind, k, q_index_of(k), columns_.column_of(km_, k), static_cast<T>(a), static_cast<T>(b)});
    if (spherical(k)) row_specs_.back().rotation_axis = k - model.body_dof_offset[model.dof_body[k]];
  };
  // q_f = m q_l + c as PhysX's q_A + G q_B + offset = 0: A the follower,
  // G = -m, offset -c. First, so that the sweeps take the limits and
  // contacts after them: those hold at the mimic's expense, as in PhysX.
  auto add_coupled_row = [&](JointRowKind kind, const std::vector<TendonJoint>& joints, double a, double b) {
    add_row(kind, joints.front().dof, a, b);
    for (const TendonJoint& j : joints)
      row_specs_.back().terms.push_back(
          {j.dof, q_index_of(j.dof), columns_.column_of(km_, j.dof), static_cast<T>(j.coefficient)});
    ++coupled_rows_;
    return &row_specs_.back();
  };
  if (plan.mimic_joints)
    for (const Mimic& mimic : model.mimics)
      add_coupled_row(JointRowKind::Mimic, {{mimic.dof, 1.0}, {mimic.leader_dof, -mimic.multiplier}}, -mimic.offset, 0);
  // A tendon's spring where it has stiffness or damping, its limits where
  // it has one (their compliances are finite: validate_fixed_tendons).
  if (plan.fixed_tendons)
    for (const FixedTendon& tendon : model.fixed_tendons) {
      if (tendon.has_spring()) {
        JointRowSpec<T>* row =
            add_coupled_row(JointRowKind::TendonSpring, tendon.joints, -(tendon.rest_length + tendon.offset), 0);
        row->stiffness = static_cast<T>(tendon.stiffness);
        row->damping = static_cast<T>(tendon.damping);
      }
      if (tendon.has_limits())
        add_coupled_row(JointRowKind::TendonLimit, tendon.joints, tendon.lower_limit, tendon.upper_limit)->stiffness =
            static_cast<T>(tendon.limit_stiffness);
    }
  // A row stage forced On gets a row on every DOF it can act on, even where
  // the scene gives it nothing to do (infinite limits, zero friction): such
  // rows never push, and cost what the stage costs.
  auto forced = [&](Stage stage) { return options.stages[static_cast<int>(stage)] == StageMode::On; };
  for (int k = 0; k < nv; ++k) {
    const DofSettings& d = dofs[k];
    const JointType type = model.body_joint[model.dof_body[k]];
    const bool positioned = type == JointType::Revolute || type == JointType::Prismatic || type == JointType::Spherical;
    const bool limited = std::isfinite(d.lower) || std::isfinite(d.upper);
    const bool hard_limited = plan.hard_limits && positioned && d.limit_stiffness == 0.0;
    if (hard_limited && (limited || forced(Stage::HardLimits))) add_row(JointRowKind::PositionLimit, k, d.lower, d.upper);
    if (plan.velocity_limits && (std::isfinite(d.velocity_limit) || forced(Stage::VelocityLimits))) {
      add_row(JointRowKind::VelocityLimit, k, d.velocity_limit, 0);
      if (hard_limited) {
        row_specs_.back().range_lower = static_cast<T>(d.lower);
        row_specs_.back().range_upper = static_cast<T>(d.upper);
      }
    }
    if (plan.coulomb_friction && d.friction_model == FrictionModel::Coulomb &&
        (d.friction > 0.0 || forced(Stage::CoulombFriction)))
      add_row(JointRowKind::Friction, k, d.friction, 0);
  }
  batch_.impulse = BatchArray<T>(copies, static_cast<int>(row_specs_.size()), kWidth);
  // without recording, empty per copy (a snapshot packs none)
  for (BatchArray<T>* a : {&batch_.applied_drive, &batch_.applied_passive, &batch_.applied_friction,
                           &batch_.applied_limits, &batch_.applied_actuation})
    *a = BatchArray<T>(copies, options.record_applied_torque ? nv : 0, kWidth);
  const bool motion = options.record_motion;
  batch_.motion_q = BatchArray<T>(copies, motion ? model.nq : 0, kWidth);
  for (BatchArray<T>* a : {&batch_.motion_v, &batch_.motion_acceleration, &batch_.motion_unbalanced})
    *a = BatchArray<T>(copies, motion ? nv : 0, kWidth);
  batch_.motion_recorded = BatchArray<T>(copies, motion ? 1 : 0, kWidth);
  const JointParameters scene = scene_joint_parameters(model, dofs);
  // every copy's per-DOF parameters, and the one block read while no copy has its own
  const std::tuple<BatchArray<T>*, BatchArray<T>*, const Eigen::VectorXd*> joint_parameters[] = {
      {&batch_.drive_stiffness, &scene_drive_stiffness_, &scene.drive_stiffness},
      {&batch_.drive_damping, &scene_drive_damping_, &scene.drive_damping},
      {&batch_.joint_damping, &scene_damping_, &scene.damping},
      {&batch_.armature, &scene_armature_, &scene.armature},
      {&batch_.joint_friction, &scene_friction_, &scene.friction}};
  for (const auto& [per_copy, shared, values] : joint_parameters) {
    per_copy->set_all(*values);
    shared->set_all(*values);
  }
  // The armature is per copy (StepBatch::armature): the step's ABA and CRBA
  // take it with the implicit diagonal (StepJointTerms), not from km_.
  std::fill(km_.dof_armature.begin(), km_.dof_armature.end(), T(0));
  int candidates = 0;
  if (plan.contacts) candidates = set_up_contacts(copies, options.contacts, pairs);
  else make_contact_arrays(copies, 0, 0, options.contacts);
  const int rows = static_cast<int>(row_specs_.size()), columns = columns_.size();
  scratch_rows_ = rows, scratch_columns_ = columns, scratch_candidates_ = candidates;
  reserve_scratch(tbb::this_task_arena::max_concurrency());
}

template <class L>
void StepEngine<L>::reserve_scratch(int slots) {
  while (static_cast<int>(scratch_.size()) < slots) {
    auto make = [&] {
      return Scratch(km_, static_cast<int>(jm_.motors.size()), scratch_rows_, scratch_columns_, contact_params_,
                     scratch_candidates_);
    };
    scratch_.push_back(std::make_unique<ScratchPair>(ScratchPair{{make(), make()}}));
    for (Scratch& s : scratch_.back()->s) s.clock.on = profiling_;
  }
}

// The pairs in the kernels' precision, the contact parameters, the per-copy
// contact arrays; returns the most narrowphase points of one pair.
template <class L>
int StepEngine<L>::set_up_contacts(int copies, const ContactSettings& settings, const ContactPairs& pairs) {
  int most = 0;
  for (const ContactPair& pair : pairs.pairs) {
    ContactPairSpec<T> spec;
    spec.kind = pair.kind;
    spec.ground = pair.a.shape == kGroundShape;
    spec.body_a = pair.a.body;
    spec.body_b = pair.b.body;
    flatten_transform(pair.a.pose, spec.pose_a);
    flatten_transform(pair.b.pose, spec.pose_b);
    for (int i = 0; i < 3; ++i) {
      spec.size_a[i] = static_cast<T>(pair.a.size[i]);
      spec.size_b[i] = static_cast<T>(pair.b.size[i]);
    }
    spec.radius_a = static_cast<T>(pair.a.bound_radius);
    spec.radius_b = static_cast<T>(pair.b.bound_radius);
    spec.reach_a = static_cast<T>(pair.a.pose.translation().norm() + pair.a.bound_radius);
    spec.reach_b = static_cast<T>(pair.b.pose.translation().norm() + pair.b.bound_radius);
    spec.friction = static_cast<T>(pair.friction);
    spec.restitution = static_cast<T>(pair.restitution);
    spec.first_candidate = pair.first_candidate;
    spec.candidates = pair_candidates(pair.kind);
    std::vector<bool> moves(km_.nv, false);  // the joints from either body to its root
    for (int body : {pair.a.body, pair.b.body})
      for (int j = body; j >= 0; j = km_.body_parent[j])
        for (int d = 0; d < joint_nv(km_.body_joint[j]); ++d) moves[km_.body_dof_offset[j] + d] = true;
    for (int j = 0; j < km_.nv; ++j)
      if (moves[j]) spec.dofs.push_back(j);
    most = std::max(most, spec.candidates);
    contact_pairs_.push_back(spec);
    for (int body : {pair.a.body, pair.b.body})
      if (body >= 0 && std::find(contact_bodies_.begin(), contact_bodies_.end(), body) == contact_bodies_.end())
        contact_bodies_.push_back(body);
  }
  ContactParams<T>& p = contact_params_;
  p.capacity = settings.capacity;
  p.rows_per_contact = settings.torsional_friction > 0 ? 4 : 3;
  p.margin = static_cast<T>(settings.margin);
  p.speculative_speed = static_cast<T>(settings.speculative_speed);
  p.stiffness = static_cast<T>(settings.stiffness);
  p.damping = static_cast<T>(settings.damping);
  p.bounce_threshold = static_cast<T>(settings.bounce_threshold);
  p.max_depenetration_speed = static_cast<T>(settings.max_depenetration_speed);
  p.torsional = static_cast<T>(settings.torsional_friction);
  p.error_reduction = static_cast<T>(options_.error_reduction);
  make_contact_arrays(copies, p.capacity, p.rows_per_contact, settings);
  return most;
}

// The per-copy ground and contact arrays, `capacity` slots of
// `rows_per_contact` rows each; a scene without contacts has them with no
// slots, so that snapshots and set_ground see every copy.
template <class L>
void StepEngine<L>::make_contact_arrays(int copies, int capacity, int rows_per_contact, const ContactSettings& settings) {
  const int C = capacity, k = rows_per_contact;
  StepBatch<T>& B = batch_;
  B.ground = BatchArray<T>(copies, 4, kWidth);
  B.ground.set_all(ground_plane(settings.ground_normal, settings.ground_height));
  B.ground_friction = BatchArray<T>(copies, 1, kWidth, static_cast<T>(settings.ground_contact.friction));
  B.contact_id = BatchArray<T>(copies, C, kWidth, T(-1));
  B.contact_impulse = BatchArray<T>(copies, C * k, kWidth);
  B.contact_point = BatchArray<T>(copies, 3 * C, kWidth);
  B.contact_normal = BatchArray<T>(copies, 3 * C, kWidth);
  B.contact_separation = BatchArray<T>(copies, C, kWidth);
  B.contact_count = BatchArray<T>(copies, 1, kWidth);
  B.contact_dropped = BatchArray<T>(copies, 1, kWidth);
  B.contact_overflow_steps = BatchArray<T>(copies, 1, kWidth);
  B.contact_wrench = BatchArray<T>(copies, options_.substeps > 1 && C > 0 ? 6 * km_.nbody : 0, kWidth);
}

template <class L>
ContactArrays<lane::scalar_t<L>> StepEngine<L>::contact_arrays(int block) {
  StepBatch<T>& B = batch_;
  return {B.ground.block(block),          B.ground_friction.block(block),   B.contact_id.block(block),
          B.contact_impulse.block(block), B.contact_point.block(block),     B.contact_normal.block(block),
          B.contact_separation.block(block), B.contact_count.block(block), B.contact_dropped.block(block),
          B.contact_overflow_steps.block(block)};
}

// The row stages are laid out once, at construction; the others may change.
template <class L>
void StepEngine<L>::set_plan(const StepPlan& plan) {
  plan_.drives = plan.drives, plan_.damping = plan.damping, plan_.springs = plan.springs;
  plan_.soft_limits = plan.soft_limits, plan_.stribeck = plan.stribeck, plan_.wrenches = plan.wrenches;
  plan_.link_damping = plan.link_damping;
  plan_.per_copy_inertia = plan.per_copy_inertia;
  plan_.per_copy_joint_parameters = plan.per_copy_joint_parameters;
  jm_.drives = plan.drives, jm_.damping = plan.damping, jm_.springs = plan.springs;
  jm_.soft_limits = plan.soft_limits, jm_.stribeck = plan.stribeck;
}

template <class L>
void StepEngine<L>::step(int steps, int substeps, double dt) {
  const T h = static_cast<T>(dt / substeps);
  // blocks in pairs (the last one alone when their count is odd), whose
  // solves may run side by side (step_blocks)
  const int blocks = batch_.state.q.blocks();
  reserve_scratch(tbb::this_task_arena::max_concurrency());  // an arena wider than at construction
  tbb::parallel_for(tbb::blocked_range<int>(0, (blocks + 1) / 2), [&](const tbb::blocked_range<int>& range) {
    const DenormalGuard flush_denormals;
    ScratchPair& pair = *scratch_[tbb::this_task_arena::current_thread_index()];
    for (int p = range.begin(); p != range.end(); ++p)
      for (int n = 0; n < steps; ++n)
        for (int k = 0; k < substeps; ++k) step_blocks(2 * p, std::min(2, blocks - 2 * p), h, k == 0, pair.s);
  });
}

template <class L>
void StepEngine<L>::set_profiling(bool on) {
  for (auto& pair : scratch_)
    for (Scratch& s : pair->s) s.clock = PhaseClock{on, {}, {}};
  profiling_ = on;
}

template <class L>
StepProfile StepEngine<L>::profile() const {
  StepProfile sum;
  for (const auto& pair : scratch_)
    for (const Scratch& s : pair->s)
      for (double StepProfile::*phase : {&StepProfile::dynamics, &StepProfile::contact_detection,
                                         &StepProfile::constraint_solve, &StepProfile::integration})
        sum.*phase += s.clock.seconds.*phase;
  return sum;
}

// The gyroscopic force at the middle of the step (implicit midpoint:
// Jacobian weight h/2). RK4 evaluates the plain equations of motion at its
// stages: explicit.
template <class L>
lane::scalar_t<L> StepEngine<L>::gyroscopic_weight(T h) const {
  return options_.implicit_gyroscopic && options_.integrator != Integrator::RK4 ? T(0.5) * h : T(0);
}

// The weight w of the joint effects' implicit part (drives, damping,
// springs, soft limits: (M + w kd + w^2 kp) a = f(q + w v, v)). Semi-implicit
// Euler: backward Euler, w = h. Trapezoid: the implicit trapezoidal rule
// (Crank-Nicolson), w = h/2 with the force taken once at (q0, v0) for both
// of Heun's accelerations: for constant M that is exactly the trapezoidal
// rule on the linear joint forces, second order and A-stable, beside
// Heun's explicit rule for the rest. RK4 evaluates the plain equations of
// motion at its stages: w = 0, explicit, fourth order (stiff gains then
// need h below about 2.8 / the drive's frequency, as for any explicit rule).
template <class L>
lane::scalar_t<L> StepEngine<L>::joint_term_weight(T h) const {
  switch (options_.integrator) {
    case Integrator::Trapezoid: return T(0.5) * h;
    case Integrator::RK4: return T(0);
    default: return h;
  }
}

template <class L>
void StepEngine<L>::free_acceleration(const T* q, const T* v, T h, const BlockInputs<T>& in, const T* tau_ff,
                                      JointTermInputs<T> terms_in, JointTerms joint_terms, Scratch& s) {
  joint_transforms<L>(km_, q, s.ws);
  if (km_.needs_world(plan_.wrenches, true, in.link_damping && in.link_damping_weight != 0))
    world_transforms<L>(km_, s.ws);
  terms_in.q = q;
  terms_in.v = v;
  if (joint_terms == JointTerms::AtThisState) joint_term_prepass<L>(km_, jm_, joint_term_weight(h), terms_in, s.terms);
  BlockInputs<T> at = in;
  at.q = q;
  at.v = v;
  StepJointTerms<L> terms{jm_, s.terms, tau_ff, terms_in.armature, gyroscopic_weight(h)};
  aba_with<L>(km_, at, terms, s.ws, fields(s.qacc));
}

// Blocks `first` and, with count 2, `first + 1`, one step each: both up to
// their solver rows, the rows' solves side by side (solve_blocks), then
// both to the end. The same bits as one block at a time.
// Only a block whose first round is contact rows alone, few enough to be
// swept unrolled, waits for the second: the side-by-side sweeps pay there
// (docs/performance.md), while two blocks of a large model with joint rows
// would only crowd the cache.
template <class L>
void StepEngine<L>::step_blocks(int first, int count, T h, bool first_run, Scratch* s) {
  begin_block(first, h, s[0]);
  const ContactScratch<L>& c = s[0].contacts;
  const bool pair = count == 2 && s[0].solving && !s[0].joint_rows_needed && c.k == 3 && c.slots <= kMaxUnrolledSlots;
  if (pair) begin_block(first + 1, h, s[1]);
  solve_blocks(s, pair ? 2 : 1, h);
  end_block(first, h, first_run, s[0]);
  if (pair) {
    end_block(first + 1, h, first_run, s[1]);
  } else if (count == 2) {
    begin_block(first + 1, h, s[0]);
    solve_blocks(s, 1, h);
    end_block(first + 1, h, first_run, s[0]);
  }
}

// The step of one block up to its solver rows: the input checks, the
// dynamics (the whole step with RK4), the contacts found and the rows set
// up (s.solving: the block has rows to solve).
template <class L>
void StepEngine<L>::begin_block(int block, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  StepBatch<T>& B = batch_;
  const int nv = km_.nv;
  const T* q = B.state.q.block(block);
  const T* v = B.state.v.block(block);
  const T* tau_ff = B.state.tau.block(block);
  s.clock.start();
  s.solving = false;

  // Inputs that are not finite fault their copy; when several are, the
  // torque is named before the targets, the wrench and gravity.
  s.input_fault = L(T(0));
  const std::pair<lane::mask_t<L>, Fault> checks[] = {
      {any_non_finite<L>(B.state.gravity.block(block), 3), Fault::NonFiniteGravity},
      {any_non_finite<L>(B.state.wrench.block(block), plan_.wrenches ? 6 * km_.nbody : 0), Fault::NonFiniteWrench},
      {plan_.drives ? any_non_finite<L>(B.target_q.block(block), driven_q_) ||
                          any_non_finite<L>(B.target_v.block(block), driven_v_)
                    : lane::mask_t<L>(false),
       Fault::NonFiniteTarget},
      {any_non_finite<L>(tau_ff, nv) ||
           any_non_finite<L>(B.actuator_command.block(block), static_cast<int>(jm_.motors.size())),
       Fault::NonFiniteTorque}};
  for (const auto& [bad, code] : checks) s.input_fault = lane::select(bad, fault_code<L>(code), s.input_fault);

  BlockInputs<T> in;
  in.inertia = inertia(block);
  in.gravity = B.state.gravity.block(block);
  in.wrench = plan_.wrenches ? B.state.wrench.block(block) : nullptr;
  in.link_damping = plan_.link_damping;
  in.link_damping_weight = static_cast<T>(link_damping_weight(options_.integrator, h));
  const JointTermInputs<T> terms_in{q,
                                    v,
                                    B.target_q.block(block),
                                    B.target_v.block(block),
                                    joint_parameter(B.drive_stiffness, scene_drive_stiffness_, block),
                                    joint_parameter(B.drive_damping, scene_drive_damping_, block),
                                    joint_parameter(B.joint_damping, scene_damping_, block),
                                    joint_parameter(B.armature, scene_armature_, block),
                                    B.actuator_command.block(block),
                                    B.actuator_strength.block(block)};
  for (int k = 0; k < nv; ++k) s.u0[k] = lane::load<L>(v + k * W);

  if (options_.integrator == Integrator::RK4) {
    rk4_block(in, tau_ff, terms_in, q, h, fields(s.q_next), s);
    record_actuator_states(block, s);
    s.clock.lap(&StepProfile::dynamics);
    return;
  }
  free_acceleration(q, v, h, in, tau_ff, terms_in, JointTerms::AtThisState, s);
  record_actuator_states(block, s);
  // u1 with the Free joints' linear velocities in the frame at the start of
  // the step (add_frame_turn_rate); back into the body frame at the end.
  for (int k = 0; k < nv; ++k) s.u1[k] = lane::fmadd(L(h), s.qacc[k], s.u0[k]);
  add_frame_turn_rate<L>(km_, v, fields(s.qacc), gyroscopic_weight(h), h, fields(s.u1));
  const bool trapezoid = options_.integrator == Integrator::Trapezoid;
  if (trapezoid) heun_velocity(in, tau_ff, terms_in, q, h, s);
  s.rows_at_rest = lane::mask_t<L>(true);
  const bool contacts = !contact_pairs_.empty();
  // rows see the step's q: the trapezoid's predictor moved the joint transforms
  if (trapezoid && (contacts || !row_specs_.empty())) joint_transforms<L>(km_, q, s.ws);
  s.clock.lap(&StepProfile::dynamics);
  s.contacts.slots = 0;
  if (contacts) {
    world_transforms<L>(km_, s.ws);
    detect_contacts<L>(km_, contact_pairs_, contact_params_, fields(s.u1), h, s.ws, contact_arrays(block),
                       s.contacts);
    s.clock.lap(&StepProfile::contact_detection);
  }
  if (!row_specs_.empty() || s.contacts.slots > 0) prepare_rows(block, q, h, s);
  else if (options_.solver == SolverType::TGS)
    for (int k = 0; k < nv; ++k) s.displacement[k] = L(h) * s.u1[k];
  s.clock.lap(&StepProfile::constraint_solve);
}

// The step of one block after its rows' solve: the rows' impulses applied,
// the contacts stored, the positions integrated, the fault check.
template <class L>
void StepEngine<L>::end_block(int block, T h, bool first_run, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  StepBatch<T>& B = batch_;
  const int nq = km_.nq, nv = km_.nv;
  T* q = B.state.q.block(block);
  T* v = B.state.v.block(block);
  T* q_next = fields(s.q_next);
  s.clock.start();
  if (options_.integrator != Integrator::RK4) {
    if (s.solving) finish_rows(block, h, s);
    if (!floating_roots_.empty()) linear_momentum_target(block, h, s);
    if (!contact_pairs_.empty()) {
      const L* impulses = s.rows.rows.lambda.data() + row_specs_.size();
      store_contacts<L>(s.contacts, impulses, s.rows_at_rest, contact_arrays(block), first_run);
      if (B.contact_wrench.size() > 0) {  // the step's sum over its runs
        T* sum = B.contact_wrench.block(block);
        if (first_run) std::fill_n(sum, B.contact_wrench.size() * W, T(0));
        add_contact_wrenches<L>(s.contacts, impulses, s.rows_at_rest, contact_bodies_, sum);
      }
    }
    s.clock.lap(&StepProfile::constraint_solve);
    if (options_.record_motion) record_motion(block, h, s);
    T* velocity = fields(s.qacc);  // free again: the position velocity
    const T step = position_velocity(s, h, velocity);
    integrate<L>(km_, q, velocity, step, q_next);
    turn_free_linear<L>(km_, velocity, step, fields(s.u1), Turn::ToEnd);
  } else if (options_.record_motion) {
    record_motion(block, h, s);
  }
  if (options_.record_applied_torque) record_applied(block, h, first_run, s);
  if (!floating_roots_.empty()) keep_linear_momentum(block, q_next, h, s);

  // Faults: a copy with non-finite inputs or state is flagged; with
  // reset_on_fault it restarts from its initial state.
  lane::mask_t<L> bad_state = any_non_finite<L>(q_next, nq);
  for (int k = 0; k < nv; ++k) bad_state = bad_state || !lane::is_finite(s.u1[k]);
  const L zero(T(0));
  const L new_fault = lane::select(s.input_fault != zero, s.input_fault,
                                   lane::select(bad_state, fault_code<L>(Fault::NonFiniteState), zero));
  T* fault = B.fault.block(block);
  const L old_fault = lane::load<L>(fault);
  lane::store(lane::select(old_fault != zero, old_fault, new_fault), fault);
  T* qacc_out = B.state.qacc.block(block);
  for (int k = 0; k < nv; ++k) lane::store((s.u1[k] - s.u0[k]) / L(h), qacc_out + k * W);
  if (options_.reset_on_fault) {
    const auto restart = new_fault != zero;
    const T* q_init = B.initial_q.block(block);
    const T* v_init = B.initial_v.block(block);
    for (int i = 0; i < nq; ++i)
      lane::store(lane::select(restart, lane::load<L>(q_init + i * W), lane::load<L>(q_next + i * W)), q + i * W);
    for (int k = 0; k < nv; ++k) lane::store(lane::select(restart, lane::load<L>(v_init + k * W), s.u1[k]), v + k * W);
    // no warm start, no contacts to warm-start from, no momentum to carry
    auto clear = [&](BatchArray<T>& a, T value) {
      T* p = a.block(block);
      for (int i = 0; i < a.size(); ++i) lane::store(lane::select(restart, L(value), lane::load<L>(p + i * W)), p + i * W);
    };
    clear(B.impulse, T(0));
    clear(B.contact_id, T(-1));
    clear(B.contact_wrench, T(0));
    clear(B.momentum_remainder, T(0));
    clear(B.motion_recorded, T(0));
    clear(B.actuator_state, T(0));
  } else {
    for (int i = 0; i < nq; ++i) lane::store(lane::load<L>(q_next + i * W), q + i * W);
    for (int k = 0; k < nv; ++k) lane::store(s.u1[k], v + k * W);
  }
  s.clock.lap(&StepProfile::integration);
}

// Positions move by velocity * step. Copies whose rows act this step move
// by what the solver leaves: PGS by v1, so that the speculative limit rows
// hold exactly, TGS by its substeps' displacement. The others move by the
// integrator's velocity: semi-implicit Euler v1, explicit Euler v0,
// trapezoid (v0 + v1)/2.
// TGS returns a displacement (the scale 1), the others a velocity (h).
template <class L>
lane::scalar_t<L> StepEngine<L>::position_velocity(const Scratch& s, T h, T* velocity) const {
  constexpr std::size_t W = lane::width_v<L>;
  const bool tgs = options_.solver == SolverType::TGS;
  const bool trapezoid = options_.integrator == Integrator::Trapezoid;
  const bool explicit_euler = options_.integrator == Integrator::ExplicitEuler;
  const L scale(tgs ? h : T(1));
  for (int k = 0; k < km_.nv; ++k) {
    const L acting = tgs ? s.displacement[k] : s.u1[k];
    const L resting = trapezoid        ? scale * (L(T(0.5)) * (s.u0[k] + s.u1[k]))
                      : explicit_euler ? scale * s.u0[k]
                                       : scale * s.u1[k];
    lane::store(lane::select(s.rows_at_rest, resting, acting), velocity + k * W);
  }
  return tgs ? T(1) : h;
}

// The trapezoidal rule's velocity, explicit (Heun): the acceleration a1 at
// (q0, v0) is in s.qacc and v0 + h a1 in s.u1; a2 at the Euler predictor
// (q0 (+) h v0, v0 + h a1) joins it, v1 = v0 + h (a1 + a2) / 2. With
// positions moved by (v0 + v1) / 2 the step is second order. Both take the
// joint effects found at (q0, v0) with weight h/2 (joint_term_weight): their
// part is the implicit trapezoidal rule's.
template <class L>
void StepEngine<L>::heun_velocity(const BlockInputs<T>& in, const T* tau_ff, const JointTermInputs<T>& terms_in,
                                  const T* q0, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km_.nv;
  // Both accelerations are taken as the Free joints' classical accelerations
  // in the frame at the start of the step, like s.u1 (add_frame_turn_rate).
  T* a1 = fields(s.a_sum);
  T* q_predicted = fields(s.q_stage);
  T* v_predicted = fields(s.v_stage);
  for (int k = 0; k < nv; ++k) {
    lane::store(s.qacc[k], a1 + k * W);
    lane::store(s.u1[k], v_predicted + k * W);
  }
  add_frame_turn_rate<L>(km_, terms_in.v, a1, gyroscopic_weight(h), T(1), a1);
  integrate<L>(km_, q0, terms_in.v, h, q_predicted);
  turn_free_linear<L>(km_, terms_in.v, h, v_predicted, Turn::ToEnd);
  free_acceleration(q_predicted, v_predicted, h, in, tau_ff, terms_in, JointTerms::AsFound, s);
  T* a2 = fields(s.qacc);
  add_frame_turn_rate<L>(km_, v_predicted, a2, gyroscopic_weight(h), T(1), a2);
  turn_free_linear<L>(km_, terms_in.v, h, a2, Turn::ToStart);
  const L half_h(T(0.5) * h);
  for (int k = 0; k < nv; ++k) s.u1[k] = lane::fmadd(half_h, lane::load<L>(a1 + k * W) + s.qacc[k], s.u0[k]);
}

// Classic RK4 on (q, v) with the joint effects evaluated at every stage
// (RaiSim: steps 1-4 at the state of the stage), explicitly; positions move
// on the manifold from q0 by the stages' slopes in its tangent space (RKMK
// for the turns: turn_rate_at_start). s.terms ends with the
// stages' forces averaged by RK4's weights: what acted over the step.
template <class L>
void StepEngine<L>::rk4_block(const BlockInputs<T>& in, const T* tau_ff, const JointTermInputs<T>& terms_in,
                              const T* q0, T h, T* q_out, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km_.nv;
  const T* v0 = terms_in.v;
  T* qs = fields(s.q_stage);
  T* vs = fields(s.v_stage);
  T* vsum = fields(s.v_sum);
  T* asum = fields(s.a_sum);
  // stage 1 at (q0, v0)
  free_acceleration(q0, v0, h, in, tau_ff, terms_in, JointTerms::AtThisState, s);
  for (int k = 0; k < nv; ++k) {
    lane::store(s.u0[k], vsum + k * W);
    lane::store(s.qacc[k], asum + k * W);
    s.command_sum[k] = s.terms.command[k];
    s.passive_sum[k] = s.terms.passive[k];
    s.actuation_sum[k] = s.terms.actuation[k];
  }
  const T fractions[3] = {T(0.5) * h, T(0.5) * h, h};
  const T weights[3] = {T(2), T(2), T(1)};
  T* previous = fields(s.u_free);  // the velocity q moved with to this stage
  for (int k = 0; k < nv; ++k) lane::store(s.u0[k], previous + k * W);
  for (int stage = 0; stage < 3; ++stage) {
    const T c = fractions[stage];
    // q at the stage from the previous stage's velocity, then v likewise
    integrate<L>(km_, q0, previous, c, qs);
    for (int k = 0; k < nv; ++k) lane::store(lane::fmadd(L(c), s.qacc[k], s.u0[k]), vs + k * W);
    free_acceleration(qs, vs, h, in, tau_ff, terms_in, JointTerms::AtThisState, s);
    // The positions move with the world velocities of the stages, R_s v_s,
    // expressed at q0 (turn_free_linear), and turn with the slopes of their
    // rotation vectors from q0 (turn_rate_at_start): the velocities
    // themselves are integrated in body coordinates, where the
    // accelerations are.
    turn_free_linear<L>(km_, previous, c, vs, Turn::ToStart);
    turn_rate_at_start<L>(km_, previous, c, vs);
    for (int k = 0; k < nv; ++k) lane::store(lane::load<L>(vs + k * W), previous + k * W);
    const L w(weights[stage]);
    for (int k = 0; k < nv; ++k) {
      lane::store(lane::fmadd(w, lane::load<L>(vs + k * W), lane::load<L>(vsum + k * W)), vsum + k * W);
      lane::store(lane::fmadd(w, s.qacc[k], lane::load<L>(asum + k * W)), asum + k * W);
      s.command_sum[k] = lane::fmadd(w, s.terms.command[k], s.command_sum[k]);
      s.passive_sum[k] = lane::fmadd(w, s.terms.passive[k], s.passive_sum[k]);
      s.actuation_sum[k] = lane::fmadd(w, s.terms.actuation[k], s.actuation_sum[k]);
    }
  }
  const T sixth = h / T(6);
  const L one_sixth(T(1) / T(6));
  for (int k = 0; k < nv; ++k) {
    s.u1[k] = lane::fmadd(L(sixth), lane::load<L>(asum + k * W), s.u0[k]);
    s.terms.command[k] = one_sixth * s.command_sum[k];
    s.terms.passive[k] = one_sixth * s.passive_sum[k];
    s.terms.actuation[k] = one_sixth * s.actuation_sum[k];
  }
  integrate<L>(km_, q0, vsum, sixth, q_out);
}

// The block's solver rows (joint rows, then the contacts found) at u* =
// s.u1, their warm start, Mt's factors and D's contact block. Lanes where
// no row needs an impulse keep a zero impulse exactly; a block where all
// lanes are so skips the rows (the same result, bit for bit, as solving)
// and is done here; otherwise s.solving, and solve_blocks and finish_rows
// follow.
template <class L>
void StepEngine<L>::prepare_rows(int block, const T* q, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  JointRowScratch<L>& rs = s.rows;
  RowBlock<L>& rows = rs.rows;
  ContactScratch<L>& contacts = s.contacts;
  const int mj = static_cast<int>(row_specs_.size()), mc = contacts.k * contacts.slots;
  rows.m = mj + mc;
  const T erp = static_cast<T>(options_.error_reduction);
  const T* friction = joint_parameter(batch_.joint_friction, scene_friction_, block);
  const L zero(T(0)), warm(static_cast<T>(options_.warm_start));
  // Without contacts the joint rows are tested before they are built (a
  // block at rest builds none); with them, built and tested once, each
  // row's slack at the free velocity kept in s.need until `rest` is known.
  lane::mask_t<L> rest(true), joint_rows_slack(true);
  if (mc > 0 || !joint_rows_all_at_rest<L>(row_specs_, q, s.u1.data(), friction, h, erp))
    rest = joint_rows_slack = build_joint_rows<L>(row_specs_, q, s.u1.data(), friction, h, erp, rs, s.need);
  // the contact rows where a round of them alone solves them, s.needed
  // (spill_contact_rows moves them behind the joint rows if a round needs
  // joint rows too)
  RowBlock<L>& contact_rows = s.needed;
  contact_rows.m = mc;
  if (mc > 0) {
    build_contact_rows<L>(contact_params_, contact_arrays(block), s.u1.data(), s.u0.data(), h, contacts, contact_rows);
    rest = rest && contact_rows_at_rest<L>(contact_rows, contacts);
  }
  s.rows_at_rest = rest;
  if (lane::all<L>(rest)) {
    T* impulse = batch_.impulse.block(block);
    for (int r = 0; r < mj; ++r) lane::store(zero, impulse + r * W);
    if (options_.solver == SolverType::TGS)
      for (int k = 0; k < km_.nv; ++k) s.displacement[k] = L(h) * s.u1[k];
    return;
  }
  s.solving = true;
  const T* impulse = batch_.impulse.block(block);
  // stored along J / sigma (finish_rows): a row whose sigma turned since
  // (a joint heading for its other limit, a mimic error crossing zero)
  // starts from the impulse that pushes as the last one did
  for (int r = 0; r < mj; ++r)
    rows.lambda[r] = lane::select(rest, zero, warm * rs.sigma[r] * lane::load<L>(impulse + r * W));
  for (int i = 0; i < mc; ++i) contact_rows.lambda[i] = contact_warm_start(s, i);
  // Mt's factors: from the step's one ABA at q (both Eulers: with link
  // damping's w D, body_terms.hpp), or, where the trapezoid's second ABA ran
  // at its predicted state, by CRBA (its link damping is explicit)
  T* H = factors(s);
  if (euler_velocity(options_.integrator))
    ltdl_factor_from_aba<L>(km_, s.ws, s.terms.implicit_diagonal.data(), H);
  else
    factor_step_mass_matrix<L>(km_, inertia(block), s.terms.implicit_diagonal.data(), s.ws);
  if (mc > 0) contact_delassus<L>(km_, contact_params_, H, h, contacts, contact_rows);
  std::fill(s.column_built.begin(), s.column_built.end(), 0);  // built by the first round that needs them
  s.contact_columns = false;
  s.contact_rows_spilled = false;
  for (int k = 0; k < km_.nv; ++k) s.u_free[k] = s.u1[k];
  // the joint rows a lane needs at the free velocity (solve_blocks); a
  // row on several DOFs (a mimic's, a tendon's) wherever the lane solves,
  // or the other rows' impulses would break it
  for (int r = 0; r < mj; ++r)
    s.need[r] = r < coupled_rows_ ? !rest : !rest && !s.need[r];  // s.need held the row's slack
  s.joint_rows_needed = lane::any<L>(!rest && (coupled_rows_ > 0 ? lane::mask_t<L>(true) : !joint_rows_slack));
}

// The columns of Mt^-1 that the round's joint rows read D off
// (build_round) and apply their impulses through, those not built yet this
// step; and the contact rows' (their coupling with the joint rows).
template <class L>
void StepEngine<L>::build_joint_columns(Scratch& s) const {
  int n = 0;
  for (int a = 0; a < s.needed_joint_rows; ++a) {
    const JointRowSpec<T>& spec = row_specs_[s.needed_source[a]];
    for_each_term(spec, [&](const RowTerm<T>& term) {
      if (s.column_built[term.column]) return;
      s.column_built[term.column] = 1;
      s.new_columns[n++] = term.column;
    });
  }
  joint_row_columns<L>(km_, columns_, s.ws, s.rows, s.new_columns.data(), n);
  build_contact_columns(s);
}

// The contact rows' columns Mt^-1 J^T (contact_columns).
template <class L>
void StepEngine<L>::build_contact_columns(Scratch& s) const {
  if (s.contact_columns) return;
  if (s.contacts.slots > 0) contact_columns<L>(km_, factors(s), s.contacts);
  s.contact_columns = true;
}

// For check_held_rows, the round's coupling of every distinct joint-row DOF
// d with its rows a: C_da = (Mt^-1 J_a^T)[d], so that d's velocity is
// u_free[d] + sum_a C_da lambda_a; a one-DOF joint row r on d has the
// velocity sigma_r times that. D's joint row r is sigma_r C_r. (sigma_r = +-1:
// the product is exact, and so is the sum's sign, so v_r has the bits of
// v_free_r + sum_a D_ra lambda_a.)
template <class L>
void StepEngine<L>::build_held_coupling(Scratch& s) const {
  const RowBlock<L>& sub = s.needed;
  const int nv = km_.nv, n = sub.m, nj = s.needed_joint_rows;
  build_contact_columns(s);
  const JointRowScratch<L>& rs = s.rows;
  for (int d = 0; d < columns_.size(); ++d) {
    const int dof = columns_.dof[d];
    L* C = &s.held_coupling[d * n];
    for (int a = 0; a < nj; ++a) {
      const int r = s.needed_source[a];
      C[a] = rs.sigma[r] * joint_row_response(row_specs_[r], rs, nv, dof);
    }
    for (int a = nj; a < n; ++a) C[a] = s.contacts.X[(a - nj) * nv + dof];
  }
}

// s.u1 (and TGS's displacement) from the solved impulses, and the joint
// rows' impulses stored as the next step's warm start.
template <class L>
void StepEngine<L>::finish_rows(int block, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km_.nv, mj = static_cast<int>(row_specs_.size());
  JointRowScratch<L>& rs = s.rows;
  RowBlock<L>& rows = rs.rows;
  ContactScratch<L>& contacts = s.contacts;
  const lane::mask_t<L> rest = s.rows_at_rest;
  const T* H = factors(s);
  const bool contact_rows = contacts.slots > 0;
  if (options_.solver != SolverType::TGS) {
    for (int k = 0; k < nv; ++k) s.u1[k] = lane::select(rest, s.u_free[k], s.u1[k] + contacts.dv[k]);
  } else {
    const int* joint_rows = s.needed_source.data();
    const int nj = s.needed_joint_rows;
    add_row_impulses<L>(km_, row_specs_, rs, joint_rows, nj, s.needed.lambda.data(), s.u1.data());
    if (contact_rows) add_contact_impulses<L>(km_, H, rows.lambda.data() + mj, contacts, s.u1.data());
    for (int k = 0; k < nv; ++k) s.u1[k] = lane::select(rest, s.u_free[k], s.u1[k]);
    for (int k = 0; k < nv; ++k) s.displacement[k] = L(h) * s.u_free[k];
    add_row_impulses<L>(km_, row_specs_, rs, joint_rows, nj, s.needed.lambda_sum.data(), s.displacement.data());
    if (contact_rows) add_contact_impulses<L>(km_, H, rows.lambda_sum.data() + mj, contacts, s.displacement.data());
    for (int k = 0; k < nv; ++k) s.displacement[k] = lane::select(rest, L(h) * s.u_free[k], s.displacement[k]);
  }
  const L zero(T(0));
  T* impulse = batch_.impulse.block(block);
  for (int r = 0; r < mj; ++r) lane::store(lane::select(rest, zero, rs.sigma[r] * rows.lambda[r]), impulse + r * W);
}

// PGS or TGS on the rows each lane needs, for the `count` blocks of s that
// are solving, side by side. A joint row needs an impulse in a lane where
// its velocity leaves its band at zero impulse: first at the free velocity
// (joint friction nearly always, a limit when the joint heads past it),
// then at the velocities the solve leaves (for TGS at any substep, its
// target following its displacement). Each round solves, from the warm
// start, the contact rows with the joint rows some lane needs; in a lane
// that does not need one of them, that row is held at zero impulse (box
// [0, 0]), adds nothing to the other rows' velocities, and the sweeps
// leave it at zero: the lane's result is that of its own rows, whatever the
// other lanes need. A lane where a row held at zero then needs an impulse
// takes it, and every lane solves again, until none does; each round adds
// a row, so there are at most as many rounds as joint rows, and a lane's
// rows held at zero end the solve slack. A standing robot solves its
// contacts alone; a humanoid with 84 joint rows, of which its 20 friction
// rows and a few limits act, solves those rather than all 84. Two blocks
// in the same round sweep together (pgs_solve_pair), each with its own
// result. Leaves the impulses (and TGS's lambda_sum) in s.rows, 0 on the
// joint rows held at zero; for PGS their velocity change Mt^-1 J^T lambda
// in s.contacts.dv.
template <class L>
void StepEngine<L>::solve_blocks(Scratch* s, int count, T h) {
  const int mj = static_cast<int>(row_specs_.size());
  bool active[2] = {false, false};
  for (int i = 0; i < count; ++i) {
    if (!s[i].solving) continue;
    if (!active[0]) s[i].clock.start();
    active[i] = true;
  }
  const bool tgs = options_.solver == SolverType::TGS;
  while (active[0] || active[1]) {
    Scratch* round[2];
    int n = 0;
    for (int i = 0; i < count; ++i)
      if (active[i]) {
        build_round(s[i], h);
        round[n++] = &s[i];
      }
    solve_round(round, n, h);
    for (int i = 0; i < count; ++i)
      if (active[i]) active[i] = end_round(s[i]);
  }
  for (int i = 0; i < count; ++i) {
    if (!s[i].solving) continue;
    RowBlock<L>& rows = s[i].rows.rows;
    const RowBlock<L>& sub = s[i].needed;
    for (int r = 0; r < mj; ++r) rows.lambda[r] = rows.lambda_sum[r] = L(T(0));
    for (int a = 0; a < sub.m; ++a) {
      const int r = s[i].needed_source[a];
      rows.lambda[r] = sub.lambda[a];
      if (tgs) rows.lambda_sum[r] = sub.lambda_sum[a];
    }
  }
  // the blocks' solves overlap: their time goes to the first one's clock
  for (int i = 0; i < count; ++i)
    if (s[i].solving) {
      s[i].clock.lap(&StepProfile::constraint_solve);
      break;
    }
}

// Row r of `from` as row a of `to`, its bound row shifted by `shift` (a
// contact friction row names its normal row), and its impulse box and
// warm start held at zero in the lanes outside `keep`.
template <class L>
void copy_row(const RowBlock<L>& from, int r, RowBlock<L>& to, int a, int shift, const lane::mask_t<L>& keep) {
  using T = lane::scalar_t<L>;
  const L zero(T(0));
  to.bound_row[a] = from.bound_row[r] < 0 ? -1 : from.bound_row[r] + shift;
  to.mu[a] = from.mu[r];
  to.cone[a] = from.cone[r];
  to.positional[a] = from.positional[r];
  to.rate[a] = from.rate[r];
  to.floor[a] = from.floor[r];
  to.ceiling[a] = from.ceiling[r];
  to.error[a] = from.error[r];
  to.v_free[a] = from.v_free[r];
  to.target[a] = from.target[r];
  to.target_hi[a] = from.target_hi[r];
  to.lo[a] = lane::select(keep, from.lo[r], zero);
  to.hi[a] = lane::select(keep, from.hi[r], zero);
  to.lambda[a] = lane::select(keep, from.lambda[r], zero);
}

// Contact row i's warm start: last step's impulse of its point, zero in
// lanes where no row acts.
template <class L>
L StepEngine<L>::contact_warm_start(const Scratch& s, int i) const {
  return lane::select(s.rows_at_rest, L(T(0)), L(static_cast<T>(options_.warm_start)) * s.contacts.warm[i]);
}

// The contact rows, built in s.needed by prepare_rows, moved behind the
// joint rows in s.rows with their warm start (a round of the contact rows
// alone has changed their impulses since): before the first round that
// needs joint rows too.
template <class L>
void StepEngine<L>::spill_contact_rows(Scratch& s) const {
  if (s.contact_rows_spilled) return;
  RowBlock<L>& rows = s.rows.rows;
  const RowBlock<L>& contact_rows = s.needed;
  const int mj = static_cast<int>(row_specs_.size()), m = rows.m, mc = m - mj;
  const lane::mask_t<L> all(true);
  for (int a = 0; a < mc; ++a) {
    copy_row(contact_rows, a, rows, mj + a, mj, all);
    rows.lambda[mj + a] = contact_warm_start(s, a);
    for (int b = 0; b < mc; ++b) rows.D[(mj + a) * m + mj + b] = contact_rows.D[a * mc + b];
  }
  s.contact_rows_spilled = true;
}

// A round's rows in s.needed: the joint rows some lane needs (held at zero
// in the others), then the contact rows. A round of the contact rows
// alone solves them where prepare_rows built them. D's entries of the
// joint rows are read off the columns of Mt^-1 here (joint_row_delassus,
// J_r X_i), only those of the rows the round takes, with a spring row's
// compliance over the run's step h on its diagonal; the contacts' own
// block from where spill_contact_rows put it.
template <class L>
void StepEngine<L>::build_round(Scratch& s, T h) const {
  const RowBlock<L>& rows = s.rows.rows;
  RowBlock<L>& sub = s.needed;
  const int mj = static_cast<int>(row_specs_.size()), m = rows.m;
  int nj = 0;
  for (int r = 0; r < mj; ++r)
    if (lane::any<L>(s.need[r])) s.needed_source[nj++] = r;
  s.needed_joint_rows = nj;
  const int n = nj + m - mj;
  for (int a = nj; a < n; ++a) s.needed_source[a] = mj + a - nj;
  if (nj == 0) return;  // rounds only add joint rows: this is the first, from the warm start
  build_joint_columns(s);
  spill_contact_rows(s);
  sub.m = n;
  const lane::mask_t<L> all(true);
  const int nv = km_.nv;
  const int* source = s.needed_source.data();
  L* D = sub.D.data();
  for (int a = 0; a < n; ++a) {
    const int r = source[a];
    copy_row(rows, r, sub, a, nj - mj, a < nj ? s.need[r] : all);  // contact friction: its normal
    if (a < nj) {
      for (int b = 0; b < nj; ++b) D[a * n + b] = joint_row_delassus<L>(row_specs_, s.rows, nv, r, source[b]);
      const T compliance = row_compliance(row_specs_[r], h);  // a spring row's
      if (compliance != T(0)) D[a * n + a] += L(compliance);
      // the coupling with the contacts, J_r X_i (X_i = Mt^-1 J_i^T,
      // contact_columns), into both of its entries
      const L sigma = s.rows.sigma[r];
      for (int b = nj; b < n; ++b)
        D[a * n + b] = D[b * n + a] = sigma * joint_row_dofs(row_specs_[r], &s.contacts.X[(source[b] - mj) * nv]);
    } else {
      for (int b = nj; b < n; ++b) D[a * n + b] = rows.D[r * m + source[b]];
    }
  }
}

// contacts.dv = Mt^-1 J^T lambda of s.needed's impulses.
template <class L>
void StepEngine<L>::needed_velocity_change(Scratch& s) const {
  const int nj = s.needed_joint_rows;
  const RowBlock<L>& sub = s.needed;
  contact_velocity_change<L>(km_, factors(s), sub.lambda.data() + nj, s.contacts);
  add_row_impulses<L>(km_, row_specs_, s.rows, s.needed_source.data(), nj, sub.lambda.data(), s.contacts.dv.data());
}

// One round of `count` blocks (1 or 2) side by side: PGS, or TGS with each
// block's held rows checked at every substep (check_held_rows).
template <class L>
void StepEngine<L>::solve_round(Scratch* const* s, int count, T h) const {
  const int iterations = options_.iterations;
  if (options_.solver != SolverType::TGS) {
    if (count == 2) pgs_solve_pair(s[0]->needed, s[1]->needed, iterations);
    else pgs_solve(s[0]->needed, iterations);
    return;
  }
  const int mj = static_cast<int>(row_specs_.size());
  RowBlock<L>* blocks[2];
  for (int i = 0; i < count; ++i) {
    blocks[i] = &s[i]->needed;
    for (int r = 0; r < mj; ++r) s[i]->violated[r] = lane::mask_t<L>(false);
  }
  if (mj > 0)
    for (int i = 0; i < count; ++i) {
      build_held_coupling(*s[i]);
      begin_held_check(*s[i], h);
    }
  auto after_substep = [&](int i) { check_held_rows(*s[i], h); };
  if (count == 2) tgs_solve_blocks<2>(blocks, iterations, h, after_substep);
  else tgs_solve_blocks<1>(blocks, iterations, h, after_substep);
}

// The velocities of the DOFs [d, d + G) that carry joint rows, at the
// round's impulses: u_free + sum_a C_da lambda_a, each summed over a in
// order. G of them side by side, so that the core has G independent
// chains of multiply-adds rather than one.
template <int G, class L>
LOCKSTEP_INLINE void held_dof_velocities(const L* coupling, const L* lambda, int n, const L* u_free,
                                         const int* column_dof, int d, L* out) {
  L w[G];
  for (int g = 0; g < G; ++g) w[g] = u_free[column_dof[d + g]];
  for (int a = 0; a < n; ++a)
    for (int g = 0; g < G; ++g) w[g] = lane::fmadd(coupling[(d + g) * n + a], lambda[a], w[g]);
  for (int g = 0; g < G; ++g) out[d + g] = w[g];
}

// Before a TGS round: per distinct row DOF, the speed below which its
// rows held at zero in each lane stay at rest (row_speed_bound; no
// bound from a row the lane's round takes), and its displacement zero.
template <class L>
void StepEngine<L>::begin_held_check(Scratch& s, T h) const {
  const L inf(std::numeric_limits<T>::infinity()), zero(T(0));
  for (int c = 0; c < columns_.size(); ++c) {
    s.held_speed[c] = inf;
    s.dof_displacement[c] = zero;
  }
  for (int r = coupled_rows_; r < static_cast<int>(row_specs_.size()); ++r) {  // a coupled row is never held
    L& speed = s.held_speed[row_specs_[r].column];
    const L bound = row_speed_bound<L>(row_specs_[r], s.rows.rows.error[r], s.rows.rows.hi[r], h);
    speed = lane::select(s.need[r], speed, lane::min(speed, bound));
  }
  s.held_rows_near_band = false;
}

// After a TGS substep: s.violated gains the lanes where a joint row held at
// zero left its band, its target following its own displacement. The
// row's velocity is v_free + D lambda over the round's rows, read as
// sigma_r times its DOF's velocity (build_held_coupling): one sum per
// distinct DOF, no pass over the tree per substep. While every DOF has
// stayed below its held_speed in every lane, no held row can have left
// its band, and the rows are not tested.
template <class L>
void StepEngine<L>::check_held_rows(Scratch& s, T h) const {
  const int mj = static_cast<int>(row_specs_.size()), iterations = options_.iterations;
  const RowBlock<L>& rows = s.rows.rows;
  const RowBlock<L>& sub = s.needed;
  const int n = sub.m, columns = columns_.size();
  L* velocity = s.dof_velocity.data();
  int d = 0;
  for (; d + 4 <= columns; d += 4)
    held_dof_velocities<4>(s.held_coupling.data(), sub.lambda.data(), n, s.u_free.data(), columns_.dof.data(), d,
                           velocity);
  for (; d < columns; ++d)
    held_dof_velocities<1>(s.held_coupling.data(), sub.lambda.data(), n, s.u_free.data(), columns_.dof.data(), d,
                           velocity);
  L* displacement = s.dof_displacement.data();
  if (!s.held_rows_near_band) {
    lane::mask_t<L> slow(true);
    for (int c = 0; c < columns; ++c) slow = slow && (lane::abs(velocity[c]) <= s.held_speed[c]);
    s.held_rows_near_band = !lane::all<L>(slow);
  }
  if (s.held_rows_near_band) {
    // sigma through a local pointer, its data pointer loaded once rather
    // than per row (the mask store below may alias it). A row's
    // displacement is sigma_r times its DOF's: sigma_r = +-1, and rounding
    // to nearest is symmetric, so these are the bits of summing
    // sigma_r w_r per row.
    const L* sigma = s.rows.sigma.data();
    const L inv_substep(T(iterations) / h);
    for (int r = coupled_rows_; r < mj; ++r) {  // a coupled row is never held (prepare_rows)
      const int c = row_specs_[r].column;
      const L v = sigma[r] * velocity[c];
      const bool positional = rows.positional[r] != 0;
      const L target = positional ? tgs_target(rows, r, sigma[r] * displacement[c], inv_substep) : rows.target[r];
      const L target_hi = positional ? target : rows.target_hi[r];
      const auto rest = row_at_rest(v, target, target_hi, rows.lo[r], rows.hi[r], rows.error[r], positional);
      s.violated[r] = s.violated[r] || !rest;
    }
  }
  const L substep(h / T(iterations));
  for (int c = 0; c < columns; ++c) displacement[c] = lane::fmadd(substep, velocity[c], displacement[c]);
}

// After a round: PGS checks its held rows at the velocities it leaves;
// a lane where a held row left its band takes that row. True: the block
// solves another round.
template <class L>
bool StepEngine<L>::end_round(Scratch& s) const {
  const int mj = static_cast<int>(row_specs_.size());
  if (options_.solver != SolverType::TGS) {
    needed_velocity_change(s);
    for (int r = coupled_rows_; r < mj; ++r)  // a coupled row is never held (prepare_rows)
      s.violated[r] = !joint_row_slack<L>(row_specs_, s.rows, r, s.contacts.dv.data());
  }
  bool grew = false;
  for (int r = 0; r < mj; ++r) {
    const lane::mask_t<L> newly = !s.rows_at_rest && !s.need[r] && s.violated[r];
    if (lane::any<L>(newly)) {
      s.need[r] = s.need[r] || newly;
      grew = true;
    }
  }
  return grew;
}

// RaiSim's torque over the step by source, with dv = v1 - v0:
// drive tau_cmd - (w_drive / h) dv, passive f - (w_passive / h) dv, and the
// solver's impulses / h split into friction and limits (with the mimic
// couplings). With substeps, the
// mean over the step's pipeline runs (each adds its share, the first
// overwrites).
template <class L>
void StepEngine<L>::record_applied(int block, T h, bool first_run, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km_.nv;
  const L inv_h(T(1) / h), share(T(1) / static_cast<T>(options_.substeps));
  T* drive = batch_.applied_drive.block(block);
  T* passive = batch_.applied_passive.block(block);
  T* friction = batch_.applied_friction.block(block);
  T* limits = batch_.applied_limits.block(block);
  T* actuation = batch_.applied_actuation.block(block);
  auto add = [&](T* out, const L& torque, bool first) {
    lane::store(first ? share * torque : lane::fmadd(share, torque, lane::load<L>(out)), out);
  };
  for (int k = 0; k < nv; ++k) {
    const L rate = (s.u1[k] - s.u0[k]) * inv_h;
    add(drive + k * W, lane::fnmadd(s.terms.drive_implicit[k], rate, s.terms.command[k]), first_run);
    add(passive + k * W, lane::fnmadd(s.terms.passive_implicit[k], rate, s.terms.passive[k]), first_run);
    add(actuation + k * W, s.terms.actuation[k], first_run);
    if (first_run) lane::store(L(T(0)), friction + k * W), lane::store(L(T(0)), limits + k * W);
  }
  // a row on several DOFs acts on each (J^T lambda): a mimic's and a
  // tendon limit's with the limits, a tendon spring's with the passive
  // torques
  const T* impulse = batch_.impulse.block(block);
  for (std::size_t r = 0; r < row_specs_.size(); ++r) {
    const JointRowSpec<T>& spec = row_specs_[r];
    T* out = spec.kind == JointRowKind::Friction       ? friction
             : spec.kind == JointRowKind::TendonSpring ? passive
                                                       : limits;
    const L torque = lane::load<L>(impulse + r * W) * inv_h;  // stored along J / sigma (finish_rows)
    for_each_term(spec, [&](const RowTerm<T>& term) { add(out + term.dof * W, L(term.coefficient) * torque, false); });
  }
}

template <class L>
void StepEngine<L>::record_actuator_states(int block, const Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const T* command = batch_.actuator_command.block(block);
  T* out = batch_.actuator_state.block(block);
  for (std::size_t m = 0; m < jm_.motors.size(); ++m) {
    lane::store(lane::load<L>(command + m * W), out + 3 * m * W);
    lane::store(s.terms.motor_speed[m], out + (3 * m + 1) * W);
    lane::store(s.terms.motor_torque[m], out + (3 * m + 2) * W);
  }
}

// StepOptions::record_motion: the run's start state and acceleration
// (u1 - u0) / h, before q and v are overwritten. Except with RK4, which
// integrates in body coordinates, a Free joint's linear u1 is still in the
// frame at the start of the step: begin_block added h times the turn rate
// w0 x v0 to the spatial acceleration, which is taken out here, and with
// it the implicit gyroscopic force's part (linearised about the free
// acceleration in s.qacc), which is kept apart as unbalanced: the motion's
// acceleration holds it, while RNEA, which takes the velocity product at
// v0, balances the step's forces without it. (The momentum projection's
// correction joins both later: record_momentum_correction.)
template <class L>
void StepEngine<L>::record_motion(int block, T h, Scratch& s) {
  constexpr std::size_t W = lane::width_v<L>;
  const T* q = batch_.state.q.block(block);
  T* q_out = batch_.motion_q.block(block);
  T* v_out = batch_.motion_v.block(block);
  T* acceleration = batch_.motion_acceleration.block(block);
  for (int i = 0; i < km_.nq; ++i) lane::store(lane::load<L>(q + i * W), q_out + i * W);
  const L inv_h(T(1) / h);
  for (int k = 0; k < km_.nv; ++k) {
    lane::store(s.u0[k], v_out + k * W);
    lane::store((s.u1[k] - s.u0[k]) * inv_h, acceleration + k * W);
  }
  T* unbalanced = batch_.motion_unbalanced.block(block);
  for (int k = 0; k < km_.nv; ++k) lane::store(L(T(0)), unbalanced + k * W);
  if (options_.integrator != Integrator::RK4) {
    add_frame_turn_rate<L>(km_, v_out, fields(s.qacc), T(0), T(-1), acceleration);
    add_frame_turn_rate<L>(km_, v_out, fields(s.qacc), gyroscopic_weight(h), T(1), unbalanced, TurnPart::Implicit);
  }
  lane::store(L(T(1)), batch_.motion_recorded.block(block));
}

template class StepEngine<float>;
template class StepEngine<double>;
template class StepEngine<lane::simd<float>>;
template class StepEngine<lane::simd<double>>;

}  // namespace lockstep
