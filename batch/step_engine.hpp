// The step pipeline for one lane type L: the per-block stages of a
// simulation step (see docs/architecture.md, "The step") and the parallel
// loop over blocks. Simulator owns one Engine<L> for the chosen precision
// and lanes; this header is internal to batch/.
#pragma once

#include "batch/contact_pairs.hpp"
#include "batch/simulator.hpp"
#include "kernels/aba.hpp"
#include "kernels/contact_rows.hpp"
#include "kernels/joint_rows.hpp"
#include "kernels/joint_terms.hpp"

#include <chrono>
#include <memory>
#include <utility>

namespace lockstep {

// What the pipeline runs, decided once per scene by the Simulator.
struct StepPlan {
  bool drives = false, damping = false, springs = false, soft_limits = false, stribeck = false;
  bool wrenches = false;
  bool link_damping = false;
  bool per_copy_inertia = false;  // else every block reads block 0's inertias (all copies hold the model's)
  // else every block reads one block of the scene's drive gains, damping,
  // armature and joint friction (all copies hold those)
  bool per_copy_joint_parameters = false;
  bool mimic_joints = false, fixed_tendons = false, hard_limits = false, velocity_limits = false;
  bool coulomb_friction = false;
  bool contacts = false;
};

struct Simulator::Engine {
  virtual ~Engine() = default;
  // Per-phase CPU time of the steps taken while profiling, summed over threads.
  virtual void set_profiling(bool on) = 0;
  virtual StepProfile profile() const = 0;
  // `steps` steps of dt, each of `substeps` substeps, every block through
  // all of them before the next (a copy's state stays in cache).
  virtual void step(int steps, int substeps, double dt) = 0;
  // The non-row stages may change between steps (drive gains, wrenches).
  virtual void set_plan(const StepPlan& plan) = 0;
  virtual int copies() const = 0;
  virtual int rows() const = 0;
  // Each joint row's kind and DOF (a row on several DOFs: its kind with
  // minus its number of terms, then its kind with each term's DOF), in row
  // order: what the warm start's joint impulses belong to.
  virtual std::vector<std::pair<int, int>> row_layout() const = 0;
  virtual std::size_t bytes_per_copy() const = 0;
};

template <class L>
class StepEngine final : public Simulator::Engine {
 public:
  using T = lane::scalar_t<L>;
  static constexpr int kWidth = static_cast<int>(lane::width_v<L>);

  // pairs: the scene's candidate shape pairs (used when plan.contacts).
  StepEngine(const Model& model, int copies, const StepOptions& options, const std::vector<DofSettings>& dofs,
             const StepPlan& plan, const ContactPairs& pairs);

  void step(int steps, int substeps, double dt) override;
  void set_plan(const StepPlan& plan) override;
  void set_profiling(bool on) override;
  StepProfile profile() const override;
  int copies() const override { return batch_.copies(); }
  int rows() const override { return static_cast<int>(row_specs_.size()); }
  std::vector<std::pair<int, int>> row_layout() const override {
    std::vector<std::pair<int, int>> layout;
    for (const JointRowSpec<T>& row : row_specs_) {
      if (row.terms.empty()) layout.emplace_back(static_cast<int>(row.kind), row.dof);
      // a row on several DOFs: minus its number of terms, then their DOFs
      // (tendons over {0, 1} and {2} are not those over {0} and {1, 2})
      if (!row.terms.empty()) layout.emplace_back(static_cast<int>(row.kind), -static_cast<int>(row.terms.size()));
      for (const RowTerm<T>& term : row.terms) layout.emplace_back(static_cast<int>(row.kind), term.dof);
    }
    return layout;
  }
  std::size_t bytes_per_copy() const override { return batch_.bytes_per_copy(); }

  StepBatch<T>& batch() { return batch_; }
  const StepBatch<T>& batch() const { return batch_; }

 private:
  // A worker's time per phase of the step, when profiling: lap(p) adds the
  // time since the previous lap to phase p (one clock read per phase and
  // block, nothing without profiling).
  struct PhaseClock {
    bool on = false;
    std::chrono::steady_clock::time_point last;
    StepProfile seconds;
    void start() {
      if (on) last = std::chrono::steady_clock::now();
    }
    void lap(double StepProfile::*phase) {
      if (!on) return;
      const auto now = std::chrono::steady_clock::now();
      seconds.*phase += std::chrono::duration<double>(now - last).count();
      last = now;
    }
  };

  // Scratch of one worker for one block at a time; never per copy.
  struct Scratch {
    PhaseClock clock;
    Workspace<L> ws;
    JointTermScratch<L> terms;
    JointRowScratch<L> rows;  // joint rows first, then (spill_contact_rows) contact rows
    ContactScratch<L> contacts;
    std::vector<L> u0, u1, u_free, qacc, displacement;  // (nv)
    lane::mask_t<L> rows_at_rest = lane::mask_t<L>(true);  // lanes where no solver row acts this step
    // [field][lane] arrays, as lanes for their alignment; read through fields()
    std::vector<L> q_next;          // (nq) the step's new positions
    std::vector<L> q_stage, v_stage;  // RK4 stage state
    std::vector<L> v_sum, a_sum;      // RK4 weighted sums
    // solve_blocks's: the rows a round solves (the joint rows some lane
    // needs, then the contact rows, which prepare_rows builds here), each
    // one's row in `rows` (the contact rows' once spill_contact_rows has
    // put them there), and per joint row the lanes that need it, those
    // where it left its band held at zero
    RowBlock<L> needed;
    std::vector<int> needed_source;
    int needed_joint_rows = 0;  // the joint rows in `needed`, before its contact rows
    std::vector<lane::mask_t<L>> need, violated;
    // the columns of Mt^-1 built this step, per distinct row DOF
    // (build_joint_columns), and the list of those a round adds
    std::vector<unsigned char> column_built;
    std::vector<int> new_columns;
    // TGS's check of the held joint rows (check_held_rows): per distinct
    // row DOF, its velocity's coefficient of each row of the round, that
    // velocity at a substep, its displacement over the round so far, and
    // the speed below which its held rows stay at rest (row_speed_bound)
    std::vector<L> held_coupling;  // (columns x needed rows)
    std::vector<L> dof_velocity, dof_displacement, held_speed;  // (columns)
    bool held_rows_near_band = false;  // some substep of the round exceeded held_speed
    // keep_linear_momentum's, per floating root body: the momentum the step
    // must leave, as P(q0, v0) and the small rest (the external and the
    // rows' impulses and the last step's remainder), and the articulation's
    // mass
    std::vector<Vec3<L>> momentum_target, momentum_added;  // (nbody)
    std::vector<L> articulation_mass;      // (nbody)
    // rk4_block's sums of the stages' joint forces, by RK4's weights (nv)
    std::vector<L> command_sum, passive_sum, actuation_sum;
    // carried from begin_block to end_block
    L input_fault;
    bool solving = false;      // the block has rows to solve this step
    bool joint_rows_needed = false;  // some lane needs a joint row at the free velocity
    bool contact_columns = false;  // the contact rows' Mt^-1 J^T are built (build_contact_columns)
    bool contact_rows_spilled = false;  // the contact rows are in `rows` too (spill_contact_rows)
    Scratch(const KernelModel<T>& km, int motors, int joint_rows, int columns, const ContactParams<T>& contact,
            int candidates);
  };
  // A worker steps two blocks at a time (step_blocks).
  struct ScratchPair {
    Scratch s[2];
  };

  static T* fields(std::vector<L>& lanes) { return reinterpret_cast<T*>(lanes.data()); }
  // Mt's factors for the rows (ltdl_factor_from_aba's or CRBA's)
  static T* factors(Scratch& s) { return reinterpret_cast<T*>(s.ws.matrix.data()); }
  static const T* factors(const Scratch& s) { return reinterpret_cast<const T*>(s.ws.matrix.data()); }
  // first_run: the first of the step's pipeline runs (StepOptions::substeps)
  void step_blocks(int first, int count, T h, bool first_run, Scratch* s);
  void begin_block(int block, T h, Scratch& s);
  void end_block(int block, T h, bool first_run, Scratch& s);
  T gyroscopic_weight(T h) const;
  T joint_term_weight(T h) const;
  // ABA with the joint effects (s.terms) found at (q, v), or as an earlier
  // call found them: s.qacc. Needs nothing prepared.
  enum class JointTerms { AtThisState, AsFound };
  void free_acceleration(const T* q, const T* v, T h, const BlockInputs<T>& in, const T* tau_ff,
                         JointTermInputs<T> terms_in, JointTerms joint_terms, Scratch& s);
  // RK4 for scenes without rows: v1 in s.u1, q1 written to q_out.
  void rk4_block(const BlockInputs<T>& in, const T* tau_ff, const JointTermInputs<T>& terms_in, const T* q0, T h,
                 T* q_out, Scratch& s);
  // Trapezoid: s.u1 from v0 + h a1 to the average of two accelerations.
  void heun_velocity(const BlockInputs<T>& in, const T* tau_ff, const JointTermInputs<T>& terms_in, const T* q0, T h,
                     Scratch& s);
  // The velocity the positions move with, into velocity; returns its step.
  T position_velocity(const Scratch& s, T h, T* velocity) const;
  // Solver rows (joint rows, then the contacts found): set up from s.u1
  // (= u*) by prepare_rows, solved by solve_blocks (the rounds: build_round,
  // solve_round or the pair's sweeps, end_round), and finish_rows puts s.u1
  // (and TGS's displacement) after them.
  void prepare_rows(int block, const T* q, T h, Scratch& s);
  void build_joint_columns(Scratch& s) const;
  void build_contact_columns(Scratch& s) const;
  void build_held_coupling(Scratch& s) const;
  void solve_blocks(Scratch* s, int count, T h);
  L contact_warm_start(const Scratch& s, int i) const;
  void spill_contact_rows(Scratch& s) const;
  void build_round(Scratch& s, T h) const;
  void solve_round(Scratch* const* s, int count, T h) const;
  void begin_held_check(Scratch& s, T h) const;
  void check_held_rows(Scratch& s, T h) const;
  bool end_round(Scratch& s) const;
  void needed_velocity_change(Scratch& s) const;
  void finish_rows(int block, T h, Scratch& s);
  ContactArrays<T> contact_arrays(int block);
  int set_up_contacts(int copies, const ContactSettings& settings, const ContactPairs& pairs);
  void make_contact_arrays(int copies, int capacity, int rows_per_contact, const ContactSettings& settings);
  void record_applied(int block, T h, bool first_run, Scratch& s);
  // The motors' commands, speeds and torques of the run's last evaluation, per copy.
  void record_actuator_states(int block, const Scratch& s);
  void record_motion(int block, T h, Scratch& s);
  // StepOptions::conserve_linear_momentum (batch/step_momentum.cpp): the
  // target from the start of the step, before the Free joints' velocities
  // turn to the end frame; then the bases' velocities corrected at q1 (and,
  // with record_motion, the recorded motion with them).
  void linear_momentum_target(int block, T h, Scratch& s);
  void keep_linear_momentum(int block, const T* q1, T h, Scratch& s);
  void record_momentum_correction(int block, int root, const Vec3<L>& world_dv, T h);

  StepOptions options_;
  StepPlan plan_;
  // The inertial parameters block `block` steps with: its copies' own, or,
  // with Stage::PerCopyInertia skipped, the model's in every lane
  // (model_inertia_): one block that stays in cache instead of 40 bytes per
  // body and copy streaming through it every step.
  const T* inertia(int block) const {
    return plan_.per_copy_inertia ? batch_.state.inertia.block(block) : model_inertia_.block(0);
  }
  // Likewise a per-DOF parameter of block `block` (drive gains, damping,
  // armature, joint friction): its copies' own, or, with
  // Stage::PerCopyJointParameters skipped, the scene's (`scene`, one block).
  const T* joint_parameter(const BatchArray<T>& per_copy, const BatchArray<T>& scene, int block) const {
    return plan_.per_copy_joint_parameters ? per_copy.block(block) : scene.block(0);
  }
  KernelModel<T> km_;
  JointTermModel<T> jm_;
  std::vector<JointRowSpec<T>> row_specs_;
  int coupled_rows_ = 0;  // the first rows of row_specs_, those on several DOFs: mimic couplings, then tendons'
  JointRowColumns columns_;  // the DOFs joint rows act on
  std::vector<ContactPairSpec<T>> contact_pairs_;  // empty unless plan.contacts
  std::vector<int> contact_bodies_;  // the moving bodies of contact_pairs_
  // With conserve_linear_momentum: the floating articulations' root bodies,
  // and per body the root whose momentum it counts in (-1: none)
  std::vector<int> floating_roots_;
  std::vector<int> momentum_root_;
  // The entries of q and v that drive targets have: every joint's but a
  // Free joint's (it takes no drive, and its target is not read).
  std::vector<int> driven_q_, driven_v_;
  ContactParams<T> contact_params_;
  StepBatch<T> batch_;
  BatchArray<T> model_inertia_;  // one block of the model's inertial parameters
  // one block each of the scene's per-DOF parameters (scene_joint_parameters)
  BatchArray<T> scene_drive_stiffness_, scene_drive_damping_, scene_damping_, scene_armature_, scene_friction_;
  // One ScratchPair per thread slot of the arena that steps, indexed by
  // tbb::this_task_arena::current_thread_index(): all of them are made
  // before a step's blocks run (reserve_scratch), so no worker allocates
  // on its first block. Sized by the rows, columns and narrowphase points
  // known at construction.
  std::vector<std::unique_ptr<ScratchPair>> scratch_;
  int scratch_rows_ = 0, scratch_columns_ = 0, scratch_candidates_ = 0;
  void reserve_scratch(int slots);
  bool profiling_ = false;
};

}  // namespace lockstep
