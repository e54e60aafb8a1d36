// The velocity-level constraint solver over one block: rows r with impulses
// lambda_r in [lo_r, hi_r], coupled through the Delassus matrix
// D = J Mt^-1 J^T (Mt: the mass matrix plus the implicit diagonal). Each row
// wants its velocity in a band [target_r, target_hi_r] (an equality when the
// two are equal):
//   v = v_free + D lambda,   lambda_r > 0 only where v_r = target_r,
//                            lambda_r < 0 only where v_r = target_hi_r,
// and the box [lo_r, hi_r] bounds lambda_r (one-sided rows: [0, inf)). A
// projected linear complementarity problem, solved by projected
// Gauss-Seidel or by TGS (PhysX's temporal Gauss-Seidel: the step split into
// substeps, the position error of positional rows advanced between them).
//
// The solver knows rows only through D, v_free, target and the bounds: joint
// limits, velocity limits and joint friction are its first row types;
// contacts, loops and mimic couplings add rows without changing it. A row
// whose bounds follow another row's impulse (friction under a normal force:
// |lambda_r| <= mu_r lambda_bound) names that row in bound_row; two such rows
// flagged as a cone pair share one bound on their length (the Coulomb
// cone, |(lambda_r, lambda_r+1)| <= mu_r lambda_bound, projected radially).
#pragma once

#include "kernels/lane.hpp"

#include <limits>
#include <utility>
#include <vector>

namespace lockstep {

// The rows of one block, [row][lane] through the lane type L.
template <class L>
struct RowBlock {
  int m = 0;
  std::vector<int> bound_row;  // (m) -1, or the row whose impulse bounds this one (times mu)
  std::vector<L> mu;           // (m) friction coefficient of bound rows
  std::vector<unsigned char> cone;        // (m) 1: rows r and r+1 are a friction cone pair bounded by row bound_row[r]
  std::vector<unsigned char> positional;  // (m) 1: target follows a position error (TGS re-evaluates it)
  std::vector<L> rate;         // (m) positional rows: share of a violation removed per second (erp / dt)
  std::vector<L> floor;        // (m) positional rows: lowest target (restitution's bounce velocity; -inf if none)
  std::vector<L> ceiling;      // (m) positional rows: highest correction target (depenetration cap; +inf if none), below the floor
  std::vector<L> D;            // (m x m) Delassus matrix
  // set by the solves before their sweeps (invert_diagonal): 1 / D_rr; for
  // a cone pair r, r + 1 the diagonal of its 2x2 block's inverse instead,
  // with the inverse's off-diagonal entry and the pair's common sliding
  // step in row r of cone_coupling and cone_step
  std::vector<L> inv_diag, cone_coupling, cone_step;  // (m)
  std::vector<L> v_free;       // (m) row velocity before the solve
  std::vector<L> target, target_hi, lo, hi;  // (m) velocity band and impulse box
  std::vector<L> error;        // (m) position error of positional rows (>= 0: separated)
  std::vector<L> lambda;       // (m) impulses: warm start in, solution out
  std::vector<L> lambda_sum;   // (m) TGS: sum over substeps of h lambda (the position-level impulse)
  std::vector<L> displacement; // (m) TGS: positional rows' displacement accumulated over substeps

  // Room for `capacity` rows; m (the rows of the current block) may be set
  // to anything up to it, D then being m x m.
  explicit RowBlock(int capacity)
      : m(capacity), bound_row(capacity, -1), mu(capacity), cone(capacity, 0), positional(capacity, 0),
        rate(capacity), floor(capacity, L(-std::numeric_limits<lane::scalar_t<L>>::infinity())),
        ceiling(capacity, L(std::numeric_limits<lane::scalar_t<L>>::infinity())),
        D(capacity * capacity), inv_diag(capacity), cone_coupling(capacity), cone_step(capacity), v_free(capacity),
        target(capacity),
        target_hi(capacity), lo(capacity), hi(capacity), error(capacity), lambda(capacity), lambda_sum(capacity),
        displacement(capacity) {}
};

// The target of a positional row with error e over a time h: speculative
// when separated (the row may close the gap exactly, never cross it: -e/h),
// a share erp of the violation per step when violated (-erp e / step).
// Takes 1/h and erp/step, so no lane divides.
template <class L>
inline L positional_target(const L& e, const L& inv_h, const L& erp_per_step) {
  using T = lane::scalar_t<L>;
  return lane::select(e >= L(T(0)), -e * inv_h, -erp_per_step * e);
}

// The impulse change that puts a row's velocity v back in its band,
// before the box: (target - v)/D if below, (target_hi - v)/D if above, else
// none.
template <class L>
inline L band_step(const L& lambda, const L& v, const L& target, const L& target_hi, const L& inv_d) {
  using T = lane::scalar_t<L>;
  const L up = lambda + (target - v) * inv_d, down = lambda + (target_hi - v) * inv_d;
  return lane::select(up > L(T(0)), up, lane::select(down < L(T(0)), down, L(T(0))));
}

// Per lane: true where one row is satisfied with all impulses zero. A row
// bounded by another row's impulse (bound_row) has the box [0, 0] then.
template <class L>
inline lane::mask_t<L> row_at_rest(const L& v_free, const L& target, const L& target_hi, const L& lo, const L& hi,
                                   const L& error, bool positional) {
  using T = lane::scalar_t<L>;
  const L zero(T(0)), one(T(1));
  lane::mask_t<L> rest = lane::clamp(band_step(zero, v_free, target, target_hi, one), lo, hi) == zero;
  if (positional) rest = rest && (error >= zero);
  return rest;
}

// Per lane: true where every row is satisfied with all impulses zero, so
// zero is the exact solution there.
template <class L>
inline lane::mask_t<L> rows_at_rest(const RowBlock<L>& rows) {
  using T = lane::scalar_t<L>;
  lane::mask_t<L> rest(true);
  for (int r = 0; r < rows.m; ++r) {
    const bool bound = rows.bound_row[r] >= 0;
    rest = rest && row_at_rest(rows.v_free[r], rows.target[r], rows.target_hi[r], bound ? L(T(0)) : rows.lo[r],
                               bound ? L(T(0)) : rows.hi[r], rows.error[r], rows.positional[r] != 0);
  }
  return rest;
}

// v[i] += D[row[i]][c] lambda[c] for the N rows side by side, over the
// columns c = from, ..., m - 1, 0, ..., until - 1 (all m columns when
// from == until), each impulse loaded once for the N chains.
template <int N, class L>
LOCKSTEP_INLINE void add_columns(const RowBlock<L>& rows, const int (&row)[N], int from, int until, L (&v)[N]) {
  const int m = rows.m;
  const L* D[N];
  for (int i = 0; i < N; ++i) D[i] = &rows.D[row[i] * m];
  const L* lambda = rows.lambda.data();
  auto columns = [&](int begin, int end) {
    for (int c = begin; c < end; ++c) {
      const L x = lambda[c];
      for (int i = 0; i < N; ++i) v[i] = lane::fmadd(D[i][c], x, v[i]);
    }
  };
  columns(from, m);
  columns(0, until);
}

// Row r's velocity at the impulses lambda, summed over the columns
// from, ..., m - 1, 0, ..., from - 1.
template <class L>
inline L row_velocity(const RowBlock<L>& rows, int r, int from = 0) {
  L v[1] = {rows.v_free[r]};
  add_columns<1>(rows, {r}, from, from, v);
  return v[0];
}

// 1 / D_rr, once per solve rather than once per sweep; for a cone pair,
// what cone_pair_step takes: its 2x2 block [a b; b c]'s inverse and the
// common step 1 / lambda_max of the block (lambda_max = (a + c) / 2 +
// sqrt(((a - c) / 2)^2 + b^2)). A block near rank one (a tangent pair
// that moves one DOF, say; b^2 > 0.999 a c) has no useful inverse: its
// sticking step is the common step too, which solves a rank-one block
// exactly along its range.
template <class L>
inline void invert_diagonal(RowBlock<L>& rows) {
  using T = lane::scalar_t<L>;
  const int m = rows.m;
  const L one(T(1)), half(T(0.5)), zero(T(0));
  for (int r = 0; r < m; ++r) {
    if (!rows.cone[r]) {
      rows.inv_diag[r] = one / rows.D[r * m + r];
      continue;
    }
    const L a = rows.D[r * m + r], b = rows.D[r * m + r + 1], c = rows.D[(r + 1) * m + r + 1];
    const L det = a * c - b * b, spread = half * (a - c);
    const L step = one / (half * (a + c) + lane::sqrt(spread * spread + b * b));
    const auto regular = det > L(T(1e-3)) * a * c;
    const L inv_det = one / lane::select(regular, det, one);
    rows.inv_diag[r] = lane::select(regular, c * inv_det, step);
    rows.inv_diag[r + 1] = lane::select(regular, a * inv_det, step);
    rows.cone_coupling[r] = lane::select(regular, -b * inv_det, zero);
    rows.cone_step[r] = step;
    ++r;
  }
}

// Per lane: true where row r, at zero impulse, needs none at velocity v.
template <class L>
inline lane::mask_t<L> row_slack(const RowBlock<L>& rows, int r, const L& v) {
  return row_at_rest(v, rows.target[r], rows.target_hi[r], rows.lo[r], rows.hi[r], rows.error[r],
                     rows.positional[r] != 0);
}

// The steps (a, b) projected radially onto the disc of radius
// mu lambda_bound (Coulomb's isotropic cone, not a pyramid).
template <class L>
LOCKSTEP_INLINE void project_to_cone(L& a, L& b, const L& radius) {
  using T = lane::scalar_t<L>;
  const L square = a * a + b * b;
  // a block whose lanes all lie well inside their cones (radius^2 with room
  // for its rounding and the root's) needs no projection: the root and the
  // division are the sweep's longest waits
  if (lane::all<L>(square < radius * radius * L(T(1) - 8 * std::numeric_limits<T>::epsilon()))) return;
  const L length = lane::sqrt(square);
  const L scale = lane::select(length > radius, radius / lane::max(length, L(std::numeric_limits<T>::min())), L(T(1)));
  a = a * scale;
  b = b * scale;
}

// Row r's band step and clamp at velocity v (a friction row bounded by its
// normal row's impulse: |lambda| <= mu lambda_normal).
template <class L>
LOCKSTEP_INLINE void update_row(RowBlock<L>& rows, int r, const L& v) {
  L lo = rows.lo[r], hi = rows.hi[r];
  if (rows.bound_row[r] >= 0) {
    hi = rows.mu[r] * rows.lambda[rows.bound_row[r]];
    lo = -hi;
  }
  const L step = band_step(rows.lambda[r], v, rows.target[r], rows.target_hi[r], rows.inv_diag[r]);
  rows.lambda[r] = lane::clamp(step, lo, hi);
}

// A cone pair's impulses (a, b) at the pair's velocities (va, vb), within
// the disc of radius mu lambda_normal. Sticking: the pair's own 2x2 solve,
// (a, b) - D_tt^-1 (va, vb), which brings both velocities to zero at once,
// kept where it lies inside the disc. Sliding: one common step s along
// -(va, vb), then projected radially onto the disc. Its fixed point is an
// impulse opposite to the slip velocity, as Coulomb's maximal dissipation
// wants, whatever the pair's D; a step per row (a - va / D_aa, b - vb /
// D_bb) has its fixed point opposite to (va / D_aa, vb / D_bb) instead,
// which turned a box sliding off the tangent axes' directions (up to 15 %
// too far down an incline at 45 degrees to them, and spinning).
template <class L>
LOCKSTEP_INLINE void cone_pair_step(const RowBlock<L>& rows, int r, L& a, L& b, const L& va, const L& vb,
                                    const L& radius) {
  const L stick_a = a - lane::fmadd(rows.inv_diag[r], va, rows.cone_coupling[r] * vb);
  const L stick_b = b - lane::fmadd(rows.cone_coupling[r], va, rows.inv_diag[r + 1] * vb);
  const auto sticks = stick_a * stick_a + stick_b * stick_b <= radius * radius;
  if (lane::all<L>(sticks)) {
    a = stick_a;
    b = stick_b;
    return;
  }
  L slide_a = a - rows.cone_step[r] * va, slide_b = b - rows.cone_step[r] * vb;
  project_to_cone(slide_a, slide_b, radius);
  a = lane::select(sticks, stick_a, slide_a);
  b = lane::select(sticks, stick_b, slide_b);
}

// A cone pair's rows r, r + 1 at velocities (va, vb) (cone_pair_step).
template <class L>
LOCKSTEP_INLINE void update_cone_pair(RowBlock<L>& rows, int r, const L& va, const L& vb) {
  cone_pair_step(rows, r, rows.lambda[r], rows.lambda[r + 1], va, vb, rows.mu[r] * rows.lambda[rows.bound_row[r]]);
}

// One Gauss-Seidel sweep; v_r recomputed from the impulses, each row's sum
// started at its own column (row_velocity's `from`): the impulses this sweep
// changed last enter its chain last, so a row waits on the row before it
// for one multiply-add rather than for the rest of the sum. Needs
// invert_diagonal. A cone pair is updated together, by cone_pair_step at
// the pair's current velocities.
// A single row r and the row or cone pair after it read the same impulses
// in the same order but for lambda_r, which enters r's sum first (its old
// value) and theirs last (its new one): their sums run side by side, each
// impulse loaded once for two or three independent chains, every chain in
// its own order, so the bits are those of one row after the other.
template <class L>
inline void gauss_seidel_sweep(RowBlock<L>& rows) {
  const int m = rows.m;
  int r = 0;
  while (r < m) {
    if (rows.cone[r]) {  // a cone pair no single row leads: both sums from r, around
      L v[2] = {rows.v_free[r], rows.v_free[r + 1]};
      add_columns<2>(rows, {r, r + 1}, r, r, v);
      update_cone_pair(rows, r, v[0], v[1]);
      r += 2;
      continue;
    }
    const int next = r + 1;
    if (next == m) {
      update_row(rows, r, row_velocity(rows, r, r));
      break;
    }
    const L v_r = lane::fmadd(rows.D[r * m + r], rows.lambda[r], rows.v_free[r]);
    if (rows.cone[next]) {
      L v[3] = {v_r, rows.v_free[next], rows.v_free[next + 1]};
      add_columns<3>(rows, {r, next, next + 1}, next, r, v);
      update_row(rows, r, v[0]);
      const L x = rows.lambda[r];
      update_cone_pair(rows, next, lane::fmadd(rows.D[next * m + r], x, v[1]),
                       lane::fmadd(rows.D[(next + 1) * m + r], x, v[2]));
      r += 3;
    } else {
      L v[2] = {v_r, rows.v_free[next]};
      add_columns<2>(rows, {r, next}, next, r, v);
      update_row(rows, r, v[0]);
      update_row(rows, next, lane::fmadd(rows.D[next * m + r], rows.lambda[r], v[1]));
      r += 2;
    }
  }
}

// --- contact-only blocks, unrolled -----------------------------------------
// A block of S contact slots without torsion and without joint rows (a
// robot standing or walking on its feet) has the rows [normal, cone pair]
// per slot. Its sweeps are unrolled at compile time with the impulses in
// registers, the same operations in the same order as gauss_seidel_sweep,
// so the same bits. Even so each row waits on the one before it (the
// rest of its sum, its band step and clamp: some 25 cycles for a normal
// row), and the core idles; two blocks' sweeps interleaved slot by slot
// (pgs_solve_pair) give it two independent chains and take about the time
// of one block's (docs/performance.md).
inline constexpr int kMaxUnrolledSlots = 8;

template <class L>
inline bool is_contact_slots(const RowBlock<L>& rows) {
  if (rows.m == 0 || rows.m % 3 != 0 || rows.m / 3 > kMaxUnrolledSlots) return false;
  for (int n = 0; n < rows.m; n += 3)
    if (rows.bound_row[n] >= 0 || rows.cone[n] || !rows.cone[n + 1] || rows.bound_row[n + 1] != n ||
        rows.bound_row[n + 2] != n)
      return false;
  return true;
}

// v + sum_c Dr[c] lambda[c] over c = from, ..., m - 1, 0, ..., from - 1
// (row_velocity's order), unrolled.
template <int m, int from, class L, std::size_t... k>
LOCKSTEP_INLINE L unrolled_row_velocity(const L* Dr, const L* lambda, L v, std::index_sequence<k...>) {
  ((v = lane::fmadd(Dr[(from + static_cast<int>(k)) % m], lambda[(from + static_cast<int>(k)) % m], v)), ...);
  return v;
}

// Slot `slot` of an unrolled sweep over S slots: its normal row, then its
// cone pair, as gauss_seidel_sweep updates them.
template <int S, int slot, class L>
LOCKSTEP_INLINE void unrolled_slot_update(const RowBlock<L>& rows, L* lambda) {
  constexpr int m = 3 * S, n = 3 * slot;
  const auto columns = std::make_index_sequence<m>{};
  const L* D = rows.D.data();
  const L v = unrolled_row_velocity<m, n>(D + n * m, lambda, rows.v_free[n], columns);
  lambda[n] = lane::clamp(band_step(lambda[n], v, rows.target[n], rows.target_hi[n], rows.inv_diag[n]), rows.lo[n],
                          rows.hi[n]);
  const L va = unrolled_row_velocity<m, n + 1>(D + (n + 1) * m, lambda, rows.v_free[n + 1], columns);
  const L vb = unrolled_row_velocity<m, n + 1>(D + (n + 2) * m, lambda, rows.v_free[n + 2], columns);
  cone_pair_step(rows, n + 1, lambda[n + 1], lambda[n + 2], va, vb, rows.mu[n + 1] * lambda[n]);
}

// `iterations` sweeps over B blocks of S slots each, interleaved slot by
// slot; each block's impulses stay in registers between sweeps.
template <int S, int B, class L, std::size_t... slot>
void unrolled_slot_sweeps(RowBlock<L>* const* blocks, int iterations, std::index_sequence<slot...>) {
  L lambda[B][3 * S];
  for (int i = 0; i < B; ++i)
    for (int r = 0; r < 3 * S; ++r) lambda[i][r] = blocks[i]->lambda[r];
  for (int it = 0; it < iterations; ++it)
    (
        [&] {
          for (int i = 0; i < B; ++i) unrolled_slot_update<S, static_cast<int>(slot)>(*blocks[i], lambda[i]);
        }(),
        ...);
  for (int i = 0; i < B; ++i)
    for (int r = 0; r < 3 * S; ++r) blocks[i]->lambda[r] = lambda[i][r];
}

// The unrolled sweeps for B blocks of `slots` slots, slots being one of
// S + 1 in the sequence (1 to kMaxUnrolledSlots).
template <int B, class L, std::size_t... S>
void contact_slot_sweeps(RowBlock<L>* const* blocks, int slots, int iterations, std::index_sequence<S...>) {
  ((slots == static_cast<int>(S) + 1 ? unrolled_slot_sweeps<static_cast<int>(S) + 1, B>(
                                           blocks, iterations, std::make_index_sequence<S + 1>{})
                                     : void()),
   ...);
}

// `iterations` sweeps of each of B blocks (1 or 2) from the impulses in
// their lambda: unrolled and interleaved where all are contact-only blocks
// of the same slots, else one block after the other. Either way each block
// gets the bits gauss_seidel_sweep gives it alone. Needs invert_diagonal.
template <int B, class L>
void sweep_blocks(RowBlock<L>* const* blocks, int iterations) {
  bool unrolled = true;
  for (int i = 0; i < B; ++i) unrolled = unrolled && blocks[i]->m == blocks[0]->m && is_contact_slots(*blocks[i]);
  if (unrolled) {
    contact_slot_sweeps<B>(blocks, blocks[0]->m / 3, iterations, std::make_index_sequence<kMaxUnrolledSlots>{});
    return;
  }
  for (int i = 0; i < B; ++i)
    for (int it = 0; it < iterations; ++it) gauss_seidel_sweep(*blocks[i]);
}

// PGS: `iterations` sweeps from the warm start in lambda.
template <class L>
void pgs_solve(RowBlock<L>& rows, int iterations) {
  invert_diagonal(rows);
  RowBlock<L>* const blocks[1] = {&rows};
  sweep_blocks<1>(blocks, iterations);
}

// PGS on two independent blocks, side by side where they have the same
// layout (sweep_blocks): each gets the bits pgs_solve gives it alone.
template <class L>
void pgs_solve_pair(RowBlock<L>& first, RowBlock<L>& second, int iterations) {
  invert_diagonal(first);
  invert_diagonal(second);
  RowBlock<L>* const blocks[2] = {&first, &second};
  sweep_blocks<2>(blocks, iterations);
}

// A positional row's target at a TGS substep, its error advanced by the
// row's displacement so far (at its own correction rate, between its floor
// and ceiling); inv_h: 1 / substep.
template <class L>
inline L tgs_target(const RowBlock<L>& rows, int r, const L& displacement, const L& inv_h) {
  return lane::max(lane::min(positional_target(rows.error[r] + displacement, inv_h, rows.rate[r]), rows.ceiling[r]),
                   rows.floor[r]);
}

// TGS over `substeps` substeps of h = dt / substeps, on B blocks (1 or
// 2) side by side (sweep_blocks): before each sweep the positional rows'
// targets follow their error advanced by the displacement so far
// (tgs_target); after it every positional row's displacement grows by
// h v_r (the other rows' is not needed) and every row's lambda_sum by
// h lambda_r (the integrator moves positions by h v_free plus the
// lambda_sum-mapped impulses), and `after_substep(i)` runs for each block
// i (the caller's look at the impulses of the substep).
template <int B, class L, class AfterSubstep>
void tgs_solve_blocks(RowBlock<L>* const* blocks, int substeps, lane::scalar_t<L> dt, AfterSubstep&& after_substep) {
  using T = lane::scalar_t<L>;
  const L h(dt / T(substeps)), inv_h(T(substeps) / dt);
  for (int i = 0; i < B; ++i) {
    RowBlock<L>& rows = *blocks[i];
    for (int r = 0; r < rows.m; ++r) {
      rows.displacement[r] = L(T(0));
      rows.lambda_sum[r] = L(T(0));
    }
    invert_diagonal(rows);
  }
  for (int k = 0; k < substeps; ++k) {
    for (int i = 0; i < B; ++i) {
      RowBlock<L>& rows = *blocks[i];
      for (int r = 0; r < rows.m; ++r)
        if (rows.positional[r]) rows.target[r] = rows.target_hi[r] = tgs_target(rows, r, rows.displacement[r], inv_h);
    }
    sweep_blocks<B>(blocks, 1);
    for (int i = 0; i < B; ++i) {
      RowBlock<L>& rows = *blocks[i];
      for (int r = 0; r < rows.m; ++r) {
        if (rows.positional[r]) rows.displacement[r] = lane::fmadd(h, row_velocity(rows, r), rows.displacement[r]);
        rows.lambda_sum[r] = lane::fmadd(h, rows.lambda[r], rows.lambda_sum[r]);
      }
      after_substep(i);
    }
  }
}

// TGS on one block.
template <class L>
void tgs_solve(RowBlock<L>& rows, int substeps, lane::scalar_t<L> dt) {
  RowBlock<L>* const blocks[1] = {&rows};
  tgs_solve_blocks<1>(blocks, substeps, dt, [](int) {});
}

}  // namespace lockstep
