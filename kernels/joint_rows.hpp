// Joint-space solver rows: mimic couplings, fixed tendons, hard position
// limits, velocity limits and Coulomb joint friction. A limit or friction
// row acts on one DOF k with the Jacobian J = sigma e_k, sigma = +-1 per lane
// (which limit the joint heads for; +1 for the others); a mimic row on two,
// J = sigma (e_A + G e_B), and a tendon's rows on its joints, J = sigma
// sum_i c_i e_i. D = J Mt^-1 J^T is read off the columns Mt^-1 e_k, computed once
// per distinct DOF from the tree-sparse factorisation of Mt = M + diag(w).
// A Spherical joint's DOF k is limited in component k of its rotation vector
// r = log(q), which moves at that DOF's velocity to first order (r' = w
// exactly for turns about one axis; docs/conventions.md).
#pragma once

#include "kernels/configuration.hpp"
#include "kernels/crba.hpp"
#include "kernels/row_solver.hpp"

namespace lockstep {

enum class JointRowKind : unsigned char {
  PositionLimit,  // sigma v >= -e/dt (speculative) with lambda >= 0; e: distance to the limit the joint heads for
  VelocityLimit,  // -v_max <= v <= v_max, lambda free (a band row)
  Friction,       // v = 0 with |lambda| <= friction dt
  Mimic,          // q_A + G q_B + offset = 0 (PhysX's mimic joint): an equality, lambda free
  TendonSpring,   // a fixed tendon's spring-damper on l = sum_i c_i q_i, implicit: a compliant equality, lambda free
  TendonLimit,    // a fixed tendon's length limits: one-sided, hard (positional) or a spring past the limit
};

// One term c e_dof of a row on several DOFs, with the DOF's entry in q and
// its column (JointRowColumns).
template <class T>
struct RowTerm {
  int dof, q_index, column;
  T coefficient;
};

// One row's topology and parameters, shared by every copy.
template <class T>
struct JointRowSpec {
  JointRowKind kind;
  int dof;
  int q_index;  // the DOF's entry in q; for a Spherical DOF its quaternion's (w, x, y, z)
  int column;  // index of the DOF among the distinct row DOFs
  // PositionLimit, TendonLimit: lower, upper; VelocityLimit: v_max; Friction: friction force; Mimic: offset;
  // TendonSpring: -(rest length + offset)
  T a = 0, b = 0;
  // A row on several DOFs (Mimic: (A, 1), (B, G); a tendon's: its joints):
  // J / sigma = sum of coefficient e_dof over the terms, dof, q_index and
  // column being the first term's. Empty for the one-DOF rows, J / sigma =
  // e_dof.
  std::vector<RowTerm<T>> terms{};
  // TendonSpring: the spring's stiffness and damping; TendonLimit: the
  // limit's stiffness (0: a hard limit).
  T stiffness = 0, damping = 0;
  // A Spherical DOF's limits: the component of log(q) they bound (0, 1, 2);
  // -1 for a 1-DOF joint's, whose position is q[q_index].
  int rotation_axis = -1;
  // VelocityLimit on a DOF with a hard position limit: that row's range
  // (joint_row: the band lets the limit's correction through).
  T range_lower = -std::numeric_limits<T>::infinity(), range_upper = std::numeric_limits<T>::infinity();
};

// Per block: the rows, each row's sign, and the columns Mt^-1 e_k.
template <class L>
struct JointRowScratch {
  RowBlock<L> rows;
  std::vector<L> sigma;    // (m)
  std::vector<L> columns;  // (ncolumn x nv)
  JointRowScratch(int m, int ncolumn, int nv) : rows(m), sigma(m), columns(ncolumn * nv) {}
};

// A Friction row's impulse bound over the (sub)step dt: its DOF's Coulomb
// force (friction: (nv) per lane) times dt.
template <class L>
inline L friction_impulse_bound(const JointRowSpec<lane::scalar_t<L>>& spec, const lane::scalar_t<L>* friction,
                                lane::scalar_t<L> dt) {
  return lane::load<L>(friction + spec.dof * lane::width_v<L>) * L(dt);
}

// The one term of a one-DOF row: its DOF with coefficient 1.
template <class T>
RowTerm<T> own_term(const JointRowSpec<T>& spec) {
  return {spec.dof, spec.q_index, spec.column, T(1)};
}

// f(term) for each term of a row: its terms, or a one-DOF row's own.
template <class T, class F>
LOCKSTEP_INLINE void for_each_term(const JointRowSpec<T>& spec, F f) {
  if (spec.terms.empty()) f(own_term(spec));
  for (const RowTerm<T>& t : spec.terms) f(t);
}

// sum_i c_i value(term_i) over a row's terms, in their order; a one-DOF
// row's value(own term) with no product.
template <class L, class T, class Value>
LOCKSTEP_INLINE L row_sum(const JointRowSpec<T>& spec, Value value) {
  const std::vector<RowTerm<T>>& terms = spec.terms;
  if (terms.empty()) return value(own_term(spec));
  L sum = L(terms[0].coefficient) * value(terms[0]);
  for (std::size_t i = 1; i < terms.size(); ++i) sum = lane::fmadd(L(terms[i].coefficient), value(terms[i]), sum);
  return sum;
}

// J_r x / sigma_r for a vector x (nv) over the DOFs.
template <class T, class L>
LOCKSTEP_INLINE L joint_row_dofs(const JointRowSpec<T>& spec, const L* x) {
  return row_sum<L>(spec, [&](const RowTerm<T>& t) { return x[t.dof]; });
}

// sum_i c_i q_i over a row's terms: a tendon's length, or a mimic's
// q_A + G q_B.
template <class L>
LOCKSTEP_INLINE L row_terms_position(const JointRowSpec<lane::scalar_t<L>>& spec, const lane::scalar_t<L>* q) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  return row_sum<L>(spec, [&](const RowTerm<T>& t) { return lane::load<L>(q + t.q_index * W); });
}

// What a spring row adds to its diagonal of D over the (sub)step dt (0: a
// rigid row): a tendon spring's 1 / (dt (k dt + c)), a springy tendon
// limit's 1 / (k dt^2). joint_row's targets take the same law.
template <class T>
inline T row_compliance(const JointRowSpec<T>& spec, T dt) {
  if (spec.kind == JointRowKind::TendonSpring) return T(1) / (dt * (spec.stiffness * dt + spec.damping));
  if (spec.kind == JointRowKind::TendonLimit && spec.stiffness != T(0)) return T(1) / (spec.stiffness * dt * dt);
  return T(0);
}

// Component `axis` of the rotation vector of the quaternion at q: out of
// line, so that the rows of 1-DOF joints, the common case, stay small
// enough to inline (inline, it slowed the step of anymal_b by 10 %).
template <class L>
__attribute__((noinline)) L rotation_vector_component(const lane::scalar_t<L>* q, int axis) {
  const Vec3<L> r = quaternion_log(load_quaternion<L>(q));
  return axis == 0 ? r.x : axis == 1 ? r.y : r.z;
}

// The position a limit row bounds: the DOF's coordinate, or for a Spherical
// DOF its component of the joint's rotation vector.
template <class L>
LOCKSTEP_INLINE L joint_row_position(const JointRowSpec<lane::scalar_t<L>>& spec, const lane::scalar_t<L>* q) {
  constexpr std::size_t W = lane::width_v<L>;
  if (spec.rotation_axis < 0) return lane::load<L>(q + spec.q_index * W);
  return rotation_vector_component<L>(q + spec.q_index * W, spec.rotation_axis);
}

// One joint row of one block, per lane, from q and the free velocity u*.
template <class L>
struct JointRow {
  L sigma, error, target, target_hi, lo, hi, v_free;
  bool positional;
  // Per lane: true where the row needs no impulse at its free velocity.
  lane::mask_t<L> at_rest() const { return row_at_rest(v_free, target, target_hi, lo, hi, error, positional); }
};

// dt is the (sub)step; friction: (nv) per lane, the Coulomb force of a
// Friction row's DOF (the copy's own, StepBatch::joint_friction).
template <class L>
LOCKSTEP_INLINE JointRow<L> joint_row(const JointRowSpec<lane::scalar_t<L>>& spec, const lane::scalar_t<L>* q, const L* v_free,
                             const lane::scalar_t<L>* friction, lane::scalar_t<L> dt, lane::scalar_t<L> erp) {
  using T = lane::scalar_t<L>;
  const T inf = std::numeric_limits<T>::infinity();
  const L one(T(1)), zero(T(0));
  const L u = joint_row_dofs(spec, v_free);
  JointRow<L> row{one, zero, zero, zero, L(-inf), L(inf), u, false};
  switch (spec.kind) {
    case JointRowKind::Mimic: {
      // An equality on e = q_A + G q_B + offset, lambda free. Its sign
      // turned against e, the row's error is -|e| <= 0: positional_target's
      // violated branch asks for the share erp of it back per step,
      // J u = -erp e / dt, from either side (and TGS, advancing the error
      // past zero, for the overshoot back at once).
      const L e = row_terms_position<L>(spec, q) + L(spec.a);
      row.sigma = lane::select(e > zero, -one, one);
      row.error = row.sigma * e;
      row.target = row.target_hi = positional_target(row.error, L(T(1) / dt), L(erp / dt));
      row.positional = true;
      break;
    }
    case JointRowKind::TendonSpring: {
      // Backward Euler of the force f = -k (l + dt J u - l_ref) - c J u
      // over the step: its impulse lambda = dt f gives
      //   J u + lambda / (dt (k dt + c)) = -k (l - l_ref) / (k dt + c),
      // an equality whose compliance (row_compliance) joins D's diagonal
      // (build_round), as a compliant contact's (contact_rows.hpp). The
      // target does not follow the position: TGS keeps it through its
      // substeps.
      const L e = row_terms_position<L>(spec, q) + L(spec.a);
      const T rate = spec.stiffness * dt + spec.damping;  // > 0: the row exists only then
      row.target = row.target_hi = L(-spec.stiffness / rate) * e;
      break;
    }
    case JointRowKind::PositionLimit:
    case JointRowKind::TendonLimit: {
      // the limit nearer to where the free motion ends the step: a fast
      // joint heading for the far limit of a narrow range meets that one
      // (a tendon's limits: on its length). With a limit stiffness k (a
      // tendon's) the impulse past it is lambda = dt k (-e - dt sigma J u)
      // where positive: sigma J u + lambda / (k dt^2) >= -e / dt, a
      // compliant one-sided row (row_compliance).
      const L x = spec.terms.empty() ? joint_row_position<L>(spec, q) : row_terms_position<L>(spec, q);
      const L x_free = lane::fmadd(L(dt), u, x);
      const auto lower = x_free - L(spec.a) < L(spec.b) - x_free;
      row.sigma = lane::select(lower, one, -one);
      row.error = lane::select(lower, x - L(spec.a), L(spec.b) - x);
      row.lo = zero;
      if (spec.stiffness == T(0)) {
        row.target = row.target_hi = positional_target(row.error, L(T(1) / dt), L(erp / dt));
        row.positional = true;
      } else {
        row.target = row.target_hi = -row.error * L(T(1) / dt);
      }
      break;
    }
    case JointRowKind::VelocityLimit: {
      // Past a hard limit, that row asks for the speed back its
      // positional_target gives (erp e / dt), which may exceed v_max: the
      // band widens to it on that side, as in RaiSim a velocity limit does
      // not act against a position limit that acts. Only so far, not off: a
      // joint resting on its limit a rounding error past it keeps its
      // velocity limit. Within the range the target is <= 0: no widening.
      const L qk = joint_row_position<L>(spec, q), inv_dt(T(1) / dt), rate(erp / dt);
      const L up = lane::max(zero, positional_target(qk - L(spec.range_lower), inv_dt, rate));
      const L down = lane::max(zero, positional_target(L(spec.range_upper) - qk, inv_dt, rate));
      row.target = -lane::max(L(spec.a), down);
      row.target_hi = lane::max(L(spec.a), up);
      break;
    }
    case JointRowKind::Friction:
      row.hi = friction_impulse_bound<L>(spec, friction, dt);
      row.lo = -row.hi;
      break;
  }
  row.v_free = row.sigma * u;
  return row;
}

// Joint row r's velocity (built by build_joint_rows) once other rows'
// impulses change the DOF velocities by dv (nv): its coupling to the others
// read from dv (sigma_r J_r dv / sigma_r) instead of from D.
template <class L>
L joint_row_velocity(const std::vector<JointRowSpec<lane::scalar_t<L>>>& specs, const JointRowScratch<L>& s, int r,
                     const L* dv) {
  return lane::fmadd(s.sigma[r], joint_row_dofs(specs[r], dv), s.rows.v_free[r]);
}

// Per lane: true where joint row r, at zero impulse, needs none at that
// velocity (row_slack's test).
template <class L>
lane::mask_t<L> joint_row_slack(const std::vector<JointRowSpec<lane::scalar_t<L>>>& specs, const JointRowScratch<L>& s,
                                int r, const L* dv) {
  return row_slack(s.rows, r, joint_row_velocity(specs, s, r, dv));
}

// A speed V per lane below which a joint row stays at rest (needs no
// impulse) through a round of substeps over the (sub)step h, held at zero:
// while its DOF's velocity w stays within |w| <= V at every substep, the
// row is at rest at every substep, so row_at_rest need not be evaluated.
// Sufficient, not necessary. error: the row's distance to its limit;
// impulse_bound: a friction row's largest impulse (a built row's error
// and hi).
//   mimic: no bound (infinite): StepEngine takes it wherever a lane
//     solves, so it is never held;
//   velocity limit: |w| <= v_max is the row's own band;
//   friction: at rest only at w = 0 (V = 0), or always with no friction;
//   position limit, error e >= 0: with V = e / (4 h) the displacement of the
//     round so far is at most h V = e / 4, so e' = e + sigma D >= 3e/4 and
//     the target -e' / h_sub <= -3e/(4 h) < -V <= sigma w (rounding is far
//     inside the factor 4). A negative or non-finite e gives no speed.
template <class L>
inline L row_speed_bound(const JointRowSpec<lane::scalar_t<L>>& spec, const L& error, const L& impulse_bound,
                         lane::scalar_t<L> h) {
  using T = lane::scalar_t<L>;
  const L inf(std::numeric_limits<T>::infinity()), zero(T(0));
  switch (spec.kind) {
    case JointRowKind::Mimic:
    case JointRowKind::TendonSpring:
    case JointRowKind::TendonLimit: return inf;  // rows on several DOFs are never held
    case JointRowKind::PositionLimit: return error * L(T(1) / (T(4) * h));
    case JointRowKind::VelocityLimit: return L(spec.a);
    case JointRowKind::Friction: break;
  }
  return lane::select(impulse_bound > zero, zero, inf);
}

// True where no joint row needs an impulse in any lane of the block: the
// same test as rows_at_rest on the built rows, without building them (a
// block at rest then skips the rows altogether). A row whose DOF moves
// below its row_speed_bound in every lane (the error the distance to the
// nearer limit, not yet the one the joint heads for) is at rest without
// the row's own test. It stops at the first row some lane needs (a
// friction row whenever its DOF's free velocity is not zero).
template <class L>
bool joint_rows_all_at_rest(const std::vector<JointRowSpec<lane::scalar_t<L>>>& specs, const lane::scalar_t<L>* q,
                            const L* v_free, const lane::scalar_t<L>* friction, lane::scalar_t<L> dt,
                            lane::scalar_t<L> erp) {
  using T = lane::scalar_t<L>;
  const L zero(T(0));
  for (const JointRowSpec<T>& spec : specs) {
    L error = zero, impulse_bound = zero;
    if (spec.kind == JointRowKind::PositionLimit) {
      const L qk = joint_row_position<L>(spec, q);
      error = lane::min(qk - L(spec.a), L(spec.b) - qk);
    } else if (spec.kind == JointRowKind::Friction) {
      impulse_bound = friction_impulse_bound<L>(spec, friction, dt);
    }
    if (spec.terms.empty() &&
        lane::all<L>(lane::abs(v_free[spec.dof]) <= row_speed_bound<L>(spec, error, impulse_bound, dt)))
      continue;
    const JointRow<L> row = joint_row<L>(spec, q, v_free, friction, dt, erp);
    if (!lane::all<L>(row.at_rest())) return false;
  }
  return true;
}

// Stores the rows of one block for the solver, and each row's slack at the
// free velocity (row_slack's test, on the row as it is built) in slack[r].
// Returns their conjunction: true in a lane where no joint row needs an
// impulse.
template <class L>
lane::mask_t<L> build_joint_rows(const std::vector<JointRowSpec<lane::scalar_t<L>>>& specs,
                                 const lane::scalar_t<L>* q, const L* v_free, const lane::scalar_t<L>* friction,
                                 lane::scalar_t<L> dt, lane::scalar_t<L> erp, JointRowScratch<L>& s,
                                 std::vector<lane::mask_t<L>>& slack) {
  RowBlock<L>& rows = s.rows;
  lane::mask_t<L> all_slack(true);
  for (std::size_t r = 0; r < specs.size(); ++r) {
    const JointRow<L> row = joint_row<L>(specs[r], q, v_free, friction, dt, erp);
    slack[r] = row.at_rest();
    all_slack = all_slack && slack[r];
    s.sigma[r] = row.sigma;
    rows.error[r] = row.error;
    rows.target[r] = row.target;
    rows.target_hi[r] = row.target_hi;
    rows.lo[r] = row.lo;
    rows.hi[r] = row.hi;
    rows.v_free[r] = row.v_free;
    rows.positional[r] = row.positional;
    rows.rate[r] = L(erp / dt);
  }
  return all_slack;
}

// Mt = CRBA + the implicit diagonal (armature and w), factored as L^T D L
// into ws.matrix for the rows' solves (the trapezoid's: it takes link
// damping explicitly, so Mt holds none). Needs ws.local; overwrites
// ws.inertia and ws.matrix.
template <class L>
void factor_step_mass_matrix(const KernelModel<lane::scalar_t<L>>& km, const lane::scalar_t<L>* inertia,
                             const L* implicit_diagonal, Workspace<L>& ws) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  T* H = reinterpret_cast<T*>(ws.matrix.data());
  crba_tree<L>(km, inertia, ws, H);
  for (int k = 0; k < km.nv; ++k) {
    T* Hkk = H + (k * km.nv + k) * W;
    lane::store(lane::load<L>(Hkk) + implicit_diagonal[k], Hkk);
  }
  ltdl_factor<L>(km, H);
}

// The distinct DOFs that joint rows act on, each with its path to the root
// (its ancestors and itself, ascending): column c's DOF is dof[c], its path
// path[path_begin[c], path_begin[c + 1]).
struct JointRowColumns {
  std::vector<int> dof, path, path_begin{0};

  // Column of DOF k, added with its path if new.
  template <class T>
  int column_of(const KernelModel<T>& km, int k) {
    for (std::size_t c = 0; c < dof.size(); ++c)
      if (dof[c] == k) return static_cast<int>(c);
    dof.push_back(k);
    const int first = km.dof_ancestor_begin[k], n = km.dof_ancestor_begin[k + 1] - first;
    for (int t = n - 1; t >= 0; --t) path.push_back(km.dof_ancestors[first + t]);  // stored nearest first
    path.push_back(k);
    path_begin.push_back(static_cast<int>(path.size()));
    return static_cast<int>(dof.size()) - 1;
  }
  int size() const { return static_cast<int>(dof.size()); }
};

// The columns Mt^-1 e_d of the distinct row DOFs d numbered which[0, count),
// one solve with the factored Mt (factor_step_mass_matrix) each: what
// add_row_impulses applies, and what joint_row_delassus reads D off. e_d is
// zero off d's path to the root, so the solve's first two passes (L^-T,
// D^-1) run on that path only (a leg's knee: 9 of anymal_b's 18 DOFs); its
// last (L^-1) takes four columns at a time, each factor entry loaded once
// for them.
template <class L>
void joint_row_columns(const KernelModel<lane::scalar_t<L>>& km, const JointRowColumns& columns,
                       const Workspace<L>& ws, JointRowScratch<L>& s, const int* which, int count) {
  using T = lane::scalar_t<L>;
  constexpr std::size_t W = lane::width_v<L>;
  const int nv = km.nv;
  const T* H = reinterpret_cast<const T*>(ws.matrix.data());
  for (int i = 0; i < count; ++i) {
    const int c = which[i];
    T* column = reinterpret_cast<T*>(&s.columns[c * nv]);
    for (int r = 0; r < nv; ++r) lane::store(L(T(r == columns.dof[c] ? 1 : 0)), column + r * W);
    const int* path = columns.path.data() + columns.path_begin[c];
    const int n = columns.path_begin[c + 1] - columns.path_begin[c];
    ltdl_transpose_solve<L>(km, H, column, path, n);
    ltdl_diagonal_solve<L>(km, H, column, path, n);
  }
  const int stride = nv * static_cast<int>(W);
  ltdl_lower_solve_columns<L>(km, H, reinterpret_cast<T*>(s.columns.data()), stride, which, count);
}

// Entry k of Mt^-1 J_c^T / sigma_c for joint row c: (Mt^-1)_{k, dof_c},
// or the sum over a row's terms of c_i (Mt^-1)_{k, dof_i}, off its columns
// (joint_row_columns).
template <class L>
inline L joint_row_response(const JointRowSpec<lane::scalar_t<L>>& spec, const JointRowScratch<L>& s, int nv, int k) {
  using T = lane::scalar_t<L>;
  return row_sum<L>(spec, [&](const RowTerm<T>& t) { return s.columns[t.column * nv + k]; });
}

// Entry (r, c) of the joint rows' block of the Delassus matrix,
// J_r Mt^-1 J_c^T: sigma_r sigma_c (Mt^-1)_{dof_r, dof_c} for two
// one-DOF rows, read off c's column (joint_row_columns). A solve takes the
// entries of the rows it needs only: a scene's joint rows are mostly slack
// (limits not reached), so their whole block would be mostly unread.
template <class L>
inline L joint_row_delassus(const std::vector<JointRowSpec<lane::scalar_t<L>>>& specs, const JointRowScratch<L>& s,
                            int nv, int r, int c) {
  using T = lane::scalar_t<L>;
  const JointRowSpec<T>& row = specs[r];
  const L J = row_sum<L>(row, [&](const RowTerm<T>& t) { return joint_row_response(specs[c], s, nv, t.dof); });
  return s.sigma[r] * s.sigma[c] * J;
}

// out[k] += sum_i x_i (Mt^-1 J_r^T)[k] over the rows r = rows[i], i <
// count, in that order (sigma_r (Mt^-1 e_{dof_r})[k], or for a row on
// several DOFs each term's c_i times its column): the velocity change of
// impulses x (lambda),
// or the displacement of lambda_sum. Their columns must be built
// (joint_row_columns).
template <class L>
void add_row_impulses(const KernelModel<lane::scalar_t<L>>& km, const std::vector<JointRowSpec<lane::scalar_t<L>>>& specs,
                      const JointRowScratch<L>& s, const int* rows, int count, const L* x, L* out) {
  const int nv = km.nv;
  for (int i = 0; i < count; ++i) {
    const int r = rows[i];
    const L scaled = s.sigma[r] * x[i];
    for_each_term(specs[r], [&](const RowTerm<lane::scalar_t<L>>& t) {
      const L weight = scaled * L(t.coefficient);  // a one-DOF row's: scaled itself
      const L* column = &s.columns[t.column * nv];
      for (int k = 0; k < nv; ++k) out[k] = lane::fmadd(weight, column[k], out[k]);
    });
  }
}

}  // namespace lockstep
