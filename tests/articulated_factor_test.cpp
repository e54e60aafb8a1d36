// The step's factors of Mt = M + diag(w) read off ABA's articulated
// inertias (ltdl_factor_from_aba) against the tree-sparse factorisation of
// CRBA's M (ltdl_factor): both must solve Mt x = b with a backward error of
// a stable factorisation, on every shared model and on a tree with a
// Spherical joint, in float and double, and the SIMD lanes must reproduce
// the scalar reference path bit for bit. With link damping (the Eulers' w D
// in the bodies' inertias) the factors from ABA must solve Mt with its share
// w J^T D J too; CRBA's, which only the trapezoid uses, never hold it.
#include "kernels/aba.hpp"
#include "kernels/crba.hpp"
#include "kernels/joint_rows.hpp"
#include "layout/batch_state.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <iostream>
#include <limits>

namespace lockstep {
namespace {

// The step's joint-terms policy reduced to what the factor reads: a given
// implicit diagonal w per DOF, no joint force, and the Free root's implicit
// gyroscopic Jacobian on (it joins only the root's own solve in ABA, never
// Mt, so the factors must not see it).
template <class L>
struct GivenImplicitDiagonal {
  const L* w;
  L apply(int dof, const L& /*D*/, L& tau) const {
    tau = L(lane::scalar_t<L>(0));
    return w[dof];
  }
  lane::scalar_t<L> implicit_gyroscopic_step() const { return lane::scalar_t<L>(0.01); }
};

// Random q, v and w for `copies` copies (w rounded to T, as the lanes hold
// it), and the weight of the model's link damping in Mt (0: none).
struct Inputs {
  std::vector<Eigen::VectorXd> q, v, w;
  double link_damping_weight = 0;
  template <class T>
  static Inputs draw(const Model& model, int copies, std::mt19937& rng, T, double link_damping_weight = 0) {
    Inputs in;
    in.link_damping_weight = static_cast<T>(link_damping_weight);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (int c = 0; c < copies; ++c) {
      in.q.push_back(test::random_configuration(model, rng));
      in.v.push_back(test::random_vector(model.nv, rng, 2.0));
      Eigen::VectorXd w(model.nv);
      for (int k = 0; k < model.nv; ++k) w[k] = static_cast<T>(0.5 * unit(rng));
      in.w.push_back(w);
    }
    return in;
  }
};

// One block holding copies [first, first + lanes) of the inputs, its
// factors of Mt computed both ways.
template <class L>
struct Factors {
  using T = lane::scalar_t<L>;
  static constexpr int W = static_cast<int>(lane::width_v<L>);
  std::vector<L> from_aba, from_crba;  // (nv x nv) each

  Factors(const Model& model, const Inputs& inputs, int first) {
    const KernelModel<T> km(model);
    Workspace<L> ws(km);
    BatchState<T> state(model, W, W);
    std::vector<L> diagonal(model.nv), qacc(model.nv);
    T* w = reinterpret_cast<T*>(diagonal.data());
    for (int c = 0; c < W; ++c) {
      state.q.set(c, inputs.q[first + c]);
      state.v.set(c, inputs.v[first + c]);
      for (int k = 0; k < model.nv; ++k) w[k * W + c] = static_cast<T>(inputs.w[first + c][k]);
    }
    BlockInputs<T> in;
    in.q = state.q.block(0);
    in.v = state.v.block(0);
    in.inertia = state.inertia.block(0);
    in.gravity = state.gravity.block(0);
    in.link_damping = inputs.link_damping_weight != 0;
    in.link_damping_weight = static_cast<T>(inputs.link_damping_weight);
    joint_transforms<L>(km, in.q, ws);
    world_transforms<L>(km, ws);
    GivenImplicitDiagonal<L> terms{diagonal.data()};
    aba_with<L>(km, in, terms, ws, reinterpret_cast<T*>(qacc.data()));
    from_aba.assign(model.nv * model.nv, L(T(0)));
    ltdl_factor_from_aba<L>(km, ws, diagonal.data(), reinterpret_cast<T*>(from_aba.data()));
    from_crba.assign(model.nv * model.nv, L(T(0)));
    T* H = reinterpret_cast<T*>(from_crba.data());
    crba<L>(km, in.inertia, ws, H);
    for (int k = 0; k < model.nv; ++k) {
      T* Hkk = H + (k * model.nv + k) * W;
      lane::store(lane::load<L>(Hkk) + diagonal[k], Hkk);
    }
    ltdl_factor<L>(km, H);
  }

  // x = Mt^-1 b per copy of the block through one set of factors.
  static std::vector<Eigen::VectorXd> solve(const Model& model, const std::vector<L>& factors,
                                            const std::vector<Eigen::VectorXd>& b) {
    const KernelModel<T> km(model);
    std::vector<L> x(model.nv);
    T* xs = reinterpret_cast<T*>(x.data());
    for (int k = 0; k < model.nv; ++k)
      for (int c = 0; c < W; ++c) xs[k * W + c] = static_cast<T>(b[c][k]);
    ltdl_solve<L>(km, reinterpret_cast<const T*>(factors.data()), xs);
    std::vector<Eigen::VectorXd> out(W, Eigen::VectorXd(model.nv));
    for (int k = 0; k < model.nv; ++k)
      for (int c = 0; c < W; ++c) out[c][k] = xs[k * W + c];
    return out;
  }
};

// Largest backward error |Mt x - b| / (|Mt| |x|) over the block's copies,
// Mt from CRBA in double (with link damping's share w J^T D J from
// Jacobians: test::link_damping_matrix).
template <class L>
double worst_backward_error(const Model& model, const Inputs& inputs, const std::vector<L>& factors,
                            std::mt19937& rng) {
  const CopyDynamics dyn(model, Precision::Double);
  std::vector<Eigen::VectorXd> b(Factors<L>::W);
  for (Eigen::VectorXd& bc : b) bc = test::random_vector(model.nv, rng, 1.0);
  const std::vector<Eigen::VectorXd> x = Factors<L>::solve(model, factors, b);
  double worst = 0;
  for (int c = 0; c < Factors<L>::W; ++c) {
    Eigen::MatrixXd Mt = dyn.mass_matrix(inputs.q[c]);
    Mt.diagonal() += inputs.w[c];
    if (inputs.link_damping_weight != 0) Mt += inputs.link_damping_weight * test::link_damping_matrix(model, inputs.q[c]);
    worst = std::max(worst, (Mt * x[c] - b[c]).norm() / (Mt.norm() * x[c].norm()));
  }
  return worst;
}

// A stable L^T D L factorisation of an n x n symmetric positive definite
// matrix solves with a backward error of a modest multiple of n eps
// (Higham, "Accuracy and Stability of Numerical Algorithms", Theorem 10.4
// for Cholesky, whose factors these are up to a diagonal scaling). The
// bound 4 n eps holds both factorisations on every model here.
template <class L>
void expect_factors_solve(const Model& model, double link_damping_weight = 0) {
  const bool crba = link_damping_weight == 0;  // CRBA's factors hold no link damping
  using T = lane::scalar_t<L>;
  constexpr int W = Factors<L>::W;
  std::mt19937 rng(11);
  const double bound = 4.0 * model.nv * std::numeric_limits<T>::epsilon();
  double worst_aba = 0, worst_crba = 0;
  for (int trial = 0; trial < 3; ++trial) {
    const Inputs inputs = Inputs::draw(model, W, rng, T(), link_damping_weight);
    const Factors<L> f(model, inputs, 0);
    worst_aba = std::max(worst_aba, worst_backward_error(model, inputs, f.from_aba, rng));
    if (crba) worst_crba = std::max(worst_crba, worst_backward_error(model, inputs, f.from_crba, rng));
  }
  std::cout << "[factor] backward error " << worst_aba << " from ABA, " << worst_crba << " from CRBA, bound " << bound
            << "\n";
  EXPECT_LE(worst_aba, bound) << "factors from ABA";
  EXPECT_LE(worst_crba, bound) << "factors from CRBA";
}

// Each lane of the SIMD factors equals, bit for bit, the scalar reference
// path's factors of that copy alone.
template <class T>
void expect_lanes_match_scalar(const Model& model, double link_damping_weight = 0) {
  using S = lane::simd<T>;
  constexpr int W = Factors<S>::W;
  std::mt19937 rng(3);
  const Inputs inputs = Inputs::draw(model, W, rng, T(), link_damping_weight);
  const Factors<S> block(model, inputs, 0);
  const T* lanes = reinterpret_cast<const T*>(block.from_aba.data());
  for (int c = 0; c < W; ++c) {
    const Factors<T> one(model, inputs, c);
    for (int r = 0; r < model.nv; ++r)
      for (int i = r; i >= 0; i = model.dof_parent[i]) {  // the tree pattern: r and its ancestors
        const T a = lanes[(r * model.nv + i) * W + c], b = one.from_aba[r * model.nv + i];
        ASSERT_EQ(std::memcmp(&a, &b, sizeof(T)), 0) << "copy " << c << ", entry (" << r << ", " << i << "): " << a
                                                       << " in the lanes, " << b << " scalar";
      }
  }
}

// The joint rows' columns Mt^-1 e_d (joint_row_columns: the first two
// passes on d's root path only, the last on four listed columns at a time)
// equal, bit for bit, one whole ltdl_solve of e_d each, for every DOF of
// the model.
template <class L>
void expect_joint_row_columns_match_solves(const Model& model) {
  using T = lane::scalar_t<L>;
  constexpr int W = Factors<L>::W;
  const KernelModel<T> km(model);
  std::mt19937 rng(5);
  const Factors<L> f(model, Inputs::draw(model, W, rng, T()), 0);
  Workspace<L> ws(km);
  ws.matrix = f.from_aba;
  JointRowColumns columns;
  for (int k = model.nv - 1; k >= 0; --k) columns.column_of(km, k);  // not in DOF order
  std::vector<int> which;  // every column, in an order of their own
  for (int c = 0; c < columns.size(); c += 2) which.push_back(c);
  for (int c = 1; c < columns.size(); c += 2) which.push_back(c);
  JointRowScratch<L> s(0, columns.size(), model.nv);
  joint_row_columns<L>(km, columns, ws, s, which.data(), columns.size());
  std::vector<L> x(model.nv);
  T* xs = reinterpret_cast<T*>(x.data());
  for (int c = 0; c < columns.size(); ++c) {
    for (int r = 0; r < model.nv; ++r) x[r] = L(T(r == columns.dof[c] ? 1 : 0));
    ltdl_solve<L>(km, reinterpret_cast<const T*>(f.from_aba.data()), xs);
    const T* column = reinterpret_cast<const T*>(&s.columns[c * model.nv]);
    ASSERT_EQ(std::memcmp(column, xs, sizeof(T) * W * model.nv), 0) << "column of DOF " << columns.dof[c];
  }
}

class ArticulatedFactor : public test::ModelCaseTest {};

TEST_P(ArticulatedFactor, JointRowColumnsMatchOneSolveEach) {
  expect_joint_row_columns_match_solves<lane::simd<float>>(model_);
  expect_joint_row_columns_match_solves<lane::simd<double>>(model_);
}

TEST_P(ArticulatedFactor, SolvesLikeTheCrbaFactorsInDouble) { expect_factors_solve<lane::simd<double>>(model_); }
TEST_P(ArticulatedFactor, SolvesLikeTheCrbaFactorsInFloat) { expect_factors_solve<lane::simd<float>>(model_); }
TEST_P(ArticulatedFactor, LanesMatchTheScalarPath) {
  expect_lanes_match_scalar<float>(model_);
  expect_lanes_match_scalar<double>(model_);
}

// With link damping (w D in each body's inertia, kernels/body_terms.hpp) at
// a weight of 4 ms, c_lin up to 2 and c_ang up to 4 per second.
Model damped(Model model) {
  for (int b = 0; b < model.nbody; ++b) {
    model.body_linear_damping[b] = 0.5 + 0.25 * (b % 7);
    model.body_angular_damping[b] = 4.0 - 0.5 * (b % 7);
  }
  return model;
}
constexpr double kLinkDampingWeight = 0.004;

TEST_P(ArticulatedFactor, FactorsFromAbaSolveWithLinkDamping) {
  const Model model = damped(model_);
  expect_factors_solve<lane::simd<double>>(model, kLinkDampingWeight);
  expect_factors_solve<lane::simd<float>>(model, kLinkDampingWeight);
}
TEST_P(ArticulatedFactor, LanesMatchTheScalarPathWithLinkDamping) {
  const Model model = damped(model_);
  expect_lanes_match_scalar<float>(model, kLinkDampingWeight);
  expect_lanes_match_scalar<double>(model, kLinkDampingWeight);
}

INSTANTIATE_TEST_SUITE_P(SharedModels, ArticulatedFactor, ::testing::ValuesIn(test::all_model_cases()),
                         [](const auto& info) { return test::case_name(info.param); });

}  // namespace
}  // namespace lockstep
