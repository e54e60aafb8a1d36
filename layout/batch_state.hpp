// The inputs of the dynamics kernels for N copies, structure-of-arrays:
// every field is a BatchArray. Per-copy inertial parameters default to the
// model's and may be overridden copy by copy (domain randomisation); every
// kernel reads them from here.
#pragma once

#include "layout/batch_array.hpp"
#include "layout/model.hpp"

namespace lockstep {

template <class T>
struct BatchState {
  static constexpr int kInertiaParams = 10;  // mass, COM (3), inertia about COM (xx yy zz xy xz yz)

  BatchState(const Model& model, int copies, int width);

  int copies() const { return q.copies(); }

  BatchArray<T> q;        // (nq) configuration, quaternions (w, x, y, z)
  BatchArray<T> v;        // (nv) generalized velocity (Free: body-frame twist [v; w])
  BatchArray<T> tau;      // (nv) joint forces
  BatchArray<T> qacc;     // (nv) joint accelerations (input of inverse dynamics)
  BatchArray<T> wrench;   // (nbody x 6) world [force; torque about the body COM]
  BatchArray<T> inertia;  // (nbody x 10) per-copy inertial parameters
  BatchArray<T> gravity;  // (3) world gravity

  // The model's inertial parameters, kInertiaParams per body: every copy's
  // at the start.
  static Eigen::VectorXd model_inertia_params(const Model& model);

  // Overrides one body's inertial parameters in one copy: mass (kg), COM in
  // the body frame, rotational inertia about the COM in body axes.
  void set_body_inertia(int copy, int body, double mass, const Eigen::Vector3d& com, const Eigen::Matrix3d& rot_inertia);

  // The rotational inertia among one body's kInertiaParams parameters
  // (mass, COM (3), xx yy zz xy xz yz), as a symmetric matrix.
  static Eigen::Matrix3d rotational_inertia(const double* params) {
    Eigen::Matrix3d I;
    I << params[4], params[7], params[8], params[7], params[5], params[9], params[8], params[9], params[6];
    return I;
  }
};

template <class T>
BatchState<T>::BatchState(const Model& model, int copies, int width)
    : q(copies, model.nq, width), v(copies, model.nv, width), tau(copies, model.nv, width),
      qacc(copies, model.nv, width), wrench(copies, 6 * model.nbody, width),
      inertia(copies, kInertiaParams * model.nbody, width), gravity(copies, 3, width) {
  q.set_all(model.neutral_configuration());
  gravity.set_all(model.gravity);
  inertia.set_all(model_inertia_params(model));
}

template <class T>
Eigen::VectorXd BatchState<T>::model_inertia_params(const Model& model) {
  Eigen::VectorXd params(kInertiaParams * model.nbody);
  for (int b = 0; b < model.nbody; ++b) {
    const Eigen::Matrix3d& I = model.body_inertia[b];
    const Eigen::Vector3d& c = model.body_com[b];
    params.segment<kInertiaParams>(kInertiaParams * b) << model.body_mass[b], c.x(), c.y(), c.z(), I(0, 0), I(1, 1),
        I(2, 2), I(0, 1), I(0, 2), I(1, 2);
  }
  return params;
}

template <class T>
void BatchState<T>::set_body_inertia(int copy, int body, double mass, const Eigen::Vector3d& com,
                                     const Eigen::Matrix3d& I) {
  if (copy < 0 || copy >= copies())
    throw std::out_of_range("copy index " + std::to_string(copy) + " outside [0, " + std::to_string(copies()) + ")");
  if (body < 0 || kInertiaParams * body >= inertia.size())
    throw std::out_of_range("body index " + std::to_string(body) + " outside the model");
  const double params[kInertiaParams] = {mass, com.x(), com.y(), com.z(), I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2), I(1, 2)};
  for (int k = 0; k < kInertiaParams; ++k) inertia.at(copy, kInertiaParams * body + k) = static_cast<T>(params[k]);
}

}  // namespace lockstep
