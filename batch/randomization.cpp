#include "batch/randomization.hpp"

#include "batch/counter_rng.hpp"
#include "batch/require.hpp"

#include <cmath>
#include <stdexcept>

namespace lockstep {

const std::vector<RandomizationField>& randomization_fields() {
  // Append only: a field's position is its counter word, so inserting one
  // would change every later field's draws for a given seed.
  static const std::vector<RandomizationField> fields = {
      {"mass_scale", &Randomization::mass_scale},
      {"com_offset", &Randomization::com_offset},
      {"ground_friction", &Randomization::ground_friction},
      {"kp_scale", &Randomization::kp_scale},
      {"kd_scale", &Randomization::kd_scale},
      {"damping_scale", &Randomization::damping_scale},
      {"armature_add", &Randomization::armature_add},
      {"gravity_offset", &Randomization::gravity_offset},
      {"joint_position_noise", &Randomization::joint_position_noise},
      {"joint_velocity_noise", &Randomization::joint_velocity_noise},
      {"root_position_noise", &Randomization::root_position_noise},
      {"root_yaw_noise", &Randomization::root_yaw_noise},
      {"root_velocity_noise", &Randomization::root_velocity_noise},
      {"joint_friction_scale", &Randomization::joint_friction_scale},
      {"actuator_strength_scale", &Randomization::actuator_strength_scale},
  };
  return fields;
}

bool Randomization::is_identity() const {
  const Randomization neutral;
  if (randomize_ground_friction) return false;
  for (const RandomizationField& f : randomization_fields()) {
    const UniformRange &a = this->*f.range, &b = neutral.*f.range;
    if (a.low != b.low || a.high != b.high) return false;
  }
  return true;
}

void validate_randomization(const Randomization& r) {
  for (const RandomizationField& f : randomization_fields()) {
    const UniformRange& range = r.*f.range;
    const std::string name = std::string("randomization.") + f.name;
    if (!std::isfinite(range.low) || !std::isfinite(range.high))
      throw std::invalid_argument(name + ": the range's bounds must be finite");
    if (range.low > range.high)
      throw std::invalid_argument(name + ": low " + number_text(range.low) + " is above high " +
                                  number_text(range.high));
  }
  auto at_least = [](const UniformRange& range, double bound, bool strict, const char* field) {
    if (strict ? range.low <= bound : range.low < bound)
      throw std::invalid_argument(std::string("randomization.") + field + ": low must be " +
                                  (strict ? "> " : ">= ") + number_text(bound) + ", got " + number_text(range.low));
  };
  at_least(r.mass_scale, 0.0, true, "mass_scale");
  at_least(r.ground_friction, 0.0, false, "ground_friction");
  at_least(r.kp_scale, 0.0, false, "kp_scale");
  at_least(r.kd_scale, 0.0, false, "kd_scale");
  at_least(r.damping_scale, 0.0, false, "damping_scale");
  at_least(r.armature_add, 0.0, false, "armature_add");
  at_least(r.joint_friction_scale, 0.0, false, "joint_friction_scale");
  at_least(r.actuator_strength_scale, 0.0, true, "actuator_strength_scale");
}

double draw(const UniformRange& range, std::uint64_t seed, int copy, std::uint32_t reset, int field, int k) {
  if (range.fixed()) return range.low;
  const PhiloxCounter bits = philox4x32(
      {static_cast<std::uint32_t>(copy), reset, static_cast<std::uint32_t>(field), static_cast<std::uint32_t>(k)},
      seed);
  return range.low + (range.high - range.low) * unit_double(bits[0], bits[1]);
}

double draw(const Randomization& r, UniformRange Randomization::*range, std::uint64_t seed, int copy,
            std::uint32_t reset, int k) {
  if ((r.*range).fixed()) return (r.*range).low;  // no field number needed
  const std::vector<RandomizationField>& fields = randomization_fields();
  for (std::size_t f = 0; f < fields.size(); ++f)
    if (fields[f].range == range) return draw(r.*range, seed, copy, reset, static_cast<int>(f), k);
  throw std::logic_error("draw: a range missing from randomization_fields()");
}

}  // namespace lockstep
