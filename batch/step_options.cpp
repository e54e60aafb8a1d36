#include "batch/step_options.hpp"

namespace lockstep {

const char* solver_name(SolverType solver) { return solver == SolverType::PGS ? "PGS" : "TGS"; }

const char* integrator_name(Integrator integrator) {
  switch (integrator) {
    case Integrator::SemiImplicitEuler: return "semi-implicit Euler";
    case Integrator::Trapezoid: return "trapezoid";
    case Integrator::RK4: return "RK4";
    case Integrator::ExplicitEuler: return "explicit Euler";
  }
  return "?";
}

const char* stage_name(Stage stage) {
  switch (stage) {
    case Stage::Drives: return "drives";
    case Stage::Damping: return "damping";
    case Stage::Springs: return "springs";
    case Stage::SoftLimits: return "soft limits";
    case Stage::StribeckFriction: return "Stribeck friction";
    case Stage::ExternalWrenches: return "external wrenches";
    case Stage::LinkDamping: return "link damping";
    case Stage::PerCopyInertia: return "per-copy inertia";
    case Stage::PerCopyJointParameters: return "per-copy joint parameters";
    case Stage::MimicJoints: return "mimic joints";
    case Stage::FixedTendons: return "fixed tendons";
    case Stage::HardLimits: return "hard limits";
    case Stage::VelocityLimits: return "velocity limits";
    case Stage::CoulombFriction: return "Coulomb friction";
    case Stage::Contacts: return "contacts";
    case Stage::Count: break;
  }
  return "?";
}

const char* fault_name(Fault fault) {
  switch (fault) {
    case Fault::None: return "none";
    case Fault::NonFiniteTorque: return "non-finite torque";
    case Fault::NonFiniteTarget: return "non-finite drive target";
    case Fault::NonFiniteWrench: return "non-finite wrench";
    case Fault::NonFiniteGravity: return "non-finite gravity";
    case Fault::NonFiniteState: return "non-finite state";
  }
  return "?";
}

std::vector<DofSettings> default_dof_settings(const Model& model) {
  std::vector<DofSettings> dofs(model.nv);
  for (int k = 0; k < model.nv; ++k) {
    DofSettings& d = dofs[k];
    d.max_force = model.dof_effort_limit[k];
    d.damping = model.dof_damping[k];
    d.spring_stiffness = model.dof_spring_stiffness[k];
    d.spring_rest = model.dof_spring_rest[k];
    d.friction = model.dof_friction[k];
    d.lower = model.dof_lower[k];
    d.upper = model.dof_upper[k];
    d.velocity_limit = model.dof_velocity_limit[k];
  }
  return dofs;
}

JointParameters scene_joint_parameters(const Model& model, const std::vector<DofSettings>& dofs) {
  JointParameters p;
  for (Eigen::VectorXd* x : {&p.drive_stiffness, &p.drive_damping, &p.damping, &p.armature, &p.friction})
    x->resize(model.nv);
  for (int k = 0; k < model.nv; ++k) {
    const DofSettings& d = dofs[k];
    p.drive_stiffness[k] = d.drive_stiffness;
    p.drive_damping[k] = d.drive_damping;
    p.damping[k] = d.damping;
    p.armature[k] = model.dof_armature[k];
    p.friction[k] = d.friction_model == FrictionModel::Coulomb ? d.friction : 0.0;
  }
  return p;
}

}  // namespace lockstep
