#include "batch/copy_dynamics.hpp"

#include "batch/batch_dynamics.hpp"

#include <stdexcept>
#include <string>

namespace lockstep {

const char* precision_name(Precision precision) { return precision == Precision::Float ? "float" : "double"; }

namespace {

// One copy on the scalar reference lane of precision T. Each call fills a
// state of its own (BatchDynamics keeps its scratch per thread), so threads
// may share one object, as its const methods promise.
template <class T>
class OneCopy {
 public:
  explicit OneCopy(const Model& model) : dynamics_(model) {}

  // Runs f(dynamics, state, out) into an output array of `size` values,
  // the state holding the call's inputs.
  template <class F>
  Eigen::VectorXd run(const Eigen::VectorXd& q, const Eigen::VectorXd& v, const Eigen::VectorXd& tau,
                      const Eigen::VectorXd& qacc, const Eigen::MatrixXd* wrench, F&& f, int size) const {
    BatchState<T> state = dynamics_.make_state(1);
    set(state.q, q, "q");
    set(state.v, v, "v");
    set(state.tau, tau, "tau");
    set(state.qacc, qacc, "qacc");
    set_wrench(state, wrench);
    BatchArray<T> out = dynamics_.make_array(1, size);
    f(dynamics_, state, out);
    return out.get(0);
  }

  Eigen::VectorXd integrate(const Eigen::VectorXd& q, const Eigen::VectorXd& v, double dt) const {
    BatchArray<T> qa = configuration(q, "q"), va = dynamics_.make_array(1, dynamics_.model().nv);
    set(va, v, "v");
    BatchArray<T> out = dynamics_.make_array(1, dynamics_.model().nq);
    dynamics_.integrate(qa, va, static_cast<T>(dt), out);
    return out.get(0);
  }
  Eigen::VectorXd difference(const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const {
    BatchArray<T> out = dynamics_.make_array(1, dynamics_.model().nv);
    dynamics_.difference(configuration(q0, "q0"), configuration(q1, "q1"), out);
    return out.get(0);
  }

 private:
  BatchArray<T> configuration(const Eigen::VectorXd& q, const char* what) const {
    BatchArray<T> a = dynamics_.make_array(1, dynamics_.model().nq);
    set(a, q, what);
    return a;
  }
  static void set(BatchArray<T>& array, const Eigen::VectorXd& values, const char* what) {
    if (values.size() != array.size())
      throw std::invalid_argument(std::string(what) + ": expected " + std::to_string(array.size()) + " values, got " +
                                  std::to_string(values.size()));
    array.set(0, values);
  }

  void set_wrench(BatchState<T>& state, const Eigen::MatrixXd* wrench) const {
    const int nbody = dynamics_.model().nbody;
    if (!wrench) {
      state.wrench.set(0, Eigen::VectorXd::Zero(6 * nbody));
      return;
    }
    if (wrench->rows() != nbody || wrench->cols() != 6)
      throw std::invalid_argument("link_wrench: expected " + std::to_string(nbody) + " x 6, got " +
                                  std::to_string(wrench->rows()) + " x " + std::to_string(wrench->cols()));
    Eigen::VectorXd flat(6 * nbody);
    for (int b = 0; b < nbody; ++b) flat.segment<6>(6 * b) = wrench->row(b).transpose();
    state.wrench.set(0, flat);
  }

  BatchDynamics<T> dynamics_;
};

std::vector<Eigen::Isometry3d> poses(const Eigen::VectorXd& flat) {
  std::vector<Eigen::Isometry3d> out(flat.size() / 12);
  for (std::size_t i = 0; i < out.size(); ++i) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) X.linear()(r, c) = flat[12 * i + 3 * r + c];
    X.translation() = flat.segment<3>(12 * i + 9);
    out[i] = X;
  }
  return out;
}

}  // namespace

struct CopyDynamics::Impl {
  std::unique_ptr<OneCopy<float>> single;
  std::unique_ptr<OneCopy<double>> twin;  // exactly one of the two is set
  template <class F>
  Eigen::VectorXd visit(F&& f) { return single ? f(*single) : f(*twin); }
};

CopyDynamics::CopyDynamics(const Model& model, Precision precision)
    : model_(&model), precision_(precision), impl_(std::make_unique<Impl>()) {
  if (precision == Precision::Float) impl_->single = std::make_unique<OneCopy<float>>(model);
  else impl_->twin = std::make_unique<OneCopy<double>>(model);
}
CopyDynamics::~CopyDynamics() = default;
CopyDynamics::CopyDynamics(CopyDynamics&&) noexcept = default;
CopyDynamics& CopyDynamics::operator=(CopyDynamics&&) noexcept = default;

namespace {
Eigen::MatrixXd row_major(const Eigen::VectorXd& flat, int rows, int cols) {
  return Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(flat.data(), rows, cols);
}
}  // namespace

struct CopyDynamics::Inputs {
  const Eigen::VectorXd* q = nullptr;
  const Eigen::VectorXd* v = nullptr;
  const Eigen::VectorXd* tau = nullptr;
  const Eigen::VectorXd* qacc = nullptr;
  const Eigen::MatrixXd* wrench = nullptr;
};

// Sets the copy's inputs, then runs method(dynamics, state, out) of the
// batch of either precision into `size` values.
template <class Method>
Eigen::VectorXd CopyDynamics::evaluate(const Inputs& in, Method&& method, int size) const {
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model_->nv);
  return impl_->visit([&](const auto& c) {
    return c.run(in.q ? *in.q : model_->neutral_configuration(), in.v ? *in.v : zero, in.tau ? *in.tau : zero,
                 in.qacc ? *in.qacc : zero, in.wrench, method, size);
  });
}

#define LOCKSTEP_BATCH_METHOD(METHOD) [](const auto& d, const auto& s, auto& o) { d.METHOD(s, o); }

std::vector<Eigen::Isometry3d> CopyDynamics::frame_poses(const Eigen::VectorXd& q) const {
  return poses(evaluate({&q}, LOCKSTEP_BATCH_METHOD(frame_poses), 12 * static_cast<int>(model_->frame_name.size())));
}
std::vector<Eigen::Isometry3d> CopyDynamics::body_poses(const Eigen::VectorXd& q) const {
  return poses(evaluate({&q}, LOCKSTEP_BATCH_METHOD(body_poses), 12 * model_->nbody));
}
Eigen::MatrixXd CopyDynamics::frame_velocities(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  const int frames = static_cast<int>(model_->frame_name.size());
  return Eigen::Map<const Eigen::MatrixXd>(evaluate({&q, &v}, LOCKSTEP_BATCH_METHOD(frame_velocities), 6 * frames).data(),
                                           6, frames);
}
Eigen::MatrixXd CopyDynamics::frame_accelerations(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                                  const Eigen::VectorXd& qacc) const {
  const int frames = static_cast<int>(model_->frame_name.size());
  const Eigen::VectorXd flat =
      evaluate({&q, &v, nullptr, &qacc}, LOCKSTEP_BATCH_METHOD(frame_accelerations), 6 * frames);
  return Eigen::Map<const Eigen::MatrixXd>(flat.data(), 6, frames);
}
Eigen::MatrixXd CopyDynamics::mass_matrix(const Eigen::VectorXd& q) const {
  const int n = model_->nv;
  return row_major(evaluate({&q}, LOCKSTEP_BATCH_METHOD(mass_matrix), n * n), n, n);
}
Eigen::MatrixXd CopyDynamics::inverse_mass_matrix(const Eigen::VectorXd& q) const {
  const int n = model_->nv;
  return row_major(evaluate({&q}, LOCKSTEP_BATCH_METHOD(inverse_mass_matrix), n * n), n, n);
}
Eigen::VectorXd CopyDynamics::bias_force(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  return evaluate({&q, &v}, LOCKSTEP_BATCH_METHOD(bias_force), model_->nv);
}
Eigen::VectorXd CopyDynamics::coriolis_force(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  return evaluate({&q, &v}, LOCKSTEP_BATCH_METHOD(coriolis_force), model_->nv);
}
Eigen::VectorXd CopyDynamics::gravity_force(const Eigen::VectorXd& q) const {
  return evaluate({&q}, LOCKSTEP_BATCH_METHOD(gravity_force), model_->nv);
}
Eigen::VectorXd CopyDynamics::external_force(const Eigen::VectorXd& q, const Eigen::MatrixXd& link_wrench) const {
  return evaluate({&q, nullptr, nullptr, nullptr, &link_wrench}, LOCKSTEP_BATCH_METHOD(external_force), model_->nv);
}
Eigen::VectorXd CopyDynamics::inverse_dynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                               const Eigen::VectorXd& a, const Eigen::MatrixXd* link_wrench) const {
  return evaluate({&q, &v, nullptr, &a, link_wrench}, LOCKSTEP_BATCH_METHOD(inverse_dynamics), model_->nv);
}
Eigen::VectorXd CopyDynamics::forward_dynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                               const Eigen::VectorXd& tau, const Eigen::MatrixXd* link_wrench) const {
  return evaluate({&q, &v, &tau, nullptr, link_wrench}, LOCKSTEP_BATCH_METHOD(forward_dynamics), model_->nv);
}
double CopyDynamics::kinetic_energy(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  return evaluate({&q, &v}, LOCKSTEP_BATCH_METHOD(kinetic_energy), 1)[0];
}
double CopyDynamics::potential_energy(const Eigen::VectorXd& q) const {
  return evaluate({&q}, LOCKSTEP_BATCH_METHOD(potential_energy), 1)[0];
}
Eigen::Vector3d CopyDynamics::linear_momentum(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  return evaluate({&q, &v}, LOCKSTEP_BATCH_METHOD(linear_momentum), 3);
}
Eigen::MatrixXd CopyDynamics::com_jacobian(const Eigen::VectorXd& q) const {
  const int rows = 6 * model_->nbody;
  return row_major(evaluate({&q}, LOCKSTEP_BATCH_METHOD(com_jacobian), rows * model_->nv), rows, model_->nv);
}
Eigen::MatrixXd CopyDynamics::point_jacobian(const Eigen::VectorXd& q, int frame, const Eigen::Vector3d& offset) const {
  const auto method = [&](const auto& d, const auto& s, auto& o) { d.point_jacobian(s, frame, offset, o); };
  return row_major(evaluate({&q}, method, 6 * model_->nv), 6, model_->nv);
}
Eigen::MatrixXd CopyDynamics::incoming_joint_forces(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                                    const Eigen::VectorXd& tau, const Eigen::MatrixXd* link_wrench) const {
  const Eigen::VectorXd flat =
      evaluate({&q, &v, &tau, nullptr, link_wrench}, LOCKSTEP_BATCH_METHOD(incoming_joint_forces), 6 * model_->nbody);
  return row_major(flat, model_->nbody, 6);
}
Eigen::MatrixXd CopyDynamics::transmitted_joint_forces(const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                                                       const Eigen::VectorXd& qacc,
                                                       const Eigen::MatrixXd* link_wrench) const {
  const Eigen::VectorXd flat = evaluate({&q, &v, nullptr, &qacc, link_wrench},
                                        LOCKSTEP_BATCH_METHOD(transmitted_joint_forces), 6 * model_->nbody);
  return row_major(flat, model_->nbody, 6);
}
Eigen::VectorXd CopyDynamics::integrate(const Eigen::VectorXd& q, const Eigen::VectorXd& v, double dt) const {
  return impl_->visit([&](auto& c) { return c.integrate(q, v, dt); });
}
Eigen::VectorXd CopyDynamics::difference(const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const {
  return impl_->visit([&](auto& c) { return c.difference(q0, q1); });
}

#undef LOCKSTEP_BATCH_METHOD

}  // namespace lockstep
