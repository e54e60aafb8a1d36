// The dynamics kernels checked against each other and against finite
// differences, in double, on every model in ../shared/models, fixed and
// floating base, at random states.
//
// Tolerances. The identities that solve with M (ABA against RNEA, M M^-1)
// lose up to cond(M) * eps relative accuracy, so they are checked against
// kSolveSlack * eps * cond(M) * scale with kSolveSlack = 100 (sums over up to
// ~40 DOFs and a few recursions). Identities without a solve (CRBA against
// RNEA, J^T F against RNEA) are checked to 1e-10 of the size of the terms.
// Central differences with step h = 1e-5 have truncation error ~h^2 * |f'''|
// ~1e-10 and round-off ~eps / h ~1e-11, so they are checked to 1e-6 relative.
#include "batch/copy_dynamics.hpp"
#include "contact_support.hpp"
#include "io/urdf_import.hpp"
#include "kernels/aba.hpp"
#include "kernels/kernel_model.hpp"
#include "test_support.hpp"

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

namespace lockstep {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
constexpr double kSolveSlack = 100.0;
constexpr double kStep = 1e-5;
constexpr double kDifferenceTolerance = 1e-6;

double condition_number(const Eigen::MatrixXd& M) {
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(M).eigenvalues();
  return ev.maxCoeff() / ev.minCoeff();
}

class Identities : public test::ModelCaseTest {
 protected:
  std::mt19937 rng_{42};
};

void expect_aba_inverts_rnea(const Model& model, const CopyDynamics& dyn, std::mt19937& rng) {
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::VectorXd q = test::random_configuration(model, rng);
    const Eigen::VectorXd v = test::random_vector(model.nv, rng, 2.0);
    const Eigen::VectorXd a = test::random_vector(model.nv, rng, 3.0);
    const Eigen::MatrixXd wrench = Eigen::MatrixXd::Random(model.nbody, 6);
    const Eigen::VectorXd tau = dyn.inverse_dynamics(q, v, a, &wrench);
    const Eigen::VectorXd a2 = dyn.forward_dynamics(q, v, tau, &wrench);
    const double cond = condition_number(dyn.mass_matrix(q));
    EXPECT_LE((a2 - a).norm(), kSolveSlack * kEps * cond * (a.norm() + 1.0)) << "cond(M) = " << cond;
  }
}

TEST_P(Identities, AbaInvertsRnea) { expect_aba_inverts_rnea(model_, *dyn_, rng_); }

// Armature is a rotor's inertia on its DOF: CRBA puts it on M's diagonal,
// ABA on D, and RNEA must add armature * qacc, or the round trip and the
// columns of M fail by about the armature (0.05-0.5 here, against joint
// inertias from 1e-3).
TEST_P(Identities, AbaInvertsRneaWithArmature) {
  Model geared = model_;
  for (int k = 0; k < geared.nv; ++k) geared.dof_armature[k] = 0.05 + 0.45 * std::uniform_real_distribution<>()(rng_);
  const CopyDynamics dyn(geared, Precision::Double);
  expect_aba_inverts_rnea(geared, dyn, rng_);
  const Eigen::VectorXd q = test::random_configuration(geared, rng_);
  const Eigen::VectorXd v = test::random_vector(geared.nv, rng_, 2.0), a = test::random_vector(geared.nv, rng_, 3.0);
  const Eigen::VectorXd expected = dyn.mass_matrix(q) * a + dyn.bias_force(q, v);
  EXPECT_LE((dyn.inverse_dynamics(q, v, a) - expected).norm(), 1e-10 * expected.norm());
}

// The Free root's implicit gyroscopic Jacobian h G, G = d(v x* I v)/dv,
// against central differences of the velocity-product force on a rigid
// inertia with an offset centre of mass. The force is quadratic in v, so
// the differences have no truncation error; their round-off is about
// eps |f| / kStep ~ 1e-11 against entries of order 1.
TEST(GyroscopicJacobian, MatchesDifferencesOfTheVelocityProductForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Vec3<double> com{0.1, -0.05, 0.2};
  const double rot[6] = {0.3, 0.5, 0.4, 0.02, -0.01, 0.03};
  const Inertia6<double> I = spatial::rigid_inertia(2.0, com, rot);
  auto force = [&](const Vec6<double>& v) { return spatial::force_cross(v, spatial::mul(I, v)); };
  for (int trial = 0; trial < 5; ++trial) {
    Vec6<double> v;
    for (double& e : v.e) e = 3.0 * u(rng);
    const double h = 0.004;
    double hG[36];
    gyroscopic_jacobian(I, v, h, hG);
    for (int j = 0; j < 6; ++j) {
      Vec6<double> plus = v, minus = v;
      plus.e[j] += kStep;
      minus.e[j] -= kStep;
      const Vec6<double> fp = force(plus), fm = force(minus);
      for (int r = 0; r < 6; ++r)
        EXPECT_NEAR(hG[r * 6 + j], h * (fp.e[r] - fm.e[r]) / (2 * kStep), h * 1e-8) << "row " << r << " column " << j;
    }
  }
}

// ABA's backward pass hands each body's articulated inertia to its parent
// in a carry when the parent is the next body visited, else into the
// parent's sum, which the first of those children starts (Store) and the
// others add to (Add). A forest of a quadruped (a base with four legs of
// three bodies), a free box and a fixed-base arm (a chain) has every kind
// and several roots; ABA must invert RNEA on it as on one robot.
TEST(SubtreeHandoff, ForestOfQuadrupedFreeBoxAndArm) {
  ModelBuilder builder;
  UrdfOptions floating;
  floating.floating_base = true;
  add_urdf(builder, test::shared_model_path("anymal_b"), floating);
  builder.add_articulation(test::free_shape_spec("box", ShapeType::Box, Eigen::Vector3d(0.1, 0.2, 0.3), 2.0));
  UrdfOptions arm;
  arm.name_prefix = "arm_";
  add_urdf(builder, test::shared_model_path("ur5"), arm);
  const Model model = builder.finalize();
  const KernelModel<double> km(model);
  using H = Handoff;
  // anymal_b: base 0, legs (1 2 3) (4 5 6) (7 8 9) (10 11 12); the box 13;
  // ur5's six links 14..19.
  const std::vector<H> expected = {H::Root,  H::Carry, H::Carry, H::Carry, H::Add,   H::Carry, H::Carry,
                                   H::Add,   H::Carry, H::Carry, H::Store, H::Carry, H::Carry, H::Root,
                                   H::Root,  H::Carry, H::Carry, H::Carry, H::Carry, H::Carry};
  ASSERT_EQ(km.nbody, static_cast<int>(expected.size()));
  EXPECT_EQ(km.body_handoff, expected);
  EXPECT_TRUE(km.body_takes_sum[0]);
  EXPECT_TRUE(km.body_takes_carry[0]);
  EXPECT_FALSE(km.body_takes_sum[1]);
  EXPECT_FALSE(km.body_takes_carry[3]);
  EXPECT_FALSE(km.body_takes_carry[13]);  // the box: its next body is the arm's root
  const CopyDynamics dyn(model, Precision::Double);
  std::mt19937 rng(7);
  expect_aba_inverts_rnea(model, dyn, rng);
}

TEST_P(Identities, CrbaColumnsAreRneaDifferences) {
  const Eigen::VectorXd q = test::random_configuration(model_, rng_);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model_.nv);
  const Eigen::MatrixXd M = dyn_->mass_matrix(q);
  const Eigen::VectorXd tau0 = dyn_->inverse_dynamics(q, zero, zero);
  for (int i = 0; i < model_.nv; ++i) {
    const Eigen::VectorXd column = dyn_->inverse_dynamics(q, zero, Eigen::VectorXd::Unit(model_.nv, i)) - tau0;
    EXPECT_LE((M.col(i) - column).norm(), 1e-10 * (M.norm() + tau0.norm())) << "column " << i;
  }
  EXPECT_LE((M - M.transpose()).norm(), 1e-14 * M.norm());
}

TEST_P(Identities, MassMatrixTimesAbaIsTauMinusBias) {
  const Eigen::VectorXd q = test::random_configuration(model_, rng_);
  const Eigen::VectorXd v = test::random_vector(model_.nv, rng_, 2.0);
  const Eigen::VectorXd tau = test::random_vector(model_.nv, rng_, 10.0);
  const Eigen::MatrixXd M = dyn_->mass_matrix(q);
  const Eigen::VectorXd rhs = tau - dyn_->bias_force(q, v);
  const Eigen::VectorXd a = dyn_->forward_dynamics(q, v, tau);
  // Backward error of the solve: |M a - rhs| <= slack eps |M| |a|.
  EXPECT_LE((M * a - rhs).norm(), kSolveSlack * kEps * (M.norm() * a.norm() + rhs.norm()));
}

TEST_P(Identities, MassMatrixTimesInverseIsIdentity) {
  const Eigen::VectorXd q = test::random_configuration(model_, rng_);
  const Eigen::MatrixXd M = dyn_->mass_matrix(q);
  const Eigen::MatrixXd Minv = dyn_->inverse_mass_matrix(q);
  const double cond = condition_number(M);
  EXPECT_LE((M * Minv - Eigen::MatrixXd::Identity(model_.nv, model_.nv)).norm(), kSolveSlack * kEps * cond * model_.nv)
      << "cond(M) = " << cond;
}

// d/dt (1/2 v^T M v) = v^T (tau - c) for the motion without gravity and
// without tau, so 1/2 v^T Mdot v = v^T c(q, v): the energy form of the
// skew-symmetry of Mdot - 2C, valid in the body-frame velocities of Free and
// Spherical joints too.
TEST_P(Identities, MassMatrixRateMatchesCoriolisPower) {
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::VectorXd q = test::random_configuration(model_, rng_);
    const Eigen::VectorXd v = test::random_vector(model_.nv, rng_, 2.0);
    const Eigen::MatrixXd Mdot =
        (dyn_->mass_matrix(dyn_->integrate(q, v, kStep)) - dyn_->mass_matrix(dyn_->integrate(q, v, -kStep))) / (2 * kStep);
    const double lhs = 0.5 * v.dot(Mdot * v);
    const double rhs = v.dot(dyn_->coriolis_force(q, v));
    ASSERT_GT(Mdot.norm(), 1e-6);  // the mass matrix does change along v
    EXPECT_NEAR(lhs, rhs, kDifferenceTolerance * (1.0 + std::abs(rhs) + Mdot.norm() * v.squaredNorm()));
  }
}

// On fixed-base models the coordinates are holonomic and the Coriolis matrix
// of the Christoffel symbols, C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j -
// dM_jk/dq_i) v_k, makes Mdot - 2C skew-symmetric and C v the RNEA Coriolis term.
class HolonomicIdentities : public Identities {};

TEST_P(HolonomicIdentities, MassMatrixRateMinusTwoCoriolisIsSkew) {
  for (JointType t : model_.body_joint) ASSERT_TRUE(t == JointType::Revolute || t == JointType::Prismatic);
  const int n = model_.nv;
  const Eigen::VectorXd q = test::random_configuration(model_, rng_);
  const Eigen::VectorXd v = test::random_vector(n, rng_, 2.0);
  std::vector<Eigen::MatrixXd> dM(n);
  for (int k = 0; k < n; ++k) {
    const Eigen::VectorXd e = Eigen::VectorXd::Unit(n, k);
    dM[k] = (dyn_->mass_matrix(q + kStep * e) - dyn_->mass_matrix(q - kStep * e)) / (2 * kStep);
  }
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(n, n), Mdot = Eigen::MatrixXd::Zero(n, n);
  for (int k = 0; k < n; ++k) Mdot += dM[k] * v[k];
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) C(i, j) += 0.5 * (dM[k](i, j) + dM[j](i, k) - dM[i](j, k)) * v[k];
  const Eigen::MatrixXd N = Mdot - 2 * C;
  const double scale = 1.0 + Mdot.norm();
  EXPECT_LE((N + N.transpose()).norm(), kDifferenceTolerance * scale);
  const Eigen::VectorXd c = dyn_->coriolis_force(q, v);
  EXPECT_LE((C * v - c).norm(), kDifferenceTolerance * scale * v.norm() + 1e-12);
}

// g(q) = dV/dq along each tangent direction.
TEST_P(Identities, GravityForceIsPotentialGradient) {
  const Eigen::VectorXd q = test::random_configuration(model_, rng_);
  const Eigen::VectorXd g = dyn_->gravity_force(q);
  ASSERT_GT(g.norm(), 1e-3);  // not trivially zero
  for (int k = 0; k < model_.nv; ++k) {
    const Eigen::VectorXd e = Eigen::VectorXd::Unit(model_.nv, k);
    const double dV = (dyn_->potential_energy(dyn_->integrate(q, e, kStep)) -
                       dyn_->potential_energy(dyn_->integrate(q, e, -kStep))) / (2 * kStep);
    EXPECT_NEAR(g[k], dV, kDifferenceTolerance * (1.0 + g.cwiseAbs().maxCoeff())) << model_.dof_name[k];
  }
}

// dT/dv = M v and T = 1/2 v^T M v.
TEST_P(Identities, KineticEnergyIsQuadraticFormOfMassMatrix) {
  const Eigen::VectorXd q = test::random_configuration(model_, rng_);
  const Eigen::VectorXd v = test::random_vector(model_.nv, rng_, 2.0);
  const double T = dyn_->kinetic_energy(q, v);
  EXPECT_NEAR(T, 0.5 * v.dot(dyn_->mass_matrix(q) * v), 1e-12 * (1.0 + T));
  EXPECT_GT(T, 0.0);
  // with armature on every DOF (rotor inertia, in M's diagonal): it once
  // left T while M took it
  Model geared = model_;
  const Eigen::VectorXd armature = Eigen::VectorXd::LinSpaced(model_.nv, 0.01, 0.2);
  geared.dof_armature.assign(armature.data(), armature.data() + model_.nv);
  const CopyDynamics with_armature(geared, Precision::Double);
  const double Tg = with_armature.kinetic_energy(q, v);
  EXPECT_NEAR(Tg, 0.5 * v.dot(with_armature.mass_matrix(q) * v), 1e-12 * (1.0 + Tg));
  EXPECT_NEAR(Tg - T, 0.5 * armature.dot(v.cwiseAbs2()), 1e-12 * (1.0 + Tg));
}

INSTANTIATE_TEST_SUITE_P(SharedModels, HolonomicIdentities, ::testing::ValuesIn(test::fixed_model_cases()),
                         [](const auto& info) { return test::case_name(info.param); });
INSTANTIATE_TEST_SUITE_P(SharedModels, Identities, ::testing::ValuesIn(test::all_model_cases()),
                         [](const auto& info) { return test::case_name(info.param); });

}  // namespace
}  // namespace lockstep
