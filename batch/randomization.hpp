// Per-copy randomisation at reset (domain randomisation): ranges a copy's
// parameters and initial state are drawn from, uniformly, every time the
// copy is reset. Nothing is rebuilt: the draws overwrite the copy's
// per-copy parameters in the batch. Draw k of a field for copy c at its r-th
// reset is Philox4x32-10 at counter (c, r, field, k) under the seed, so the
// values never depend on threads, batch size or which other copies reset.
#pragma once

#include "layout/model.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace lockstep {

// A value drawn uniformly from [low, high]; low == high always gives low.
struct UniformRange {
  double low = 0.0, high = 0.0;
  bool fixed() const { return low == high; }
};

struct Randomization {
  // Inertial parameters, per body: the mass and the rotational inertia are
  // scaled together (a density scale); the COM moves by an offset drawn per
  // body-frame axis [m].
  UniformRange mass_scale{1.0, 1.0};
  UniformRange com_offset{0.0, 0.0};
  // Ground friction coefficient (absolute); used when the scene has a ground.
  // Unset (the default) keeps the contact settings' value.
  bool randomize_ground_friction = false;
  UniformRange ground_friction{1.0, 1.0};
  // Per DOF: drive gains and joint damping scale their configured values;
  // armature adds to the model's [kg m^2 or kg].
  UniformRange kp_scale{1.0, 1.0};
  UniformRange kd_scale{1.0, 1.0};
  UniformRange damping_scale{1.0, 1.0};
  UniformRange armature_add{0.0, 0.0};
  UniformRange joint_friction_scale{1.0, 1.0};  // per DOF: scales its Coulomb joint friction
  // per actuator: its strength, the share of its motor's torque that
  // reaches the joints (Simulator::set_actuator_strength)
  UniformRange actuator_strength_scale{1.0, 1.0};
  // Added to each axis of the scene's gravity [m/s^2].
  UniformRange gravity_offset{0.0, 0.0};
  // Initial-state noise, added to the configured initial state: each
  // revolute and prismatic joint's position (then clamped to its limits) and
  // velocity; a floating root's x and y [m], yaw about world z [rad] and each
  // of its six body-frame twist components.
  UniformRange joint_position_noise{0.0, 0.0};
  UniformRange joint_velocity_noise{0.0, 0.0};
  UniformRange root_position_noise{0.0, 0.0};
  UniformRange root_yaw_noise{0.0, 0.0};
  UniformRange root_velocity_noise{0.0, 0.0};

  // True when every range is fixed at its neutral value.
  bool is_identity() const;
};

// Throws std::invalid_argument naming the field: a non-finite bound, low >
// high, a mass scale that is not positive, a negative friction, scale or
// armature.
void validate_randomization(const Randomization& r);

// The ranges in a fixed order, with their names (as in scene files and
// rollout attributes); field i draws with counter word 2 = i.
struct RandomizationField {
  const char* name;
  UniformRange Randomization::*range;
};
const std::vector<RandomizationField>& randomization_fields();

// Draw k of field `field` for (seed, copy, reset), uniform in the range.
double draw(const UniformRange& range, std::uint64_t seed, int copy, std::uint32_t reset, int field, int k);
// The same for one of r's ranges, named by member (its field number is its
// place in randomization_fields()).
double draw(const Randomization& r, UniformRange Randomization::*range, std::uint64_t seed, int copy,
            std::uint32_t reset, int k);

}  // namespace lockstep
