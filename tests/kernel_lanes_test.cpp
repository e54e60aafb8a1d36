// Every kernel, float and double: the SIMD lanes reproduce the scalar
// reference lane bit for bit (lane.hpp rounds identically on both), and a
// copy's result does not depend on its lane or block.
#include "batch/batch_dynamics.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <functional>

namespace lockstep {
namespace {

using test::ModelCase;

// Fills copy c of `s` with random inputs; a few copies get their own masses.
template <class T>
void randomize(const Model& model, BatchState<T>& s, int copy, std::mt19937& rng) {
  s.q.set(copy, test::random_configuration(model, rng));
  s.v.set(copy, test::random_vector(model.nv, rng, 2.0));
  s.tau.set(copy, test::random_vector(model.nv, rng, 5.0));
  s.qacc.set(copy, test::random_vector(model.nv, rng, 3.0));
  s.wrench.set(copy, test::random_vector(6 * model.nbody, rng, 1.0));
  if (copy % 3 == 1)
    for (int b = 0; b < model.nbody; ++b)
      s.set_body_inertia(copy, b, model.body_mass[b] * (1.0 + 0.1 * copy), model.body_com[b] * 0.9,
                         model.body_inertia[b] * (1.0 + 0.05 * copy));
}

// Copies every input of copy `from` of `a` into copy `to` of `b`.
template <class T, class U>
void copy_inputs(const BatchState<T>& a, int from, BatchState<U>& b, int to) {
  b.q.set(to, a.q.get(from));
  b.v.set(to, a.v.get(from));
  b.tau.set(to, a.tau.get(from));
  b.qacc.set(to, a.qacc.get(from));
  b.wrench.set(to, a.wrench.get(from));
  b.inertia.set(to, a.inertia.get(from));
  b.gravity.set(to, a.gravity.get(from));
}

// One batch utility under test: its name, output size, and how to call it.
template <class L>
struct Operation {
  const char* name;
  int size;
  std::function<void(const BatchDynamics<L>&, const BatchState<lane::scalar_t<L>>&, BatchArray<lane::scalar_t<L>>&)> run;
};

template <class L>
std::vector<Operation<L>> operations(const Model& m) {
  using T = lane::scalar_t<L>;
  using D = BatchDynamics<L>;
  using S = BatchState<T>;
  using A = BatchArray<T>;
  const int nframe = static_cast<int>(m.frame_name.size());
  const int last_frame = nframe - 1;
  return {
      {"frame_poses", 12 * nframe, [](const D& d, const S& s, A& o) { d.frame_poses(s, o); }},
      {"frame_velocities", 6 * nframe, [](const D& d, const S& s, A& o) { d.frame_velocities(s, o); }},
      {"frame_accelerations", 6 * nframe, [](const D& d, const S& s, A& o) { d.frame_accelerations(s, o); }},
      {"forward_dynamics", m.nv, [](const D& d, const S& s, A& o) { d.forward_dynamics(s, o); }},
      {"inverse_dynamics", m.nv, [](const D& d, const S& s, A& o) { d.inverse_dynamics(s, o); }},
      {"bias_force", m.nv, [](const D& d, const S& s, A& o) { d.bias_force(s, o); }},
      {"coriolis_force", m.nv, [](const D& d, const S& s, A& o) { d.coriolis_force(s, o); }},
      {"gravity_force", m.nv, [](const D& d, const S& s, A& o) { d.gravity_force(s, o); }},
      {"external_force", m.nv, [](const D& d, const S& s, A& o) { d.external_force(s, o); }},
      {"mass_matrix", m.nv * m.nv, [](const D& d, const S& s, A& o) { d.mass_matrix(s, o); }},
      {"inverse_mass_matrix", m.nv * m.nv, [](const D& d, const S& s, A& o) { d.inverse_mass_matrix(s, o); }},
      {"com_jacobian", 6 * m.nbody * m.nv, [](const D& d, const S& s, A& o) { d.com_jacobian(s, o); }},
      {"point_jacobian", 6 * m.nv,
       [last_frame](const D& d, const S& s, A& o) { d.point_jacobian(s, last_frame, Eigen::Vector3d(0.1, -0.2, 0.3), o); }},
      {"kinetic_energy", 1, [](const D& d, const S& s, A& o) { d.kinetic_energy(s, o); }},
      {"potential_energy", 1, [](const D& d, const S& s, A& o) { d.potential_energy(s, o); }},
      {"linear_momentum", 3, [](const D& d, const S& s, A& o) { d.linear_momentum(s, o); }},
      {"incoming_joint_forces", 6 * m.nbody, [](const D& d, const S& s, A& o) { d.incoming_joint_forces(s, o); }},
      {"transmitted_joint_forces", 6 * m.nbody, [](const D& d, const S& s, A& o) { d.transmitted_joint_forces(s, o); }},
      {"integrate", m.nq, [](const D& d, const S& s, A& o) { d.integrate(s.q, s.v, T(0.01), o); }},
  };
}

template <class T>
void expect_lanes_match_reference(const Model& model) {
  using Simd = lane::simd<T>;
  const int width = static_cast<int>(lane::width_v<Simd>);
  const int copies = 2 * width + 3;  // several blocks and a partly padded one
  BatchDynamics<Simd> simd(model);
  BatchDynamics<T> scalar(model);
  BatchState<T> s = simd.make_state(copies);
  BatchState<T> r = scalar.make_state(copies);
  // The same copies in reverse order: every copy changes lane and block.
  BatchState<T> reversed = simd.make_state(copies);
  std::mt19937 rng(7);
  for (int c = 0; c < copies; ++c) {
    randomize(model, s, c, rng);
    copy_inputs(s, c, r, c);
    copy_inputs(s, c, reversed, copies - 1 - c);
  }
  const auto simd_ops = operations<Simd>(model);
  const auto scalar_ops = operations<T>(model);
  for (std::size_t k = 0; k < simd_ops.size(); ++k) {
    BatchArray<T> out = simd.make_array(copies, simd_ops[k].size);
    BatchArray<T> out_reversed = simd.make_array(copies, simd_ops[k].size);
    BatchArray<T> ref = scalar.make_array(copies, simd_ops[k].size);
    simd_ops[k].run(simd, s, out);
    simd_ops[k].run(simd, reversed, out_reversed);
    scalar_ops[k].run(scalar, r, ref);
    for (int c = 0; c < copies; ++c) {
      const Eigen::VectorXd a = out.get(c), b = ref.get(c), p = out_reversed.get(copies - 1 - c);
      ASSERT_TRUE(a.allFinite()) << simd_ops[k].name << " copy " << c;
      for (int i = 0; i < a.size(); ++i) {
        ASSERT_EQ(a[i], b[i]) << simd_ops[k].name << ": copy " << c << " value " << i << " differs from the scalar lane";
        ASSERT_EQ(a[i], p[i]) << simd_ops[k].name << ": copy " << c << " value " << i << " depends on its lane";
      }
    }
  }
}

// difference() (whose Spherical and Free joints go through lane::atan2, the
// same code on both lane types) reproduces the scalar lane bit for bit.
template <class T>
void expect_difference_matches_reference(const Model& model) {
  using Simd = lane::simd<T>;
  const int copies = 2 * static_cast<int>(lane::width_v<Simd>) + 3;
  BatchDynamics<Simd> simd(model);
  BatchDynamics<T> scalar(model);
  BatchArray<T> q0 = simd.make_array(copies, model.nq), q1 = simd.make_array(copies, model.nq);
  BatchArray<T> r0 = scalar.make_array(copies, model.nq), r1 = scalar.make_array(copies, model.nq);
  std::mt19937 rng(11);
  for (int c = 0; c < copies; ++c) {
    const Eigen::VectorXd a = test::random_configuration(model, rng), b = test::random_configuration(model, rng);
    q0.set(c, a); q1.set(c, b); r0.set(c, a); r1.set(c, b);
  }
  BatchArray<T> v = simd.make_array(copies, model.nv), ref = scalar.make_array(copies, model.nv);
  simd.difference(q0, q1, v);
  scalar.difference(r0, r1, ref);
  for (int c = 0; c < copies; ++c) {
    const Eigen::VectorXd simd_v = v.get(c), scalar_v = ref.get(c);
    for (int k = 0; k < model.nv; ++k) ASSERT_EQ(simd_v[k], scalar_v[k]) << "copy " << c << " DOF " << k;
  }
}

class KernelLanes : public ::testing::TestWithParam<ModelCase> {};

TEST_P(KernelLanes, FloatLanesMatchScalarReference) {
  const Model model = test::load_model_case(GetParam());
  expect_lanes_match_reference<float>(model);
  expect_difference_matches_reference<float>(model);
}

TEST_P(KernelLanes, DoubleLanesMatchScalarReference) {
  const Model model = test::load_model_case(GetParam());
  expect_lanes_match_reference<double>(model);
  expect_difference_matches_reference<double>(model);
}

// The same with gravity switched off on every second body
// (Model::body_gravity): the weight that cancels it takes the same path.
TEST_P(KernelLanes, LanesMatchScalarReferenceWithBodiesWithoutGravity) {
  Model model = test::load_model_case(GetParam());
  for (int b = 1; b < model.nbody; b += 2) model.body_gravity[b] = 0;
  expect_lanes_match_reference<float>(model);
  expect_lanes_match_reference<double>(model);
}

INSTANTIATE_TEST_SUITE_P(SharedModels, KernelLanes, ::testing::ValuesIn(test::all_model_cases()),
                         [](const auto& info) { return test::case_name(info.param); });

}  // namespace
}  // namespace lockstep
