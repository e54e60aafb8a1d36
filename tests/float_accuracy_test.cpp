// What float costs against double, per model: relative errors of the mass
// matrix, the bias force, ABA and the link positions at random states. The
// bound is the one of the double identities with float's epsilon: the
// solves lose up to cond(M) * eps, the rest a few hundred eps. The measured
// numbers are printed (and written in docs/accuracy.md).
#include "batch/copy_dynamics.hpp"
#include "test_support.hpp"

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include <cstdio>

namespace lockstep {
namespace {

constexpr double kFloatEps = std::numeric_limits<float>::epsilon();

class FloatAccuracy : public ::testing::TestWithParam<test::ModelCase> {};

double relative(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / std::max(b.norm(), 1e-300); }

TEST_P(FloatAccuracy, WithinConditioningBound) {
  const Model model = test::load_model_case(GetParam());
  CopyDynamics single(model, Precision::Float), twin(model, Precision::Double);
  std::mt19937 rng(17);
  double worst_M = 0, worst_bias = 0, worst_qacc = 0, worst_pos = 0, worst_cond = 0;
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::VectorXd q = test::random_configuration(model, rng), v = test::random_vector(model.nv, rng, 2.0);
    const Eigen::VectorXd tau = test::random_vector(model.nv, rng, 5.0);
    const Eigen::MatrixXd M = twin.mass_matrix(q);
    const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(M).eigenvalues();
    const double cond = ev.maxCoeff() / ev.minCoeff();
    const double eM = relative(single.mass_matrix(q), M);
    const double eb = relative(single.bias_force(q, v), twin.bias_force(q, v));
    const double ea = relative(single.forward_dynamics(q, v, tau), twin.forward_dynamics(q, v, tau));
    const auto Xs = single.frame_poses(q), Xd = twin.frame_poses(q);
    double ep = 0;
    for (std::size_t f = 0; f < Xs.size(); ++f)
      ep = std::max(ep, (Xs[f].translation() - Xd[f].translation()).norm() / (1.0 + Xd[f].translation().norm()));
    EXPECT_LE(eM, 300 * kFloatEps);
    EXPECT_LE(eb, 300 * kFloatEps * (1.0 + v.norm()));
    EXPECT_LE(ea, 100 * kFloatEps * cond);
    EXPECT_LE(ep, 100 * kFloatEps);
    worst_M = std::max(worst_M, eM);
    worst_bias = std::max(worst_bias, eb);
    worst_qacc = std::max(worst_qacc, ea);
    worst_pos = std::max(worst_pos, ep);
    worst_cond = std::max(worst_cond, cond);
  }
  std::printf("| %s | %.1e | %.1e | %.1e | %.1e | %.1e |\n", test::case_name(GetParam()).c_str(), worst_cond, worst_M,
              worst_bias, worst_qacc, worst_pos);
}

INSTANTIATE_TEST_SUITE_P(SharedModels, FloatAccuracy, ::testing::ValuesIn(test::all_model_cases()),
                         [](const auto& info) { return test::case_name(info.param); });

}  // namespace
}  // namespace lockstep
